"""Evaluations and sweeps on Ray: ``python -m herb_sim.sweep SPEC.toml [--address HOST:PORT]``.

A spec (TOML, ``docs/sweeps.md``) names rows (methods with their settings), a grid of
settings (orders, budgets, error models, seeds: every combination), and episode sets (BoxED,
sampled episodes). Every (configuration, batch of episodes) is one Ray task that runs the
same Rust episode loop as ``herb-sim eval`` through the bindings (``Evaluation.run``): the
per-episode CSV of a configuration is the one ``herb-sim eval`` writes for that row.

- Without ``--address`` the sweep starts Ray on this machine (``ray.init()``); with it, it joins
  that cluster (``auto``: the one ``ray start`` left on this machine).
- A finished task's result is kept under ``OUT/cache/<configuration hash>/``: a rerun of the
  same spec runs only the tasks that have no result yet (the hash covers the configuration,
  the episode set, the extension's code and the policy and sequence model files).
- Ray runs a task again when its worker dies (``max_retries``); an error inside a task (a bad
  model file, say) is an error of the sweep, named with its configuration.
- Each task takes one CPU (``search_threads`` CPUs for a search with more threads) and runs its
  episodes on one thread; the catalog, episodes and models stay loaded in each worker.
- An episode's seed is the base seed plus its index in the episode set, whatever the batch
  and the worker.

Results (``OUT``): per run (an episode set and its settings) ``runs/<run>/table1.md`` and
``table1.csv`` as ``herb-sim eval`` writes them; ``episodes.csv`` (every episode of every
configuration); ``sweep.md`` and ``sweep.csv`` (each configuration's success with its 95 %
interval, objects packed, decision time) and the charts ``success.png`` and ``objects.png``.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import itertools
import json
import os
import signal
import socket
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from . import _native

#: Keys of a spec's top level.
SPEC_KEYS = {"out", "batch", "boxed", "meshes", "models", "episodes", "settings", "grid", "rows"}
#: Keys of a row.
ROW_KEYS = {"method", "policy", "settings", "grid", "label"}
#: Settings holding paths, resolved against the directory the sweep is started from.
PATH_SETTINGS = ("sequence_model", "bc_models")


class SpecError(ValueError):
    """A spec that cannot be run, with what is wrong in it."""


@dataclass(frozen=True)
class Config:
    """One configuration: a row with its settings, on one episode set."""

    row: str
    policy: str | None
    settings: dict
    episodes: dict
    key: str = field(compare=False)

    def describe(self) -> str:
        policy = f" {self.policy}" if self.policy else ""
        return f"{self.row}{policy} {json.dumps(self.settings, sort_keys=True)} on {json.dumps(self.episodes, sort_keys=True)}"


@dataclass(frozen=True)
class Task:
    """One Ray task: a configuration over consecutive episodes ``first .. first + count``."""

    config: Config
    first: int
    count: int

    @property
    def cache_file(self) -> str:
        return f"{self.config.key}/{self.first:05d}-{self.first + self.count - 1:05d}.json"


_DIGESTS: dict = {}


def _file_digest(path: Path) -> str:
    """A file's sha256, read once per (file, size, time of change) in this process."""
    st = os.stat(path)
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _DIGESTS:
        _DIGESTS[key] = _read_digest(path)
    return _DIGESTS[key]


def _read_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _code_digest() -> str:
    """The extension module's digest: results of another build are not reused."""
    return _file_digest(Path(_native.__file__))


def _grid_points(grid: dict, where: str) -> list[dict]:
    if not isinstance(grid, dict):
        raise SpecError(f"{where}: expected a table of KEY = [values]")
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise SpecError(f"{where}.{k}: expected a non-empty list of values")
    keys = sorted(grid)
    return [dict(zip(keys, values)) for values in itertools.product(*(grid[k] for k in keys))]


