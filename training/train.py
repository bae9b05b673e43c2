#!/usr/bin/env python3
"""Discrete SAC over the placement lattice's candidates, with the lookahead teacher's prior data.

    python training/train.py --config training/configs/cs06-start.toml --out runs/cs06-start          # start
    python training/train.py --config training/configs/cs06-start.toml --out runs/cs06-start --resume # go on

The shipped recipe (training/README.md; the continuous-action recipe it replaced is in git
history, docs/research-log.md).
A policy here does not regress a placement: for each decision, Rust (``herb_sim.features``)
lists up to 64 feasible candidate placements of the next object from the placement lattice
(``herb_sim`` ``sim/src/lattice.rs``), each described by a row of features, plus a context
vector (the pooled heightmap, the next object, the rest of the job); the actor scores the
candidates (one shared network per candidate, so weights are shared across positions) and
the critic gives each a Q value. Infeasible placements are never candidates: they are masked,
not penalised.

Phases, in order, each resumable (one run folder holds everything):

1. ``collect``: the lookahead teacher (``VecEnv.teacher``: the first ``teacher.k``
   candidates each simulated to the episode's end with the lattice BLBF rule after it) acts
   in ``teacher.episodes`` training episodes. Every state is stored with the teacher's
   choice and the simulated return of each candidate it tried: the prior data.
2. ``offline``: ``offline.updates`` updates on the prior data alone: the critic regresses
   both TD targets and the simulated returns of all tried candidates (dense, counterfactual
   supervision), the actor imitates the teacher (cross-entropy) beside the SAC loss.
3. ``online``: discrete SAC (Christodoulou 2019: exact expectations over candidates; twin
   critics with LayerNorm, min of targets, a modest entropy target), acting with its own
   policy in ``env.num_envs`` environments, each batch half prior and half online data
   (RLPD, Ball et al. 2023), the imitation weight decaying to ``sac.bc_weight_end``.

Every batch is augmented with the box's half turn (``herb_sim.half_turn_*``) with probability
1/2: exact for the box. Every ``run.chunk_minutes``, at the run's end (``--minutes``, default
one chunk, ``inf`` to the end of the last phase) and on SIGTERM, the run saves its checkpoint
**and its replay buffer** atomically (write, then rename); at the run's end and on SIGTERM it
also exports ``policy.onnx`` (the candidate contract: inputs ``context``, ``candidates``,
``mask``; output ``logits``) with parity samples. ``progress.csv`` grows by a row every
``run.log_every_s``. ``--resume`` continues where the last save stopped; a missing or corrupt
checkpoint or buffer is an error naming the file, never a silent restart from an empty buffer.
"""

import argparse
import csv
import json
import math
import os
import signal
import sys
import time
import tomllib
import warnings
import zipfile

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

import herb_sim

C = herb_sim.MAX_CANDIDATES
G = herb_sim.CONTEXT_LEN
FEAT = herb_sim.CANDIDATE_LEN
NEG = -1e9  # masked logit (finite: exported graphs stay NaN-free)
PHASES = ("collect", "offline", "online", "done")


def load_config(path):
    """The run configuration; a clear error names what is missing or wrong."""
    try:
        with open(path, "rb") as f:
            c = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise SystemExit(f"{path}: cannot read the config: {err}")
    need = {
        "env": ("reward", "sequence", "num_envs", "min_objects", "max_objects"),
        "teacher": ("k", "episodes"),
        "offline": ("updates",),
        "sac": ("total_steps", "batch_size", "updates_per_step", "gamma", "tau", "lr",
                "entropy_frac", "bc_weight_start", "bc_weight_end", "bc_decay_steps",
                "mc_weight", "buffer_size"),
        "run": ("chunk_minutes", "log_every_s"),
    }
    for table, keys in need.items():
        if table not in c:
            raise SystemExit(f"{path}: missing table [{table}]")
        for k in keys:
            if k not in c[table]:
                raise SystemExit(f"{path}: missing {table}.{k}")
    for k in ("num_envs", "min_objects", "max_objects"):
        if not (isinstance(c["env"][k], int) and c["env"][k] > 0):
            raise SystemExit(f"{path}: env.{k} must be a positive integer")
    if not 1 <= c["teacher"]["k"] <= C:
        raise SystemExit(f"{path}: teacher.k must be 1 to {C}")
    h = c["teacher"].get("horizon")
    if h is not None and not (isinstance(h, int) and h >= 1):
        raise SystemExit(f"{path}: teacher.horizon must be a positive integer (objects per rollout)")
    for k in ("total_steps", "batch_size", "buffer_size"):
        if not (isinstance(c["sac"][k], int) and c["sac"][k] > 0):
            raise SystemExit(f"{path}: sac.{k} must be a positive integer")
    if "seed" not in c or "name" not in c:
        raise SystemExit(f"{path}: missing 'name' or 'seed'")
    return c


