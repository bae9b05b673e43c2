"""A live 3D view of a HERB cell in Rerun, from the bus only.

    python -m herb_client.view --prefix herb              # serve the web viewer, open a browser
    python -m herb_client.view --prefix herb --save job.rrd --until-job-end   # record a job
    herbd replay RUN.log --events job.jsonl             # a finished job, from herbd's run log,
    python -m herb_client.view --events job.jsonl --save job.rrd   # recorded afterwards

It subscribes like any client (one subscriber on each of ``status``, ``decision``,
``heightmap``, ``joint_state`` and, with the loopback, ``sim/outcome``) and reads nothing else of herbd. What
it shows, on the timeline ``cell`` (seconds of the cell's monotonic clock):

* ``cell/box``: the box (wireframe) in the box frame B (z up, origin at the inner floor's
  centre, as every HERB frame);
* ``cell/pile``: the latest heightmap, as points on the pile's surface;
* ``cell/objects/<n>``: each object as its convex hull at its decided pose, labelled with its
  number and name: orange once decided, blue once placed, red when the loopback says it ended
  outside the success volume;
* ``cell/decision/candidates``: the candidates the search rolled out for the current object
  (herbd's ``decision`` service): a dot at each candidate's position, coloured from the lowest
  return (grey) to the highest (green), labelled with its return; the chosen one larger;
* ``arm/joints/<name>``: the arm's joint positions (rad) over time;
* ``job/objects_done``, ``job/decision_ms``, ``job/decision_wait_ms``: the job's progress;
  ``loop/max_cycle_us``, ``loop/deadline_misses``: herbd's loop statistics (from its
  heartbeats); ``job/events``: accepted, decided, placed, faults and the job's end, as a log.

The object shapes come from ``herbctl catalog`` (the catalog herbd uses, hulls from the BoxED
meshes when present), so the view draws what the controller decides with. ``--web-port``
serves Rerun's web viewer on localhost (bundled in the ``rerun-sdk`` wheel: nothing is
downloaded at run time); ``--save`` writes a recording anyone can open later with
``rerun job.rrd`` or the web viewer.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import iceoryx2 as iox2

from .payloads import (
    DOF,
    NO_OBJECT,
    DecisionReport,
    Fault,
    HeightmapFrame,
    JointState,
    SimOutcome,
    Status,
    StatusEvent,
)

#: Baxter's left arm, in `JointState` order.
JOINT_NAMES = ("s0", "s1", "e0", "e1", "w0", "w1", "w2")
#: Heightmap points: every `PILE_STRIDE`-th cell in each direction, cells above this (m).
PILE_STRIDE = 3
PILE_MIN_M = 0.002
#: Redraw the pile at most this often (s of the cell's clock): frames come at 5 Hz.
PILE_PERIOD_S = 0.5
#: Log the arm's joints at most this often (s): the adapter publishes them at 1 kHz.
JOINT_PERIOD_S = 0.05

DECIDED = (255, 160, 40)
PLACED = (70, 130, 230)
OUTSIDE = (220, 50, 50)


def find_herbctl() -> str:
    """``herbctl``: ``$HERB_BIN_DIR``, then ``PATH``, then this checkout's ``target/release`` and
    ``target/debug``."""
    repo = Path(__file__).resolve().parents[3]
    candidates = []
    if os.environ.get("HERB_BIN_DIR"):
        candidates.append(Path(os.environ["HERB_BIN_DIR"]) / "herbctl")
    found = shutil.which("herbctl")
    if found:
        candidates.append(Path(found))
    candidates += [repo / "target" / "release" / "herbctl", repo / "target" / "debug" / "herbctl"]
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return str(c)
    raise SystemExit(
        "herbctl not found (set HERB_BIN_DIR, put it on PATH, or build it: cargo build -p herbctl)"
    )


def load_catalog(path: str | None, boxed: str | None) -> dict:
    """The catalog document of ``herbctl catalog`` (from ``path``, or by running herbctl)."""
    if path:
        text = Path(path).read_text()
    else:
        cmd = [find_herbctl()]
        if boxed:
            cmd += ["--boxed", boxed]
        run = subprocess.run(cmd + ["catalog"], capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} catalog failed: {run.stderr.strip()}")
        text = run.stdout
    doc = json.loads(text)
    if doc.get("format") != 1:
        raise SystemExit(f"catalog format {doc.get('format')!r}: this view reads format 1")
    return doc


class View:
    """Turns what the bus says into Rerun entities (see the module docs)."""

    def __init__(self, rr, catalog: dict):
        self.rr = rr
        self.objects = catalog["objects"]
        self.box = catalog["box"]
        self.shown: dict[int, dict] = {}  # object index -> its pose, type, state
        self.last_pile_s = -math.inf
        self.last_pile_sum = None
        self.last_joints_s = -math.inf
        self.t0_ns: int | None = None
        self.job_id = 0
        self.ended = False

    def time(self, stamp_ns: int) -> None:
        # Seconds since the first message seen (every stamp is the cell's CLOCK_MONOTONIC).
        if self.t0_ns is None:
            self.t0_ns = stamp_ns
        self.rr.set_time("cell", duration=(stamp_ns - self.t0_ns) * 1e-9)

    def blueprint(self):
        """The layout: the cell in 3D, large; the job, the arm and the loop beside it."""
        rrb = self.rr.blueprint
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(
                    origin="cell",
                    name="cell",
                    eye_controls=rrb.archetypes.EyeControls3D(
                        position=[0.35, -0.45, 0.42],
                        look_target=[0.0, 0.0, 0.04],
                        eye_up=[0.0, 0.0, 1.0],
                    ),
                ),
                rrb.Vertical(
                    rrb.TextLogView(origin="job/events", name="events"),
                    rrb.TimeSeriesView(
                        origin="job",
                        contents=["job/objects_done", "job/decision_wait_ms"],
                        name="job",
                    ),
                    rrb.TimeSeriesView(origin="job/decision_ms", name="decision (ms)"),
                    rrb.TimeSeriesView(origin="arm/joints", name="arm joints (rad)"),
                    rrb.TimeSeriesView(origin="loop", name="loop"),
                ),
                column_shares=[3, 2],
            ),
            collapse_panels=True,
        )

    def static(self) -> None:
        rr, b = self.rr, self.box
        rr.log("cell", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rr.log(
            "cell/box",
            rr.Boxes3D(
                half_sizes=[[b["half_x"], b["half_y"], 0.5 * b["height"]]],
                centers=[[0.0, 0.0, 0.5 * b["height"]]],
                colors=[(160, 160, 160)],
                fill_mode=rr.components.FillMode.MajorWireframe,
                labels=["box"],
                show_labels=False,
            ),
            static=True,
        )

    def heightmap(self, f: HeightmapFrame) -> None:
        t = f.header.stamp_ns * 1e-9
        if t - self.last_pile_s < PILE_PERIOD_S:
            return
        self.last_pile_s = t
        nx, ny, cell = f.nx, f.ny, f.cell_m
        cells = np.ctypeslib.as_array(f.data)[: nx * ny].reshape(ny, nx)
        # The camera repeats an unchanged pile: drawn again only when it changed.
        total = float(np.nansum(cells))
        if total == self.last_pile_sum:
            return
        self.last_pile_sum = total
        rows, cols = np.mgrid[0:ny:PILE_STRIDE, 0:nx:PILE_STRIDE]
        z = cells[rows, cols]
        keep = np.isfinite(z) & (z > PILE_MIN_M)
        # Row 0 is the box's +y edge, column 0 its -x edge (herb_core::heightmap::GridSpec).
        x = -0.5 * nx * cell + (cols[keep] + 0.5) * cell
        y = 0.5 * ny * cell - (rows[keep] + 0.5) * cell
        pts = np.stack([x, y, z[keep]], axis=1)
        self.time(f.header.stamp_ns)
        self.rr.log(
            "cell/pile",
            self.rr.Points3D(pts, radii=0.5 * cell * PILE_STRIDE, colors=[(120, 180, 120)]),
        )

    def object(self, index: int, color) -> None:
        o = self.shown[index]
        spec = self.objects[o["type"]]
        x, y, z, yaw = o["pose"]
        c, s = math.cos(yaw), math.sin(yaw)
        v = np.asarray(spec["vertices"], dtype=np.float32)
        world = np.stack([x + c * v[:, 0] - s * v[:, 1], y + s * v[:, 0] + c * v[:, 1], z + v[:, 2]], 1)
        path = f"cell/objects/{index + 1}"
        self.rr.log(
            path,
            self.rr.Mesh3D(
                vertex_positions=world,
                triangle_indices=np.asarray(spec["triangles"], dtype=np.uint32),
                albedo_factor=color,
            ),
        )
        top = float(world[:, 2].max())
        self.rr.log(
            f"{path}/label",
            self.rr.Points3D(
                [[x, y, top + 0.01]],
                radii=0.002,
                labels=[f"{index + 1} {spec['id']} {spec['name']}"],
                colors=[color],
            ),
        )

    def status(self, s: Status) -> None:
        rr = self.rr
        ev = StatusEvent(s.event)
        self.time(s.header.stamp_ns)
        if ev == StatusEvent.Heartbeat:
            rr.log("loop/max_cycle_us", rr.Scalars(s.max_cycle_ns / 1e3))
            rr.log("loop/deadline_misses", rr.Scalars(float(s.deadline_misses)))
            return
        if ev == StatusEvent.Accepted:
            self.job_id = s.job_id
            self.ended = False
            for i in list(self.shown):
                rr.log(f"cell/objects/{i + 1}", rr.Clear(recursive=True))
            self.shown.clear()
        text = f"job {s.job_id}: {ev.name}"
        if s.object_type != NO_OBJECT and ev in (
            StatusEvent.Decided,
            StatusEvent.Placed,
            StatusEvent.Skipped,
        ):
            name = self.objects[s.object_type]["name"] if s.object_type < len(self.objects) else "?"
            text += f" object {s.object_index + 1}/{s.objects_total} ({name})"
        if ev in (StatusEvent.Decided, StatusEvent.Placed) and s.object_type < len(self.objects):
            self.shown[s.object_index] = {"type": s.object_type, "pose": list(s.pose)}
            self.object(s.object_index, DECIDED if ev == StatusEvent.Decided else PLACED)
            text += " at x {:+.3f} y {:+.3f} z {:.3f} m, yaw {:+.2f} rad".format(*s.pose)
        if ev == StatusEvent.Decided:
            rr.log("job/decision_ms", rr.Scalars(s.decision_ns / 1e6))
        if s.fault:
            text += f", fault {Fault(s.fault).name}"
        level = "WARN" if s.fault and ev in (StatusEvent.Fault, StatusEvent.JobFailed) else "INFO"
        rr.log("job/events", rr.TextLog(text, level=level))
        rr.log("job/objects_done", rr.Scalars(float(s.objects_done)))
        rr.log("job/decision_wait_ms", rr.Scalars(float(s.decision_wait_ms)))
        if ev in (StatusEvent.JobDone, StatusEvent.JobFailed, StatusEvent.JobCancelled):
            self.ended = True

    def decision(self, d: DecisionReport) -> None:
        """A search's candidates for the object just decided (a policy has none)."""
        rr = self.rr
        self.time(d.header.stamp_ns)
        cands = d.candidates[: min(d.count, len(d.candidates))]
        if d.method != 1 or not cands:
            rr.log("cell/decision", rr.Clear(recursive=True))
            return
        rets = np.array([c.ret for c in cands])
        lo, hi = float(rets.min()), float(rets.max())
        share = (rets - lo) / (hi - lo) if hi > lo else np.ones_like(rets)
        grey, green = np.array([150, 150, 150]), np.array([40, 200, 60])
        colors = [tuple(int(v) for v in grey + f * (green - grey)) for f in share]
        top = self.box["height"] + 0.02
        chosen = [bool(c.flags & 2) for c in cands]
        rr.log(
            "cell/decision/candidates",
            rr.Points3D(
                [[c.x, c.y, top] for c in cands],
                radii=[0.008 if ch else 0.004 for ch in chosen],
                colors=colors,
                labels=[f"{c.ret:+.2f}" + (" chosen" if ch else "") for c, ch in zip(cands, chosen)],
            ),
        )
        rr.log(
            "job/events",
            rr.TextLog(
                f"object {d.object_index + 1}: the search rolled out {d.allowed} of "
                f"{d.feasible} candidates in {d.decision_ns / 1e6:.0f} ms",
                level="DEBUG",
            ),
        )

    def joints(self, js: JointState) -> None:
        t = js.header.stamp_ns * 1e-9
        if t - self.last_joints_s < JOINT_PERIOD_S:
            return
        self.last_joints_s = t
        self.time(js.header.stamp_ns)
        for name, q in zip(JOINT_NAMES, js.position[:DOF]):
            self.rr.log(f"arm/joints/{name}", self.rr.Scalars(q))

    def outcome(self, o: SimOutcome) -> None:
        # The loopback's word on where each released object ended: red if outside.
        for i in range(min(o.objects, len(self.shown))):
            if o.placed[i].bound != 0 and i in self.shown:
                self.object(i, OUTSIDE)


