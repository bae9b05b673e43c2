"""The Python client against a real herbd and herb-loopback: a job is
submitted and followed to its end, a heightmap is read as a numpy view into shared memory (no
copy, read-only), and a bad job is refused with herbd's reason.

The binaries come from ``$HERB_BIN_DIR`` (default ``target/debug``, which ``cargo test
--workspace`` builds); each test run uses its own IPC prefix.
"""

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from herb_client import (
    Herb,
    JobState,
    JobWait,
    Rejected,
    RejectReason,
    StatusEvent,
    catalog_ids,
)
from herb_client.payloads import HeightmapFrame

REPO = Path(__file__).resolve().parents[3]
BIN = Path(os.environ.get("HERB_BIN_DIR", REPO / "target" / "debug"))


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    for exe in ("herbd", "herb-loopback"):
        if not (BIN / exe).is_file():
            pytest.fail(f"{BIN / exe} is missing: build the workspace first (cargo test --workspace)")
    prefix = f"py{os.getpid()}"
    logs = tmp_path_factory.mktemp("cell")
    procs = []
    for exe in ("herb-loopback", "herbd"):
        log = open(logs / f"{exe}.log", "w")
        procs.append(
            subprocess.Popen(
                [str(BIN / exe), "--prefix", prefix],
                cwd=REPO,
                stdout=subprocess.DEVNULL,
                stderr=log,
            )
        )
    try:
        herb = Herb(prefix, timeout_s=60.0)
        yield herb, logs
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()


def test_a_job_is_submitted_and_followed_to_its_end(cell):
    herb, logs = cell
    ids = catalog_ids(REPO / "models" / "objects.toml")
    objects = [ids.index("003"), ids.index("005")]
    herb.outcomes()  # subscribe to the loopback's outcomes before the job
    result = herb.pack(objects, timeout_s=300.0)
    events = [StatusEvent(s.event) for s in result.statuses if s.event != StatusEvent.Heartbeat]
    assert result.ok, (events, (logs / "herbd.log").read_text())
    assert events[0] == StatusEvent.Accepted
    assert events.count(StatusEvent.Decided) == 2
    assert events.count(StatusEvent.Placed) == 2
    assert events[-1] == StatusEvent.JobDone
    assert result.placed == 2 and JobState(result.final.state) == JobState.Done
    # Heartbeats of the running job carry the loop's counters.
    beats = [s for s in result.statuses if s.event == StatusEvent.Heartbeat]
    assert beats and beats[-1].cycles > 0
    # The simulated box: both objects released by this job (the last one settles after the
    # job's end).
    outcomes = []
    t0 = time.monotonic()
    while len(outcomes) < 2 and time.monotonic() - t0 < 5.0:
        outcomes += [o for o in herb.outcomes() if o.job_id == result.job_id]
        time.sleep(0.05)
    assert [o.objects for o in outcomes] == [1, 2]
    assert sorted(o.object_type for o in outcomes) == sorted(objects)


def test_a_confirmation_counts_only_while_herbd_awaits_it(cell):
    """A job of two objects fed by hand: the wait is in the statuses (``waiting_for``, with the
    object and try), a confirmation is taken then and a repeat of it too; the second object's,
    sent while herbd has not asked for it yet, is refused (``NotAwaited``) and not kept: herbd
    asks for it later and takes it then. The job ends done."""
    herb, logs = cell
    ids = catalog_ids(REPO / "models" / "objects.toml")
    job = herb.submit([ids.index("003"), ids.index("005")], confirm_picks=True)
    confirmed = []
    final = None
    for s in herb.statuses(job, timeout_s=600.0):
        awaited = (s.object_index, s.attempt)
        if s.waiting_for == JobWait.Confirmation and awaited not in confirmed:
            herb.confirm_pick(job, *awaited)
            herb.confirm_pick(job, *awaited)  # a repeat (a slow reply resent): taken again
            confirmed.append(awaited)
            if awaited == (0, 0):
                with pytest.raises(Rejected) as early:
                    herb.confirm_pick(job, 1, 0)  # herbd has not asked for object 1 yet
                assert early.value.reason == RejectReason.NotAwaited
        if s.event in (StatusEvent.JobDone, StatusEvent.JobFailed, StatusEvent.JobCancelled):
            final = s
    assert confirmed == [(0, 0), (1, 0)], confirmed
    assert final is not None and final.event == StatusEvent.JobDone, (
        logs / "herbd.log"
    ).read_text()
    assert final.waiting_for == JobWait.NONE