def make_env(c, seed, boxed=None, threads=None):
    """The vectorised environment of config `c`'s ``[env]`` table."""
    e = c["env"]
    return herb_sim.HerbVectorEnv(
        e["num_envs"], reward=e["reward"], sequence=e["sequence"], seed=seed,
        min_objects=e["min_objects"], max_objects=e["max_objects"], meshes=e.get("meshes", True),
        boxed=boxed, threads=threads,
    )


class Scorer(nn.Module):
    """Scores every candidate of a decision: a context encoder, one MLP shared by all
    candidates (their row plus the context code), and a second layer that also sees the mean
    code of the decision's candidates. ``heads`` outputs per candidate. A linear layer over a
    candidate's row joined with a decision-wide code is written as the sum of two linear maps
    (the decision's part computed once), which is the same function and keeps the exported
    graph free of broadcast concatenations."""

    def __init__(self, heads, width=64, ctx_len=G, cand_len=FEAT):
        super().__init__()
        self.ctx = nn.Sequential(nn.Linear(ctx_len, 128), nn.LayerNorm(128), nn.ReLU(),
                                 nn.Linear(128, width), nn.ReLU())
        self.cand_in = nn.Linear(cand_len, width)
        self.ctx_in = nn.Linear(width, width, bias=False)
        self.cand = nn.Sequential(nn.LayerNorm(width), nn.ReLU(), nn.Linear(width, width), nn.ReLU())
        self.own = nn.Linear(width, width)
        self.mean_in = nn.Linear(width, width, bias=False)
        self.out = nn.Sequential(nn.LayerNorm(width), nn.ReLU(), nn.Linear(width, heads))

    def forward(self, ctx, cand, mask):
        g = self.ctx(ctx)
        h = self.cand(self.cand_in(cand) + self.ctx_in(g)[:, None, :])
        m = mask[..., None]
        pooled = (h * m).sum(1) / m.sum(1).clamp(min=1.0)
        return self.out(self.own(h) + self.mean_in(pooled)[:, None, :])


class Actor(nn.Module):
    """Masked logits over candidates."""

    def __init__(self):
        super().__init__()
        self.net = Scorer(1)

    def forward(self, ctx, cand, mask):
        logits = self.net(ctx, cand, mask)[..., 0]
        return torch.where(mask > 0, logits, torch.full_like(logits, NEG))


class Critic(nn.Module):
    """Twin Q values per candidate, two separate networks: ``[B, C, 2]``."""

    def __init__(self):
        super().__init__()
        self.q1, self.q2 = Scorer(1), Scorer(1)

    def forward(self, ctx, cand, mask):
        return torch.cat([self.q1(ctx, cand, mask), self.q2(ctx, cand, mask)], -1)


def parse_reward(text):
    """``simple``, ``c`` or ``cs<alpha>`` as (alpha for C, alpha for S, constant when inside)."""
    t = text.lower()
    if t == "simple":
        return 0.0, 0.0, 1.0
    if t == "c":
        return 1.0, 0.0, 0.0
    if t.startswith("cs"):
        a = float(t[2:])
        return a, 1.0 - a, 0.0
    raise SystemExit(f"unknown reward {text!r} (simple, c, cs<alpha>)")


