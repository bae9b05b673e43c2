"""The sweep runner (`herb_sim.sweep`) on a local Ray runtime of 2 CPUs.

Its per-episode CSV equals `herb-sim eval`'s for BLBF, the shipped policy cs06 and the search
with a count of rollouts on 8 BoxED episodes (in batches of 3: the seeds do not depend on the
batch); a resumed sweep runs no finished task again; a task whose worker is killed is run again
by Ray with the same result. The `latency_mean_ms` column is a measured time and is left out of
the comparisons.

`herb-sim` comes from `$HERB_BIN_DIR` (default `target/debug`, which `cargo test --workspace`
builds). Needs the BoxED data (HERB_BOXED or ../shared/boxed): skipped without it, except under
CI=true, where a missing data folder fails the test.
"""

import csv
import os
import pathlib
import subprocess

import pytest
import ray

from herb_sim import sweep

REPO = pathlib.Path(__file__).resolve().parents[3]
BIN = pathlib.Path(os.environ.get("HERB_BIN_DIR", REPO / "target" / "debug"))


def boxed_root():
    root = os.environ.get("HERB_BOXED") or str(REPO.parent / "shared" / "boxed")
    if not pathlib.Path(root, "sessions").is_dir():
        if os.environ.get("CI") == "true":
            pytest.fail(f"BoxED data missing at {root} (CI=true: tests that need it must run)")
        pytest.skip(f"BoxED data not at {root}")
    return root


@pytest.fixture(scope="module")
def local_ray():
    """A Ray runtime of its own with 2 CPUs (never a cluster this machine may be running)."""
    os.environ.pop("RAY_ADDRESS", None)
    ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=200 * 1024**2,
             log_to_driver=False, runtime_env={"env_vars": {"RAYON_NUM_THREADS": "1"}})
    yield
    ray.shutdown()


def rows_without_latency(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][-1] == "latency_mean_ms", rows[0]
    return [r[:-1] for r in rows]