def load_spec(path: str | Path) -> dict:
    """Reads a spec file (TOML), with a clear error for a missing file or bad TOML."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            spec = tomllib.load(f)
    except OSError as e:
        raise SpecError(f"{p}: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError(f"{p}: not TOML: {e}") from None
    spec.setdefault("out", str(Path("results") / "sweeps" / p.stem))
    return spec


def _resolve(value: str | None, base: Path) -> str | None:
    if value is None:
        return None
    p = Path(value)
    return str(p if p.is_absolute() else (base / p).resolve())


def expand(spec: dict, base: Path | None = None) -> list[Config]:
    """The spec's configurations, in the spec's order (rows, then their grid, then the spec's
    grid, then the episode sets). Relative paths are resolved against ``base`` (the current
    directory), so that every worker reads the same files."""
    base = Path.cwd() if base is None else base
    unknown = set(spec) - SPEC_KEYS
    if unknown:
        raise SpecError(f"unknown key(s) {sorted(unknown)}; a spec has {sorted(SPEC_KEYS)}")
    rows = spec.get("rows")
    if not rows or not isinstance(rows, list):
        raise SpecError("no [[rows]]: name at least one method")
    sets = spec.get("episodes", [{"set": "boxed"}])
    if isinstance(sets, dict):
        sets = [sets]
    for key in ("settings", "grid"):
        if not isinstance(spec.get(key, {}), dict):
            raise SpecError(f"{key}: expected a table of KEY = value")
    if not isinstance(sets, list) or not all(isinstance(e, dict) for e in sets):
        raise SpecError("episodes: expected [[episodes]] tables (set = \"boxed\" or \"sample\")")
    shared = dict(spec.get("settings", {}))
    for k in PATH_SETTINGS:
        if k in shared:
            shared[k] = _resolve(shared[k], base)
    shared.setdefault("sequence_model", _resolve("models/sequence.json", base))
    shared.setdefault("bc_models", _resolve("models", base))
    grid = _grid_points(spec.get("grid", {}), "grid")
    code = _code_digest()
    configs = []
    for i, row in enumerate(rows):
        where = f"rows[{i}]"
        if not isinstance(row, dict) or "method" not in row:
            raise SpecError(f"{where}: expected a table with a method")
        unknown = set(row) - ROW_KEYS
        if unknown:
            raise SpecError(f"{where}: unknown key(s) {sorted(unknown)}; a row has {sorted(ROW_KEYS)}")
        if not isinstance(row.get("settings", {}), dict):
            raise SpecError(f"{where}.settings: expected a table of KEY = value")
        policy = row.get("policy")
        if policy is not None and not isinstance(policy, str):
            raise SpecError(f"{where}.policy: expected a name (cs06) or an ONNX file")
        if policy is not None and ("/" in policy or policy.endswith(".onnx")):
            policy = _resolve(policy, base)
        for row_point in _grid_points(row.get("grid", {}), f"{where}.grid"):
            for point in grid:
                settings = {**shared, **point, **row.get("settings", {}), **row_point}
                for k in PATH_SETTINGS:
                    settings[k] = _resolve(settings[k], base)
                # The field model by its absolute path too (`field`: the checkout's own file).
                world = settings.get("world", "ideal")
                if world != "ideal":
                    settings["world"] = _resolve("models/field.toml" if world == "field" else world, base)
                for episodes in sets:
                    body = {"row": row["method"], "policy": policy, "settings": settings, "episodes": episodes,
                            "boxed": spec.get("boxed"), "meshes": spec.get("meshes", True), "code": code,
                            "files": _files_digest(policy, settings, spec, base)}
                    key = hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:20]
                    configs.append(Config(row["method"], policy, copy.deepcopy(settings), dict(episodes), key))
    return configs


def _files_digest(policy, settings, spec, base: Path) -> dict:
    """Digests of the files a configuration reads that a rerun may find changed."""
    out = {}
    models = Path(_resolve(spec.get("models", "models"), base))
    files = [Path(settings["sequence_model"])]
    if settings.get("world", "ideal") != "ideal":
        files.append(Path(settings["world"]))
    if policy is not None:
        p = Path(policy)
        files.append(p if p.is_absolute() else models / f"policy-{policy}.onnx")
    for f in files:
        out[str(f)] = _file_digest(f) if f.is_file() else None
    return out


# --- the Ray task -----------------------------------------------------------------------------

_EVALUATIONS: dict = {}


def _evaluation(boxed, meshes):
    """The worker's ``Evaluation`` (catalog, episode sets, models), made once per worker."""
    key = (boxed, meshes)
    if key not in _EVALUATIONS:
        _EVALUATIONS[key] = _native.Evaluation(boxed=boxed, meshes=meshes)
    return _EVALUATIONS[key]


