"""``Herb``: a client of one herbd (one IPC prefix). It opens the services herbd and the camera
adapter created (start them first), submits pack jobs, follows their statuses and hands out
heightmap frames as read-only numpy views into shared memory.
"""

from __future__ import annotations

import dataclasses
import os
import time
import tomllib
from pathlib import Path
from typing import Iterator, Optional, Sequence

import iceoryx2 as iox2
import numpy as np

from .payloads import (
    NO_OBJECT,
    PROTOCOL_VERSION,
    ConfirmPickReply,
    ConfirmPickRequest,
    Fault,
    HeightmapFrame,
    JobState,
    JobWait,
    PackJobReply,
    PackJobRequest,
    RejectReason,
    SimOutcome,
    Status,
    StatusEvent,
)

#: ``PackJobRequest.flags`` bit: a person feeds the pick station (``ipc/CONTRACT.md``).
PackJobRequest_CONFIRM_PICKS = 1
#: herbd heartbeats at 10 Hz; silent this long (s), it is taken as lost.
LOST_AFTER_S = 1.0
#: Events that end a job.
END_EVENTS = (StatusEvent.JobDone, StatusEvent.JobFailed, StatusEvent.JobCancelled)


class Rejected(Exception):
    """herbd refused the job: ``reason`` (a ``RejectReason``) and ``detail``."""

    def __init__(self, reason: RejectReason, detail: int):
        super().__init__(f"job rejected: {reason.name} (detail {detail})")
        self.reason, self.detail = reason, detail


class WireVersionMismatch(Exception):
    """A service under the prefix was created by a process of another HERB wire version
    (``ipc/CONTRACT.md``, "Versions"): ``ours`` and ``theirs`` name both, ``type_name`` the
    service's payload type."""

    def __init__(self, service: str, ours: int, theirs: int, type_name: str):
        super().__init__(
            f"{service}: wire version mismatch: this client speaks HERB wire version {ours}, the "
            f"service was created by a process of version {theirs} (payload type {type_name}); "
            "run herbd, the adapters and the clients of one release"
        )
        self.service, self.ours, self.theirs, self.type_name = service, ours, theirs, type_name


def wire_version_of(type_name: str) -> Optional[int]:
    """The wire version an iceoryx2 type name of the contract says (``herb::v<N>::<Name>``)."""
    head, _, rest = type_name.partition("::v")
    number, sep, _ = rest.partition("::")
    return int(number) if head == "herb" and sep and number.isdigit() else None


#: Where iceoryx2 (default configuration) keeps each service's static configuration.
ICEORYX2_SERVICES = Path("/tmp/iceoryx2/services")


def existing_type_names(service: str) -> list[str]:
    """The payload type names of the existing iceoryx2 service called ``service`` (the
    request's and the response's for a request-response service), read from its static
    configuration; empty when it cannot be read."""
    names = []
    for f in ICEORYX2_SERVICES.glob("*.service"):
        try:
            c = tomllib.loads(f.read_text())
        except (OSError, ValueError):
            continue
        if c.get("service_name") != service:
            continue
        for pattern in c.get("messaging_pattern", {}).values():
            for key in ("message_type_details", "request_message_type_details",
                        "response_message_type_details"):
                name = pattern.get(key, {}).get("payload", {}).get("type_name")
                if isinstance(name, str):
                    names.append(name)
    return names


class DaemonLost(Exception):
    """No status from herbd for ``LOST_AFTER_S`` and it did not come back with the job within
    the reconnect window (or it came back without it): it stopped or crashed."""


@dataclasses.dataclass
class JobResult:
    """A job's end as followed: its statuses in order, the last one, and whether it was done."""

    job_id: int
    statuses: list
    final: Status

    @property
    def ok(self) -> bool:
        return self.final.event == StatusEvent.JobDone

    @property
    def placed(self) -> int:
        return self.final.objects_done


def catalog_ids(objects_toml: os.PathLike | str = "models/objects.toml") -> list[str]:
    """The catalog's object ids (``"003"``...) in type-index order: a job names objects by index."""
    with open(objects_toml, "rb") as f:
        return [o["id"] for o in tomllib.load(f)["object"]]


class Heightmap:
    """One received frame: ``cells`` is a read-only ``(ny, nx)`` float32 view into shared memory
    (no copy) that is valid while this object lives; ``release()`` gives the sample back."""

    def __init__(self, sample):
        self._sample = sample
        frame = sample.payload().contents
        self.stamp_ns = frame.header.stamp_ns
        self.cell_m = frame.cell_m
        self.objects = frame.objects
        n = frame.nx * frame.ny
        flat = np.ctypeslib.as_array(frame.data)[:n]
        # The subscriber's mapping is read-only: writing through it would crash the process.
        flat.flags.writeable = False
        self.cells = flat.reshape(frame.ny, frame.nx)

    @property
    def address(self) -> int:
        """Where the cells start in this process's mapping of the shared memory."""
        return self.cells.ctypes.data

    def copy(self) -> np.ndarray:
        """The cells, copied out of shared memory (to keep beyond ``release``)."""
        return self.cells.copy()

    def release(self) -> None:
        """Gives the sample back to iceoryx2 (the views become invalid)."""
        self.cells = None
        self._sample = None


