#!/usr/bin/env python3
"""SAC training of HERB's placement policy in our packing world (herb_sim), in chunks.

    python models/continuous/train.py --config models/continuous/configs/cs06.toml --out runs/cs06 [--minutes 8]

One call is one chunk: it resumes from ``<out>/checkpoint-{actor,critic}.pt`` when present, trains for
``run.chunk_minutes`` (or ``--minutes``), then saves the checkpoint, exports the deterministic
actor to ``<out>/policy.onnx`` (only if it passes the ONNX contract check and matches PyTorch
within 1e-4 in onnxruntime; a failing export never replaces a good one), writes parity samples
(``policy.parity.bin`` + ``.json``) for the tract test, and appends progress to
``<out>/progress.csv``. The checkpoint is three files, each under 16 MiB (the accelerator
returns at most 8 files of 16 MiB per call): actor (with its and the temperature's Adam
state), critic and target, and the critic's Adam state. The replay buffer is not saved: it
restarts with every chunk.

Networks (``[net] pool`` in the config): ``herbnet112`` (pool = 2, chosen by the decision-latency
benchmark): 2 x 2 average pool of the [2, 224, 224] observation, convolutions 16@8s4, 32@4s2,
32@3s1 (ReLU); ``herblite56`` (pool = 4, the CPU recipe): 4 x 4 average pool, convolutions
16@5s2, 32@3s2, 32@3s2. Both continue with an MLP 256-256-256 (ReLU), then a Gaussian head
(actor) or two Q values (twin critic heads on one shared extractor, trained by the critic loss
only; the actor's loss reads it without gradient, as in DrQ).
Observations are stored pooled and quantised to uint8 (1/255 of the 0.30 m height scale,
1.2 mm) to fit the buffer in memory; the exported actor takes the full-resolution float input.

Guidance by the BLBF heuristic (optional ``[bc]`` table; without it, plain SAC as in the
paper): every stored state is labelled with the BLBF action (``VecEnv.expert_actions``, the
daemon's ``Blbf``); for the first ``bc.expert_act_steps`` steps each environment acts with
that label with a probability falling linearly from ``bc.expert_act`` to 0 (off-policy
demonstrations), and the actor's loss is the SAC loss divided by the batch's mean |Q| plus
``w`` times the squared distance of its mean action to the label, ``w`` falling linearly from
``bc.weight_start`` to ``bc.weight_end`` over ``bc.decay_steps`` (as in TD3+BC).
``run.snapshot_every_min`` saves the actor to ``<out>/snapshots/actor-<steps>.pt``;
``--export-snapshot`` exports one of them instead of training.
"""

import argparse
import csv
import json
import math
import os
import pickle
import random
import sys
import time
import tomllib
import warnings

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

import herb_sim

NETS = {2: "herbnet112", 4: "herblite56"}
CONTRACT = dict(input=herb_sim.INPUT_NAME, input_shape=list(herb_sim.MODEL_INPUT_SHAPE),
                output=herb_sim.OUTPUT_NAME, output_shape=list(herb_sim.MODEL_OUTPUT_SHAPE))
C_OBS, S_OBS = herb_sim.OBS_CHANNELS, herb_sim.OBS_SIZE  # [2, 224, 224]


def load_config(path):
    try:
        with open(path, "rb") as f:
            c = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise SystemExit(f"{path}: cannot read the config: {err}")
    for key in ("name", "seed", "env", "sac", "run"):
        if key not in c:
            raise SystemExit(f"{path}: missing '{key}'")
    s = c["sac"]
    for key in ("total_steps", "learning_starts", "buffer_size", "batch_size"):
        if not (isinstance(s.get(key), int) and s[key] > 0):
            raise SystemExit(f"{path}: sac.{key} must be a positive integer")
    for key in ("updates_per_step", "gamma", "tau", "lr"):
        if not (isinstance(s.get(key), (int, float)) and s[key] > 0):
            raise SystemExit(f"{path}: sac.{key} must be a positive number")
    b = c.get("bc")
    if b is not None:
        for key in ("expert_act", "weight_start", "weight_end"):
            v = b.get(key)
            if not (isinstance(v, (int, float)) and v >= 0):
                raise SystemExit(f"{path}: bc.{key} must be a number >= 0")
        if b["expert_act"] > 1:
            raise SystemExit(f"{path}: bc.expert_act is a probability, in [0, 1]")
        for key in ("expert_act_steps", "decay_steps"):
            if not (isinstance(b.get(key), int) and b[key] > 0):
                raise SystemExit(f"{path}: bc.{key} must be a positive integer")
    pool = c.setdefault("net", {}).setdefault("pool", 2)
    if pool not in NETS:
        raise SystemExit(f"{path}: net.pool must be one of {sorted(NETS)} (got {pool!r})")
    return c