def replay_events(view: View, path: str) -> int:
    """Feeds ``herbd replay --events`` JSON lines (statuses and decision heightmaps of a run
    log) to ``view``; the number of events."""
    n = 0
    with open(path) as f:
        for line in f:
            e = json.loads(line)
            if "status" in e:
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
            else:
                raise SystemExit(f"{path}: an event of no known kind: {line[:80]!r}")
            n += 1
    return n


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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--prefix", default="herb", help="IPC prefix of the cell (herbd's ipc_prefix)")
    ap.add_argument("--web-port", type=int, default=9090, help="the web viewer's port on localhost")
    ap.add_argument("--grpc-port", type=int, default=9876, help="the Rerun data server's port")
    ap.add_argument("--no-browser", action="store_true", help="serve without opening a browser")
    ap.add_argument("--save", help="write a recording (.rrd) instead of serving the viewer")
    ap.add_argument(
        "--events", help="record a finished job from `herbd replay RUN.log --events FILE` (with --save)"
    )
    ap.add_argument("--catalog", help="a `herbctl catalog` JSON file (default: run herbctl)")
    ap.add_argument("--boxed", help="the BoxED folder for the meshes (passed to herbctl)")
    ap.add_argument("--until-job-end", action="store_true", help="stop after the first job ends")
    ap.add_argument("--duration", type=float, help="stop after this many seconds")
    ap.add_argument("--timeout", type=float, default=30.0, help="wait this long for the cell (s)")
    a = ap.parse_args(argv)
    import rerun as rr

    if a.events and not a.save:
        raise SystemExit("--events writes a recording: give --save FILE.rrd too")
    catalog = load_catalog(a.catalog, a.boxed)
    rr.init("herb", recording_id=f"herb-{a.prefix}-{int(time.time())}")
    if a.save:
        rr.save(a.save)
    else:
        uri = rr.serve_grpc(grpc_port=a.grpc_port)
        rr.serve_web_viewer(web_port=a.web_port, open_browser=not a.no_browser, connect_to=uri)
        print(f"viewer: http://localhost:{a.web_port}/?url={uri}", flush=True)
    if a.events:
        view = View(rr, catalog)
        rr.send_blueprint(view.blueprint())
        view.static()
        n = replay_events(view, a.events)
        rr.disconnect()
        print(f"recording: {a.save} ({n} events)", flush=True)
        return 0
    iox2.set_log_level(iox2.LogLevel.Error)
    node = (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new(f"herb-view-{os.getpid()}"))
        .create(iox2.ServiceType.Ipc)
    )
    subs = {
        "status": (subscribe(node, a.prefix, "status", Status, a.timeout), Status),
        "decision": (subscribe(node, a.prefix, "decision", DecisionReport, a.timeout), DecisionReport),
        "heightmap": (subscribe(node, a.prefix, "heightmap", HeightmapFrame, a.timeout), HeightmapFrame),
        "joint_state": (subscribe(node, a.prefix, "joint_state", JointState, a.timeout), JointState),
    }
    try:
        subs["sim/outcome"] = (subscribe(node, a.prefix, "sim/outcome", SimOutcome, 1.0), SimOutcome)
    except SystemExit:
        pass  # a real cell: no simulated outcomes
    view = View(rr, catalog)
    rr.send_blueprint(view.blueprint())
    view.static()
    stop = {"now": False}
    signal.signal(signal.SIGINT, lambda *_: stop.update(now=True))
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    t0 = time.monotonic()
    handlers = {
        "status": view.status,
        "decision": view.decision,
        "heightmap": view.heightmap,
        "joint_state": view.joints,
        "sim/outcome": view.outcome,
    }
    seen_job = False
    while not stop["now"]:
        for leaf, (sub, payload) in subs.items():
            for m in drain(sub, payload):
                handlers[leaf](m)
        seen_job |= view.job_id != 0
        if a.until_job_end and seen_job and view.ended:
            # The last outcomes come after the job's end: one more round for them.
            time.sleep(1.5)
            for m in drain(*subs["sim/outcome"]) if "sim/outcome" in subs else ():
                view.outcome(m)
            break
        if a.duration is not None and time.monotonic() - t0 > a.duration:
            break
        node.wait(iox2.Duration.from_millis(20))
    rr.disconnect()  # flushes the recording or the stream
    if a.save:
        print(f"recording: {a.save}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
