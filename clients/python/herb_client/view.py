"""A live 3D view of a HERB cell in Rerun, from the bus only.

    python -m herb_client.view --prefix herb              # serve the web viewer, open a browser
    python -m herb_client.view --prefix herb --save job.rrd --until-job-end   # record a job
    python -m herb_client.view RUN.log                  # a finished job, from herbd's run log
    python -m herb_client.view RUN.log --save job.rrd   # ... recorded instead of served

It subscribes like any client (one subscriber on each of ``status``, ``decision``,
``heightmap``, ``joint_state``, ``gripper_state`` and, with the loopback, ``sim/outcome``) and
reads nothing else of herbd. What it shows, on the timeline ``cell`` (seconds of the cell's
monotonic clock), in the box frame B (z up, origin at the inner floor's centre):

* ``cell/arm``: Baxter's left arm, drawn from the joint states with herbd's own kinematic chain
  (``herbd cell-model``, checked against herbd's forward kinematics at start), its gripper open
  or closed; ``cell/pick_station``: where objects wait to be picked;
* ``cell/box``: the box's floor and walls, seen through, and its outline;
* ``cell/pile``: the latest heightmap, as points on the pile's surface;
* ``cell/objects/<n>``: object *n* in its own colour (the same for the whole job), a shaded hull
  with its edges: at the pose it settled at when the loopback says so (``sim/outcome``), at its
  decided pose until then; ``cell/objects/<n>/decided``: the decided pose as a ghost (edges,
  faint fill), with the landing's offset (mm, degrees) in the label and the events. Only the
  current object's label is shown, the others on hover; an object outside the success volume
  has red edges;
* ``cell/decision/candidates``: the candidates the search rolled out for the current object
  (herbd's ``decision`` service): a dot at each candidate's position, coloured from the lowest
  return (grey) to the highest (green), labelled with its return; the chosen one larger;
* ``arm/joints/<name>``: the arm's joint positions (rad) over time;
* ``job/objects_done``, ``job/decision_ms``, ``job/decision_wait_ms``, ``job/landing_mm``,
  ``job/landing_deg``: the job's progress; ``loop/max_cycle_us``, ``loop/deadline_misses``:
  herbd's loop statistics (from its heartbeats); ``job/events``: accepted, decided, placed,
  landed, faults and the job's end, as a log.

The object shapes come from ``herbctl catalog`` and the arm and cell from ``herbd cell-model``
(``--config``: herbd's configuration file), so the view draws what the controller plans with.
``--web-port`` serves Rerun's web viewer on localhost (bundled in the ``rerun-sdk`` wheel:
nothing is downloaded at run time); ``--save`` writes a recording anyone can open later with
``rerun job.rrd`` or the web viewer. A run log (``herbd --record DIR``) is replayed by
``herbd replay --events`` first, which also gives the cell as the run had it.
"""

from __future__ import annotations

import argparse
import colorsys
import math
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import iceoryx2 as iox2

