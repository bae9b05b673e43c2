"""The live view's geometry (numpy): herbd's arm chain composed for a joint state and checked
against herbd's own forward kinematics, convex hulls' edges, and the footprints the camera's
landing estimate compares. Every frame is herbd's (``herbd cell-model``); only composed here.
"""

from __future__ import annotations

import math

import numpy as np

#: The view's arm must compose to herbd's forward kinematics within this (m).
ARM_CHECK_M = 1e-4
#: Edges between hull faces turned by more than this are drawn (the rest are triangulation).
EDGE_ANGLE_DEG = 12.0


def quat_matrix(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion ``[x, y, z, w]``."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def frame(f: dict) -> np.ndarray:
    """The 4x4 matrix of a cell-model frame (``translation``, ``quaternion_xyzw``)."""
    m = np.eye(4)
    m[:3, :3] = quat_matrix(f["quaternion_xyzw"])
    m[:3, 3] = f["translation"]
    return m


def rot_z(a: float) -> np.ndarray:
    """A rotation by ``a`` (rad) about z, 4x4."""
    m = np.eye(4)
    c, s = math.cos(a), math.sin(a)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def arm_frames(model: dict, q) -> list[np.ndarray]:
    """The arm's frames in B for joint angles ``q``: ``base``, the mount, each joint after its
    rotation (seven), the gripper endpoint. The composition ``base_in_box * mount * Π (origin_i
    * Rz(q_i)) * tool`` of ``herbd cell-model``."""
    t = frame(model["base_in_box"])
    out = [t]
    t = t @ frame(model["mount"])
    out.append(t)
    for j, a in zip(model["joints"], q):
        t = t @ frame(j["origin"]) @ rot_z(float(a))
        out.append(t)
    out.append(t @ frame(model["tool"]))
    return out


def check_cell_model(model: dict) -> None:
    """Refuses a model of another format, or one this view would compose differently from
    herbd's forward kinematics (its ``check``)."""
    if model.get("format") != 1:
        raise SystemExit(f"cell model format {model.get('format')!r}: this view reads format 1")
    got = arm_frames(model, model["check"]["q"])[-1][:3, 3]
    want = np.asarray(model["check"]["endpoint_in_box"])
    if not np.linalg.norm(got - want) <= ARM_CHECK_M:
        raise SystemExit(
            f"the arm composed here ends at {got.round(4).tolist()}, herbd's kinematics at "
            f"{want.round(4).tolist()}: this view does not read herbd's cell model right"
        )


def feature_edges(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The hull's edges between faces turned by more than ``EDGE_ANGLE_DEG``, as segments
    ``(n, 2, 3)`` in the object's frame (the diagonals of flat faces left out)."""
    v, t = vertices, triangles
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    faces: dict[tuple[int, int], list[int]] = {}
    for f, tri in enumerate(t.tolist()):
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            faces.setdefault((min(a, b), max(a, b)), []).append(f)
    cos = math.cos(math.radians(EDGE_ANGLE_DEG))
    keep = [
        e for e, fs in faces.items() if len(fs) != 2 or float(n[fs[0]] @ n[fs[1]]) < cos
    ]
    return v[np.asarray(keep, dtype=np.int64).reshape(-1, 2)]


def convex_polygon(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2D points, counter-clockwise (monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 6).tolist())))
    if len(pts) < 3:
        return np.asarray(pts, dtype=np.float64)

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) - (
                out[-1][1] - out[-2][1]
            ) * (p[0] - out[-2][0]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.asarray(lower[:-1] + upper[:-1], dtype=np.float64)


def inside_polygon(poly: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Which points (x, y) are inside a counter-clockwise convex polygon."""
    ok = np.ones(np.shape(x), dtype=bool)
    for (ax, ay), (bx, by) in zip(poly, np.roll(poly, -1, axis=0)):
        ok &= (bx - ax) * (y - ay) - (by - ay) * (x - ax) >= 0
    return ok


def spread(x: np.ndarray, y: np.ndarray) -> tuple:
    """Centroid and long axis (rad, modulo a half turn) of a set of cells; the axis is None when
    the cells are nearly round (their two spreads within 20 %)."""
    cx, cy = float(x.mean()), float(y.mean())
    cov = np.cov(np.stack([x - cx, y - cy])) if x.size > 2 else np.zeros((2, 2))
    w, v = np.linalg.eigh(cov)
    axis = math.atan2(v[1, 1], v[0, 1]) if w[1] > 1.2 * max(w[0], 1e-12) else None
    return cx, cy, axis


def cell_centres(nx: int, ny: int, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """The x and y (m, in B) of a heightmap's cell centres, columns and rows: row 0 is the box's
    +y edge, column 0 its -x edge (``herb_core::heightmap::GridSpec``)."""
    x = -0.5 * nx * cell + (np.arange(nx) + 0.5) * cell
    y = 0.5 * ny * cell - (np.arange(ny) + 0.5) * cell
    return x, y


def yaw_of(r: np.ndarray) -> float:
    """The heading of a rotation's x axis about z (rad)."""
    return math.atan2(r[1, 0], r[0, 0])


def wrap(a: float) -> float:
    """``a`` (rad) in (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))
