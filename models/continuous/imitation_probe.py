#!/usr/bin/env python3
"""How closely can an actor network imitate the BLBF teacher? A supervised probe.

    python models/continuous/imitation_probe.py collect --actor runs/cs06-bc/checkpoint-actor.pt --out runs/probe
    python models/continuous/imitation_probe.py fit --net herblite56 --minutes 6 --out runs/probe
    python models/continuous/imitation_probe.py fit --net spatial --minutes 6 --lr 1e-3 --out runs/probe
    python models/continuous/imitation_probe.py fit --net spatial-ce --minutes 6 --lr 1e-3 --out runs/probe
    python models/continuous/imitation_probe.py fit --net herblite56 --actor runs/cs06-bc/checkpoint-actor.pt --minutes 0 --out runs/probe

The guided CS0.6 policy places about 3 cm and 25 degrees away from its teacher, and fails
where the teacher would not. This probe separates the network from the RL: ``collect``
records states of training-distribution episodes (the ``[env]`` of ``--config``, default
``configs/cs06-bc.toml``: CS0.6 world, Beam-3 order, 16 environments) in which each
environment acts, with probability 1/2 per step, with the teacher's label, else with the
given actor's deterministic action (so the states look like the ones the actor meets), and
stores each state's pooled observation and BLBF label (``VecEnv.expert_actions``); a
training set (seed 11) and a held-out set (seed 99).
``fit`` trains one network on the labels alone for a fixed wall time and prints the
held-out error: mean |dx|, |dy| (cm), the share of states with both under 1 cm, and the
yaw error (degrees). With ``--actor`` and ``--minutes 0`` it only measures a saved actor.

Networks: ``herblite56``, the training recipe's actor (``train.Actor``, pool 4), fitted by
the squared distance of tanh(mean) to the label, as in the guided recipe; ``spatial``, a
soft-argmax head: a 28 x 28 grid (12.5 mm cells) of scores for yaw 0 and 90 degrees, from
dilated residual convolutions of the heightmap with coordinate channels, modulated (FiLM)
by an embedding of the object's projection, plus a sub-cell offset per cell, fitted like
herblite56; ``spatial-ce``, the same network fitted by cross-entropy on the teacher's cell
and yaw plus the offset's squared error. This is a diagnostic, not part of training.
"""

import argparse
import os
import pickle
import sys
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import herb_sim  # noqa: E402
from train import Actor, load_config, make_env, pool_u8  # noqa: E402

BOX_HALF_X, BOX_HALF_Y = herb_sim.BOX_HALF_X, herb_sim.BOX_HALF_Y  # the sim's frames
GRID = 28
SPAN = herb_sim.OBS_CELL_M * herb_sim.OBS_SIZE  # the observation's side (0.35 m)
CELL = SPAN / GRID  # 12.5 mm