from .payloads import (
    DOF,
    NO_OBJECT,
    DecisionReport,
    Fault,
    GripperState,
    HeightmapFrame,
    JointState,
    SimOutcome,
    Status,
    StatusEvent,
)
from .view_geometry import (
    arm_frames,
    cell_centres,
    check_cell_model,
    convex_polygon,
    feature_edges,
    inside_polygon,
    quat_matrix,
    rot_z,
    spread,
    wrap,
    yaw_of,
)
from .view_inputs import (
    drain,
    load_catalog,
    load_cell_model,
    replay_events,
    replay_run_log,
    subscribe,
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

#: The first objects' colours, by the object's number in the job (stable for the whole job):
#: far apart in hue, none of them the box's grey or the outside red ([`colour`] goes on).
PALETTE = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (148, 103, 189),
    (23, 190, 207),
    (227, 119, 194),
    (188, 189, 34),
    (140, 86, 75),
    (255, 187, 120),
    (152, 223, 138),
    (174, 199, 232),
    (197, 176, 213),
)
OUTSIDE = (220, 30, 30)
BOX_SURFACE = (190, 190, 200, 50)
BOX_EDGES = (120, 120, 130)
ARM = (200, 40, 40)  # Baxter's red
ARM_JOINT = (60, 60, 60)
#: The 3D panel's eye and where it looks (B, m): from the operator's side of the box, facing the
#: robot, high enough to see into the box and the arm above it.
EYE = (0.78, -0.6, 0.72)
LOOK = (-0.2, 0.03, 0.2)
#: A ghost's fill (alpha of 255).
GHOST_ALPHA = 50
#: Baxter's electric gripper: finger length and the distance between the fingers (m).
FINGER_M = 0.045
GRIP_OPEN_M = 0.09
GRIP_CLOSED_M = 0.03
#: The camera's landing estimate: cells that rose by more than this between the heightmap an
#: object was decided on and the next decision's (m), within this of the decided footprint (m),
#: and at least this many of them.
RISE_M = 0.004
NEAR_M = 0.05
MIN_CELLS = 6
#: ... waiting at most this many heightmaps for the last object to settle.
DUE_FRAMES = 10


def edge_colour(index: int, outside: bool = False) -> tuple:
    """The colour of object ``index``'s edges: its own, darker; red when it ended outside."""
    return OUTSIDE if outside else tuple(int(0.55 * v) for v in colour(index))


def colour(index: int) -> tuple:
    """The colour of object ``index`` (0-based) in a job: the palette's, then hues a golden
    angle apart at alternating strengths, so that no two objects of a job share one."""
    if index < len(PALETTE):
        return PALETTE[index]
    k = index - len(PALETTE)
    hue = (0.07 + 0.381966 * k) % 1.0
    if hue < 0.04 or hue > 0.93:
        hue = (hue + 0.12) % 1.0  # not the arm's or the outside red
    r, g, b = colorsys.hsv_to_rgb(hue, 0.45 + 0.3 * (k % 2), 0.95 - 0.2 * (k % 3 == 2))
    return (int(255 * r), int(255 * g), int(255 * b))