def test_a_heightmap_is_a_read_only_view_into_shared_memory(cell):
    herb, _ = cell
    hm = herb.heightmap(timeout_s=10.0)
    sample_address = hm._sample.payload_ptr
    assert hm.address == sample_address + HeightmapFrame.data.offset, "no copy"
    assert not hm.cells.flags.writeable
    assert hm.cells.dtype == np.float32 and hm.cells.ndim == 2
    assert np.isfinite(hm.cells).all() and hm.cells.min() >= -0.05
    kept = hm.copy()
    hm.release()
    assert kept.shape[0] > 0


def test_a_bad_job_is_refused_with_its_reason(cell):
    herb, _ = cell
    with pytest.raises(Rejected) as e:
        herb.submit([9999])
    assert e.value.reason == RejectReason.UnknownObject
    with pytest.raises(Rejected) as e:
        herb.submit([])
    assert e.value.reason == RejectReason.Empty
    # And the daemon is still there to take the next one.
    t0 = time.monotonic()
    hm = herb.heightmap(timeout_s=10.0)
    hm.release()
    assert time.monotonic() - t0 < 10.0


def test_a_flood_of_requests_from_many_processes_is_answered_and_the_cell_still_serves(cell):
    """Four processes send 300 bad requests each as fast as they can: every one gets an answer
    with its reason, and a good job runs afterwards."""
    herb, logs = cell
    script = (
        "import sys; from herb_client import Herb, Rejected, RejectReason\n"
        "h = Herb(sys.argv[1], name='flood-' + sys.argv[2], timeout_s=30.0)\n"
        "n = 0\n"
        "for _ in range(300):\n"
        "    try:\n"
        "        h.submit([9999], timeout_s=30.0)\n"
        "    except Rejected as e:\n"
        "        assert e.reason == RejectReason.UnknownObject, e\n"
        "        n += 1\n"
        "print(n)\n"
    )
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", script, herb.prefix, str(k)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in range(4)
    ]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert out.strip() == "300", (out, err)
    ids = catalog_ids(REPO / "models" / "objects.toml")
    result = herb.pack([ids.index("011")], timeout_s=300.0)
    assert result.ok, (logs / "herbd.log").read_text()


def test_a_client_started_before_herbd_waits_for_it(tmp_path):
    """The client opens the services only once herbd created them (it never creates them with
    other settings): started first, it connects when herbd and the loopback come up."""
    prefix = f"pyearly{os.getpid()}"
    opened = {}

    def connect():
        opened["herb"] = Herb(prefix, name="early", timeout_s=60.0)

    t = threading.Thread(target=connect)
    t.start()
    time.sleep(1.0)
    assert "herb" not in opened, "nothing to connect to yet"
    procs = []
    try:
        for exe in ("herb-loopback", "herbd"):
            log = open(tmp_path / f"{exe}.log", "w")
            procs.append(
                subprocess.Popen(
                    [str(BIN / exe), "--prefix", prefix],
                    cwd=REPO,
                    stdout=subprocess.DEVNULL,
                    stderr=log,
                )
            )
        t.join(timeout=60)
        herb = opened["herb"]
        ids = catalog_ids(REPO / "models" / "objects.toml")
        result = herb.pack([ids.index("003")], timeout_s=300.0)
        assert result.ok, (tmp_path / "herbd.log").read_text()
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