def run_task(job: dict) -> dict:
    """Runs one task's episodes (in whatever process Ray gives it): the body of the Ray task."""
    marker = job.get("fault_marker")
    if marker:
        # Fault injection for the tests: the first task to run dies with its worker, once.
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            pass
        else:
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
    t0 = time.perf_counter()
    ev = _evaluation(job["boxed"], job["meshes"])
    name, sequence, label, outcomes = ev.run(
        job["row"], json.dumps(job["settings"]), json.dumps(job["episodes"]),
        list(range(job["first"], job["first"] + job["count"])), policy=job["policy"], models=job["models"],
        threads=1)
    import ray
    node = ray.get_runtime_context().get_node_id() if ray.is_initialized() else None
    return {"name": name, "sequence": sequence, "label": label, "outcomes": outcomes,
            "seconds": time.perf_counter() - t0, "host": socket.gethostname(), "node": node, "pid": os.getpid()}


# --- the driver -------------------------------------------------------------------------------


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, unit="task", desc="sweep", file=sys.stderr)


def plan(spec: dict, base: Path | None = None):
    """The configurations, the tasks and the folders (``models``, ``boxed``) of a spec, checked
    before any task runs (a bad row, setting or episode set is one clear error)."""
    configs = expand(spec, base)
    batch = spec.get("batch", 8)
    if not isinstance(batch, int) or batch < 1:
        raise SpecError(f"batch {batch!r}: expected a number of episodes >= 1")
    base = Path.cwd() if base is None else base
    models = _resolve(spec.get("models", "models"), base)
    boxed = spec.get("boxed")
    checker = _native.Evaluation(boxed=_resolve(boxed, base), meshes=False)
    sizes = {}
    tasks = []
    for c in configs:
        try:
            checker.check(c.row, json.dumps(c.settings), c.policy, models)
            set_key = json.dumps(c.episodes, sort_keys=True)
            if set_key not in sizes:
                names, _objects, _skipped = checker.episodes_of(set_key)
                sizes[set_key] = len(names)
        except ValueError as e:
            raise SpecError(f"{c.describe()}: {e}") from None
        n = sizes[json.dumps(c.episodes, sort_keys=True)]
        if n == 0:
            raise SpecError(f"episode set {json.dumps(c.episodes, sort_keys=True)}: no episodes")
        tasks.extend(Task(c, first, min(batch, n - first)) for first in range(0, n, batch))
    # The workers read the BoxED folder the driver found (HERB_BOXED, ../shared/boxed...), by
    # its absolute path: the same path on every node of a cluster.
    return configs, tasks, {"models": models, "boxed": checker.boxed_root}