class Spatial(nn.Module):
    """Soft-argmax placement head (see the module docs); returns (mean, log_std) like Actor."""

    def __init__(self, ch=16):
        super().__init__()
        self.obj = nn.Sequential(
            nn.Conv2d(1, 16, 3, 2, 1), nn.ReLU(), nn.Conv2d(16, 32, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(32, 32, 3, 2, 1), nn.ReLU(), nn.Flatten(), nn.Linear(32 * 49, 128), nn.ReLU(),
        )
        self.stem = nn.Conv2d(3, ch, 3, 2, 1)
        self.film = nn.ModuleList([nn.Linear(128, 2 * ch) for _ in range(3)])
        self.convs = nn.ModuleList([nn.Conv2d(ch, ch, 3, 1, d, dilation=d) for d in (1, 2, 4, 8)])
        self.head = nn.Conv2d(ch, 6, 1)  # 2 score maps (yaw 0, 90), then 2 x (dx, dy) offsets
        self.std = nn.Sequential(nn.Linear(128 + ch, 64), nn.ReLU(), nn.Linear(64, 3))
        c = (torch.arange(GRID, dtype=torch.float32) + 0.5 - GRID / 2) * CELL
        self.register_buffer("gx", (c / BOX_HALF_X).view(1, GRID).expand(GRID, GRID).reshape(-1).clone())
        self.register_buffer("gy", (-c / BOX_HALF_Y).view(GRID, 1).expand(GRID, GRID).reshape(-1).clone())
        # Coordinate channels at the input's 56 x 56 (nearest of the 28 x 28 cell centres, over half the span).
        xx = (c / (SPAN / 2)).view(1, GRID).expand(GRID, GRID)
        yy = (-c / (SPAN / 2)).view(GRID, 1).expand(GRID, GRID)
        up = [F.interpolate(v[None, None], 56)[0, 0] for v in (xx, yy)]
        self.register_buffer("coords", torch.stack(up)[None])
        self.last_maps = None

    def forward(self, x):
        b = x.shape[0]
        e = self.obj(x[:, 1:2])
        h = self.stem(torch.cat([x[:, 0:1], self.coords.expand(b, -1, -1, -1)], 1))
        for i, conv in enumerate(self.convs):
            h = F.relu(h)
            if i < len(self.film):
                g, s = self.film[i](e).chunk(2, -1)
                h = h * (1 + g[..., None, None]) + s[..., None, None]
            h = conv(h) + (h if i > 0 else 0)
        o = self.head(F.relu(h))
        self.last_maps = o
        p = torch.softmax(o[:, :2].reshape(b, -1), -1).view(b, 2, -1)
        off = torch.tanh(o[:, 2:].reshape(b, 2, 2, -1)) * 0.5  # up to one cell each way (x 2)
        ax = (p * (self.gx + off[:, :, 0] * 2 * CELL / BOX_HALF_X)).sum((1, 2))
        ay = (p * (self.gy - off[:, :, 1] * 2 * CELL / BOX_HALF_Y)).sum((1, 2))
        at = 0.5 * p[:, 1].sum(-1)
        a = torch.stack([ax, ay, at], -1).clamp(-0.999, 0.999)
        return torch.atanh(a), self.std(torch.cat([e, h.mean((2, 3))], -1)).clamp(-20.0, 2.0)


def cell_loss(net, a):
    """Cross-entropy on the teacher's cell and yaw, plus the offset's squared error there."""
    n = len(a)
    x, y = a[:, 0] * BOX_HALF_X, a[:, 1] * BOX_HALF_Y
    col = ((x + SPAN / 2) / CELL).floor().clamp(0, GRID - 1).long()
    row = ((SPAN / 2 - y) / CELL).floor().clamp(0, GRID - 1).long()
    yaw = (a[:, 2].abs() > 0.25).long()
    o = net.last_maps
    loss = F.cross_entropy(o[:, :2].reshape(n, -1), yaw * GRID * GRID + row * GRID + col)
    cx = (col.float() + 0.5 - GRID / 2) * CELL
    cy = (GRID / 2 - (row.float() + 0.5)) * CELL
    off = torch.tanh(o[:, 2:].reshape(n, 2, 2, -1)) * 0.5
    i, k = torch.arange(n), row * GRID + col
    ex = off[i, yaw, 0, k] - ((x - cx) / CELL / 2).clamp(-0.49, 0.49)
    ey = off[i, yaw, 1, k] - ((cy - y) / CELL / 2).clamp(-0.49, 0.49)
    return loss + 10 * (ex ** 2 + ey ** 2).mean()


def load_actor(net, path):
    """Loads a saved herblite56 actor (checkpoint or snapshot) into `net`, or stops clearly."""
    try:
        net.load_state_dict(torch.load(path, map_location="cpu", weights_only=False)["actor"])
    except (OSError, KeyError, ValueError, EOFError, RuntimeError, pickle.UnpicklingError) as err:
        raise SystemExit(f"{path}: not a herblite56 actor checkpoint or snapshot: {err}")
    return net


def collect(config, actor_path, n, seed, path):
    env = make_env(config, seed)
    n_envs = config["env"]["num_envs"]
    actor = load_actor(Actor(4), actor_path)
    actor.eval()
    rng = np.random.default_rng(seed)
    obs = env.reset(seed=seed)[0]
    xs, labels, have = [], [], 0
    t = time.time()
    while have < n:
        po = pool_u8(obs, 4)
        ea, ev = env.expert_actions()
        with torch.no_grad():
            act = actor.sample(torch.as_tensor(po).float() / 255)[2].numpy().astype(np.float32)
        xs.append(po[ev])
        labels.append(ea[ev])
        have += int(ev.sum())
        use = ev & (rng.random(n_envs) < 0.5)
        act[use] = ea[use]
        obs = env.step(act)[0]
    np.savez(path, X=np.concatenate(xs)[:n], A=np.concatenate(labels)[:n])
    print(f"{path}: {n} states in {time.time() - t:.0f} s", flush=True)


def held_out_error(net, vx, va):
    net.eval()
    with torch.no_grad():
        a = torch.cat([torch.tanh(net(vx[i:i + 500])[0]) for i in range(0, len(vx), 500)])
    net.train()
    dx = (a[:, 0] - va[:, 0]).abs() * BOX_HALF_X * 100
    dy = (a[:, 1] - va[:, 1]).abs() * BOX_HALF_Y * 100
    dt = ((a[:, 2] - va[:, 2] + 1) % 2 - 1).abs() * 180
    return (f"dx {dx.mean():.2f} cm, dy {dy.mean():.2f} cm, both under 1 cm "
            f"{((dx < 1) & (dy < 1)).float().mean() * 100:.1f} %, yaw {dt.mean():.1f} deg")


def fit(a):
    torch.manual_seed(0)
    try:
        tr = np.load(os.path.join(a.out, "train.npz"))
        va = np.load(os.path.join(a.out, "val.npz"))
    except OSError as err:
        raise SystemExit(f"{a.out}: run 'collect' first ({err})")
    x, lab = torch.as_tensor(tr["X"]), torch.as_tensor(tr["A"])
    vx, va = torch.as_tensor(va["X"]).float() / 255, torch.as_tensor(va["A"])
    net = Actor(4) if a.net == "herblite56" else Spatial()
    if a.actor:
        load_actor(net, a.actor)
    opt = torch.optim.Adam(net.parameters(), lr=a.lr)
    t0 = last = time.time()
    it = 0
    while time.time() - t0 < a.minutes * 60:
        idx = torch.randint(0, len(x), (a.batch,))
        mu = net(x[idx].float() / 255)[0]
        if a.net == "spatial-ce":
            loss = cell_loss(net, lab[idx])
        else:
            loss = ((torch.tanh(mu) - lab[idx]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        it += 1
        if time.time() - last > 60:
            last = time.time()
            print(f"{it} updates, {last - t0:.0f} s: {held_out_error(net, vx, va)}", flush=True)
    print(f"{a.net}: {it} updates in {time.time() - t0:.0f} s: {held_out_error(net, vx, va)}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=["collect", "fit"])
    ap.add_argument("--out", required=True, help="folder of train.npz and val.npz")
    ap.add_argument("--actor", help="collect: the actor whose states to visit; fit: start from it")
    ap.add_argument("--config", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "configs", "cs06-bc.toml"),
                    help="collect: the training config whose [env] the episodes follow")
    ap.add_argument("--train-states", type=int, default=24_000)
    ap.add_argument("--val-states", type=int, default=3_000)
    ap.add_argument("--net", choices=["herblite56", "spatial", "spatial-ce"], default="herblite56")
    ap.add_argument("--minutes", type=float, default=6.0)
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--batch", type=int, default=128)
    a = ap.parse_args()
    if a.actor and a.net != "herblite56":
        raise SystemExit("--actor is a herblite56 actor (train.Actor, pool 4)")
    if a.what == "collect":
        if not a.actor:
            raise SystemExit("collect needs --actor (e.g. runs/cs06-bc/checkpoint-actor.pt)")
        os.makedirs(a.out, exist_ok=True)
        c = load_config(a.config)
        collect(c, a.actor, a.train_states, 11, os.path.join(a.out, "train.npz"))
        collect(c, a.actor, a.val_states, 99, os.path.join(a.out, "val.npz"))
    else:
        fit(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
