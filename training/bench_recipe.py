#!/usr/bin/env python3
"""Throughput of the lattice recipe (training/train.py) on this machine: discrete-SAC updates per
second (batch of the config, real network sizes, random data of the right shapes), and
environment steps per second with candidates computed and a random candidate chosen
(16 environments, mesh hulls, the config's episodes), p50/p99 per call.

    python training/bench_recipe.py --config training/configs/cs06-start.toml [--seconds 30] [--threads 2]
"""

import argparse
import os
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import train  # noqa: E402


def pct(v):
    v = np.asarray(v) * 1e3
    return f"p50 {np.percentile(v, 50):.1f} ms, p99 {np.percentile(v, 99):.1f} ms"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    c = train.load_config(a.config)
    torch.set_num_threads(a.threads)
    s = c["sac"]
    rng = np.random.default_rng(0)
    n = 4096
    rb = train.Replay(n)
    count = rng.integers(8, train.C + 1, n)
    rb.add(rng.random((n, train.G), np.float32), rng.random((n, train.C, train.FEAT), np.float32),
           train.masks(count), np.arange(n) % 2 == 0,
           np.where(rng.random((n, train.C, 4)) < 0.1, rng.random((n, train.C, 4)), np.nan))
    rb.act[:n] = rng.integers(0, count)
    rb.inside[:n] = True
    rb.nxt[: n - 1] = np.arange(1, n)
    m = dict(actor=train.Actor(), critic=train.Critic(), target=train.Critic())
    m["log_alpha"] = torch.zeros((), requires_grad=True)
    m["opt_q"] = torch.optim.Adam(m["critic"].parameters(), lr=s["lr"])
    m["opt_pi"] = torch.optim.Adam(m["actor"].parameters(), lr=s["lr"])
    m["opt_a"] = torch.optim.Adam([m["log_alpha"]], lr=s["lr"])
    reward = train.parse_reward(c["env"]["reward"])
    times = []
    t_end = time.time() + a.seconds
    while time.time() < t_end:
        rows = rng.integers(0, n - 1, s["batch_size"])
        t0 = time.perf_counter()
        train.update(m, train.batch_tensors(rb, rows, rng, "cpu", reward), c, 1.0, s["mc_weight"])
        times.append(time.perf_counter() - t0)
    print(f"updates: batch {s['batch_size']}, {a.threads} threads: {len(times) / sum(times):.1f} "
          f"updates/s ({pct(times)})", flush=True)
    env = train.make_env(c, 1, threads=a.threads)
    env.reset(seed=1)
    steps, times = 0, []
    t_end = time.time() + a.seconds
    while time.time() < t_end:
        t0 = time.perf_counter()
        _, _, mask = env.candidates()
        idx = np.array([rng.integers(0, max(1, int(k))) for k in mask.sum(1)])
        env.step_candidates(idx)
        times.append(time.perf_counter() - t0)
        steps += len(idx)
    print(f"environment: {c['env']['num_envs']} environments, {a.threads} threads: "
          f"{steps / sum(times):.0f} steps/s (random candidates; per vectorised step {pct(times)})",
          flush=True)


if __name__ == "__main__":
    sys.exit(main())
