#!/usr/bin/env python3
"""Held-out probe: does a wider view of each candidate make the teacher's outcomes predictable?

    python models/probe_patch.py --run runs/teacher-h2 --updates 4000

The recipe's candidate row sees a 5 x 5 patch (6.25 cm) of the pooled heightmap around the
candidate's lattice node, smaller than most objects, and the context knows the object after
the next only through a summary of the rest of the job. This probe asks whether those two
blind spots are why the teacher's choices could not be learned (``probe_teacher.py``):

- **patch**: for each tried candidate, a ``--patch`` x ``--patch`` window of the pooled
  heightmap (12.5 mm cells; 24 cells = 30 cm, wider than any object's footprint) centred on the
  candidate's origin and turned into the object's frame (the yaw is a multiple of 90 degrees,
  so the turn is exact), as height minus the object's bottom at rest, with a second channel
  marking the object's bounding rectangle; a small convolutional encoder;
- **after**: the extents and volume of the object after the next (read from the stored
  successor state, whose context describes it; herbd knows it from the job's order).

Both scorers (``--arch base``: the recipe's ``Scorer`` on the stored rows; ``--arch patch``:
the same plus the two additions) regress each tried candidate's simulated return as an
advantage over candidate 0 on the first 80 % of the teacher's states and are scored on the last
20 %: mean regret, big misses and agreement, beside always taking candidate 0 (the lattice BLBF
rule), as in ``probe_teacher.py``. The rule written before running it: the wider view is worth
building into the contract only if the patch scorer's held-out regret falls below candidate
0's.
"""

import argparse
import os
import sys
import time

import numpy as np
import torch
from torch import nn

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import train as T  # noqa: E402  (the recipe's Scorer, Replay, masks and reward parsing)

# The feature layout (sim/src/features.rs).
NX, NY = 28, 19
CELL = 0.0125
HEIGHT_SCALE = 0.30
SIZE_SCALE = 0.3
RIM = 0.16390
NEXT = NX * NY  # context index of the next object's extents x, y, z and volume
REST_Z, TOP = 6, 7  # candidate row: rest z and top (/ HEIGHT_SCALE)


def patches(ctx, cand, k, size):
    """``[N, k, 2, size, size]`` float16: per candidate, the pooled heightmap around its origin
    in the object's frame minus the object's bottom (/ 0.1 m, clamped to [-2, 2]; outside the
    box the rim's height) and the object's bounding rectangle."""
    n = len(ctx)
    hm = ctx[:, :NEXT].astype(np.float32).reshape(n, NY, NX) * HEIGHT_SCALE
    pad = size
    big = np.full((n, NY + 2 * pad, NX + 2 * pad), RIM, np.float32)
    big[:, pad:pad + NY, pad:pad + NX] = hm
    ext = ctx[:, NEXT:NEXT + 3].astype(np.float32) * SIZE_SCALE
    out = np.zeros((n, k, 2, size, size), np.float16)
    half = size // 2
    offs = np.arange(size) - half
    for j in range(k):
        c = cand[:, j].astype(np.float32)
        x = c[:, 0] * 0.17306
        y = c[:, 1] * 0.11382
        col = np.floor(x / CELL + NX / 2).astype(int)
        row = np.floor(NY / 2 - y / CELL).astype(int)
        rr = (row + pad)[:, None, None] + offs[None, :, None]
        cc = (col + pad)[:, None, None] + offs[None, None, :]
        rr = np.clip(rr, 0, big.shape[1] - 1)
        cc = np.clip(cc, 0, big.shape[2] - 1)
        win = big[np.arange(n)[:, None, None], rr, cc]
        bottom = c[:, TOP] * HEIGHT_SCALE - ext[:, 2]
        rel = np.clip((win - bottom[:, None, None]) / 0.1, -2.0, 2.0)
        yaw = np.argmax(c[:, 2:6], 1)
        for q in range(4):
            sel = yaw == q
            if sel.any():
                rel[sel] = np.rot90(rel[sel], k=-q, axes=(1, 2))
        out[:, j, 0] = rel
        # The object's bounding rectangle in its own frame (x along columns, y along rows).
        hx = np.clip(np.ceil(ext[:, 0] / CELL / 2).astype(int), 1, half)
        hy = np.clip(np.ceil(ext[:, 1] / CELL / 2).astype(int), 1, half)
        inx = np.abs(offs)[None, :] < hx[:, None]
        iny = np.abs(offs)[None, :] < hy[:, None]
        out[:, j, 1] = (iny[:, :, None] & inx[:, None, :]).astype(np.float16)
    return out