class Replay:
    """States stored once, linked to their successors (episodic storage), in float16.

    Row ``i`` holds a decision state (context, candidate rows, candidate count), the action
    taken (-1: none, the state had no candidate or its episode was cut), the placement's C, S
    and whether it stayed inside, whether the episode ended, the row of the next state (-1 at
    the end), whether the row is prior (teacher) data, and for each candidate the teacher
    tried the parts of its simulated return (sum of C, sum of S, objects packed, failed; NaN
    elsewhere). Rewards and returns are computed from the parts for the run's reward, so
    prior data collected under one reward serves every setting."""

    FIELDS = ("ctx", "cand", "count", "act", "c", "s", "inside", "done", "nxt", "prior", "mcp")

    def __init__(self, cap, ctx_len=G, cand_len=FEAT):
        self.cap, self.n = cap, 0
        self.ctx = np.zeros((cap, ctx_len), np.float16)
        self.cand = np.zeros((cap, C, cand_len), np.float16)
        self.count = np.zeros(cap, np.uint8)
        self.act = np.full(cap, -1, np.int16)
        self.c = np.zeros(cap, np.float32)
        self.s = np.zeros(cap, np.float32)
        self.inside = np.zeros(cap, bool)
        self.done = np.zeros(cap, bool)
        self.nxt = np.full(cap, -1, np.int64)
        self.prior = np.zeros(cap, bool)
        self.mcp = np.full((cap, C, 4), np.nan, np.float16)

    def add(self, ctx, cand, mask, prior, mcp=None):
        """Stores states (a batch), returns their rows."""
        k = len(ctx)
        if self.n + k > self.cap:
            raise SystemExit(f"replay buffer full ({self.cap} states): raise sac.buffer_size")
        rows = np.arange(self.n, self.n + k)
        self.ctx[rows], self.cand[rows] = ctx, cand
        self.count[rows] = mask.sum(1).astype(np.uint8)
        self.prior[rows] = prior
        if mcp is not None:
            self.mcp[rows] = mcp
        self.n += k
        return rows

    def save(self, path, cut=()):
        """Writes the buffer (then renames it into place). Rows in `cut`, the last states of
        episodes still running, are saved without an action: a resumed run starts new
        episodes, so those never get their successor."""
        tmp = path + ".tmp"
        fields = {k: getattr(self, k)[: self.n] for k in self.FIELDS}
        if len(cut):
            fields["act"] = fields["act"].copy()
            fields["act"][np.asarray(cut)] = -1
        with open(tmp, "wb") as f:
            np.savez(f, n=np.int64(self.n), cap=np.int64(self.cap), **fields)
        os.replace(tmp, path)

    @classmethod
    def load(cls, path, cap, any_layout=False):
        """The buffer at `path` with room for `cap` states; a clear error if it is corrupt,
        truncated or of another feature layout (`any_layout`: take the file's, for probes)."""
        try:
            z = np.load(path)
            n = int(z["n"])
            dims = (z["ctx"].shape[1], z["cand"].shape[2]) if any_layout else (G, FEAT)
            r = cls(max(cap, n), *dims)
            for k in cls.FIELDS:
                a = z[k]
                want = getattr(r, k)
                if a.shape[1:] != want.shape[1:] or a.dtype != want.dtype or len(a) != n:
                    raise ValueError(f"field {k}: {a.dtype} {a.shape}, expected {want.dtype} "
                                     f"(n, {', '.join(map(str, want.shape[1:]))}) with n = {n}")
                want[:n] = a
            r.n = n
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
            raise SystemExit(f"{path}: corrupt or truncated replay buffer ({err}); "
                             "the run does not go on from an empty one")
        return r

    def rewards(self, rows, reward):
        """The rewards of `rows` under `reward` (``parse_reward``)."""
        wc, ws, k = reward
        r = wc * self.c[rows] + ws * self.s[rows] + k
        return np.where(self.inside[rows], r, -1.0).astype(np.float32)

    def returns(self, rows, reward):
        """The teacher's simulated returns of `rows`' candidates under `reward` (NaN where
        not simulated)."""
        wc, ws, k = reward
        p = self.mcp[rows].astype(np.float32)
        return wc * p[..., 0] + ws * p[..., 1] + k * p[..., 2] - p[..., 3]

    def keep_prior(self):
        """Drops everything but the prior rows (which come first)."""
        n = int(self.prior[: self.n].sum())
        if not self.prior[:n].all():
            raise SystemExit("prior rows are not the buffer's first rows")
        self.n = n
        self.nxt[:n][self.nxt[:n] >= n] = -1

    def sample(self, rng, k, prior):
        """`k` rows with an action, from the prior or the online part."""
        pool = np.flatnonzero((self.act[: self.n] >= 0) & (self.prior[: self.n] == prior))
        if len(pool) == 0:
            return None
        return pool[rng.integers(0, len(pool), k)]


def masks(count):
    return (np.arange(C)[None, :] < count[:, None]).astype(np.float32)


