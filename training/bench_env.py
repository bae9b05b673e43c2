"""Environment throughput: vectorised steps per second (total and per core) of
herb_sim.HerbVectorEnv with random actions, mesh hulls, CS0.6 reward, Beam-3 episodes in the
order its figures were measured in (beam3-last, docs/benchmarks.md).

Usage: python training/bench_env.py [--envs 16] [--threads N] [--steps 200] [--no-meshes]
Prints one JSON line. Needs the herb_sim extension (scripts/test.sh builds it into .venv).
"""

import argparse
import json
import os
import time

import numpy as np

import herb_sim


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--no-meshes", action="store_true")
    ap.add_argument("--boxed", default=None)
    a = ap.parse_args()
    v = herb_sim.HerbVectorEnv(
        a.envs, reward="cs0.6", sequence="beam3-last", seed=0, threads=a.threads,
        meshes=not a.no_meshes, boxed=a.boxed,
    )
    v.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, size=(a.steps + 10, a.envs, 3)).astype(np.float32)
    for i in range(10):  # warm-up
        v.step(acts[i])
    t0 = time.perf_counter()
    episodes = 0
    for i in range(a.steps):
        _, _, term, _, _ = v.step(acts[10 + i])
        episodes += int(term.sum())
    dt = time.perf_counter() - t0
    sps = a.steps * a.envs / dt
    print(json.dumps({
        "envs": a.envs, "threads": a.threads, "meshes": not a.no_meshes,
        "env_steps": a.steps * a.envs, "seconds": round(dt, 3),
        "steps_per_s": round(sps, 1), "steps_per_s_per_thread": round(sps / a.threads, 1),
        "episodes_ended": episodes,
    }))


if __name__ == "__main__":
    main()
