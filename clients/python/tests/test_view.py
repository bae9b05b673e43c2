"""The live view as a person uses it, against a real herbd and herb-loopback: the web viewer is
opened in headless Chromium (Debian's package) while a job runs, and its screenshot must show
the packed objects, each in its own colour, and the arm in the 3D panel; a recording
(``--save``) of a job, live or made afterwards from herbd's run log (``python -m
herb_client.view RUN.log``), is read back and must hold every placed object, the arm moving
through the job and, live, where each object landed against where it was decided.

Needs ``rerun-sdk`` (the test command installs it) and, for the browser test, ``chromium``
(``.ci/run`` installs it): without them the tests are skipped, except under ``CI=true``, where
they fail.
"""

import colorsys
import math
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from herb_client import Herb, StatusEvent, catalog_ids
from herb_client import view as hv

REPO = Path(__file__).resolve().parents[3]
BIN = Path(os.environ.get("HERB_BIN_DIR", REPO / "target" / "debug"))
CI = os.environ.get("CI") == "true"


def need(ok: bool, what: str):
    if not ok:
        if CI:
            pytest.fail(f"{what} is missing (CI=true: the test command installs it)")
        pytest.skip(f"{what} is missing")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    for exe in ("herbd", "herb-loopback", "herbctl"):
        if not (BIN / exe).is_file():
            pytest.fail(f"{BIN / exe} is missing: build the workspace first (cargo test --workspace)")
    prefix = f"pyview{os.getpid()}"
    logs = tmp_path_factory.mktemp("view")
    # herbd decides by searching (a short budget): the view shows the search's candidates.
    cfg = logs / "herbd.toml"
    cfg.write_text('[decision]\nmethod = "search"\nbudget_s = 0.2\nk = 4\n')
    procs = []
    herbd = ["--record", str(logs / "runs"), "--config", str(cfg)]
    for exe, extra in (("herb-loopback", []), ("herbd", herbd)):
        log = open(logs / f"{exe}.log", "w")
        procs.append(
            subprocess.Popen(
                [str(BIN / exe), "--prefix", prefix, *extra],
                cwd=REPO,
                stdout=subprocess.DEVNULL,
                stderr=log,
            )
        )
    try:
        herb = Herb(prefix, name="herb-view-test", timeout_s=60.0)
        yield herb, prefix, logs
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()