def test_the_sweeps_episodes_are_herb_sim_evals(tmp_path, local_ray):
    boxed = boxed_root()
    cli_csv = tmp_path / "cli.csv"
    cmd = [str(BIN / "herb-sim"), "--boxed", boxed, "--quiet", "eval", "--method", "blbf", "--method", "herb",
           "--policy", "cs06", "--method", "search", "--search-rollouts", "2", "--limit", "8", "--threads", "2",
           "--out", str(tmp_path / "cli.md"), "--csv", str(cli_csv), "--plots", str(tmp_path / "plots")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    spec = {"batch": 3, "boxed": boxed, "episodes": [{"set": "boxed", "limit": 8}],
            "rows": [{"method": "blbf"}, {"method": "herb", "policy": "cs06"},
                     {"method": "search", "settings": {"search_rollouts": 2}}]}
    out = tmp_path / "sweep"
    r = sweep.run_sweep(spec, out, progress=False, base=REPO)
    assert (r["tasks"], r["ran"], r["cached"]) == (9, 9, 0), r
    expected = rows_without_latency(cli_csv)
    assert len(expected) == 1 + 3 * 8
    got_runs = sorted(out.glob("runs/*/table1.csv"))
    got = [rows_without_latency(p) for p in got_runs]
    assert all(g[0] == expected[0] for g in got)
    assert sorted(row for g in got for row in g[1:]) == sorted(expected[1:])
    # Every episode of every configuration, in the CLI's order, in episodes.csv.
    with open(out / "episodes.csv", newline="") as f:
        every = [row[1:-1] for row in list(csv.reader(f))[1:]]
    assert every == expected[1:]
    summary = (out / "sweep.md").read_text()
    assert "| c3 | search (2 rollouts, k = 16, job, release check of 5 mm / 3 deg, median-filtered camera, gap 6.25 mm) (beam3) |" in summary, summary
    for chart in ("success.png", "objects.png"):
        assert (out / chart).stat().st_size > 1000

    # Resumed: nothing runs again, and the results are the same.
    before = (out / "episodes.csv").read_text()
    r = sweep.run_sweep(spec, out, progress=False, base=REPO)
    assert (r["ran"], r["cached"]) == (0, 9), r
    assert (out / "episodes.csv").read_text() == before
    # One task's result lost: that task alone runs again.
    lost = sorted((out / "cache").glob("*/*.json"))[4]
    lost.unlink()
    r = sweep.run_sweep(spec, out, progress=False, base=REPO)
    assert (r["ran"], r["cached"]) == (1, 8), r
    assert rows_without_latency(out / "episodes.csv") == rows_without_latency_text(before)


def rows_without_latency_text(text):
    return [r[:-1] for r in csv.reader(text.splitlines())]


def test_a_task_whose_worker_is_killed_runs_again(tmp_path, local_ray):
    boxed = boxed_root()
    spec = {"batch": 2, "boxed": boxed, "episodes": [{"set": "boxed", "limit": 4}],
            "rows": [{"method": "blbf", "settings": {"seed": 3}}]}
    clean = sweep.run_sweep(spec, tmp_path / "clean", progress=False, base=REPO)
    assert clean["ran"] == 2
    marker = tmp_path / "killed"
    r = sweep.run_sweep(spec, tmp_path / "killed-run", progress=False, base=REPO, fault_marker=str(marker))
    assert marker.exists(), "no worker was killed"
    assert (r["ran"], r["cached"]) == (2, 0), r
    assert rows_without_latency(tmp_path / "killed-run" / "episodes.csv") == \
        rows_without_latency(tmp_path / "clean" / "episodes.csv")


def test_a_bad_spec_is_refused_before_anything_runs(tmp_path):
    boxed = boxed_root()
    base = {"boxed": boxed, "episodes": [{"set": "boxed", "limit": 2}]}
    with pytest.raises(sweep.SpecError, match=r"unknown key\(s\) \['method'\]"):
        sweep.plan({**base, "method": "blbf", "rows": [{"method": "blbf"}]}, REPO)
    with pytest.raises(sweep.SpecError, match="search_rolouts"):
        sweep.plan({**base, "rows": [{"method": "search", "settings": {"search_rolouts": 4}}]}, REPO)
    with pytest.raises(sweep.SpecError, match="herb needs a policy"):
        sweep.plan({**base, "rows": [{"method": "herb"}]}, REPO)
    with pytest.raises(sweep.SpecError, match="no such file"):
        sweep.plan({**base, "rows": [{"method": "herb", "policy": "nowhere/p.onnx"}]}, REPO)
    with pytest.raises(sweep.SpecError, match=r"rows\[0\]\.settings: expected a table"):
        sweep.plan({**base, "rows": [{"method": "blbf", "settings": 3}]}, REPO)
    with pytest.raises(sweep.SpecError, match="no episodes"):
        sweep.plan({**base, "episodes": [{"set": "boxed", "limit": 0}], "rows": [{"method": "blbf"}]}, REPO)
    with pytest.raises(sweep.SpecError, match="not TOML"):
        (tmp_path / "bad.toml").write_text("rows = [")
        sweep.load_spec(tmp_path / "bad.toml")
    # The field model by name: the checkout's file, by its absolute path (the workers' own
    # directory may be another); a missing model file is refused.
    configs, _, _ = sweep.plan({**base, "rows": [{"method": "blbf", "settings": {"world": "field"}}]}, REPO)
    assert configs[0].settings["world"] == str(REPO / "models" / "field.toml")
    with pytest.raises(sweep.SpecError, match="nope.toml"):
        sweep.plan({**base, "rows": [{"method": "blbf", "settings": {"world": "nope.toml"}}]}, REPO)
    # Sampled episodes: seeded by (seed, index), the same names and sizes every time.
    spec = {**base, "episodes": [{"set": "sample", "seed": 777, "count": 5}], "rows": [{"method": "blbf"}]}
    configs, tasks, _ = sweep.plan(spec, REPO)
    assert len(configs) == 1 and sum(t.count for t in tasks) == 5
