#!/usr/bin/env python3
"""Validation of exported policies on training-distribution episodes, not on BoxED.

    python training/validate.py --policy models/policy-cs06.onnx --policy models/policy-cs09.onnx
    python training/validate.py --rule blbf --rule lattice-blbf --rule lookahead --k 8

Each policy (or rule) packs the same ``--episodes`` episodes sampled as in training
(``herb_sim``: 10 to 25 random catalog objects, HERB's order ``beam3`` unless
``--sequence`` says otherwise, seed ``--seed``), acting deterministically through onnxruntime
on the shipped ONNX contract. Prints success rate and mean objects packed per policy. Used to
choose between training runs without looking at the BoxED test episodes (Table I). Needs
onnxruntime for ``--policy``. ``--rule`` runs a decision rule in Rust instead: ``blbf`` (the
daemon's BLBF heuristic, through the same action mapping as a policy), ``lattice-blbf`` (BLBF
restricted to the placement lattice), ``lattice-reserve`` (keeping room for later objects),
``lookahead`` (the teacher, ``--k`` candidates, rollouts of ``--horizon`` objects or to the end),
``geo-lookahead`` (the teacher's rollouts without physics), ``search`` (herbd's decision-time
search: ``--k`` candidates, ``--rollouts`` rollouts, in a twin built from the heightmap),
``search-job`` (the same search in the job's own twin: its decisions replayed, fitted to the
heightmaps) or ``search-exact`` (the same search in a clone of the episode's world: the twins'
fidelity bound).
"""

import argparse
import sys
import time

import numpy as np

import herb_sim


def onnx_actor(path):
    """The policy at `path` through onnxruntime: ``("obs", f)`` with f from observations
    [N, 2, 224, 224] to actions [N, 3] (the observation contract), or ``("candidates", f)``
    with f from (context, candidates, mask) to candidate indices [N] (the candidate
    contract, ``training/train.py``)."""
    import onnxruntime as ort

    try:
        sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    except Exception as err:  # onnxruntime raises its own exception types
        raise SystemExit(f"{path}: cannot load the policy: {err}")
    names = [i.name for i in sess.get_inputs()]
    if names == ["context", "candidates", "mask"]:
        def pick(ctx, cand, mask):
            idx = []
            for k in range(len(ctx)):
                logits = sess.run(None, {"context": ctx[k:k + 1], "candidates": cand[k:k + 1],
                                         "mask": mask[k:k + 1]})[0][0]
                idx.append(int(np.argmax(np.where(mask[k] > 0, logits, -np.inf))))
            return np.array(idx, np.int64)
        return "candidates", pick
    if names != [herb_sim.INPUT_NAME]:
        raise SystemExit(f"{path}: inputs {names} follow neither policy contract")
    return "obs", lambda obs: np.stack([sess.run(None, {herb_sim.INPUT_NAME: obs[k:k + 1]})[0][0]
                                        for k in range(len(obs))]).astype(np.float32)


