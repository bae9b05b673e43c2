"""The live view as a person uses it, against a real herbd and herb-loopback: the web viewer is
opened in headless Chromium (Debian's package) while a job runs, and its screenshot must show
the packed objects in the 3D panel; a recording (``--save``) of a job, live or made afterwards
from herbd's run log (``herbd replay --events``), is read back and must hold every placed
object.

Needs ``rerun-sdk`` (the test command installs it) and, for the browser test, ``chromium``
(``.ci/run`` installs it): without them the tests are skipped, except under ``CI=true``, where
they fail.
"""

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
        [sys.executable, "-m", "herb_client.view", "--prefix", prefix, *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=open(logs / "view.log", "a"),
        text=True,
    )


def pack(herb: Herb, ids: list[str]) -> None:
    all_ids = catalog_ids(REPO / "models" / "objects.toml")
    result = herb.pack([all_ids.index(i) for i in ids], timeout_s=300.0)
    assert result.ok, [StatusEvent(s.event).name for s in result.statuses]


def test_a_recording_holds_every_placed_object(cell, tmp_path):
    pytest.importorskip("rerun") if not CI else __import__("rerun")
    from rerun.chunk import RrdReader

    herb, prefix, logs = cell
    rrd = tmp_path / "job.rrd"
    v = view(prefix, logs, "--save", str(rrd), "--until-job-end", "--timeout", "60")
    time.sleep(3.0)  # subscribed before the job starts
    pack(herb, ["003", "005", "011"])
    out, _ = v.communicate(timeout=60)
    assert v.returncode == 0, (logs / "view.log").read_text()
    assert f"recording: {rrd}" in out
    reader = RrdReader(str(rrd))
    assert len(reader.recordings()) == 1
    paths = {chunk.entity_path for chunk in reader.stream()}
    for n in (1, 2, 3):
        assert f"/cell/objects/{n}" in paths, sorted(paths)
        assert f"/cell/objects/{n}/label" in paths
    for p in (
        "/cell/box",
        "/cell/pile",
        "/cell/decision/candidates",
        "/job/events",
        "/arm/joints/s0",
        "/loop/max_cycle_us",
    ):
        assert p in paths, sorted(paths)
    assert "/cell/objects/4" not in paths


def blue_pixels(png: Path) -> int:
    """Pixels of the placed objects' blue in the 3D panel (the left 60 % of the window)."""
    from PIL import Image  # a dependency of rerun-sdk

    rgb = np.asarray(Image.open(png).convert("RGB"), dtype=np.int16)
    panel = rgb[:, : int(0.6 * rgb.shape[1])]
    target = np.array([70, 130, 230])
    return int((np.abs(panel - target).sum(axis=2) < 60).sum())


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
        browser = Chromium(1400, 900)
        try:
            page = Page(browser, url)
            pack(herb, ["003", "005"])
            # The browser renders in software and catches up at its own pace: shots until the
            # objects are drawn, or the deadline.
            shot = tmp_path / "view.png"
            deadline = time.monotonic() + 150
            seen = 0
            while time.monotonic() < deadline:
                time.sleep(5)
                page.shoot(str(shot))
                seen = blue_pixels(shot)
                if seen > 2000:
                    break
            assert seen > 2000, f"the 3D panel shows {seen} pixels of placed objects ({shot})"
        finally:
            browser.close()
    finally:
        v.terminate()
        v.wait(timeout=15)


def test_a_finished_job_is_recorded_from_herbds_run_log(cell, tmp_path):
    if not CI:
        pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    herb, prefix, logs = cell
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
    rrd = tmp_path / "job.rrd"
    env = dict(os.environ, HERB_BIN_DIR=str(BIN))
    v = subprocess.run(
        [sys.executable, "-m", "herb_client.view", "--events", str(events), "--save", str(rrd)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
    )
    assert v.returncode == 0, v.stderr
    paths = {chunk.entity_path for chunk in RrdReader(str(rrd)).stream()}
    objects = {p for p in paths if p.startswith("/cell/objects/") and p.count("/") == 3}
    assert len(objects) >= 2 and "/cell/pile" in paths, sorted(paths)