class View:
    """Turns what the bus says into Rerun entities (see the module docs)."""

    def __init__(self, rr, catalog: dict, cell: dict | None = None):
        self.rr = rr
        self.objects = catalog["objects"]
        self.box = catalog["box"]
        self.cell = cell
        if cell is not None:
            check_cell_model(cell)
        self.shapes: dict[int, tuple] = {}  # type -> (vertices, triangles, edges)
        self.shown: dict[int, dict] = {}  # object index -> its type, decided pose, state
        self.order: list[int] = []  # object indices in the order they were decided
        self.current: int | None = None
        self.last_pile_s = -math.inf
        self.last_pile_sum = None
        self.last_joints_s = -math.inf
        self.gripper_closed = False
        self.frame: tuple | None = None  # the latest heightmap: (cells, nx, ny, cell_m)
        # Objects waiting for a heightmap (camera_landing), with the frames they waited.
        self.frame_due: list[tuple[int, int]] = []
        self.q: list[float] | None = None
        self.t0_ns: int | None = None
        self.job_id = 0
        self.ended = False

    def time(self, stamp_ns: int) -> None:
        # Seconds since the first message seen (every stamp is the cell's CLOCK_MONOTONIC).
        if self.t0_ns is None:
            self.t0_ns = stamp_ns
        self.rr.set_time("cell", duration=(stamp_ns - self.t0_ns) * 1e-9)

    def blueprint(self):
        """The layout: the cell in 3D, large, seen from the operator's side of the box (facing
        the robot); the job, the arm's joints and the loop beside it."""
        rrb = self.rr.blueprint
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(
                    origin="cell",
                    name="cell",
                    eye_controls=rrb.archetypes.EyeControls3D(
                        position=[EYE[0], EYE[1], EYE[2]],
                        look_target=[LOOK[0], LOOK[1], LOOK[2]],
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
                    rrb.TimeSeriesView(
                        origin="job",
                        contents=["job/landing_mm", "job/landing_deg"],
                        name="landing off the decided pose (mm, deg)",
                    ),
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
        hx, hy, h, w = b["half_x"], b["half_y"], b["height"], b["wall"]
        # The floor and the four walls, seen through; the inner outline over them.
        slabs = [
            ([0.0, 0.0, -0.5 * w], [hx + w, hy + w, 0.5 * w]),
            ([hx + 0.5 * w, 0.0, 0.5 * h], [0.5 * w, hy + w, 0.5 * h]),
            ([-hx - 0.5 * w, 0.0, 0.5 * h], [0.5 * w, hy + w, 0.5 * h]),
            ([0.0, hy + 0.5 * w, 0.5 * h], [hx, 0.5 * w, 0.5 * h]),
            ([0.0, -hy - 0.5 * w, 0.5 * h], [hx, 0.5 * w, 0.5 * h]),
        ]
        rr.log(
            "cell/box",
            rr.Boxes3D(
                centers=[c for c, _ in slabs],
                half_sizes=[s for _, s in slabs],
                colors=[BOX_SURFACE],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=True,
        )
        rr.log(
            "cell/box/outline",
            rr.Boxes3D(
                half_sizes=[[hx, hy, 0.5 * h]],
                centers=[[0.0, 0.0, 0.5 * h]],
                colors=[BOX_EDGES],
                fill_mode=rr.components.FillMode.MajorWireframe,
            ),
            static=True,
        )
        if self.cell is not None:
            sx, sy, sz = self.cell["pick_station"]
            rr.log(
                "cell/pick_station",
                rr.Boxes3D(
                    centers=[[sx, sy, sz - 0.005]],
                    half_sizes=[[0.1, 0.1, 0.005]],
                    rotation_axis_angles=[rr.RotationAxisAngle(axis=[0, 0, 1], radians=self.cell["pick_yaw"])],
                    colors=[(150, 150, 150, 120)],
                    fill_mode=rr.components.FillMode.Solid,
                    labels=["pick station"],
                    show_labels=False,
                ),
                static=True,
            )

    def heightmap(self, f: HeightmapFrame) -> None:
        t = f.header.stamp_ns * 1e-9
        if self.frame_due:
            nx, ny = f.nx, f.ny
            cells = np.ctypeslib.as_array(f.data)[: nx * ny].reshape(ny, nx).copy()
            self.frame = (cells, nx, ny, f.cell_m)
            self.time(f.header.stamp_ns)
            # An object not seen landing yet (its release still settling) waits a few frames.
            self.frame_due = [
                (i, n + 1) for i, n in self.frame_due if not self.camera_landing(i) and n < DUE_FRAMES
            ]
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
        xs, ys = cell_centres(nx, ny, cell)
        pts = np.stack([xs[cols[keep]], ys[rows[keep]], z[keep]], axis=1)
        self.time(f.header.stamp_ns)
        self.rr.log(
            "cell/pile",
            self.rr.Points3D(pts, radii=0.25 * cell * PILE_STRIDE, colors=[(120, 180, 120)]),
        )

    # --- the arm ---------------------------------------------------------------------------

    def arm(self) -> None:
        """Draws the arm at the last joint angles and gripper state."""
        if self.cell is None or self.q is None:
            return
        rr = self.rr
        fr = arm_frames(self.cell, self.q)
        base, joints, end = fr[0], fr[1:-1], fr[-1]
        palm = end @ np.array([0.0, 0.0, -FINGER_M, 1.0])
        # From the torso (`base`) through the mount and each joint to the palm.
        strip = [base[:3, 3]] + [f[:3, 3] for f in joints] + [palm[:3]]
        rr.log(
            "cell/arm/links",
            rr.LineStrips3D([np.asarray(strip)], radii=0.03, colors=[ARM]),
        )
        rr.log(
            "cell/arm/joints",
            rr.Points3D([f[:3, 3] for f in joints[1:]], radii=0.038, colors=[ARM_JOINT]),
        )
        half = 0.5 * (GRIP_CLOSED_M if self.gripper_closed else GRIP_OPEN_M)
        local = [
            [[0.0, -half - 0.01, -FINGER_M], [0.0, half + 0.01, -FINGER_M]],
            [[0.0, -half, -FINGER_M], [0.0, -half, 0.0]],
            [[0.0, half, -FINGER_M], [0.0, half, 0.0]],
        ]
        segs = [[(end @ np.array([*p, 1.0]))[:3] for p in s] for s in local]
        rr.log(
            "cell/arm/gripper",
            rr.LineStrips3D(segs, radii=0.008, colors=[(40, 40, 40)]),
        )

    def joints(self, js: JointState) -> None:
        t = js.header.stamp_ns * 1e-9
        if t - self.last_joints_s < JOINT_PERIOD_S:
            return
        self.last_joints_s = t
        self.time(js.header.stamp_ns)
        self.joint_angles(list(js.position[:DOF]))

    def joint_angles(self, q: list[float]) -> None:
        """The arm's joints at the current time: the plots and the arm in 3D."""
        for name, a in zip(JOINT_NAMES, q):
            self.rr.log(f"arm/joints/{name}", self.rr.Scalars(a))
        self.q = q
        self.arm()

    def gripper(self, g: GripperState) -> None:
        if bool(g.closed) == self.gripper_closed:
            return
        self.time(g.header.stamp_ns)
        self.gripper_closed = bool(g.closed)
        self.arm()

    # --- the objects -----------------------------------------------------------------------

    def shape(self, ty: int) -> tuple:
        if ty not in self.shapes:
            spec = self.objects[ty]
            v = np.asarray(spec["vertices"], dtype=np.float64)
            t = np.asarray(spec["triangles"], dtype=np.int64)
            self.shapes[ty] = (v, t, feature_edges(v, t))
        return self.shapes[ty]

    def hull(self, path: str, ty: int, r: np.ndarray, p, fill, edges, edge_radius) -> float:
        """Object type ``ty`` turned by ``r`` and moved to ``p``: its hull (``fill``, RGBA)
        and its edges; the height of its top."""
        v, t, e = self.shape(ty)
        world = v @ r.T + np.asarray(p)
        self.rr.log(
            path,
            self.rr.Mesh3D(
                vertex_positions=world.astype(np.float32),
                triangle_indices=t.astype(np.uint32),
                albedo_factor=fill,
            ),
        )
        self.rr.log(
            f"{path}/edges",
            self.rr.LineStrips3D(e @ r.T + np.asarray(p), radii=edge_radius, colors=[edges]),
        )
        return float(world[:, 2].max())

    def label(self, index: int) -> None:
        """Object ``index``'s label: shown for the current object, on hover for the others."""
        o = self.shown[index]
        spec = self.objects[o["type"]]
        text = f"{index + 1} {spec['name']}"
        if "landed" in o:
            text += f": {o['landed']}"
        elif "seen" in o:
            text += f": {o['seen']}"
        self.rr.log(
            f"cell/objects/{index + 1}/label",
            self.rr.Points3D(
                [[o["at"][0], o["at"][1], o["top"] + 0.015]],
                radii=0.002,
                labels=[text],
                colors=[colour(index)],
                show_labels=index == self.current,
            ),
        )

    def decided(self, index: int) -> None:
        """Object ``index`` at its decided pose: a ghost, and the solid there too until the
        landing is known."""
        o = self.shown[index]
        x, y, z, yaw = o["pose"]
        r = rot_z(yaw)[:3, :3]
        c = colour(index)
        top = self.hull(f"cell/objects/{index + 1}/decided", o["type"], r, (x, y, z), (*c, GHOST_ALPHA), c, 0.0012)
        if "landed" not in o:
            edges = edge_colour(index, o.get("outside", False))
            top = self.hull(f"cell/objects/{index + 1}", o["type"], r, (x, y, z), (*c, 255), edges, 0.0015)
        o["at"], o["top"] = (x, y), top

    def landed(self, index: int, placed) -> None:
        """Object ``index`` where it settled (the loopback's word), and its offset from the
        decided pose (in the events and plots the first time: its landing)."""
        o = self.shown[index]
        r = quat_matrix(placed.rotation)
        p = np.asarray(placed.origin, dtype=np.float64)
        x, y, z, yaw = o["pose"]
        dxy = 1e3 * math.hypot(p[0] - x, p[1] - y)
        dz = 1e3 * (p[2] - z)
        dyaw = math.degrees(wrap(yaw_of(r) - yaw))
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, r[2, 2]))))
        o["outside"] = placed.bound != 0
        edges, radius = edge_colour(index, o["outside"]), 0.003 if o["outside"] else 0.0015
        o["top"] = self.hull(f"cell/objects/{index + 1}", o["type"], r, p, (*colour(index), 255), edges, radius)
        o["at"] = (float(p[0]), float(p[1]))
        first = "landed" not in o
        o["landed"] = f"{dxy:.1f} mm {dyaw:+.1f} deg off"
        self.label(index)
        if not first:
            return  # pushed by a later object: drawn where it is now, told once
        spec = self.objects[o["type"]]
        self.rr.log("job/landing_mm", self.rr.Scalars(dxy))
        self.rr.log("job/landing_deg", self.rr.Scalars(abs(dyaw)))
        self.rr.log(
            "job/events",
            self.rr.TextLog(
                f"object {index + 1} ({spec['name']}) landed {dxy:.1f} mm from its decided x-y, "
                f"{dz:+.1f} mm in z, {dyaw:+.1f} deg in yaw, tilted {tilt:.1f} deg"
                + (", outside the success volume" if o["outside"] else ""),
                level="WARN" if o["outside"] else "INFO",
            ),
        )

    def camera_landing(self, index: int) -> bool:
        """What the camera says of object ``index``: with the heightmap it was decided on
        (``before``), the first after its decision is its own; with the heightmap the next
        object was decided on (taken after this one was released and settled), where it
        landed: the cells that rose near its decided footprint, against that footprint
        (centroid in x-y; the long axis for the yaw, when neither is round). False when
        nothing rose yet."""
        o = self.shown.get(index)
        if o is None or self.frame is None:
            return True
        cells, nx, ny, cell = self.frame
        if "before" not in o:
            o["before"] = cells
            return True
        if o["before"].shape != cells.shape or "camera" in o:
            return True
        gx, gy = np.meshgrid(*cell_centres(nx, ny, cell))
        v, _, _ = self.shape(o["type"])
        px, py, _, yaw = o["pose"]
        poly = convex_polygon(v[:, :2] @ rot_z(yaw)[:2, :2].T + [px, py])
        decided = inside_polygon(poly, gx, gy)
        if decided.sum() < MIN_CELLS:
            return True
        lo, hi = poly.min(axis=0) - NEAR_M, poly.max(axis=0) + NEAR_M
        near = (gx >= lo[0]) & (gx <= hi[0]) & (gy >= lo[1]) & (gy <= hi[1])
        with np.errstate(invalid="ignore"):
            rose = near & np.isfinite(cells) & np.isfinite(o["before"]) & (cells - o["before"] > RISE_M)
        if rose.sum() < MIN_CELLS:
            return False
        dx, dy, da = spread(gx[decided], gy[decided])
        sx, sy, sa = spread(gx[rose], gy[rose])
        dxy = 1e3 * math.hypot(sx - dx, sy - dy)
        turn = None if da is None or sa is None else math.degrees(0.5 * wrap(2.0 * (sa - da)))
        o["camera"] = (dxy, turn)
        yaw_text = "its yaw unseen (round)" if turn is None else f"{turn:+.1f} deg in yaw"
        spec = self.objects[o["type"]]
        self.rr.log(
            "job/events",
            self.rr.TextLog(
                f"object {index + 1} ({spec['name']}): the camera sees it {dxy:.1f} mm from its "
                f"decided footprint, {yaw_text} ({int(rose.sum())} cells rose)",
                level="INFO",
            ),
        )
        if "landed" not in o:
            # No simulated outcome (a real cell, a run log): the camera's word is the landing.
            self.rr.log("job/landing_mm", self.rr.Scalars(dxy))
            if turn is not None:
                self.rr.log("job/landing_deg", self.rr.Scalars(abs(turn)))
            r = rot_z(yaw + math.radians(turn or 0.0))[:3, :3]
            at = (px + sx - dx, py + sy - dy, o["pose"][2])
            o["top"] = self.hull(
                f"cell/objects/{index + 1}", o["type"], r, at, (*colour(index), 255), edge_colour(index), 0.0015
            )
            o["at"] = at[:2]
            o["seen"] = f"{dxy:.1f} mm" + ("" if turn is None else f" {turn:+.1f} deg") + " off (camera)"
            self.label(index)
        return True

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
            self.order.clear()
            self.current = None
            self.frame_due.clear()
        text = f"job {s.job_id}: {ev.name}"
        if s.object_type != NO_OBJECT and ev in (
            StatusEvent.Decided,
            StatusEvent.Placed,
            StatusEvent.Skipped,
        ):
            name = self.objects[s.object_type]["name"] if s.object_type < len(self.objects) else "?"
            text += f" object {s.object_index + 1}/{s.objects_total} ({name})"
        if ev == StatusEvent.Decided and s.object_type < len(self.objects):
            i = s.object_index
            first = i not in self.shown
            self.shown[i] = {"type": s.object_type, "pose": list(s.pose)}
            if first:
                self.order.append(i)
            previous, self.current = self.current, i
            # The next heightmap: this object's "before", the previous one's landing.
            self.frame_due = [(j, 0) for j in (previous, i) if j is not None]
            self.decided(i)
            self.label(i)
            if previous is not None and previous != i and previous in self.shown:
                self.label(previous)
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
            if self.current is not None:
                self.frame_due = [(self.current, 0)]  # the last object: the next heightmaps

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
                show_labels=False,
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

    def outcome(self, o: SimOutcome) -> None:
        """The loopback's word on where each released object settled. The box may hold earlier
        jobs' objects: the one just released is the box's last (``objects - 1``), and it is
        this job's earliest decided object not yet seen landing (of the same type; anything
        else is not drawn). Every object of the job is drawn again when it moved (a later one
        may push it)."""
        if o.job_id != self.job_id or o.objects == 0 or o.objects > len(o.placed):
            return  # an earlier job's, from the service's history, or nothing to read
        self.time(o.header.stamp_ns)
        last = o.objects - 1
        waiting = [i for i in self.order if "slot" not in self.shown[i]]
        if waiting and o.placed[last].object_type == self.shown[waiting[0]]["type"]:
            self.shown[waiting[0]]["slot"] = last
        for i in self.order:
            s = self.shown[i]
            if "slot" not in s or s["slot"] >= o.objects:
                continue
            p = o.placed[s["slot"]]
            now = tuple(round(float(v), 4) for v in (*p.origin, *p.rotation))
            if s.get("landed_at") != now:
                s["landed_at"] = now
                self.landed(i, p)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "run_log",
        nargs="?",
        help="a finished job: herbd's run log (RUN-*.log of `herbd --record DIR`), replayed by "
        "`herbd replay` and served (or recorded with --save)",
    )
    ap.add_argument("--prefix", default="herb", help="IPC prefix of the cell (herbd's ipc_prefix)")
    ap.add_argument(
        "--config", help="herbd's configuration file, for the cell and the arm (default: herbd's defaults)"
    )
    ap.add_argument("--web-port", type=int, default=9090, help="the web viewer's port on localhost")
    ap.add_argument("--grpc-port", type=int, default=9876, help="the Rerun data server's port")
    ap.add_argument("--no-browser", action="store_true", help="serve without opening a browser")
    ap.add_argument("--save", help="write a recording (.rrd) instead of serving the viewer")
    ap.add_argument(
        "--events", help="a finished job from `herbd replay RUN.log --events FILE` (what RUN_LOG does)"
    )
    ap.add_argument("--catalog", help="a `herbctl catalog` JSON file (default: run herbctl)")
    ap.add_argument("--boxed", help="the BoxED folder for the meshes (passed to herbctl and herbd)")
    ap.add_argument("--until-job-end", action="store_true", help="stop after the first job ends")
    ap.add_argument("--duration", type=float, help="stop after this many seconds")
    ap.add_argument("--timeout", type=float, default=30.0, help="wait this long for the cell (s)")
    a = ap.parse_args(argv)
    import rerun as rr

    if a.run_log and a.events:
        raise SystemExit("give a run log or --events, not both")
    if a.run_log and not Path(a.run_log).is_file():
        raise SystemExit(f"{a.run_log}: no such run log")
    catalog = load_catalog(a.catalog, a.boxed)
    offline = a.run_log or a.events
    # A finished job's cell is the run's own (the events' first line); a live one is herbd's.
    cell = None if offline else load_cell_model(a.config)
    tmp = tempfile.TemporaryDirectory(prefix="herb-view-")
    events = a.events
    if a.run_log:
        # Replayed before anything is written: a log herbd cannot read leaves no recording.
        events = str(Path(tmp.name) / "events.jsonl")
        replay_run_log(a.run_log, a.boxed, events)
    rr.init("herb", recording_id=f"herb-{a.prefix}-{int(time.time())}")
    if a.save:
        rr.save(a.save)
    else:
        uri = rr.serve_grpc(grpc_port=a.grpc_port)
        rr.serve_web_viewer(web_port=a.web_port, open_browser=not a.no_browser, connect_to=uri)
        print(f"viewer: http://localhost:{a.web_port}/?url={uri}", flush=True)
    if offline:
        view = View(rr, catalog)
        rr.send_blueprint(view.blueprint())
        with tmp:
            n = replay_events(view, events)
        if view.cell is None:
            view.static()  # events of an older herbd: no arm
        if a.save:
            rr.disconnect()
            print(f"recording: {a.save} ({n} events)", flush=True)
            return 0
        print(f"serving {n} events until Ctrl-C", flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        rr.disconnect()
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
        "gripper_state": (subscribe(node, a.prefix, "gripper_state", GripperState, a.timeout), GripperState),
    }
    try:
        subs["sim/outcome"] = (subscribe(node, a.prefix, "sim/outcome", SimOutcome, 1.0), SimOutcome)
    except SystemExit:
        pass  # a real cell: no simulated outcomes
    view = View(rr, catalog, cell)
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
        "gripper_state": view.gripper,
        "sim/outcome": view.outcome,
    }
    seen_job = False
    while not stop["now"]:
        for leaf, (sub, payload) in subs.items():
            for m in drain(sub, payload):
                handlers[leaf](m)
        seen_job |= view.job_id != 0
        if a.until_job_end and seen_job and view.ended:
            # The last outcomes and heightmaps come after the job's end: one more round.
            time.sleep(1.5)
            for leaf in ("sim/outcome", "heightmap"):
                for m in drain(*subs[leaf]) if leaf in subs else ():
                    handlers[leaf](m)
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
