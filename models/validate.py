#!/usr/bin/env python3
"""Validation of exported policies on training-distribution episodes, not on BoxED.

    python models/validate.py --policy runs/cs09/policy.onnx --policy runs/cs09-bc/policy.onnx

Each policy packs the same ``--episodes`` episodes sampled as in training (``herb_sim``: 10 to 25
random catalog objects, Beam-3 order, seed ``--seed``), acting deterministically through
onnxruntime on the shipped ONNX contract. Prints success rate and mean objects packed per
policy. Used to choose between training runs without looking at the BoxED test episodes
(Table I). Needs onnxruntime.
"""

import argparse
import sys

import numpy as np

import herb_sim


def validate(path, episodes, seed, reward, boxed):
    import onnxruntime as ort

    try:
        sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    except Exception as err:  # onnxruntime raises its own exception types
        raise SystemExit(f"{path}: cannot load the policy: {err}")
    # One environment per episode; each counts its first episode only (autoreset keeps the
    # finished ones stepping, their later episodes are ignored), so short episodes are not
    # over-represented.
    env = herb_sim.HerbVectorEnv(episodes, reward=reward, sequence="beam3", seed=seed, boxed=boxed)
    obs = env.reset(seed=seed)[0]
    done = np.zeros(episodes, bool)
    packed = np.zeros(episodes, int)
    success = np.zeros(episodes, bool)
    while not done.all():
        act = np.stack([sess.run(None, {herb_sim.INPUT_NAME: obs[k:k + 1]})[0][0]
                        for k in range(episodes)]).astype(np.float32)
        obs, _, term, _, info = env.step(act)
        first = term & ~done
        packed[first] = info["packed"][first]
        success[first] = info["success"][first]
        done |= term
    return success.mean(), packed.mean()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policy", action="append", required=True, help="ONNX policy (repeat)")
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--reward", default="cs0.6", help="reward mode (does not change the episodes)")
    ap.add_argument("--boxed", default=None)
    a = ap.parse_args()
    if not 1 <= a.episodes <= 4096:
        raise SystemExit(f"--episodes {a.episodes}: need 1 to 4096")
    print(f"{a.episodes} training-distribution episodes, seed {a.seed}")
    for p in a.policy:
        s, n = validate(p, a.episodes, a.seed, a.reward, a.boxed)
        print(f"{p}: success {100 * s:.2f} %, objects packed {n:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
