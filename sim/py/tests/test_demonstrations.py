"""The humans' demonstrations for the BC rows of Table I (`herb_sim.human_demonstrations`).

Needs the BoxED data (HERB_BOXED or ../shared/boxed): skipped without it, except under CI=true,
where a missing data folder fails the test.
"""

import os
import pathlib

import numpy as np
import pytest

import herb_sim


def boxed_root():
    # The checkout is parents[3]; the data sits beside it (../shared/boxed from the workspace root).
    root = os.environ.get("HERB_BOXED") or str(pathlib.Path(__file__).resolve().parents[4] / "shared" / "boxed")
    if not pathlib.Path(root, "sessions").is_dir():
        if os.environ.get("CI") == "true":
            pytest.fail(f"BoxED data missing at {root} (CI=true: tests that need it must run)")
        pytest.skip(f"BoxED data not at {root}")
    return root


def test_every_first_placement_becomes_a_demonstration():
    d = herb_sim.human_demonstrations(boxed=boxed_root(), pool=8)
    obs, acts, ep, part = d["obs"], d["actions"], d["episode"], d["participant"]
    assert d["skipped"] == []
    assert len(d["names"]) == 263
    assert obs.shape == (4576, 2, 28, 28) and obs.dtype == np.uint8
    assert acts.shape == (4576, 3) and acts.dtype == np.float32
    assert np.isfinite(acts).all()
    # Planar placements of the human: most pivots inside the box, yaw in [-1, 1].
    assert (np.abs(acts[:, :2]) <= 1.0).mean() > 0.97
    assert (np.abs(acts[:, 2]) <= 1.0).all()
    assert len(np.unique(part)) == 87 and (part > 0).all()
    # The first object of every episode sees the empty box; the box fills up as objects come.
    first = np.flatnonzero(np.r_[True, ep[1:] != ep[:-1]])
    assert len(first) == 263
    empty = obs[first, 0]
    assert (empty == empty[0]).all()
    last = np.r_[first[1:], len(ep)] - 1
    filled = obs[last, 0].astype(np.int64).sum(axis=(1, 2))
    assert (filled > empty[0].astype(np.int64).sum()).all()


def test_a_bad_pool_is_refused():
    with pytest.raises(ValueError, match="pool 5"):
        herb_sim.human_demonstrations(pool=5)
