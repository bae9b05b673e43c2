"""How well a student ranks the lattice's candidates as a prior for the search: on held-out
states of the full lookahead teacher (every candidate simulated to the episode's end), how often
the teacher's choice is among the student's top 1, 2, 4 and 8, by the actor's logits and by the
critic's Q values (min of the twins), beside lattice BLBF's own order (candidate index). The
teacher breaks ties between candidates of equal simulated outcome by that order, which favours
it; a second table counts a hit when any candidate of the best outcome is in the top k.

    python training/train.py --config training/configs/teacher-full-heldout.toml --out runs/teacher-full-heldout --minutes inf
    python training/topk.py --run runs/teacher-full-heldout --student runs/cs06-start --student runs/cs09-start

Prints a Markdown table (one row per ranking) and, with ``--json``, writes the figures.
"""

import argparse
import json
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import train  # noqa: E402  (the recipe's networks and replay buffer, one definition)

KS = (1, 2, 4, 8)


def ranks(scores, count, best):
    """The best rank among the candidates `best` within the first `count` scores (0 = best);
    ties go to the lower index, as the lattice's own order breaks them."""
    s = scores[:count]
    return min(int((s > s[j]).sum() + (s[:j] == s[j]).sum()) for j in best)


def table_rows(name, r):
    r = np.asarray(r)
    return [name] + [f"{100.0 * (r < k).mean():.1f} %" for k in KS]


def print_table(title, lines):
    print(f"{title}\n")
    print("| ranking | " + " | ".join(f"top {k}" for k in KS) + " |")
    print("| --- | " + " | ".join("---:" for _ in KS) + " |")
    for ln in lines:
        print("| " + " | ".join(ln) + " |")
    print()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="run folder of the full teacher's collection")
    ap.add_argument("--student", action="append", default=[], help="a student's run folder")
    ap.add_argument("--json", default=None, help="write the figures here")
    a = ap.parse_args()
    try:
        rb = train.Replay.load(os.path.join(a.run, "replay.npz"), 0)
    except SystemExit as e:
        raise SystemExit(f"{a.run}: {e}")
    rows = np.nonzero(rb.prior[: rb.n] & (rb.act[: rb.n] >= 0))[0]
    if len(rows) == 0:
        raise SystemExit(f"{a.run}: no teacher states with a choice")
    count = rb.count[rows].astype(int)
    choice = rb.act[rows].astype(int)
    # How many candidates the teacher simulated: all of them (k = 64) for this table.
    tried = (~np.isnan(rb.mcp[rows, :, 0].astype(np.float32))).sum(1)
    if (tried < count).any():
        print(f"warning: the teacher simulated fewer than all candidates in "
              f"{int((tried < count).sum())} states", file=sys.stderr)
    # The candidates whose simulated outcome (the parts of the return) equals the chosen one's.
    parts = rb.mcp[rows].astype(np.float32)
    best = [[j for j in range(count[i]) if np.allclose(parts[i, j], parts[i, choice[i]], equal_nan=True)]
            for i in range(len(rows))]
    out = {"states": int(len(rows)), "candidates_mean": float(count.mean()), "k": list(KS),
           "states_with_tied_best": int(sum(len(b) > 1 for b in best))}
    tables = {"choice": [], "any_best": []}
    index = np.arange(train.C, dtype=np.float32)
    rankings = [("lattice BLBF order", "lattice_blbf", -index[None, :].repeat(len(rows), 0))]
    ctx = torch.tensor(rb.ctx[rows].astype(np.float32))
    cand = torch.tensor(rb.cand[rows].astype(np.float32))
    mask = torch.tensor((np.arange(train.C)[None, :] < count[:, None]).astype(np.float32))
    for path in a.student:
        name = os.path.basename(os.path.normpath(path))
        ck = torch.load(os.path.join(path, "checkpoint.pt"), weights_only=False)
        actor, critic = train.Actor(), train.Critic()
        actor.load_state_dict(ck["actor"])
        critic.load_state_dict(ck["critic"])
        actor.eval()
        critic.eval()
        with torch.no_grad():
            logits = actor(ctx, cand, mask).numpy()
            q = critic(ctx, cand, mask).min(-1).values.numpy()
        rankings.append((f"{name} actor", f"{name}_actor", logits))
        rankings.append((f"{name} critic", f"{name}_critic", q))
    for label, key, scores in rankings:
        for table, sets in (("choice", [[c] for c in choice]), ("any_best", best)):
            r = [ranks(scores[i], count[i], sets[i]) for i in range(len(rows))]
            tables[table].append(table_rows(label, r))
            out[f"{key}_{table}"] = [float((np.asarray(r) < k).mean()) for k in KS]
    print(f"{len(rows)} held-out states of {a.run}, {count.mean():.1f} candidates on average; "
          f"in {out['states_with_tied_best']} several candidates share the best outcome.\n")
    print_table("Share of states where the teacher's choice is in the ranking's top k:", tables["choice"])
    print_table("Share of states where a candidate of the best outcome is in the ranking's top k:",
                tables["any_best"])
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