def run_sweep(spec: dict, out: str | Path | None = None, *, address: str | None = None,
              num_cpus: int | None = None, progress: bool = True, base: Path | None = None,
              fault_marker: str | None = None) -> dict:
    """Runs a spec's tasks on Ray (the one already initialised, else ``ray.init(address)``),
    skipping those with a cached result, and writes the results. ``fault_marker``: fault
    injection for the tests (the first task kills its own worker, once). Returns counts:
    ``tasks``, ``ran``, ``cached``, ``seconds``, and ``out``."""
    import ray

    configs, tasks, paths = plan(spec, base)
    out = Path(out if out is not None else spec["out"])
    cache = out / "cache"
    todo = [t for t in tasks if not (cache / t.cache_file).is_file()]
    t0 = time.perf_counter()
    if todo:
        if not ray.is_initialized():
            import logging
            try:
                ray.init(address=address, num_cpus=num_cpus, include_dashboard=False,
                         logging_level=logging.WARNING, runtime_env={"env_vars": {"RAYON_NUM_THREADS": "1"}})
            except (ConnectionError, ValueError, RuntimeError) as e:
                where = f"the cluster at {address}" if address else "Ray on this machine"
                raise RuntimeError(f"cannot start or join {where}: {e}") from None
        remote = ray.remote(run_task)
        pending = {}
        for t in todo:
            job = {"row": t.config.row, "policy": t.config.policy, "settings": t.config.settings,
                   "episodes": t.config.episodes, "first": t.first, "count": t.count, "models": paths["models"],
                   "boxed": paths["boxed"], "meshes": spec.get("meshes", True), "fault_marker": fault_marker}
            cpus = max(1, int(t.config.settings.get("search_threads", 1)))
            pending[remote.options(num_cpus=cpus, max_retries=3).remote(job)] = t
        bar = _progress(len(todo), progress)
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                t = pending.pop(done[0])
                try:
                    result = ray.get(done[0])
                except ray.exceptions.RayTaskError as e:
                    raise RuntimeError(f"{t.config.describe()}, episodes {t.first}..{t.first + t.count - 1}: "
                                       f"{e.cause if e.cause is not None else e}") from None
                _write_atomic(cache / t.cache_file, json.dumps(result))
                if bar is not None:
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
            for ref in pending:
                ray.cancel(ref)
    seconds = time.perf_counter() - t0
    write_results(out, configs, tasks)
    return {"tasks": len(tasks), "ran": len(todo), "cached": len(tasks) - len(todo), "seconds": seconds,
            "out": str(out)}


def _gather(out: Path, config: Config, tasks: list[Task]):
    """A configuration's outcomes in episode order (its tasks are listed in that order)."""
    parts = [json.loads((out / "cache" / t.cache_file).read_text()) for t in tasks if t.config.key == config.key]
    outcomes = [o for p in parts for o in p["outcomes"]]
    return parts[0]["name"], parts[0]["sequence"], parts[0]["label"], outcomes, sum(p["seconds"] for p in parts)


def _run_key(c: Config) -> str:
    return hashlib.sha256(json.dumps([c.episodes, c.settings], sort_keys=True).encode()).hexdigest()[:10]


def _settings_text(settings: dict) -> str:
    shown = {k: v for k, v in settings.items() if k not in PATH_SETTINGS}
    if shown.get("world", "ideal") != "ideal":
        shown["world"] = Path(shown["world"]).name
    return ", ".join(f"{k}={json.dumps(v)}" for k, v in sorted(shown.items())) or "defaults"


def _episodes_text(episodes: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in episodes.items())