def batch_tensors(rb, rows, rng, dev, reward):
    """The tensors of an update for `rows`, half-turned with probability 1/2 (the whole batch
    at once: the same rows turned are the same decision)."""
    nxt = rb.nxt[rows]
    has_next = nxt >= 0
    nrows = np.where(has_next, nxt, rows)
    ctx, cand = rb.ctx[rows].astype(np.float32), rb.cand[rows].astype(np.float32)
    nctx, ncand = rb.ctx[nrows].astype(np.float32), rb.cand[nrows].astype(np.float32)
    if rng.random() < 0.5:
        ctx, nctx = herb_sim.half_turn_context(ctx), herb_sim.half_turn_context(nctx)
        cand, ncand = herb_sim.half_turn_candidates(cand), herb_sim.half_turn_candidates(ncand)
    mc = rb.returns(rows, reward)
    # The teacher's choice under this run's reward: the best simulated return (first of equals).
    teacher = np.argmax(np.where(np.isnan(mc), -np.inf, mc), axis=1)
    t = lambda a, dt=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=dev)
    return dict(
        ctx=t(ctx), cand=t(cand), mask=t(masks(rb.count[rows])),
        act=t(rb.act[rows], torch.int64), rew=t(rb.rewards(rows, reward)),
        # The episode ended, or the next state had no candidate (a forced failure, value -1).
        end=t(rb.done[rows] | ~has_next), nctx=t(nctx), ncand=t(ncand),
        nmask=t(masks(rb.count[nrows])), nempty=t(has_next & (rb.count[nrows] == 0)),
        mc=t(mc), teacher=t(teacher, torch.int64), prior=t(rb.prior[rows]),
    )


def update(m, b, c, bc_weight, mc_weight):
    """One discrete-SAC update (critic, actor, temperature, targets); returns the losses."""
    s = c["sac"]
    actor, critic, target, log_alpha = m["actor"], m["critic"], m["target"], m["log_alpha"]
    alpha = log_alpha.exp().detach()
    with torch.no_grad():
        nl = actor(b["nctx"], b["ncand"], b["nmask"])
        nlogp = F.log_softmax(nl, -1)
        qn = target(b["nctx"], b["ncand"], b["nmask"]).min(-1).values
        v = (nlogp.exp() * (qn - alpha * nlogp) * b["nmask"]).sum(-1)
        v = torch.where(b["nempty"] > 0, torch.full_like(v, -1.0), v)
        y = b["rew"] + s["gamma"] * (1.0 - b["end"]) * v
    q = critic(b["ctx"], b["cand"], b["mask"])
    qa = q.gather(1, b["act"][:, None, None].expand(-1, 1, 2))[:, 0]
    loss_td = F.mse_loss(qa, y[:, None].expand(-1, 2))
    # The teacher's simulated returns of every candidate it tried (prior rows only).
    known = ~torch.isnan(b["mc"])
    if known.any():
        mc = torch.nan_to_num(b["mc"])[..., None].expand(-1, -1, 2)
        kk = known[..., None].expand(-1, -1, 2)
        loss_mc = ((q - mc) ** 2)[kk].mean()
    else:
        loss_mc = torch.zeros((), device=q.device)
    loss_q = loss_td + mc_weight * loss_mc
    m["opt_q"].zero_grad()
    loss_q.backward()
    m["opt_q"].step()

    logits = actor(b["ctx"], b["cand"], b["mask"])
    logp = F.log_softmax(logits, -1)
    p = logp.exp()
    with torch.no_grad():
        qmin = critic(b["ctx"], b["cand"], b["mask"]).min(-1).values
    loss_sac = (p * (alpha * logp - qmin) * b["mask"]).sum(-1).mean()
    pr = b["prior"] > 0
    loss_bc = F.nll_loss(logp[pr], b["teacher"][pr]) if pr.any() else torch.zeros((), device=q.device)
    loss_pi = loss_sac + bc_weight * loss_bc
    m["opt_pi"].zero_grad()
    loss_pi.backward()
    m["opt_pi"].step()

    # Temperature: entropy target a fraction of the uniform entropy over each decision's
    # candidates.
    ent = -(p * logp * b["mask"]).sum(-1).detach()
    target_ent = s["entropy_frac"] * torch.log(b["mask"].sum(-1).clamp(min=1.0))
    loss_a = (log_alpha * (ent - target_ent)).mean()
    m["opt_a"].zero_grad()
    loss_a.backward()
    m["opt_a"].step()
    with torch.no_grad():
        for tp, cp in zip(target.parameters(), critic.parameters()):
            tp.lerp_(cp, s["tau"])
    return tuple(float(v.detach()) for v in (loss_td, loss_mc, loss_bc, ent.mean(), alpha))


