"""Where the humans of BoxED put the objects taller than the box in their order.

Scratch measurement for docs/table1.md, "The objects taller than the box first". Each
session's placements in the order they happened, each object instance counted at its first
record (a re-grasp of the same id is skipped); an object's place is its index over the
session's count minus one (0 first, 1 last).

    python3 results/table1-field/failures/tall-positions.py [BOXED]   # default ../shared/boxed
"""

import glob
import json
import os
import sys

TALL = ("003", "004", "006", "021")

root = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("HERB_BOXED", "../shared/boxed")
files = sorted(glob.glob(os.path.join(root, "sessions", "*", "PickPlace_dataset.json")))
if not files:
    sys.exit(f"no sessions under {root}/sessions")
places = {t: [] for t in TALL}
for f in files:
    with open(f) as fh:
        records = json.load(fh)
    seen, order = set(), []
    for r in records:
        if r["id"] not in seen:
            seen.add(r["id"])
            order.append(r["id"][:3])
    for i, t in enumerate(order):
        if t in places:
            places[t].append(i / (len(order) - 1) if len(order) > 1 else 0.0)
print(f"{len(files)} sessions")
for t, p in places.items():
    quarter = sum(x < 0.25 for x in p) / len(p)
    print(f"{t}: {len(p)} objects, mean place {sum(p) / len(p):.2f}, first quarter {quarter:.0%}")
