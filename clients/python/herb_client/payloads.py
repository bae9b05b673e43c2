"""HERB's IPC payloads as ``ctypes`` structures and its codes as ``enum.IntEnum``, field for field
and code for code as ``ipc/CONTRACT.md`` lists them (natural alignment, no padding; little-endian
x86-64). Each structure carries its iceoryx2 type name ``herb::v<PROTOCOL_VERSION>::<Name>``
(``type_name()``), which iceoryx2 checks with the size and alignment when a service is opened.

Generated from the Rust types by ``cargo test -p herb-ipc --test contract_doc``: do not edit
(``HERB_UPDATE_CONTRACT=1`` rewrites it after a deliberate change of the wire).
``tests/test_layout.py`` checks what ``ctypes`` makes of it against the contract's tables.
"""

from __future__ import annotations

import ctypes
import enum

PROTOCOL_VERSION = 2
DOF = 7
HEIGHTMAP_MAX_CELLS = 50176
MAX_JOB_OBJECTS = 64
MAX_REPORTED_CANDIDATES = 64
NO_OBJECT = 0xFFFFFFFF
NO_JOINT = 0xFFFFFFFF

_u16, _u32, _u64 = ctypes.c_uint16, ctypes.c_uint32, ctypes.c_uint64
_f32, _f64 = ctypes.c_float, ctypes.c_double


class _Struct(ctypes.Structure):
    """A contract structure: iceoryx2 registers it under ``herb::v<PROTOCOL_VERSION>::<class name>``."""

    @classmethod
    def type_name(cls) -> str:
        return f"herb::v{PROTOCOL_VERSION}::{cls.__name__}"


class Header(_Struct):
    _fields_ = [("version", _u32), ("reserved", _u32), ("seq", _u64), ("stamp_ns", _u64)]


class JointState(_Struct):
    _fields_ = [("header", Header), ("position", _f64 * 7), ("velocity", _f64 * 7)]


class JointCommand(_Struct):
    _fields_ = [("header", Header), ("position", _f64 * 7), ("velocity", _f64 * 7),
        ("acceleration", _f64 * 7)]


class GripperCommand(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("action", _u32), ("object_type", _u32)]


class GripperState(_Struct):
    _fields_ = [("header", Header), ("closed", _u32), ("holding", _u32), ("object_type", _u32),
        ("reserved", _u32)]


class ArmStatus(_Struct):
    _fields_ = [("header", Header), ("blocker", _u32), ("reserved", _u32),
        ("commands_refused", _u64)]


class HeightmapFrame(_Struct):
    _fields_ = [("header", Header), ("nx", _u32), ("ny", _u32), ("cell_m", _f32),
        ("objects", _u32), ("data", _f32 * 50176)]


class CancelJobRequest(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64)]


class CancelJobReply(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("accepted", _u32), ("reason", _u32)]


class ConfirmPickRequest(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("object_index", _u32), ("attempt", _u32)]


class ConfirmPickReply(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("accepted", _u32), ("reason", _u32)]


class Status(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("event", _u32), ("state", _u32),
        ("fault", _u32), ("objects_total", _u32), ("objects_done", _u32), ("object_index", _u32),
        ("object_type", _u32), ("decision_wait_ms", _u32), ("pose", _f32 * 4),
        ("decision_ns", _u64), ("cycles", _u64), ("deadline_misses", _u64),
        ("rejected_inputs", _u64), ("max_cycle_ns", _u64), ("rejected_requests", _u64),
        ("limit_joint", _u32), ("limit_position_rad", _f32), ("limit_bound_rad", _f32),
        ("attempt", _u32), ("waiting_for", _u32), ("reserved", _u32)]


class PackJobRequest(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("count", _u32), ("flags", _u32),
        ("objects", _u16 * 64)]


class PackJobReply(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("accepted", _u32), ("reason", _u32),
        ("detail", _u32), ("reserved", _u32)]


class SimReset(_Struct):
    _fields_ = [("header", Header)]


class SimObject(_Struct):
    _fields_ = [("object_type", _u32), ("bound", _u32), ("over_m", _f32), ("yaw_rad", _f32),
        ("lo", _f32 * 3), ("hi", _f32 * 3), ("origin", _f32 * 3), ("rotation", _f32 * 4)]