class Herb:
    """A client of the herbd serving ``prefix``. Open it after herbd has started."""

    def __init__(self, prefix: str = "herb", name: str = "herb-py", timeout_s: float = 10.0):
        iox2.set_log_level(iox2.LogLevel.Error)
        self.prefix = prefix
        self.node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(name))
            .create(iox2.ServiceType.Ipc)
        )
        self._status = self._open_pubsub("status", Status, timeout_s).subscriber_builder().create()
        rr = self._retry(
            lambda: self.node.service_builder(self._name("pack_job"))
            .request_response(PackJobRequest, PackJobReply)
            .open(),
            timeout_s,
            "pack_job",
        )
        self._jobs = rr.client_builder().create()
        self._confirms = None
        self._heightmaps = None
        self._outcomes = None
        self._seq = 0

    # -- services -------------------------------------------------------------------------

    def _name(self, leaf: str):
        return iox2.ServiceName.new(f"{self.prefix}/{leaf}")

    def _version_check(self, leaf: str) -> None:
        """Raises ``WireVersionMismatch`` when service ``leaf`` exists with payloads of another
        wire version. The payloads' type names are read from the service's static configuration
        (iceoryx2 keeps it as TOML under its root, ``/tmp/iceoryx2/services``, with the default
        configuration that every HERB process uses)."""
        service = f"{self.prefix}/{leaf}"
        for name in existing_type_names(service):
            theirs = wire_version_of(name)
            if theirs is not None and theirs != PROTOCOL_VERSION:
                raise WireVersionMismatch(service, PROTOCOL_VERSION, theirs, name)

    def _retry(self, open_fn, timeout_s: float, leaf: Optional[str] = None):
        deadline = time.monotonic() + timeout_s
        checked = 0.0
        while True:
            try:
                return open_fn()
            except Exception as e:  # iceoryx2 raises one exception class per error kind
                # The services' files are read at most once a second while herbd is awaited.
                if leaf is not None and time.monotonic() - checked >= 1.0:
                    checked = time.monotonic()
                    self._version_check(leaf)
                if time.monotonic() > deadline:
                    raise TimeoutError(
                        f"cannot open a service under prefix {self.prefix!r}: {e!r} "
                        "(is herbd running with this prefix?)"
                    ) from e
                time.sleep(0.05)

    def _open_pubsub(self, leaf: str, payload, timeout_s: float):
        return self._retry(
            lambda: self.node.service_builder(self._name(leaf)).publish_subscribe(payload).open(),
            timeout_s,
            leaf,
        )

    def _header(self):
        self._seq += 1
        return (PROTOCOL_VERSION, 0, self._seq, time.monotonic_ns())

    # -- jobs -----------------------------------------------------------------------------

    def submit(self, objects: Sequence[int], job_id: Optional[int] = None,
               timeout_s: float = 30.0, confirm_picks: bool = False) -> int:
        """Submits a job of catalog type indices; returns its id once herbd accepted it. Raises
        ``Rejected`` with herbd's reason (``NotReady`` is retried until ``timeout_s``). With
        ``confirm_picks`` a person feeds the pick station: herbd waits before each grasp until
        ``confirm_pick`` (statuses say so: ``waiting_for == JobWait.Confirmation``)."""
        if job_id is None:
            job_id = (time.monotonic_ns() & 0xFFFF_FFFF) << 16 | (os.getpid() & 0xFFFF) | 1
        deadline = time.monotonic() + timeout_s
        while True:
            req = PackJobRequest()
            req.header.version, req.header.reserved, req.header.seq, req.header.stamp_ns = (
                self._header()
            )
            req.job_id = job_id
            req.flags = PackJobRequest_CONFIRM_PICKS if confirm_picks else 0
            req.count = len(objects)
            for i, o in enumerate(objects[: len(req.objects)]):
                req.objects[i] = o
            pending = self._jobs.send_copy(req)
            reply = None
            t1 = time.monotonic() + 2.0
            while reply is None and time.monotonic() < t1:
                reply = pending.receive()
                if reply is None:
                    self.node.wait(iox2.Duration.from_millis(2))
            if time.monotonic() > deadline:
                raise TimeoutError(f"no reply from herbd under prefix {self.prefix!r}")
            if reply is None:
                continue
            r = PackJobReply.from_buffer_copy(reply.payload().contents)
            reason = RejectReason(r.reason)
            if reason == RejectReason.NONE:
                return job_id
            if reason == RejectReason.NotReady:
                time.sleep(0.2)
                continue
            raise Rejected(reason, r.detail)

    def confirm_pick(self, job_id: int, object_index: int, attempt: int,
                     timeout_s: float = 5.0) -> None:
        """Confirms that the object herbd awaits for job ``job_id`` (``object_index``, try
        ``attempt``: a status with ``waiting_for == JobWait.Confirmation`` names them) is at the
        pick station. Raises ``Rejected`` with herbd's reason (``NotAwaited`` when herbd does
        not await that object and try now: a confirmation is never kept for later)."""
        if self._confirms is None:
            rr = self._retry(
                lambda: self.node.service_builder(self._name("confirm_pick"))
                .request_response(ConfirmPickRequest, ConfirmPickReply)
                .open(),
                timeout_s,
                "confirm_pick",
            )
            self._confirms = rr.client_builder().create()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            req = ConfirmPickRequest()
            req.header.version, req.header.reserved, req.header.seq, req.header.stamp_ns = (
                self._header()
            )
            req.job_id, req.object_index, req.attempt = job_id, object_index, attempt
            pending = self._confirms.send_copy(req)
            t1 = min(deadline, time.monotonic() + 2.0)
            while time.monotonic() < t1:
                reply = pending.receive()
                if reply is None:
                    self.node.wait(iox2.Duration.from_millis(2))
                    continue
                r = ConfirmPickReply.from_buffer_copy(reply.payload().contents)
                reason = RejectReason(r.reason)
                if reason != RejectReason.NONE:
                    raise Rejected(reason, 0)
                return
            # No answer: sent again (a repeat of an accepted confirmation is accepted again).
        raise TimeoutError(f"no reply from herbd under prefix {self.prefix!r}")

    def statuses(self, job_id: int, timeout_s: float = 900.0,
                 reconnect_s: float = 60.0) -> Iterator[Status]:
        """Yields the job's statuses (copies; heartbeats included) as they come, up to its
        end. When herbd falls silent, waits up to ``reconnect_s`` for it to come back with the
        job (a restarted herbd takes an unfinished job up from its journal) and goes on.
        Raises ``DaemonLost`` when it does not (or comes back without the job),
        ``TimeoutError`` after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        heard = time.monotonic()
        while True:
            now = time.monotonic()
            if now > deadline:
                raise TimeoutError(f"job {job_id} not ended after {timeout_s} s")
            if now - heard > LOST_AFTER_S + reconnect_s:
                raise DaemonLost(f"no status from herbd for {now - heard:.1f} s (job {job_id})")
            while (sample := self._status.receive()) is not None:
                s = Status.from_buffer_copy(sample.payload().contents)
                sample.delete()
                if s.header.version != PROTOCOL_VERSION:
                    continue
                lost = time.monotonic() - heard > LOST_AFTER_S
                if s.job_id != job_id:
                    if lost and s.event == StatusEvent.Heartbeat:
                        raise DaemonLost(
                            f"herbd came back without job {job_id} (no journal, or abandoned)"
                        )
                    heard = time.monotonic()
                    continue
                heard = time.monotonic()
                yield s
                if s.event in END_EVENTS:
                    return
            self.node.wait(iox2.Duration.from_millis(5))

    def pack(self, objects: Sequence[int], timeout_s: float = 900.0) -> JobResult:
        """Submits a job and follows it to its end."""
        job_id = self.submit(objects)
        seen = [s for s in self.statuses(job_id, timeout_s)]
        return JobResult(job_id, seen, seen[-1])

    # -- heightmaps and the simulated box ----------------------------------------------------

    def heightmap(self, timeout_s: float = 5.0) -> Heightmap:
        """The next heightmap frame from the camera (or the loopback), without copying."""
        if self._heightmaps is None:
            svc = self._open_pubsub("heightmap", HeightmapFrame, timeout_s)
            self._heightmaps = svc.subscriber_builder().create()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            sample = self._heightmaps.receive()
            if sample is not None:
                return Heightmap(sample)
            self.node.wait(iox2.Duration.from_millis(5))
        raise TimeoutError(f"no heightmap within {timeout_s} s")

    def outcomes(self) -> list[SimOutcome]:
        """Simulated outcomes received since the last call (loopback only; copies)."""
        if self._outcomes is None:
            svc = self._open_pubsub("sim/outcome", SimOutcome, 5.0)
            self._outcomes = svc.subscriber_builder().create()
        out = []
        while (sample := self._outcomes.receive()) is not None:
            out.append(SimOutcome.from_buffer_copy(sample.payload().contents))
            sample.delete()
        return out


def describe(s: Status) -> str:
    """One line for people about a status."""
    ev = StatusEvent(s.event)
    what = f"job {s.job_id}: {ev.name}"
    if ev in (StatusEvent.Decided, StatusEvent.Placed) and s.object_type != NO_OBJECT:
        what += f" object {s.object_index + 1}/{s.objects_total} (type {s.object_type})"
    if s.fault:
        what += f", fault {Fault(s.fault).name}"
    return what + f", {s.objects_done}/{s.objects_total} placed, {JobState(s.state).name}"


__all__ = ["DaemonLost", "Heightmap", "Herb", "JobResult", "Rejected", "catalog_ids", "describe"]