class Deployed(nn.Module):
    """The exported graph: masked logits (padding at -1e9)."""

    def __init__(self, actor):
        super().__init__()
        self.actor = actor

    def forward(self, context, candidates, mask):
        return self.actor(context, candidates, mask)


def export(actor, out, env):
    """Exports the actor with the candidate contract; replaces out/policy.onnx only if it
    passes the checks, with parity samples for the tract test."""
    import onnx
    import onnxruntime as ort

    model = Deployed(actor).to("cpu").eval()
    tmp = os.path.join(out, "policy.onnx.tmp")
    names = ["context", "candidates", "mask"]
    shapes = [[1, G], [1, C, FEAT], [1, C]]
    dummy = tuple(torch.zeros(*s) for s in shapes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, dummy, tmp, input_names=names, output_names=["logits"],
                          opset_version=17, dynamo=False)
    mdl = onnx.load(tmp)
    onnx.checker.check_model(mdl)
    dims = lambda v: [d.dim_value for d in v.type.tensor_type.shape.dim]
    ins, outs = mdl.graph.input, mdl.graph.output
    ok = ([i.name for i in ins] == names and [dims(i) for i in ins] == shapes
          and len(outs) == 1 and outs[0].name == "logits" and dims(outs[0]) == [1, C])
    if not ok:
        os.remove(tmp)
        raise RuntimeError("exported model breaks the I/O contract; the shipped one is kept")
    env.reset(seed=12345)
    ctx, cand, mask = env.candidates()
    sess = ort.InferenceSession(tmp, providers=["CPUExecutionProvider"])
    expect = []
    for k in range(min(4, len(ctx))):
        x = (ctx[k:k + 1], cand[k:k + 1], mask[k:k + 1])
        with torch.no_grad():
            want = model(*(torch.as_tensor(a) for a in x)).numpy()
        got = sess.run(None, dict(zip(names, x)))[0]
        if not np.allclose(want, got, atol=1e-4, rtol=1e-4):
            os.remove(tmp)
            raise RuntimeError("onnxruntime differs from PyTorch")
        expect.append(want[0].tolist())
    os.replace(tmp, os.path.join(out, "policy.onnx"))
    with open(os.path.join(out, "policy.parity.bin"), "wb") as f:
        for k in range(len(expect)):
            for a in (ctx[k], cand[k], mask[k]):
                f.write(a.astype("<f4").tobytes())
    with open(os.path.join(out, "policy.parity.json"), "w") as f:
        json.dump({"samples": len(expect), "inputs": names, "shapes": shapes,
                   "logits": expect}, f)


def append_progress(out, row):
    path = os.path.join(out, "progress.csv")
    new = not os.path.exists(path)
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


def save(out, m, st, rb, cut=()):
    """Checkpoint and buffer, each written then renamed (`cut`: see ``Replay.save``)."""
    ck = {k: m[k].state_dict() for k in ("actor", "critic", "target", "opt_q", "opt_pi", "opt_a")}
    ck["log_alpha"] = m["log_alpha"].detach().cpu()
    ck["state"] = st
    ck["rng"] = (np.random.get_state(), torch.get_rng_state())
    tmp = os.path.join(out, "checkpoint.pt.tmp")
    torch.save(ck, tmp)
    rb.save(os.path.join(out, "replay.npz"), cut)
    os.replace(tmp, os.path.join(out, "checkpoint.pt"))