def make_env(c, seed, boxed=None, threads=None):
    """The vectorised environment of config `c`'s ``[env]`` table."""
    e = c["env"]
    return herb_sim.HerbVectorEnv(
        e["num_envs"], reward=e["reward"], sequence=e["sequence"], seed=seed,
        min_objects=e["min_objects"], max_objects=e["max_objects"], meshes=e["meshes"],
        boxed=boxed, threads=threads,
    )


def pooled_shape(pool):
    """Shape of one stored (pooled) observation."""
    return (C_OBS, S_OBS // pool, S_OBS // pool)


def extractor(pool):
    """Convolutional features of a pooled observation; returns (module, feature count)."""
    if pool == 2:
        convs = [nn.Conv2d(2, 16, 8, stride=4), nn.ReLU(), nn.Conv2d(16, 32, 4, stride=2), nn.ReLU()]
        side = 10
        last = nn.Conv2d(32, 32, 3, stride=1)
    else:
        convs = [nn.Conv2d(2, 16, 5, stride=2), nn.ReLU(), nn.Conv2d(16, 32, 3, stride=2), nn.ReLU()]
        side = 5
        last = nn.Conv2d(32, 32, 3, stride=2)
    return nn.Sequential(*convs, last, nn.ReLU(), nn.Flatten()), 32 * side * side


def mlp(n_in, n_out):
    return nn.Sequential(
        nn.Linear(n_in, 256), nn.ReLU(),
        nn.Linear(256, 256), nn.ReLU(),
        nn.Linear(256, 256), nn.ReLU(),
        nn.Linear(256, n_out),
    )


class Actor(nn.Module):
    """Gaussian policy on pooled observations; tanh-squashed actions in (-1, 1)."""

    def __init__(self, pool=2):
        super().__init__()
        self.pool = pool
        self.features, n = extractor(pool)
        self.body = mlp(n, 6)

    def forward(self, x):
        mu, log_std = self.body(self.features(x)).chunk(2, dim=-1)
        return mu, log_std.clamp(-20.0, 2.0)

    def sample(self, x):
        """A sampled action, its log-probability and the deterministic action tanh(mean)."""
        mu, log_std = self(x)
        std = log_std.exp()
        u = mu + std * torch.randn_like(mu)
        a = torch.tanh(u)
        logp = (-0.5 * ((u - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        logp = logp - (2 * (math.log(2) - u - F.softplus(-2 * u))).sum(-1)
        return a, logp, torch.tanh(mu)


class Deployed(nn.Module):
    """What ships: full observation in, deterministic action (tanh of the mean) out."""

    def __init__(self, actor):
        super().__init__()
        self.actor = actor

    def forward(self, obs):
        mu, _ = self.actor(F.avg_pool2d(obs, self.actor.pool))
        return torch.tanh(mu)


class Critic(nn.Module):
    """Twin Q heads on one extractor."""

    def __init__(self, pool=2):
        super().__init__()
        self.features, n = extractor(pool)
        self.q1, self.q2 = mlp(n + 3, 1), mlp(n + 3, 1)

    def heads(self, h, a):
        """Both Q values from extracted features `h` and actions `a`."""
        ha = torch.cat([h, a], -1)
        return self.q1(ha).squeeze(-1), self.q2(ha).squeeze(-1)

    def forward(self, x, a):
        return self.heads(self.features(x), a)


def pool_u8(obs, pool):
    """[N, 2, 224, 224] float in [0, 1] -> [N, 2, 224/pool, 224/pool] uint8."""
    n, m = obs.shape[0], S_OBS // pool
    p = obs.reshape(n, C_OBS, m, pool, m, pool).mean(axis=(3, 5))
    return np.rint(p * 255.0).astype(np.uint8)


class Replay:
    """Transitions, each with the expert's label of its state (zero and invalid without one)."""

    def __init__(self, size, shape):
        self.obs = np.zeros((size, *shape), np.uint8)
        self.next = np.zeros((size, *shape), np.uint8)
        self.act = np.zeros((size, 3), np.float32)
        self.rew = np.zeros(size, np.float32)
        self.done = np.zeros(size, np.float32)
        self.expert = np.zeros((size, 3), np.float32)
        self.valid = np.zeros(size, np.float32)
        self.size, self.n, self.i = size, 0, 0

    def add(self, o, a, r, o2, d, ea, ev):
        for k in range(len(a)):
            j = self.i
            self.obs[j], self.next[j], self.act[j], self.rew[j], self.done[j] = o[k], o2[k], a[k], r[k], d[k]
            self.expert[j], self.valid[j] = ea[k], ev[k]
            self.i = (self.i + 1) % self.size
            self.n = min(self.n + 1, self.size)

    def sample(self, b, dev):
        """(obs, action, reward, next obs, done, expert action, expert valid) tensors."""
        idx = np.random.randint(0, self.n, size=b)
        f = lambda x: torch.as_tensor(x[idx], device=dev)
        return (f(self.obs).float() / 255.0, f(self.act), f(self.rew),
                f(self.next).float() / 255.0, f(self.done), f(self.expert), f(self.valid))


def sac_update(actor, critic, target, log_alpha, opts, batch, gamma, tau, target_entropy, bc_weight=None):
    """One SAC update: twin critics on the soft Bellman target, then the actor, then the
    entropy temperature, then a Polyak step of the target critics. `opts` = (actor, critic,
    temperature) optimisers; `batch` = (obs, action, reward, next obs, done, expert action,
    expert valid). With `bc_weight` (a number), the actor's loss is normalised by the mean |Q|
    and adds that weight times the squared distance of the mean action to the expert's; returns
    that distance (mean over labelled states), else None."""
    opt_a, opt_c, opt_t = opts
    o, ac, r, o2, d, ea, ev = batch
    alpha = log_alpha.exp().detach()
    with torch.no_grad():
        a2, logp2, _ = actor.sample(o2)
        q1t, q2t = target(o2, a2)
        y = r + gamma * (1 - d) * (torch.min(q1t, q2t) - alpha * logp2)
    q1, q2 = critic(o, ac)
    loss_c = F.mse_loss(q1, y) + F.mse_loss(q2, y)
    opt_c.zero_grad(set_to_none=True)
    loss_c.backward()
    opt_c.step()
    an, logp, mean_a = actor.sample(o)
    with torch.no_grad():
        h = critic.features(o)
    qn = torch.min(*critic.heads(h, an))
    loss_a = (alpha * logp - qn).mean()
    bc = None
    if bc_weight is not None:
        dist = ((mean_a - ea) ** 2).sum(-1)
        bc = (dist * ev).sum() / ev.sum().clamp(min=1.0)
        loss_a = loss_a / qn.detach().abs().mean().clamp(min=1e-3) + bc_weight * bc
    opt_a.zero_grad(set_to_none=True)
    loss_a.backward()
    opt_a.step()
    loss_t = -(log_alpha * (logp.detach() + target_entropy)).mean()
    opt_t.zero_grad(set_to_none=True)
    loss_t.backward()
    opt_t.step()
    with torch.no_grad():
        for p, pt in zip(critic.parameters(), target.parameters()):
            pt.mul_(1 - tau).add_(tau * p)
    return None if bc is None else bc.item()


def export(actor, out, env, dev):
    """Exports the deterministic actor; replaces out/policy.onnx only if it passes the checks."""
    import onnx
    import onnxruntime as ort

    model = Deployed(actor).to("cpu").eval()
    tmp = os.path.join(out, "policy.onnx.tmp")
    dummy = torch.zeros(*CONTRACT["input_shape"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(model, dummy, tmp, input_names=[CONTRACT["input"]],
                          output_names=[CONTRACT["output"]], opset_version=17, dynamo=False)
    m = onnx.load(tmp)
    onnx.checker.check_model(m)
    dims = lambda v: [d.dim_value for d in v.type.tensor_type.shape.dim]
    ins, outs = m.graph.input, m.graph.output
    ok = (len(ins) == 1 and ins[0].name == CONTRACT["input"] and dims(ins[0]) == CONTRACT["input_shape"]
          and len(outs) == 1 and outs[0].name == CONTRACT["output"] and dims(outs[0]) == CONTRACT["output_shape"])
    if not ok:
        os.remove(tmp)
        raise RuntimeError("exported model breaks the I/O contract; the shipped one is kept")
    # Parity samples: real observations from the environment.
    obs = env.reset(seed=12345)[0][:4]
    sess = ort.InferenceSession(tmp, providers=["CPUExecutionProvider"])
    expect = []
    for k in range(len(obs)):
        x = obs[k:k + 1].astype(np.float32)
        with torch.no_grad():
            t = model(torch.as_tensor(x)).numpy()
        o = sess.run(None, {CONTRACT["input"]: x})[0]
        if not np.allclose(t, o, atol=1e-4):
            os.remove(tmp)
            raise RuntimeError(f"onnxruntime differs from PyTorch: {t} vs {o}")
        expect.append(t[0].tolist())
    os.replace(tmp, os.path.join(out, "policy.onnx"))
    obs.astype("<f4").tofile(os.path.join(out, "policy.parity.bin"))
    with open(os.path.join(out, "policy.parity.json"), "w") as f:
        json.dump({"samples": len(expect), "shape": CONTRACT["input_shape"], "actions": expect}, f)


def progress_row(steps, updates, episodes, wall, ep_len, ep_ret, dev, bc=None):
    """One line of progress.csv: totals so far, the mean length (objects packed) and return
    of the last 200 episodes that ended, and with BLBF guidance the actor's last mean squared
    distance to the expert's action (`bc_dist`, over the last 200 updates)."""
    row = {"steps": steps, "updates": updates, "episodes": episodes, "wall_s": round(wall, 1),
           "mean_len": round(float(np.mean(ep_len[-200:])), 3) if ep_len else "",
           "mean_return": round(float(np.mean(ep_ret[-200:])), 4) if ep_ret else "",
           "device": str(dev)}
    if bc is not None:
        row["bc_dist"] = round(float(np.mean(bc[-200:])), 5) if bc else ""
    return row


def ramp(start, end, steps, t):
    """Linear from `start` at t = 0 to `end` at t = `steps`, then `end`."""
    return end + (start - end) * max(0.0, 1.0 - t / steps)


def append_progress(out, row):
    path = os.path.join(out, "progress.csv")
    new = not os.path.exists(path)
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--minutes", type=float, default=None,
                    help="chunk length (default run.chunk_minutes; 'inf' trains to sac.total_steps)")
    ap.add_argument("--boxed", default=None)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--export-snapshot", default=None, metavar="ACTOR_PT",
                    help="export this saved actor (a snapshot) to <out>/policy.onnx, and stop")
    a = ap.parse_args()
    c = load_config(a.config)
    e, s = c["env"], c["sac"]
    os.makedirs(a.out, exist_ok=True)
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    seed = int(c["seed"])
    env = make_env(c, seed, a.boxed, a.threads)
    pool = c["net"]["pool"]
    if a.export_snapshot is not None:
        actor = Actor(pool)
        try:
            actor.load_state_dict(torch.load(a.export_snapshot, map_location="cpu", weights_only=False)["actor"])
        except (OSError, KeyError, ValueError, EOFError, RuntimeError, pickle.UnpicklingError) as err:
            raise SystemExit(f"{a.export_snapshot}: not an actor snapshot of a {NETS[pool]} run "
                             f"(net.pool = {pool} in {a.config}): {err}")
        export(actor, a.out, env, torch.device("cpu"))
        print(f"exported {a.export_snapshot} to {os.path.join(a.out, 'policy.onnx')}", flush=True)
        return 0
    bc = c.get("bc")
    actor, critic = Actor(pool).to(dev), Critic(pool).to(dev)
    target = Critic(pool).to(dev)
    target.load_state_dict(critic.state_dict())
    log_alpha = torch.zeros((), device=dev, requires_grad=True)
    opt_a = torch.optim.Adam(actor.parameters(), lr=s["lr"])
    opt_c = torch.optim.Adam(critic.parameters(), lr=s["lr"])
    opt_t = torch.optim.Adam([log_alpha], lr=s["lr"])
    steps, updates, episodes, wall = 0, 0, 0, 0.0
    ck_a = os.path.join(a.out, "checkpoint-actor.pt")
    ck_c = os.path.join(a.out, "checkpoint-critic.pt")
    ck_o = os.path.join(a.out, "checkpoint-critic-adam.pt")
    if os.path.exists(ck_a) and os.path.exists(ck_c):
        st = torch.load(ck_a, map_location=dev, weights_only=False)
        sc = torch.load(ck_c, map_location=dev, weights_only=False)
        actor.load_state_dict(st["actor"])
        opt_a.load_state_dict(st["opt_a"])
        opt_t.load_state_dict(st["opt_t"])
        critic.load_state_dict(sc["critic"])
        target.load_state_dict(sc["target"])
        if os.path.exists(ck_o):  # absent in checkpoints from before it was saved
            opt_c.load_state_dict(torch.load(ck_o, map_location=dev, weights_only=False))
        with torch.no_grad():
            log_alpha.copy_(st["log_alpha"])
        steps, updates, episodes, wall = st["steps"], st["updates"], st["episodes"], st["wall_s"]
        seed = seed + steps  # a fresh stream of episodes per chunk
        print(f"resumed at {steps} steps, {updates} updates", flush=True)
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)
    buf = Replay(s["buffer_size"], pooled_shape(pool))
    obs = env.reset(seed=seed)[0]
    po = pool_u8(obs, pool)
    n = e["num_envs"]
    minutes = a.minutes if a.minutes is not None else c["run"]["chunk_minutes"]
    t0 = last_log = time.time()
    ep_len, ep_ret, bc_dist = [], [], []
    debt = 0.0
    chunk_start, chunk_updates = steps, updates
    snap_every = c["run"].get("snapshot_every_min")
    last_snap = time.time()
    no_label = (np.zeros((n, 3), np.float32), np.zeros(n, bool))
    while steps < s["total_steps"] and time.time() - t0 < minutes * 60:
        if steps - chunk_start < s["learning_starts"] and updates == 0:
            act = np.random.uniform(-1, 1, size=(n, 3)).astype(np.float32)
        else:
            with torch.no_grad():
                x = torch.as_tensor(po, device=dev).float() / 255.0
                act = actor.sample(x)[0].cpu().numpy().astype(np.float32)
        ea, ev = env.expert_actions() if bc else no_label
        if bc:
            p = ramp(bc["expert_act"], 0.0, bc["expert_act_steps"], steps)
            use = ev & (np.random.random_sample(n) < p)
            act[use] = ea[use]
        obs2, rew, term, _, info = env.step(act)
        # With same-step autoreset the returned observation of an ended episode is the next
        # episode's first; its value is never bootstrapped (done = 1), so it is stored as is.
        po2 = pool_u8(obs2, pool)
        buf.add(po, act, rew, po2, term.astype(np.float32), ea, ev.astype(np.float32))
        po = po2
        steps += n
        for k in np.flatnonzero(term):
            episodes += 1
            ep_len.append(int(info["episode_length"][k]))
            ep_ret.append(float(info["episode_return"][k]))
        if buf.n >= max(s["batch_size"], s["learning_starts"]):
            debt += n * s["updates_per_step"]
            while debt >= 1.0:
                debt -= 1.0
                w = ramp(bc["weight_start"], bc["weight_end"], bc["decay_steps"], steps) if bc else None
                d = sac_update(actor, critic, target, log_alpha, (opt_a, opt_c, opt_t),
                               buf.sample(s["batch_size"], dev), s["gamma"], s["tau"],
                               s["target_entropy"], w)
                if d is not None:
                    bc_dist.append(d)
                    del bc_dist[:-200]
                updates += 1
        if snap_every and time.time() - last_snap >= snap_every * 60:
            last_snap = time.time()
            os.makedirs(os.path.join(a.out, "snapshots"), exist_ok=True)
            torch.save({"actor": actor.state_dict(), "steps": steps, "updates": updates},
                       os.path.join(a.out, "snapshots", f"actor-{steps}.pt"))
        if time.time() - last_log >= c["run"]["log_every_s"]:
            last_log = time.time()
            el = time.time() - t0
            row = progress_row(steps, updates, episodes, wall + el, ep_len, ep_ret, dev,
                               bc_dist if bc else None)
            append_progress(a.out, row)
            print(f"steps {steps} ({(steps - chunk_start) / el:.0f}/s) updates {updates} "
                  f"({(updates - chunk_updates) / max(el, 1e-9):.1f}/s this chunk) episodes {episodes} "
                  f"len {row['mean_len']} return {row['mean_return']} alpha {log_alpha.exp().item():.4f}"
                  f"{' bc_dist ' + str(row['bc_dist']) if bc else ''}",
                  flush=True)
    wall += time.time() - t0
    # Three files under 16 MiB each (the accelerator returns at most 16 MiB per file).
    meta = {"steps": steps, "updates": updates, "episodes": episodes, "wall_s": wall, "config": c}
    torch.save({"actor": actor.state_dict(), "opt_a": opt_a.state_dict(), "opt_t": opt_t.state_dict(),
                "log_alpha": log_alpha.detach(), **meta}, ck_a + ".tmp")
    torch.save({"critic": critic.state_dict(), "target": target.state_dict()}, ck_c + ".tmp")
    torch.save(opt_c.state_dict(), ck_o + ".tmp")
    os.replace(ck_a + ".tmp", ck_a)
    os.replace(ck_c + ".tmp", ck_c)
    os.replace(ck_o + ".tmp", ck_o)
    row = progress_row(steps, updates, episodes, wall, ep_len, ep_ret, dev, bc_dist if bc else None)
    append_progress(a.out, row)
    export(actor, a.out, env, dev)
    print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
