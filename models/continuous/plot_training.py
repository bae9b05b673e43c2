#!/usr/bin/env python3
"""The sequence and reward ablation: episode length (objects placed before the episode ended)
over environment steps, one curve per training run, from the runs' ``progress.csv``.

    python models/continuous/plot_training.py --out results/ablation.png results/training/*.csv

Each CSV is named after its setting (``cs06.csv`` -> "cs06"); ``mean_len`` is the mean over the
last 200 episodes that ended when the row was written (models/continuous/train.py). Needs matplotlib.
"""

import argparse
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {
    "cs06": "CS0.6, Beam-3",
    "cs09": "CS0.9, Beam-3",
    "c": "C, Beam-3",
    "simple": "Simple, Beam-3",
    "cs06-random": "CS0.6, random order",
    "cs06-bc": "CS0.6, Beam-3, BLBF-guided (expert actions mixed in to 60k steps)",
}


def read(path):
    steps, lens = [], []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row.get("mean_len"):
                steps.append(int(row["steps"]))
                lens.append(float(row["mean_len"]))
    if not steps:
        raise SystemExit(f"{path}: no rows with mean_len")
    return steps, lens


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("csv", nargs="+")
    ap.add_argument("--out", default="results/ablation.png")
    ap.add_argument("--max-steps", type=int, default=None, help="clip the x axis here")
    ap.add_argument("--title", default="SAC training in herb-sim: sequence and reward ablation")
    a = ap.parse_args()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for path in a.csv:
        name = os.path.splitext(os.path.basename(path))[0]
        steps, lens = read(path)
        if a.max_steps:
            keep = [i for i, s in enumerate(steps) if s <= a.max_steps]
            steps, lens = [steps[i] for i in keep], [lens[i] for i in keep]
        style = "--" if name.endswith("random") else "-"
        ax.plot(steps, lens, style, label=LABELS.get(name, name))
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode length (objects placed), last 200 episodes")
    ax.set_title(a.title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    fig.savefig(a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
