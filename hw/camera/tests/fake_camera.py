#!/usr/bin/python3
"""A fake depth camera for herb-camera's tests: a rospy node publishing sensor_msgs/Image
(16UC1 millimetres) and sensor_msgs/CameraInfo rendered from a known heightmap.

A test fixture: the scene (the truth heightmap over the box interior, the rim over the walls,
the table outside) is rendered once by marching each pixel's ray through a tilted pinhole
camera, then published at 10 Hz stamped with the current time. The cells some pixel of the
published (millimetre) image saw are written to --seen (one byte per cell) so a test can compare on observed cells only.

Bad input on request: --bad-every N makes every Nth image bad (in turn: encoding rgb8, a
width that disagrees with the camera info, data one row short); --info-after S withholds the
camera info for the first S seconds.

    fake_camera.py --truth T.f32 --nx NX --ny NY --cell C --box HX,HY,HEIGHT,WALL \
        --pose tx,ty,tz,qx,qy,qz,qw --seen S.u8 --report R.json
"""

import argparse
import json
import os
import signal
import sys
import threading
import time

import numpy as np
import rospy
from sensor_msgs.msg import CameraInfo, Image

W, H = 640, 480
FX = FY = 600.0
CX, CY = 319.5, 239.5


def floats(text, n):
    v = [float(x) for x in text.split(",")]
    if len(v) != n:
        raise SystemExit(f"expected {n} comma-separated numbers, got {text!r}")
    return v


def rotation(qx, qy, qz, qw):
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def render(truth, nx, ny, cell, box, pose):
    hx, hy, height, wall = box
    t = np.array(pose[:3])
    r = rotation(*pose[3:])
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    d_c = np.stack([(u - CX) / FX, (v - CY) / FY, np.ones_like(u)], axis=-1).reshape(-1, 3)
    d_b = d_c @ r.T
    x_min, y_max = -0.5 * nx * cell, 0.5 * ny * cell

    def surface(x, y):
        inside = (np.abs(x) <= hx) & (np.abs(y) <= hy)
        rim = (np.abs(x) <= hx + wall) & (np.abs(y) <= hy + wall) & ~inside
        col = np.clip(np.floor((x - x_min) / cell).astype(np.int64), 0, nx - 1)
        row = np.clip(np.floor((y_max - y) / cell).astype(np.int64), 0, ny - 1)
        s = np.full(x.shape, -wall)
        s[inside] = truth[row[inside], col[inside]]
        s[rim] = height
        return s

    def below(depth, idx):
        p = t + d_b[idx] * depth[:, None]
        return p[:, 2] <= surface(p[:, 0], p[:, 1])

    step = 0.002
    depth = np.full(len(d_b), np.nan)
    hit = np.zeros(len(d_b), bool)
    d = 0.2
    while d < 1.5 and not hit.all():
        todo = np.flatnonzero(~hit)
        b = below(np.full(len(todo), d), todo)
        idx = todo[b]
        depth[idx] = d
        hit[idx] = True
        d += step
    lo, hi = depth - step, depth.copy()
    ok = hit
    for _ in range(20):
        m = 0.5 * (lo + hi)
        b = np.zeros(len(m), bool)
        b[ok] = below(m[ok], np.flatnonzero(ok))
        hi = np.where(ok & b, m, hi)
        lo = np.where(ok & ~b, m, lo)
    # Published in whole millimetres: the cells seen are those of the published depths.
    depth = np.where(ok, np.round(hi * 1000.0) / 1000.0, np.nan)
    p = t + d_b * np.nan_to_num(depth)[:, None]
    inside = ok & (np.abs(p[:, 0]) <= hx) & (np.abs(p[:, 1]) <= hy)
    col = np.clip(np.floor((p[inside, 0] - x_min) / cell).astype(np.int64), 0, nx - 1)
    row = np.clip(np.floor((y_max - p[inside, 1]) / cell).astype(np.int64), 0, ny - 1)
    seen = np.zeros((ny, nx), np.uint8)
    seen[row, col] = 1
    return depth.reshape(H, W), seen


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--truth", required=True)
    ap.add_argument("--nx", type=int, required=True)
    ap.add_argument("--ny", type=int, required=True)
    ap.add_argument("--cell", type=float, required=True)
    ap.add_argument("--box", required=True)
    ap.add_argument("--pose", required=True)
    ap.add_argument("--seen", required=True)
    ap.add_argument("--report", required=True)
    ap.add_argument("--bad-every", type=int, default=0)
    ap.add_argument("--info-after", type=float, default=0.0)
    a = ap.parse_args()
    truth = np.fromfile(a.truth, dtype="<f4").reshape(a.ny, a.nx).astype(np.float64)
    depth, seen = render(truth, a.nx, a.ny, a.cell, floats(a.box, 4), floats(a.pose, 7))
    seen.tofile(a.seen + ".tmp")
    os.replace(a.seen + ".tmp", a.seen)
    mm = np.where(np.isnan(depth), 0, np.round(depth * 1000.0)).astype("<u2")
    good = mm.tobytes()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    rospy.init_node("fake_camera", anonymous=False, disable_signals=True)
    img_pub = rospy.Publisher("/camera/depth/image_rect_raw", Image, queue_size=4)
    info_pub = rospy.Publisher("/camera/depth/camera_info", CameraInfo, queue_size=4)
    info = CameraInfo(width=W, height=H, distortion_model="plumb_bob", D=[0.0] * 5,
                      K=[FX, 0.0, CX, 0.0, FY, CY, 0.0, 0.0, 1.0],
                      R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                      P=[FX, 0.0, CX, 0.0, 0.0, FY, CY, 0.0, 0.0, 0.0, 1.0, 0.0])
    counts = {"images": 0, "bad": {"encoding": 0, "size": 0, "short": 0}, "infos": 0}
    t0 = time.monotonic()
    seq = 0
    while not stop.is_set():
        seq += 1
        now = rospy.Time.now()
        img = Image(height=H, width=W, encoding="16UC1", is_bigendian=0, step=2 * W, data=good)
        img.header.seq, img.header.stamp, img.header.frame_id = seq, now, "camera_depth_optical_frame"
        if a.bad_every and seq % a.bad_every == 0:
            kind = ("encoding", "size", "short")[(seq // a.bad_every) % 3]
            if kind == "encoding":
                img.encoding = "rgb8"
            elif kind == "size":
                img.width, img.step = W - 1, 2 * (W - 1)
                img.data = good[: 2 * (W - 1) * H]
            else:
                img.data = good[: -2 * W]
            counts["bad"][kind] += 1
        if time.monotonic() - t0 >= a.info_after:
            info.header.stamp = now
            info_pub.publish(info)
            counts["infos"] += 1
        img_pub.publish(img)
        counts["images"] += 1
        time.sleep(0.1)
    tmp = a.report + ".tmp"
    with open(tmp, "w") as f:
        json.dump(counts, f)
    os.replace(tmp, a.report)
    rospy.signal_shutdown("done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