def validate(act, episodes, seed, reward, boxed, rule=None, k=8, horizon=None, sequence=herb_sim.HERB_ORDER,
             rollouts=None, twin="heightmap", threads=None, world="ideal"):
    """Success rate and mean objects packed of ``act`` (a policy from ``onnx_actor``) or, with
    ``rule``, of a lattice rule stepped in Rust, on the validation episodes."""
    # One environment per episode; each counts its first episode only (autoreset keeps the
    # finished ones stepping, their later episodes are ignored), so short episodes are not
    # over-represented.
    extra = {} if threads is None else {"threads": threads}
    env = herb_sim.HerbVectorEnv(episodes, reward=reward, sequence=sequence, seed=seed, boxed=boxed, world=world,
                                 **extra)
    obs = env.reset(seed=seed)[0]
    done = np.zeros(episodes, bool)
    packed = np.zeros(episodes, int)
    success = np.zeros(episodes, bool)
    while not done.all():
        if rule is not None:
            # Only environments still in their first episode: the teacher is costly.
            obs, _, term, _, info = env.step_rule(rule, k, active=~done, horizon=horizon,
                                                  rollouts=rollouts, twin=twin)
        elif act is not None and act[0] == "candidates":
            _, term, info = env.step_candidates(act[1](*env.candidates()))
        elif act is not None:
            obs, _, term, _, info = env.step(act[1](obs))
        else:
            labels, valid = env.expert_actions()
            if not valid[~done].all():
                raise SystemExit("blbf: an object fits between the walls in neither yaw")
            obs, _, term, _, info = env.step(labels)
        first = term & ~done
        packed[first] = info["packed"][first]
        success[first] = info["success"][first]
        done |= term
    return success.mean(), packed.mean()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policy", action="append", default=[], help="ONNX policy (repeat)")
    ap.add_argument("--rule", action="append", default=[],
                    choices=["blbf", "lattice-blbf", "lookahead", "lattice-reserve", "geo-lookahead", "search", "search-job", "search-exact"],
                    help="decision rule (repeat); search: the decision-time search in a twin built from "
                         "the heightmap; search-job: the same search in the job's own twin (its decisions replayed, "
                         "fitted to the heightmaps); search-exact: the same search in a clone of the world (the "
                         "twins' fidelity bound)")
    ap.add_argument("--rollouts", type=int, default=None, help="rollouts of the search per decision (default --k)")
    ap.add_argument("--k", type=int, default=8, help="candidates of the lookahead rules")
    ap.add_argument("--horizon", type=int, default=None,
                    help="objects per lookahead rollout, the candidate's included (default: to the end)")
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--reward", default="cs0.6", help="reward mode (does not change the episodes)")
    ap.add_argument("--sequence", default=herb_sim.HERB_ORDER, choices=["beam3", "beam3-last", "beam3-start", "random"],
                    help="object order of the episodes (default HERB's, beam3: Algorithm 1 as written; "
                         "beam3-last: each search rooted at the last object chosen, HERB's earlier order; "
                         "beam3-start: old name of beam3, kept for one release)")
    ap.add_argument("--boxed", default=None)
    ap.add_argument("--threads", type=int, default=None, help="worker threads (default: one per core)")
    ap.add_argument("--world", default="ideal",
                    help="the episodes' world: ideal, field (models/field.toml: a real cell's errors, told to no "
                    "policy or rule) or a field model file")
    a = ap.parse_args()
    if not 1 <= a.episodes <= 4096:
        raise SystemExit(f"--episodes {a.episodes}: need 1 to 4096")
    if a.horizon is not None and a.horizon < 1:
        raise SystemExit(f"--horizon {a.horizon}: need at least 1 object")
    if not a.policy and not a.rule:
        raise SystemExit("give at least one --policy or --rule")
    print(f"{a.episodes} training-distribution episodes, seed {a.seed}, order {a.sequence}, world {a.world}")
    for p in a.policy:
        s, n = validate(onnx_actor(p), a.episodes, a.seed, a.reward, a.boxed, sequence=a.sequence, world=a.world)
        print(f"{p}: success {100 * s:.2f} %, objects packed {n:.2f}", flush=True)
    for r in a.rule:
        t = time.perf_counter()
        rule = {"blbf": None, "search-exact": "search", "search-job": "search"}.get(r, r)
        s, n = validate(None, a.episodes, a.seed, a.reward, a.boxed,
                        rule=rule, k=a.k, horizon=a.horizon, sequence=a.sequence,
                        rollouts=a.rollouts, twin={"search-exact": "exact", "search-job": "job"}.get(r, "heightmap"),
                        threads=a.threads, world=a.world)
        label = f"{r} (k = {a.k})" if r in ("lookahead", "geo-lookahead") else r
        if rule == "search":
            label = f"{r} (k = {a.k}, {a.rollouts or a.k} rollouts)"
        if r == "lookahead" and a.horizon is not None:
            label = f"{r} (k = {a.k}, horizon {a.horizon})"
        print(f"{label}: success {100 * s:.2f} %, objects packed {n:.2f} "
              f"({time.perf_counter() - t:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