def load(out, m):
    path = os.path.join(out, "checkpoint.pt")
    try:
        ck = torch.load(path, weights_only=False)
        for k in ("actor", "critic", "target", "opt_q", "opt_pi", "opt_a"):
            m[k].load_state_dict(ck[k])
        with torch.no_grad():
            m["log_alpha"].copy_(ck["log_alpha"])
        np.random.set_state(ck["rng"][0])
        torch.set_rng_state(ck["rng"][1])
        return ck["state"]
    except (OSError, KeyError, RuntimeError, EOFError, ValueError) as err:
        raise SystemExit(f"{path}: cannot resume from this checkpoint ({err})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--resume", action="store_true", help="go on from <out>/checkpoint.pt")
    ap.add_argument("--minutes", type=float, default=None, help="this chunk's length (inf: to the end)")
    ap.add_argument("--threads", type=int, default=2, help="torch and environment threads")
    ap.add_argument("--boxed", default=None)
    a = ap.parse_args()
    c = load_config(a.config)
    reward = parse_reward(c["env"]["reward"])
    os.makedirs(a.out, exist_ok=True)
    torch.set_num_threads(a.threads)
    torch.manual_seed(c["seed"])
    np.random.seed(c["seed"])
    s = c["sac"]
    m = dict(actor=Actor(), critic=Critic(), target=Critic())
    m["target"].load_state_dict(m["critic"].state_dict())
    m["log_alpha"] = torch.zeros((), requires_grad=True)
    m["opt_q"] = torch.optim.Adam(m["critic"].parameters(), lr=s["lr"])
    m["opt_pi"] = torch.optim.Adam(m["actor"].parameters(), lr=s["lr"])
    m["opt_a"] = torch.optim.Adam([m["log_alpha"]], lr=s["lr"])
    ck_path = os.path.join(a.out, "checkpoint.pt")
    if a.resume:
        if not os.path.exists(ck_path):
            raise SystemExit(f"--resume: {ck_path} does not exist")
        st = load(a.out, m)
        rb = Replay.load(os.path.join(a.out, "replay.npz"), s["buffer_size"])
        print(f"resumed {a.out}: phase {st['phase']}, {rb.n} states, {st['steps']} online steps, "
              f"{st['updates']} updates", flush=True)
    else:
        if os.path.exists(ck_path):
            raise SystemExit(f"{ck_path} exists: pass --resume to go on, or choose another --out")
        st = dict(phase="collect", teacher_episodes=0, teacher_steps=0, offline_updates=0,
                  steps=0, updates=0, episodes=0, wall=0.0, cpu=0.0, env_seed=int(c["seed"]),
                  ep_len=[], ep_ret=[], ep_success=[])
        rb = Replay(s["buffer_size"])
        src = c["teacher"].get("prior_from")
        if src:
            # Prior data shared with another setting's run (relabelled for this reward).
            shared = Replay.load(os.path.join(src, "replay.npz"), s["buffer_size"])
            shared.keep_prior()
            rb = shared
            st["phase"] = "offline"
            st["teacher_episodes"] = -1
            print(f"prior data from {src}: {rb.n} states", flush=True)
    rng = np.random.default_rng(c["seed"] + st["updates"] + st["steps"])
    minutes = a.minutes if a.minutes is not None else c["run"]["chunk_minutes"]
    stop = {"now": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    t0, cpu0, last_log = time.time(), time.process_time(), time.time()
    deadline = t0 + minutes * 60.0
    # A checkpoint every run.chunk_minutes, whatever the run's length.
    every = c["run"]["chunk_minutes"] * 60.0
    next_save = t0 + every
    # Each chunk opens its environments with a fresh seed (recorded): episodes differ from
    # the last chunk's, and a resumed run never repeats them.
    env = make_env(c, st["env_seed"], a.boxed, a.threads)
    st["env_seed"] += 1
    env.reset(seed=st["env_seed"])
    n_env = c["env"]["num_envs"]
    prev = np.full(n_env, -1)
    stats = []

    def log(extra):
        row = dict(phase=st["phase"], teacher_episodes=st["teacher_episodes"],
                   offline_updates=st["offline_updates"], steps=st["steps"],
                   updates=st["updates"], episodes=st["episodes"],
                   wall_s=round(st["wall"] + time.time() - t0, 1),
                   cpu_s=round(st["cpu"] + time.process_time() - cpu0, 1),
                   mean_len=round(float(np.mean(st["ep_len"][-200:])), 3) if st["ep_len"] else "",
                   success=round(float(np.mean(st["ep_success"][-200:])), 4) if st["ep_success"] else "",
                   mean_return=round(float(np.mean(st["ep_ret"][-200:])), 4) if st["ep_ret"] else "")
        row.update(extra)
        append_progress(a.out, row)
        print(", ".join(f"{k} {v}" for k, v in row.items()), flush=True)

    def truncate():
        # Episodes still running when a phase or a chunk ends are cut: their last state keeps
        # no action (it still serves as the previous state's successor).
        open_rows = prev[prev >= 0]
        rb.act[open_rows] = -1
        prev[:] = -1

    def step_and_store(ctx, cand, mask, act, prior, mcp=None):
        rows = rb.add(ctx, cand, mask, prior, mcp)
        ok = prev >= 0
        rb.nxt[prev[ok]] = rows[ok]
        rew, term, info = env.step_candidates(np.maximum(act, 0))
        rb.act[rows] = np.where(mask.sum(1) > 0, act, -1)
        rb.c[rows], rb.s[rows] = info["compactness"], info["stable"].astype(np.float32)
        # A placement ended outside exactly when its reward is -1 (every other reward >= 0).
        rb.inside[rows] = rew > -1.0
        rb.done[rows] = term
        prev[:] = np.where(term, -1, rows)
        ended = np.flatnonzero(term)
        st["ep_len"] += info["episode_length"][ended].tolist()
        st["ep_ret"] += info["episode_return"][ended].tolist()
        st["ep_success"] += info["success"][ended].astype(float).tolist()
        del st["ep_len"][:-1000], st["ep_ret"][:-1000], st["ep_success"][:-1000]
        return len(ended)

    while time.time() < deadline and not stop["now"] and st["phase"] != "done":
        if st["phase"] == "collect":
            if st["teacher_episodes"] >= c["teacher"]["episodes"]:
                truncate()
                st["phase"] = "offline"
                continue
            ctx, cand, mask, _, packed, choice, parts = env.teacher(
                c["teacher"]["k"], c["teacher"].get("horizon"))
            mcp = np.concatenate([parts[..., :2], packed[..., None].astype(np.float32),
                                  parts[..., 2:]], -1)
            mcp[packed < 0] = np.nan
            st["teacher_episodes"] += step_and_store(ctx, cand, mask, choice, True, mcp)
            st["teacher_steps"] += n_env
        elif st["phase"] == "offline":
            if st["offline_updates"] >= c["offline"]["updates"]:
                st["phase"] = "online"
                env.reset(seed=st["env_seed"] + 1000)
                prev[:] = -1
                continue
            rows = rb.sample(rng, s["batch_size"], True)
            stats.append(update(m, batch_tensors(rb, rows, rng, "cpu", reward), c, s["bc_weight_start"],
                                s["mc_weight"]))
            st["offline_updates"] += 1
            st["updates"] += 1
        else:
            if st["steps"] >= s["total_steps"]:
                st["phase"] = "done"
                continue
            ctx, cand, mask = env.candidates()
            with torch.no_grad():
                logits = m["actor"](torch.as_tensor(ctx), torch.as_tensor(cand), torch.as_tensor(mask))
                act = torch.distributions.Categorical(logits=logits).sample().numpy()
            st["episodes"] += step_and_store(ctx, cand, mask, act, False)
            st["steps"] += n_env
            want = int(st["steps"] * s["updates_per_step"])
            bc = s["bc_weight_end"] + (s["bc_weight_start"] - s["bc_weight_end"]) * max(
                0.0, 1.0 - st["steps"] / s["bc_decay_steps"])
            while st["updates"] - st["offline_updates"] < want:
                half = s["batch_size"] // 2
                on = rb.sample(rng, half, False)
                pr = rb.sample(rng, s["batch_size"] - half if on is not None else s["batch_size"], True)
                rows = pr if on is None else np.concatenate([pr, on])
                stats.append(update(m, batch_tensors(rb, rows, rng, "cpu", reward), c, bc, s["mc_weight"]))
                st["updates"] += 1
        if time.time() >= next_save:
            next_save = time.time() + every
            wall, cpu = time.time() - t0, time.process_time() - cpu0
            st["wall"] += wall
            st["cpu"] += cpu
            save(a.out, m, st, rb, prev[prev >= 0])
            st["wall"] -= wall
            st["cpu"] -= cpu
            print(f"checkpoint: {rb.n} states", flush=True)
        if time.time() - last_log >= c["run"]["log_every_s"]:
            last_log = time.time()
            extra = {}
            if stats:
                v = np.mean(stats[-200:], axis=0)
                extra = dict(loss_td=round(v[0], 4), loss_mc=round(v[1], 4), loss_bc=round(v[2], 4),
                             entropy=round(v[3], 3), alpha=round(v[4], 5))
            log(extra)
    truncate()
    log({})
    st["wall"] += time.time() - t0
    st["cpu"] += time.process_time() - cpu0
    save(a.out, m, st, rb)
    try:
        export(m["actor"], a.out, env)
    except RuntimeError as err:
        print(f"export not replaced: {err}", file=sys.stderr)
    print(f"saved {a.out}: phase {st['phase']}, {rb.n} states", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
