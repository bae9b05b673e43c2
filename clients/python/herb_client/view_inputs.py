"""Where the live view's data comes from: herbd's and herbctl's tools (the catalog, the cell
model, a run log's replay), the events file of ``herbd replay --events``, and the bus.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import iceoryx2 as iox2

from .payloads import DOF, GripperState, HeightmapFrame, Status
from .view_geometry import check_cell_model


def find_exe(name: str) -> str:
    """``name`` (``herbctl``, ``herbd``): ``$HERB_BIN_DIR``, then ``PATH``, then this checkout's
    ``target/release`` and ``target/debug``."""
    repo = Path(__file__).resolve().parents[3]
    candidates = []
    if os.environ.get("HERB_BIN_DIR"):
        candidates.append(Path(os.environ["HERB_BIN_DIR"]) / name)
    found = shutil.which(name)
    if found:
        candidates.append(Path(found))
    candidates += [repo / "target" / "release" / name, repo / "target" / "debug" / name]
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return str(c)
    package = "herb-daemon" if name == "herbd" else name
    raise SystemExit(
        f"{name} not found (set HERB_BIN_DIR, put it on PATH, or build it: cargo build -p {package})"
    )


def tool_output(cmd: list[str], sub: str) -> str:
    """What ``cmd sub`` (one of herbd's or herbctl's tools) printed; it failing ends the view,
    saying why."""
    run = subprocess.run(cmd + [sub], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} {sub} failed: {run.stderr.strip()}")
    return run.stdout


def load_catalog(path: str | None, boxed: str | None) -> dict:
    """The catalog document of ``herbctl catalog`` (from ``path``, or by running herbctl)."""
    if path:
        text = Path(path).read_text()
    else:
        cmd = [find_exe("herbctl")]
        if boxed:
            cmd += ["--boxed", boxed]
        text = tool_output(cmd, "catalog")
    doc = json.loads(text)
    if doc.get("format") != 1:
        raise SystemExit(f"catalog format {doc.get('format')!r}: this view reads format 1")
    return doc


def load_cell_model(config: str | None) -> dict:
    """The arm and the cell as herbd plans with them (``herbd [--config FILE] cell-model``)."""
    cmd = [find_exe("herbd")]
    if config:
        cmd += ["--config", config]
    return json.loads(tool_output(cmd, "cell-model"))


def replay_events(view, path: str) -> int:
    """Feeds ``herbd replay --events`` JSON lines (the cell, statuses, decision heightmaps, joint
    and gripper states of a run log) to ``view``; the number of events."""
    n = 0
    with open(path) as f:
        for lineno, line in enumerate(f, 1):
            try:
                replay_event(view, json.loads(line))
            except (ValueError, KeyError, TypeError, AttributeError) as err:
                raise SystemExit(f"{path}:{lineno}: not an event of herbd replay --events ({err!r})") from err
            n += 1
    return n


def replay_event(view, e: dict) -> None:
    """One line of ``herbd replay --events``, to ``view``."""
    if "cell" in e:
        check_cell_model(e["cell"])
        view.cell = e["cell"]
        view.static()
    elif "status" in e:
        d, s = e["status"], Status()
        s.header.stamp_ns = d["stamp_ns"]
        for k in (
            "job_id",
            "event",
            "state",
            "fault",
            "objects_total",
            "objects_done",
            "object_index",
            "object_type",
            "decision_wait_ms",
            "decision_ns",
        ):
            setattr(s, k, d[k])
        s.pose[:] = d["pose"]
        view.status(s)
    elif "heightmap" in e:
        d, h = e["heightmap"], HeightmapFrame()
        h.header.stamp_ns, h.nx, h.ny, h.cell_m = d["stamp_ns"], d["nx"], d["ny"], d["cell_m"]
        cells = np.asarray(d["cells"], dtype=np.float32)
        np.ctypeslib.as_array(h.data)[: cells.size] = cells
        view.last_pile_s = -math.inf  # one heightmap per decision: each is drawn
        view.heightmap(h)
    elif "joint_state" in e:
        d = e["joint_state"]
        view.time(d["stamp_ns"])
        view.joint_angles([float(v) for v in d["position"][:DOF]])
    elif "gripper" in e:
        d, g = e["gripper"], GripperState()
        g.header.stamp_ns, g.closed, g.holding = d["stamp_ns"], int(d["closed"]), int(d["holding"])
        view.gripper(g)
    else:
        raise ValueError(f"an event of no known kind: {sorted(e)}")


def replay_run_log(log: str, boxed: str | None, out: str) -> None:
    """``herbd replay LOG --events OUT``: a run log's events for a recording. A log that ends
    early or diverges still gives what was replayed before, with a warning."""
    cmd = [find_exe("herbd")]
    if boxed:
        cmd += ["--boxed", boxed]
    run = subprocess.run(cmd + ["replay", log, "--events", out], capture_output=True, text=True)
    if run.returncode not in (0, 1, 3) or not Path(out).is_file():
        raise SystemExit(f"{' '.join(cmd)} replay {log} failed: {(run.stderr or run.stdout).strip()}")
    if run.returncode != 0:
        last = run.stdout.strip().splitlines()
        print(f"warning: herbd replay: {' '.join(last[-2:])}", file=sys.stderr, flush=True)


def subscribe(node, prefix: str, leaf: str, payload, timeout_s: float):
    """A subscriber of ``<prefix>/<leaf>``, retried until the service exists."""
    deadline = time.monotonic() + timeout_s
    name = iox2.ServiceName.new(f"{prefix}/{leaf}")
    while True:
        try:
            svc = node.service_builder(name).publish_subscribe(payload).open()
            return svc.subscriber_builder().create()
        except Exception as e:  # iceoryx2 raises one class per error kind
            if time.monotonic() > deadline:
                raise SystemExit(f"cannot open {prefix}/{leaf}: {e!r} (is the cell running?)") from e
            time.sleep(0.05)


def drain(sub, payload):
    """Every sample that arrived, copied."""
    while (sample := sub.receive()) is not None:
        yield payload.from_buffer_copy(sample.payload().contents)
        sample.delete()
