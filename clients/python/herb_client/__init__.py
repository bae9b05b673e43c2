"""Python client of herbd, HERB's packing controller, over iceoryx2's own Python bindings.

Submit a pack job, follow its ``Status`` live, read heightmap frames as numpy arrays without
copying. The payloads and codes (``herb_client.payloads``) are generated from the Rust types,
as ``ipc/CONTRACT.md`` is; ``tests/test_layout.py`` checks every size, offset, type name and code
``ctypes`` makes of them against the contract, so the two sides cannot drift.
"""

from .client import DaemonLost, Herb, JobResult, Rejected, WireVersionMismatch, catalog_ids
from .payloads import (
    Fault,
    GripperAction,
    JobState,
    JobWait,
    RejectReason,
    SimBound,
    StatusEvent,
)

__all__ = [
    "DaemonLost",
    "Fault",
    "GripperAction",
    "Herb",
    "JobResult",
    "JobState",
    "JobWait",
    "Rejected",
    "RejectReason",
    "SimBound",
    "StatusEvent",
    "WireVersionMismatch",
    "catalog_ids",
]