class CommandChecks(_Struct):
    _fields_ = [("max_limit_excess_rad", _f64), ("received", _u64), ("rejected", _u64)]


class SimOutcome(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("objects", _u32), ("object_type", _u32),
        ("all_inside", _u32), ("stable", _u32), ("tilt_rad", _f32), ("compactness", _f32),
        ("release", _f32 * 4), ("commands", CommandChecks), ("placed", SimObject * 64)]


class CandidateReport(_Struct):
    _fields_ = [("x", _f32), ("y", _f32), ("yaw", _f32), ("ret", _f32), ("packed", _u32),
        ("flags", _u32)]


class DecisionReport(_Struct):
    _fields_ = [("header", Header), ("job_id", _u64), ("object_index", _u32),
        ("object_type", _u32), ("method", _u32), ("feasible", _u32), ("allowed", _u32),
        ("count", _u32), ("pose", _f32 * 4), ("decided", _u32), ("reserved", _u32),
        ("decision_ns", _u64), ("candidates", CandidateReport * 64)]


#: Every structure of the contract, by name.
PAYLOADS = {c.__name__: c for c in (Header, JointState, JointCommand, GripperCommand, GripperState,
    ArmStatus, HeightmapFrame, CancelJobRequest, CancelJobReply, ConfirmPickRequest,
    ConfirmPickReply, Status, PackJobRequest, PackJobReply, SimReset, SimObject, CommandChecks,
    SimOutcome, CandidateReport, DecisionReport)}


class GripperAction(enum.IntEnum):
    Open = 0
    Close = 1


class JobState(enum.IntEnum):
    Idle = 0
    Running = 1
    Braking = 2
    Faulted = 3
    Done = 4
    Failed = 5
    Cancelled = 6


class StatusEvent(enum.IntEnum):
    Heartbeat = 0
    Accepted = 1
    Decided = 2
    Placed = 3
    Fault = 4
    Braked = 5
    Resumed = 6
    JobDone = 7
    JobFailed = 8
    Shutdown = 9
    JobCancelled = 10
    Skipped = 11
    AwaitingObject = 12


class Fault(enum.IntEnum):
    NONE = 0
    JointStateTimeout = 1
    GripperStateTimeout = 2
    HeightmapTimeout = 3
    Gripper = 4
    Unreachable = 5
    Decision = 6
    Motion = 7
    Stop = 8
    ObjectLost = 9
    NoFeasiblePlacement = 10
    Restarted = 11
    RobotDisabled = 12
    RobotEStop = 13
    RobotError = 14
    MasterLost = 15
    RobotSilent = 16
    MissedGrasp = 17
    CommandRefused = 18
    OutsideLimits = 19
    BeyondArmLimits = 20


class ArmBlocker(enum.IntEnum):
    NONE = 0
    Disabled = 1
    EStop = 2
    RobotError = 3
    MasterLost = 4
    RobotSilent = 5
    CommandRefused = 6


#: Names of the success volume's bounds by `SimObject.bound` code.
SimBound = ("inside", "-x wall", "+x wall", "-y wall", "+y wall", "floor", "top")


class RejectReason(enum.IntEnum):
    NONE = 0
    Busy = 1
    Empty = 2
    TooMany = 3
    UnknownObject = 4
    Malformed = 5
    ShuttingDown = 6
    NotReady = 7
    NoSuchJob = 8
    Holding = 9
    NotAwaited = 10


class JobWait(enum.IntEnum):
    NONE = 0
    Confirmation = 1
    Decision = 2


#: Every code table of the contract (but `SimBound`), by enum name.
CODES = {"GripperAction": GripperAction, "JobState": JobState, "StatusEvent": StatusEvent,
    "Fault": Fault, "ArmBlocker": ArmBlocker, "RejectReason": RejectReason, "JobWait": JobWait}


def code_name(member: enum.IntEnum) -> str:
    """The contract's name of a code (``None`` for the ``NONE`` members)."""
    return "None" if member.name == "NONE" else member.name