def write_results(out: Path, configs: list[Config], tasks: list[Task]) -> None:
    """Writes the runs' tables and CSVs, ``episodes.csv``, ``sweep.md``, ``sweep.csv`` and the
    charts from the cached task results."""
    runs: dict[str, list] = {}
    summary_rows = []
    all_csv = ["config," + _native.CSV_HEADER]
    for i, c in enumerate(configs):
        name, sequence, label, outcomes, seconds = _gather(out, c, tasks)
        run = _run_key(c)
        runs.setdefault(run, []).append((c, name, sequence, label, outcomes))
        csv = _native.csv_rows(name, sequence, outcomes)
        all_csv.extend(f"c{i + 1},{line}\n" for line in csv.splitlines())
        s = _native.summary(outcomes)
        summary_rows.append((i + 1, c, label, run, s, seconds))
    for run, rows in runs.items():
        c0 = rows[0][0]
        notes = [f"sweep run {run}: episodes {_episodes_text(c0.episodes)}; settings {_settings_text(c0.settings)}"]
        noise = c0.settings.get("release_noise")
        if noise and any(noise):
            notes.append(_native.release_noise_note(float(noise[0]), float(noise[1])))
        table = _native.report([(label, outcomes) for _, _, _, label, outcomes in rows], notes)
        csv = _native.CSV_HEADER + "".join(_native.csv_rows(n, s, o) for _, n, s, _, o in rows)
        _write_atomic(out / "runs" / run / "table1.md", table)
        _write_atomic(out / "runs" / run / "table1.csv", csv)
    _write_atomic(out / "episodes.csv", "".join(all_csv))
    md = ["| config | row | episodes | settings | success % (95 % interval) | objects packed (95 % interval) "
          "| decision ms p50 / p99 | task time s | run |",
          "| --- | --- | --- | --- | ---: | ---: | ---: | ---: | --- |"]
    csv = ["config,row,episodes,settings,n,errors,successes,success_pct,success_lo_pct,success_hi_pct,packed_mean,"
           "packed_ci,latency_p50_ms,latency_p99_ms,task_seconds,run"]
    for k, c, label, run, s, seconds in summary_rows:
        lat = (f"{s['latency_p50_ms']:.3f} / {s['latency_p99_ms']:.3f}" if s["latency_p50_ms"] is not None else "-")
        md.append(f"| c{k} | {label} | {_episodes_text(c.episodes)} ({s['episodes']}) | {_settings_text(c.settings)} "
                  f"| {s['success_pct']:.2f} ({s['success_lo_pct']:.1f} to {s['success_hi_pct']:.1f}) "
                  f"| {s['packed_mean']:.2f} (± {s['packed_ci']:.2f}) | {lat} | {seconds:.1f} | {run} |")
        fmt = (lambda v: "" if v is None else f"{v:.4f}")
        csv.append(",".join([f"c{k}", json.dumps(label), json.dumps(_episodes_text(c.episodes)),
                             json.dumps(_settings_text(c.settings)), str(s["episodes"]), str(s["errors"]),
                             str(s["successes"]), fmt(s["success_pct"]), fmt(s["success_lo_pct"]),
                             fmt(s["success_hi_pct"]), fmt(s["packed_mean"]), fmt(s["packed_ci"]),
                             fmt(s["latency_p50_ms"]), fmt(s["latency_p99_ms"]), f"{seconds:.3f}", run]))
        if s["errors"]:
            md.append(f"|  | c{k}: {s['errors']} episodes could not be run: see runs/{run}/table1.md | | | | | | | |")
    _write_atomic(out / "sweep.md", "\n".join(md) + "\n")
    _write_atomic(out / "sweep.csv", "\n".join(csv) + "\n")
    chart_rows = [(f"c{k} {label}", s) for k, _c, label, _run, s, _ in summary_rows]
    try:
        _native.interval_chart(str(out / "success.png"), "Success with its 95 % interval", "success %", 100.0,
                               [(lab, s["success_pct"], s["success_lo_pct"], s["success_hi_pct"])
                                for lab, s in chart_rows])
        top = max([s["packed_mean"] + s["packed_ci"] for _, s in chart_rows] + [1.0])
        _native.interval_chart(str(out / "objects.png"), "Objects packed, mean with its 95 % interval",
                               "objects packed", top * 1.05,
                               [(lab, s["packed_mean"], s["packed_mean"] - s["packed_ci"],
                                 s["packed_mean"] + s["packed_ci"]) for lab, s in chart_rows])
    except RuntimeError as e:
        # The tables are written: report the charts' failure (a missing font, say) and keep them.
        print(f"herb_sim.sweep: charts not written: {e}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m herb_sim.sweep", description=__doc__.split("\n\n")[0])
    ap.add_argument("spec", help="the sweep's spec (TOML; docs/sweeps.md)")
    ap.add_argument("--address", help="join this Ray cluster (HOST:PORT, or auto: the one `ray start` left "
                    "on this machine); default: start Ray on this machine")
    ap.add_argument("--num-cpus", type=int, help="CPUs of the Ray runtime started on this machine (default: all)")
    ap.add_argument("--out", help="results folder (default: the spec's out, else results/sweeps/<spec name>)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    a = ap.parse_args(argv)
    if a.address and a.num_cpus:
        ap.error("--num-cpus applies to a runtime started here, not to a cluster joined with --address")
    try:
        spec = load_spec(a.spec)
        r = run_sweep(spec, a.out, address=a.address, num_cpus=a.num_cpus, progress=not a.no_progress)
    except (SpecError, RuntimeError) as e:
        print(f"herb_sim.sweep: error: {e}", file=sys.stderr)
        return 2
    print(f"{r['tasks']} tasks: {r['ran']} ran, {r['cached']} from the cache, in {r['seconds']:.1f} s; "
          f"results in {r['out']} (sweep.md)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
