"""Python client of herbd, HERB's packing controller, over iceoryx2's own Python bindings.

Submit a pack job, follow its ``Status`` live, read heightmap frames as numpy arrays without
copying. The payloads (``herb_client.payloads``) mirror ``ipc/CONTRACT.md``, which is generated
from the Rust types; ``tests/test_layout.py`` checks every size, offset, type name and code
against it, so the two sides cannot drift.
"""

from .client import DaemonLost, Herb, JobResult, Rejected, catalog_ids
from .payloads import (
    Fault,
    GripperAction,
    JobState,
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
    "Rejected",
    "RejectReason",
    "SimBound",
    "StatusEvent",
    "catalog_ids",
]
