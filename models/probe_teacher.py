#!/usr/bin/env python3
"""Held-out probe: do the candidate features predict the teacher's simulated outcomes?

    python models/probe_teacher.py --run runs/cs06 --epochs 100

Reads a run's replay buffer (``replay.npz``), keeps the teacher's states (prior rows) where
candidate 0 and at least one other candidate were simulated, and splits them in collection
order: the first 80 % train a scorer (the recipe's ``Scorer``) to regress each tried
candidate's simulated return under ``--reward``, as an advantage over candidate 0 (``adv``)
or as is (``abs``); the last 20 % are held out. Every ``--every`` epochs it prints, on both
parts, the share of states where the scorer's best tried candidate is the teacher's, its mean
regret (best simulated return minus the chosen candidate's), the share of "big misses"
(chosen return more than 0.5 below the best: a failure another candidate avoided) and the
same for always taking candidate 0 (the lattice BLBF rule). A student can only recover the
teacher's gain if the held-out regret falls below candidate 0's.

``--train-sizes 2500,5000,10000`` draws a learning curve instead: a fresh scorer trained on the
first N states of the training part for each N (same held-out part, same number of updates),
to tell whether more teacher data would help. The network's input sizes are the buffer's, so
buffers written with other feature layouts can be probed too.
"""

import argparse
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import train as T  # noqa: E402  (the recipe's Scorer, masks and reward parsing)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="run folder holding replay.npz")
    ap.add_argument("--reward", default="cs0.6")
    ap.add_argument("--mode", choices=["adv", "abs"], default="adv")
    ap.add_argument("--epochs", type=int, default=100)
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--train-sizes", default="",
                    help="comma-separated training-set sizes: a learning curve (see above)")
    ap.add_argument("--updates", type=int, default=0,
                    help="with --train-sizes: updates per size (default: --epochs over the "
                         "whole training part)")
    ap.add_argument("--margins", default="",
                    help="comma-separated advantage margins: at the end, the held-out regret of "
                         "leaving candidate 0 only for a predicted advantage above each")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    path = os.path.join(a.run, "replay.npz")
    rb = T.Replay.load(path, 0, any_layout=True)
    rows = np.flatnonzero(rb.prior[: rb.n])
    ret = rb.returns(rows, T.parse_reward(a.reward))
    known = ~np.isnan(ret)
    keep = known[:, 0] & (known.sum(1) > 1)
    rows, ret, known = rows[keep], ret[keep], known[keep]
    if len(rows) < 10:
        raise SystemExit(f"{path}: {len(rows)} teacher states with simulated candidates; need 10")
    ctx = torch.as_tensor(rb.ctx[rows].astype(np.float32))
    cand = torch.as_tensor(rb.cand[rows].astype(np.float32))
    mask = torch.as_tensor(T.masks(rb.count[rows]))
    n = len(rows)
    cut = int(0.8 * n)
    train, held = np.arange(cut), np.arange(cut, n)
    target = ret - ret[:, :1] if a.mode == "adv" else ret
    rng = np.random.default_rng(a.seed)

    def fit(train, updates, every):
        torch.manual_seed(a.seed)
        net = T.Scorer(1, ctx_len=ctx.shape[1], cand_len=cand.shape[2])
        opt = torch.optim.Adam(net.parameters(), lr=3e-4)

        def score(idx):
            q = net(ctx[idx], cand[idx], mask[idx])[..., 0]
            return q - q[:, :1] if a.mode == "adv" else q

        for u in range(updates):
            b = train[rng.integers(0, len(train), 128)]
            k = torch.as_tensor(known[b])
            loss = ((score(b) - torch.as_tensor(np.nan_to_num(target[b]))) ** 2)[k].mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            if every and (u + 1) % every == 0:
                print(f"update {u + 1}: held out {report(score, held)} | "
                      f"train {report(score, train)}", flush=True)
        return score

    def report(score, idx):
        with torch.no_grad():
            q = score(idx).numpy()
        q = np.where(known[idx], q, -np.inf)
        r = np.where(known[idx], ret[idx], -np.inf)
        best = r.max(1)
        chosen = ret[idx, q.argmax(1)]
        agree = (q.argmax(1) == r.argmax(1)).mean()
        return (f"agree {agree:.3f} regret {np.mean(best - chosen):.4f} "
                f"(candidate 0: {np.mean(best - ret[idx, 0]):.4f}) big misses "
                f"{np.mean(chosen < best - 0.5):.3f} (candidate 0: {np.mean(ret[idx, 0] < best - 0.5):.3f})")

    print(f"{n} teacher states ({cut} train, {n - cut} held out), {a.reward}, {a.mode}, "
          f"inputs {ctx.shape[1]} / {cand.shape[2]}")
    per_epoch = (cut + 127) // 128
    sizes = [int(v) for v in a.train_sizes.split(",") if v.strip()]
    if sizes:
        updates = a.updates or a.epochs * per_epoch
        for size in sizes:
            if not 0 < size <= cut:
                raise SystemExit(f"--train-sizes: {size} is not in 1..{cut}")
            score = fit(train[:size], updates, 0)
            print(f"size {size}: {updates} updates: held out {report(score, held)} | "
                  f"train {report(score, train[:size])}", flush=True)
        return 0
    score = fit(train, a.epochs * per_epoch, a.every * per_epoch)
    for m in [float(v) for v in a.margins.split(",") if v.strip()]:
        with torch.no_grad():
            q = score(held).numpy()
        q = np.where(known[held], q - q[:, :1], -np.inf)
        pick = np.where(q.max(1) > m, q.argmax(1), 0)
        r = np.where(known[held], ret[held], -np.inf)
        best = r.max(1)
        chosen = ret[held, pick]
        print(f"margin {m}: held out leaves candidate 0 in {np.mean(pick != 0):.3f} of states, "
              f"regret {np.mean(best - chosen):.4f} (candidate 0: {np.mean(best - ret[held, 0]):.4f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