def view(prefix: str, logs: Path, *args: str) -> subprocess.Popen:
    env = dict(os.environ, HERB_BIN_DIR=str(BIN))
    return subprocess.Popen(
        [sys.executable, "-m", "herb_client.view", "--prefix", prefix, "--config", str(logs / "herbd.toml"), *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=open(logs / "view.log", "a"),
        text=True,
    )


# Jobs the module's cell has packed to their end: herbd's run log holds every one of them.
packed_jobs = 0


def pack(herb: Herb, ids: list[str]) -> None:
    global packed_jobs
    all_ids = catalog_ids(REPO / "models" / "objects.toml")
    result = herb.pack([all_ids.index(i) for i in ids], timeout_s=300.0)
    assert result.ok, [StatusEvent(s.event).name for s in result.statuses]
    packed_jobs += 1


def rows(rrd: Path) -> dict[str, int]:
    """Rows logged per entity path (on a timeline) in a recording."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(rrd))
    assert len(reader.recordings()) == 1
    out: dict[str, int] = {}
    for chunk in reader.stream():
        out.setdefault(chunk.entity_path, 0)
        if not chunk.is_static:
            out[chunk.entity_path] += chunk.num_rows
    return out


def test_the_view_composes_the_arm_as_herbd_and_refuses_a_model_it_would_not(monkeypatch):
    if not (BIN / "herbd").is_file():
        pytest.fail(f"{BIN / 'herbd'} is missing: build the workspace first (cargo test --workspace)")
    monkeypatch.setenv("HERB_BIN_DIR", str(BIN))
    model = hv.load_cell_model(None)
    hv.check_cell_model(model)  # herbd's own forward kinematics, at its check configuration
    end = hv.arm_frames(model, model["check"]["q"])[-1][:3, 3]
    assert np.allclose(end, model["check"]["endpoint_in_box"], atol=1e-9)
    bad = dict(model, joints=[dict(j) for j in model["joints"]])
    bad["joints"][3] = dict(bad["joints"][3], origin=dict(bad["joints"][3]["origin"], translation=[0.0, 0.0, 0.3]))
    with pytest.raises(SystemExit, match="does not read herbd's cell model right"):
        hv.check_cell_model(bad)
    with pytest.raises(SystemExit, match="format"):
        hv.check_cell_model(dict(model, format=2))
    # A cube's hull (12 triangles): its 12 edges, not the faces' diagonals.
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    assert hv.feature_edges(v, np.array(faces)).shape == (12, 2, 3)
    # Every object of the largest job in its own colour, none of them the arm's or outside red.
    colours = [hv.colour(i) for i in range(64)]
    assert len(set(colours)) == 64
    for red in (hv.ARM, hv.OUTSIDE):
        assert min(sum(abs(a - b) for a, b in zip(c, red)) for c in colours) > 60


def test_a_recording_holds_every_placed_object_the_arm_and_the_landings(cell, tmp_path):
    pytest.importorskip("rerun") if not CI else __import__("rerun")

    herb, prefix, logs = cell
    rrd = tmp_path / "job.rrd"
    v = view(prefix, logs, "--save", str(rrd), "--until-job-end", "--timeout", "60")
    time.sleep(3.0)  # subscribed before the job starts
    pack(herb, ["003", "005", "011"])
    out, _ = v.communicate(timeout=60)
    assert v.returncode == 0, (logs / "view.log").read_text()
    assert f"recording: {rrd}" in out
    paths = rows(rrd)
    for n in (1, 2, 3):
        for p in ("", "/edges", "/label", "/decided", "/decided/edges"):
            assert f"/cell/objects/{n}{p}" in paths, sorted(paths)
        # Drawn at its decided pose, then where it landed.
        assert paths[f"/cell/objects/{n}"] >= 2, paths
    for p in (
        "/cell/box",
        "/cell/pile",
        "/cell/pick_station",
        "/cell/decision/candidates",
        "/job/events",
        "/arm/joints/s0",
        "/loop/max_cycle_us",
    ):
        assert p in paths, sorted(paths)
    assert "/cell/objects/4" not in paths
    # The arm, drawn through three picks and places at 20 Hz, its gripper closing and opening
    # (twice per object at least), and a landing offset for each object.
    assert paths.get("/cell/arm/links", 0) > 100, paths
    assert paths.get("/cell/arm/gripper", 0) > 100 + 6, paths
    assert paths.get("/job/landing_mm", 0) >= 3, paths


def pixels_of(png: Path, rgb: tuple, hue_tolerance: float = 0.04) -> int:
    """Pixels of colour ``rgb``'s hue in the 3D panel (the left 60 % of the window, below the
    viewer's toolbar and the panel's title): within ``hue_tolerance`` of its hue, saturated and
    bright enough not to be the grey box, the floor or the background. By hue, not by the exact
    colour: the panel shades each face, and an object seen through the box's translucent wall
    keeps its hue but not its colour. The toolbar is left out: its warning sign is orange."""
    from PIL import Image  # a dependency of rerun-sdk

    img = Image.open(png).convert("RGB")
    w, h = img.size
    panel = img.crop((0, int(0.07 * h), int(0.6 * w), h))
    hsv = np.asarray(panel.convert("HSV"), dtype=np.float64)
    hue, sat, val = hsv[..., 0] / 255.0, hsv[..., 1] / 255.0, hsv[..., 2] / 255.0
    want = colorsys.rgb_to_hsv(*(c / 255.0 for c in rgb))[0]
    off = np.abs(hue - want)
    off = np.minimum(off, 1.0 - off)
    return int(((off < hue_tolerance) & (sat >= 0.35) & (val >= 0.25)).sum())


def test_the_live_view_in_a_browser_shows_the_packed_objects(cell, tmp_path):
    if not CI:
        pytest.importorskip("rerun")
    need(shutil.which("chromium") is not None, "chromium")
    from herb_client.screenshot import Chromium, Page

    herb, prefix, logs = cell
    web, grpc = free_port(), free_port()
    v = view(prefix, logs, "--no-browser", "--web-port", str(web), "--grpc-port", str(grpc))
    try:
        line = v.stdout.readline()
        assert line.startswith("viewer: "), (line, (logs / "view.log").read_text())
        url = line.split()[1]
        # Laid out at 1400 x 900, drawn at half scale: the same picture at a quarter of the
        # pixels, which the software renderer draws faster (the viewer ingests the stream
        # between frames: at full scale it fell more than a minute behind the job).
        browser = Chromium(1400, 900, scale=0.5)
        try:
            page = Page(browser, url)
            pack(herb, ["003", "005"])
            # The browser renders in software and catches up at its own pace: shots until both
            # objects are drawn in their colours, and the arm in its red, or the deadline. More
            # than 100 pixels each at half scale (the smallest, the soup can, draws about 650).
            shot = tmp_path / "view.png"
            deadline = time.monotonic() + 150
            seen = {}
            while time.monotonic() < deadline:
                time.sleep(5)
                page.shoot(str(shot))
                seen = {
                    "object 1": pixels_of(shot, hv.colour(0)),
                    "object 2": pixels_of(shot, hv.colour(1)),
                    "the arm": pixels_of(shot, hv.ARM),
                }
                if all(n > 100 for n in seen.values()):
                    break
            assert all(n > 100 for n in seen.values()), f"pixels in the 3D panel: {seen} ({shot})"
        finally:
            browser.close()
    finally:
        v.terminate()
        v.wait(timeout=15)


def test_a_finished_job_is_recorded_from_herbds_run_log(cell, tmp_path):
    if not CI:
        pytest.importorskip("rerun")

    herb, prefix, logs = cell
    # The jobs the tests before this one packed are in the run log (each takes half a minute of
    # arm motion); a job is packed here only when this test runs alone.
    if packed_jobs == 0:
        pack(herb, ["004", "002"])
    time.sleep(1.0)  # the run log's writer flushes every 100 ms
    log = sorted((logs / "runs").glob("RUN-*.log"))[0]
    events = tmp_path / "job.jsonl"
    # herbd still writes the segment: its replay may end "incomplete" (exit 3) at the tail.
    r = subprocess.run(
        [str(BIN / "herbd"), "replay", str(log), "--events", str(events)],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert r.returncode in (0, 3), r.stdout + r.stderr
    placed = [
        line for line in events.read_text().splitlines() if '"event":%d,' % StatusEvent.Placed in line
    ]
    assert len(placed) >= 2, r.stdout
    lines = events.read_text().splitlines()
    assert lines[0].startswith('{"cell":'), lines[0][:80]
    assert sum('"joint_state"' in line for line in lines) > 50
    assert any('"gripper"' in line for line in lines)
    rrd = tmp_path / "job.rrd"
    env = dict(os.environ, HERB_BIN_DIR=str(BIN))
    # One command from the run log: the replay and the recording.
    v = subprocess.run(
        [sys.executable, "-m", "herb_client.view", str(log), "--save", str(rrd)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
    )
    assert v.returncode == 0, v.stderr
    paths = rows(rrd)
    objects = {p for p in paths if p.startswith("/cell/objects/") and p.count("/") == 3}
    assert len(objects) >= 2 and "/cell/pile" in paths, sorted(paths)
    # The arm as the run had it, moving (the run log's joint states at 20 Hz).
    assert paths.get("/cell/arm/links", 0) > 50, paths
    assert "/cell/pick_station" in paths, sorted(paths)


def test_the_camera_sees_where_an_object_landed_against_its_decided_footprint():
    """The camera's landing estimate, on heightmaps made here (a fixture: a 10 x 6 cm block
    decided at the box's centre, seen landed 12 mm off in x and turned by 20 degrees)."""
    from unittest import mock

    from herb_client.payloads import HeightmapFrame, Status, StatusEvent as Ev

    hx, hy = 0.05, 0.03
    v = [[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-0.02, 0.02)]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    catalog = {
        "box": {"half_x": 0.2, "half_y": 0.15, "height": 0.2, "wall": 0.005},
        "objects": [{"id": "900", "name": "block", "vertices": v, "triangles": faces}],
    }
    view = hv.View(mock.MagicMock(), catalog)
    nx, ny, cell = 80, 60, 0.005

    def frame(landed):
        f = HeightmapFrame()
        f.nx, f.ny, f.cell_m = nx, ny, cell
        z = np.zeros((ny, nx), dtype=np.float32)
        if landed:
            x = -0.5 * nx * cell + (np.arange(nx) + 0.5) * cell
            y = 0.5 * ny * cell - (np.arange(ny) + 0.5) * cell
            gx, gy = np.meshgrid(x, y)
            c, s = math.cos(math.radians(20)), math.sin(math.radians(20))
            u, w = c * (gx - 0.012) + s * gy, -s * (gx - 0.012) + c * gy
            z[(np.abs(u) <= hx) & (np.abs(w) <= hy)] = 0.04
        z[5, 5] = np.nan  # a dropout
        np.ctypeslib.as_array(f.data)[: nx * ny] = z.ravel()
        return f

    def status(ev, index, pose=(0.0, 0.0, 0.02, 0.0)):
        s = Status()
        s.event, s.job_id, s.object_index, s.object_type, s.objects_total = ev, 7, index, 0, 2
        s.pose[:] = pose
        return s

    view.status(status(Ev.Accepted, 0))
    view.status(status(Ev.Decided, 0))
    view.heightmap(frame(False))  # decided on the empty box
    assert "camera" not in view.shown[0]
    view.status(status(Ev.Decided, 1, (0.1, 0.0, 0.02, 0.0)))
    view.heightmap(frame(True))  # the next decision's heightmap: the block landed
    dxy, turn = view.shown[0]["camera"]
    assert abs(dxy - 12.0) < 3.0, dxy
    assert abs(turn - 20.0) < 3.0, turn
    assert "off (camera)" in view.shown[0]["seen"]


def test_a_bad_events_file_is_refused_naming_the_line(tmp_path):
    from unittest import mock

    view = hv.View(mock.MagicMock(), {"box": {}, "objects": []})
    bad = tmp_path / "job.jsonl"
    for second in ('{"status": {"stamp_ns": 1}}', "not json", '{"what": 1}'):
        bad.write_text('{"joint_state": {"stamp_ns": 1, "position": [0, 0, 0, 0, 0, 0, 0]}}\n' + second + "\n")
        with pytest.raises(SystemExit, match=r"job.jsonl:2: not an event of herbd replay --events"):
            hv.replay_events(view, str(bad))