class PatchScorer(nn.Module):
    """The recipe's scorer with a convolutional code of each candidate's patch joined to its
    row, and the object after the next joined to the context."""

    def __init__(self, ctx_len, cand_len, size, code=32):
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv2d(2, 16, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=2, padding=1), nn.ReLU(),
            nn.AdaptiveAvgPool2d(2), nn.Flatten(), nn.Linear(128, code), nn.ReLU())
        self.score = T.Scorer(1, ctx_len=ctx_len, cand_len=cand_len + code)

    def forward(self, ctx, cand, mask, patch):
        b, k = patch.shape[:2]
        code = self.conv(patch.reshape(b * k, *patch.shape[2:])).reshape(b, k, -1)
        return self.score(ctx, torch.cat([cand, code], -1), mask)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="run folder holding replay.npz (teacher data)")
    ap.add_argument("--reward", default="cs0.6")
    ap.add_argument("--arch", default="base,patch", help="comma-separated: base, patch")
    ap.add_argument("--patch", type=int, default=24, help="window side (12.5 mm cells)")
    ap.add_argument("--updates", type=int, default=4000)
    ap.add_argument("--every", type=int, default=1000)
    ap.add_argument("--batch", type=int, default=128)
    ap.add_argument("--max-k", type=int, default=64,
                    help="score only the first candidates (BLBF order) of each state")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--margins", default="",
                    help="comma-separated advantage margins: train on the first 70 %% only, "
                         "choose the margin (leave candidate 0 only for a predicted advantage "
                         "above it) on the next 10 %%, report every margin on the last 20 %%")
    a = ap.parse_args()
    margins = [float(v) for v in a.margins.split(",") if v.strip()]
    torch.set_num_threads(a.threads)
    path = os.path.join(a.run, "replay.npz")
    rb = T.Replay.load(path, 0, any_layout=True)
    rows = np.flatnonzero(rb.prior[: rb.n])
    ret = rb.returns(rows, T.parse_reward(a.reward))
    known = ~np.isnan(ret)
    keep = known[:, 0] & (known.sum(1) > 1)
    rows, ret, known = rows[keep], ret[keep], known[keep]
    # The teacher tries the first k candidates.
    k = min(int(known.sum(1).max()), a.max_k)
    ret, known = ret[:, :k], known[:, :k]
    n = len(rows)
    if n < 10:
        raise SystemExit(f"{path}: {n} teacher states with simulated candidates; need 10")
    ctx = rb.ctx[rows].astype(np.float32)
    cand = rb.cand[rows, :k].astype(np.float32)
    nxt = rb.nxt[rows]
    after = np.where((nxt >= 0)[:, None], rb.ctx[np.maximum(nxt, 0), NEXT:NEXT + 4], 0.0)
    t0 = time.time()
    pat = torch.as_tensor(patches(ctx, cand, k, a.patch))
    print(f"{n} teacher states, {k} tried candidates each, patches {a.patch} x {a.patch} "
          f"({time.time() - t0:.1f} s)", flush=True)
    ctx_t = torch.as_tensor(ctx)
    ctx_after = torch.as_tensor(np.concatenate([ctx, after.astype(np.float32)], 1))
    cand_t = torch.as_tensor(cand)
    mask = torch.as_tensor(known.astype(np.float32))
    cut = int(0.8 * n)
    train, held = np.arange(cut), np.arange(cut, n)
    choose = np.arange(0)
    if margins:
        train, choose = np.arange(int(0.7 * n)), np.arange(int(0.7 * n), cut)
    target = torch.as_tensor(np.nan_to_num(ret - ret[:, :1]))
    known_t = torch.as_tensor(known)

    def report(score, idx):
        with torch.no_grad():
            q = torch.cat([score(idx[i:i + 512]) for i in range(0, len(idx), 512)]).numpy()
        q = np.where(known[idx], q, -np.inf)
        r = np.where(known[idx], ret[idx], -np.inf)
        best = r.max(1)
        chosen = ret[idx, q.argmax(1)]
        return (f"agree {(q.argmax(1) == r.argmax(1)).mean():.3f} regret "
                f"{np.mean(best - chosen):.4f} (candidate 0: {np.mean(best - ret[idx, 0]):.4f}) "
                f"big misses {np.mean(chosen < best - 0.5):.3f} "
                f"(candidate 0: {np.mean(ret[idx, 0] < best - 0.5):.3f}) "
                f"leaves 0 in {np.mean(q.argmax(1) != 0):.3f}")

    for arch in [s.strip() for s in a.arch.split(",") if s.strip()]:
        torch.manual_seed(a.seed)
        rng = np.random.default_rng(a.seed)
        if arch == "base":
            net = T.Scorer(1, ctx_len=ctx.shape[1], cand_len=cand.shape[2])

            def score(idx, net=net):
                q = net(ctx_t[idx], cand_t[idx], mask[idx])[..., 0]
                return q - q[:, :1]
        elif arch == "patch":
            net = PatchScorer(ctx_after.shape[1], cand.shape[2], a.patch)

            def score(idx, net=net):
                q = net(ctx_after[idx], cand_t[idx], mask[idx], pat[idx].float())[..., 0]
                return q - q[:, :1]
        else:
            raise SystemExit(f"--arch: unknown {arch!r} (base, patch)")
        opt = torch.optim.Adam(net.parameters(), lr=3e-4)
        t0 = time.time()
        for u in range(a.updates):
            b = train[rng.integers(0, len(train), a.batch)]
            loss = ((score(b) - target[b]) ** 2)[known_t[b]].mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            if (u + 1) % a.every == 0 or u + 1 == a.updates:
                print(f"{arch} update {u + 1} ({time.time() - t0:.0f} s): held out "
                      f"{report(score, held)} | train {report(score, train[:len(held)])}",
                      flush=True)
        if margins:
            def scored(idx):
                # Scored once per index set; every margin is applied to the same scores.
                with torch.no_grad():
                    q = torch.cat([score(idx[i:i + 512]) for i in range(0, len(idx), 512)]).numpy()
                return idx, np.where(known[idx], q, -np.inf)

            def regret(sq, m):
                idx, q = sq
                pick = np.where(q.max(1) > m, q.argmax(1), 0)
                best = np.where(known[idx], ret[idx], -np.inf).max(1)
                chosen = ret[idx, pick]
                return np.mean(best - chosen), np.mean(chosen < best - 0.5), np.mean(pick != 0)

            on_choose, on_held = scored(choose), scored(held)
            best_m = min(margins, key=lambda m: regret(on_choose, m)[0])
            base0 = np.mean(np.where(known[held], ret[held], -np.inf).max(1) - ret[held, 0])
            for m in margins:
                r, big, leave = regret(on_held, m)
                tag = " (chosen on the 10 % slice)" if m == best_m else ""
                print(f"{arch} margin {m}{tag}: held out regret {r:.4f} (candidate 0: "
                      f"{base0:.4f}) big misses {big:.3f} leaves 0 in {leave:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
