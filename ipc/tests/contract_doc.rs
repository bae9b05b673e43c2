//! `ipc/CONTRACT.md` and the Python client's payloads cannot drift from the Rust types: the
//! document's generated blocks (payload layouts, code tables, services and their QoS) and the
//! whole of `clients/python/herb_client/payloads.py` are rendered here from the types themselves
//! and must match the files. `HERB_UPDATE_CONTRACT=1 cargo test -p herb-ipc --test contract_doc`
//! rewrites them after a deliberate change of the wire.

use herb_ipc::bus::{REQUEST_QOS, qos};
use herb_ipc::*;
use std::fmt::Write;
use std::mem::{align_of, offset_of, size_of};
use std::path::Path;

/// The size, alignment and short type name of a field, from an accessor (no value needed).
fn field<T, F>(_: fn(&T) -> &F) -> (usize, usize, String) {
    let full = std::any::type_name::<F>();
    // `[f64; 7]`, `u32`, `herb_ipc::Header` -> `Header`.
    let short = full
        .split(['[', ';', ']'])
        .map(|part| part.rsplit("::").next().unwrap_or(part))
        .collect::<Vec<_>>();
    let name = if full.starts_with('[') {
        format!("[{}; {}]", short[1], short[2].trim())
    } else {
        short[0].to_string()
    };
    (size_of::<F>(), align_of::<F>(), name)
}

/// `n` rounded up to a multiple of `align`.
fn round_up(n: usize, align: usize) -> usize {
    n.div_ceil(align) * align
}

/// A field of a contract structure.
struct Field {
    name: &'static str,
    /// The contract's type name: `u32`, `[f32; 4]`, `Header`.
    ty: String,
    offset: usize,
    size: usize,
    /// Unit or meaning.
    unit: &'static str,
}

/// A contract structure, fields in order.
struct Payload {
    name: &'static str,
    align: usize,
    size: usize,
    fields: Vec<Field>,
}

/// Push one [`Payload`] of its fields' names, types, offsets, sizes and units. The fields must
/// be listed completely and in order: each starts where the previous ended (plus its alignment's
/// padding) and the last ends the struct, so a field missing here fails.
macro_rules! layout {
    ($out:expr, $t:ident, $( $f:ident : $unit:expr ),+ $(,)?) => {{
        let mut end = 0usize;
        let mut fields = Vec::new();
        $(
            let (size, align, ty) = field::<$t, _>(|v| &v.$f);
            assert_eq!(
                offset_of!($t, $f),
                round_up(end, align),
                "{}.{} is not where the listed fields end: a field is missing from the list",
                stringify!($t),
                stringify!($f)
            );
            // No padding either (`Payload::as_bytes` relies on it).
            assert_eq!(
                offset_of!($t, $f),
                end,
                "{}.{} follows padding: add a reserved field before it",
                stringify!($t),
                stringify!($f)
            );
            end = offset_of!($t, $f) + size;
            fields.push(Field {
                name: stringify!($f),
                ty,
                offset: offset_of!($t, $f),
                size,
                unit: $unit,
            });
        )+
        assert_eq!(
            round_up(end, align_of::<$t>()),
            size_of::<$t>(),
            "{}: fields missing from the list at its end",
            stringify!($t)
        );
        assert_eq!(end, size_of::<$t>(), "{}: padding at its end", stringify!($t));
        $out.push(Payload {
            name: stringify!($t),
            align: align_of::<$t>(),
            size: size_of::<$t>(),
            fields,
        });
    }};
}

/// The layout table of `ipc/CONTRACT.md`.
fn layout_table(payloads: &[Payload]) -> String {
    let mut s = String::from(
        "| payload | field | type | offset (bytes) | size (bytes) | unit, meaning |\n| --- | --- | --- | ---: | ---: | --- |\n",
    );
    for p in payloads {
        for f in &p.fields {
            writeln!(
                s,
                "| `{}` | `{}` | `{}` | {} | {} | {} |",
                p.name, f.name, f.ty, f.offset, f.size, f.unit
            )
            .unwrap();
        }
        writeln!(
            s,
            "| `{0}` | (whole) | align {1} | 0 | {2} | type name `herb::v{3}::{0}` |",
            p.name, p.align, p.size, PROTOCOL_VERSION
        )
        .unwrap();
    }
    s
}

/// Every contract structure, each after the structures it contains.
fn layouts() -> Vec<Payload> {
    let mut s = Vec::new();
    layout!(s, Header,
        version: "protocol version, must be `PROTOCOL_VERSION`",
        reserved: "zero",
        seq: "per-publisher sequence number, from 1, strictly increasing",
        stamp_ns: "ns, CLOCK_MONOTONIC, when the content was produced (measured, captured)");
    layout!(s, JointState,
        header: "",
        position: "rad, joints s0 s1 e0 e1 w0 w1 w2",
        velocity: "rad/s");
    layout!(s, JointCommand,
        header: "stamp: the loop cycle's start",
        position: "rad",
        velocity: "rad/s, feed-forward",
        acceleration: "rad/s^2, feed-forward");
    layout!(s, GripperCommand,
        header: "",
        job_id: "the job this command serves (0 outside a job)",
        action: "`GripperAction` code",
        object_type: "catalog type index expected at the pick station, or `NO_OBJECT`");
    layout!(s, GripperState,
        header: "",
        closed: "1 closed, 0 open",
        holding: "1 when an object is held",
        object_type: "held object's catalog type index if known, else `NO_OBJECT`",
        reserved: "zero");
    layout!(s, ArmStatus,
        header: "",
        blocker: "`ArmBlocker` code: why joint state is withheld (0: it is not)",
        reserved: "zero",
        commands_refused: "joint commands the adapter's jump guard refused since it started");
    layout!(s, HeightmapFrame,
        header: "stamp: capture time",
        nx: "columns, along box x",
        ny: "rows, along box y",
        cell_m: "m, cell side",
        objects: "objects in the box if the source knows, else 0",
        data: "m above the inner floor; row-major, row 0 at +y, column 0 at -x; first nx*ny used");
    layout!(s, CancelJobRequest,
        header: "",
        job_id: "the running job to cancel");
    layout!(s, CancelJobReply,
        header: "",
        job_id: "the request's job id",
        accepted: "1 when the job is being cancelled",
        reason: "`RejectReason` code: `None`, `Malformed`, `ShuttingDown`, `NoSuchJob`");
    layout!(s, ConfirmPickRequest,
        header: "",
        job_id: "the running job",
        object_index: "the object awaited (`Status.object_index` of its `AwaitingObject`)",
        attempt: "the try awaited (`Status.attempt` of its `AwaitingObject`)");
    layout!(s, ConfirmPickReply,
        header: "",
        job_id: "the request's job id",
        accepted: "1 when taken (the arm may descend to the grasp)",
        reason: "`RejectReason` code: `None`, `Malformed`, `ShuttingDown`, `NoSuchJob`, `NotAwaited`");
    layout!(s, Status,
        header: "",
        job_id: "the job (0 when idle)",
        event: "`StatusEvent` code",
        state: "`JobState` code",
        fault: "`Fault` code, the current or last fault",
        objects_total: "objects in the job",
        objects_done: "objects released",
        object_index: "index in the packing order of the object this event is about",
        object_type: "its catalog type index, or `NO_OBJECT`",
        decision_wait_ms: "ms this job has held objects at the lift pose waiting for their decisions, so far",
        pose: "m, m, m, rad: x, y, z of the canonical origin in the box frame, yaw",
        decision_ns: "ns, the decision's latency (Decided)",
        cycles: "loop cycles run",
        deadline_misses: "loop cycles that overran",
        rejected_inputs: "sensor inputs dropped: invalid, from the future or out of order",
        max_cycle_ns: "ns, worst cycle since start",
        rejected_requests: "client requests refused (pack, cancel, confirm)",
        limit_joint: "joint 0..7 outside its limits (`OutsideLimits`, `BeyondArmLimits`), else `NO_JOINT`",
        limit_position_rad: "rad, its measured angle then (0 without `limit_joint`)",
        limit_bound_rad: "rad, the limit it was beyond (0 without `limit_joint`)",
        attempt: "the current object's pick try this event is about, from 0",
        waiting_for: "`JobWait` code: what the running job waits for now (every status and heartbeat)",
        reserved: "zero");
    layout!(s, PackJobRequest,
        header: "",
        job_id: "chosen by the client, non-zero",
        count: "objects used",
        flags: "bit 0 `CONFIRM_PICKS`: a person feeds the station, each grasp waits for a `ConfirmPickRequest`; other bits zero",
        objects: "catalog type indices (not ids); first `count` used");
    layout!(s, PackJobReply,
        header: "",
        job_id: "the request's",
        accepted: "1 when accepted",
        reason: "`RejectReason` code",
        detail: "e.g. the position of an unknown object",
        reserved: "zero");
    layout!(s, SimReset, header: "stamp: the request's time");
    layout!(s, SimObject,
        object_type: "catalog type index",
        bound: "0 inside the success volume, else the bound crossed most (`SimBound` code)",
        over_m: "m by which it crosses that bound (0 inside)",
        yaw_rad: "rad, heading of its canonical x axis about z",
        lo: "m, lowest corner of its bounds in the box frame",
        hi: "m, highest corner of its bounds in the box frame",
        origin: "m, where its canonical origin settled, in the box frame",
        rotation: "its orientation in the box frame, unit quaternion x, y, z, w");
    layout!(s, CommandChecks,
        max_limit_excess_rad: "rad, largest joint-limit excess among received commands",
        received: "joint commands received",
        rejected: "joint commands rejected (out of limits, malformed)");
    layout!(s, SimOutcome,
        header: "",
        job_id: "the job whose gripper command released the object",
        objects: "objects in the box after the release",
        object_type: "released object's catalog type index",
        all_inside: "1 when every object is inside the success volume",
        stable: "1 when the released object's tilt is within the threshold",
        tilt_rad: "rad",
        compactness: "C of the box after settling",
        release: "m, m, m, rad: release pose in the box frame",
        commands: "what the simulated arm found of the joint commands it received so far",
        placed: "every object in the box after the release, in placement order (the first `min(objects, 64)`)");
    layout!(s, CandidateReport,
        x: "m, B x of the canonical origin",
        y: "m, B y",
        yaw: "rad, about B z",
        ret: "the rollout's return (the configured reward)",
        packed: "objects the rollout placed inside, the candidate's included",
        flags: "bit 0: every object inside; bit 1: the candidate chosen");
    layout!(s, DecisionReport,
        header: "stamp: the decision's end",
        job_id: "the job",
        object_index: "index in the packing order",
        object_type: "catalog type index",
        method: "0 a placement policy, 1 the search",
        feasible: "feasible candidates on the placement lattice (search; 0 for a policy)",
        allowed: "rollouts the search's budget allowed (finished)",
        count: "candidates listed",
        pose: "m, m, m, rad: the placement decided (zeros when none)",
        decided: "1 when a placement was decided",
        reserved: "zero",
        decision_ns: "ns, the decision's latency",
        candidates: "the candidates rolled out, in the prior's order (the first `count`)");
    s
}

/// The names of an enum's codes 0, 1, 2..., by probing its decoder (codes are contiguous).
fn names<E: std::fmt::Debug>(decode: fn(u32) -> Option<E>) -> Vec<String> {
    (0..)
        .map_while(|c| decode(c).map(|v| format!("{v:?}")))
        .collect()
}

/// Every code table: the enum's name and its members' names by code.
fn code_tables() -> Vec<(&'static str, Vec<String>)> {
    vec![
        ("GripperAction", names(GripperAction::from_code)),
        ("JobState", names(JobState::from_code)),
        ("StatusEvent", names(StatusEvent::from_code)),
        ("Fault", names(Fault::from_code)),
        ("ArmBlocker", names(ArmBlocker::from_code)),
        (
            "SimBound",
            SIM_BOUNDS.iter().map(|b| b.to_string()).collect(),
        ),
        ("RejectReason", names(RejectReason::from_code)),
        ("JobWait", names(JobWait::from_code)),
    ]
}

/// The codes table of `ipc/CONTRACT.md`.
fn codes() -> String {
    let mut s = String::from("| enum | name | code |\n| --- | --- | ---: |\n");
    for (e, members) in code_tables() {
        for (c, n) in members.iter().enumerate() {
            writeln!(s, "| `{e}` | `{n}` | {c} |").unwrap();
        }
    }
    s
}

/// The `ctypes` type of a contract type name.
fn py_type(ty: &str) -> String {
    if let Some((t, n)) = ty
        .strip_prefix('[')
        .and_then(|a| a.strip_suffix(']'))
        .and_then(|a| a.split_once("; "))
    {
        return format!("{} * {n}", py_type(t));
    }
    match ty {
        "u16" | "u32" | "u64" | "f32" | "f64" => format!("_{ty}"),
        other => other.to_string(),
    }
}

/// `items` joined by ", " after `head` and before `tail`, wrapped at 99 columns with
/// continuation lines indented by `indent` spaces.
fn wrapped(head: &str, items: &[String], tail: &str, indent: usize) -> String {
    let mut out = String::from(head);
    let mut line = head.len();
    for (i, item) in items.iter().enumerate() {
        let piece = if i + 1 == items.len() {
            format!("{item}{tail}")
        } else {
            format!("{item},")
        };
        if i > 0 {
            if line + 1 + piece.len() > 99 {
                out.push('\n');
                out.push_str(&" ".repeat(indent));
                line = indent;
            } else {
                out.push(' ');
                line += 1;
            }
        }
        out.push_str(&piece);
        line += piece.len();
    }
    out
}

/// The Python client's `payloads.py`: the constants, every structure as `ctypes` (in the order
/// of [`layouts`], which puts a contained structure first), every code table as an `IntEnum`
/// (`None` is a Python keyword: that member is `NONE`).
fn python(payloads: &[Payload]) -> String {
    let mut s = String::from(PY_HEAD);
    writeln!(
        s,
        "PROTOCOL_VERSION = {PROTOCOL_VERSION}\nDOF = {DOF}\nHEIGHTMAP_MAX_CELLS = {HEIGHTMAP_MAX_CELLS}\nMAX_JOB_OBJECTS = {MAX_JOB_OBJECTS}\nMAX_REPORTED_CANDIDATES = {MAX_REPORTED_CANDIDATES}\nNO_OBJECT = 0x{NO_OBJECT:X}\nNO_JOINT = 0x{NO_JOINT:X}"
    )
    .unwrap();
    s.push_str(PY_BASE);
    for p in payloads {
        let fields: Vec<String> = p
            .fields
            .iter()
            .map(|f| format!("(\"{}\", {})", f.name, py_type(&f.ty)))
            .collect();
        writeln!(
            s,
            "\n\nclass {}(_Struct):\n{}",
            p.name,
            wrapped("    _fields_ = [", &fields, "]", 8)
        )
        .unwrap();
    }
    let names: Vec<String> = payloads.iter().map(|p| p.name.to_string()).collect();
    writeln!(
        s,
        "\n\n#: Every structure of the contract, by name.\n{}",
        wrapped("PAYLOADS = {c.__name__: c for c in (", &names, ")}", 4)
    )
    .unwrap();
    let mut enums = Vec::new();
    for (e, members) in code_tables() {
        if e == "SimBound" {
            let quoted: Vec<String> = members.iter().map(|m| format!("\"{m}\"")).collect();
            writeln!(
                s,
                "\n\n#: Names of the success volume's bounds by `SimObject.bound` code.\n{}",
                wrapped("SimBound = (", &quoted, ")", 4)
            )
            .unwrap();
            continue;
        }
        write!(s, "\n\nclass {e}(enum.IntEnum):\n").unwrap();
        for (c, m) in members.iter().enumerate() {
            let m = if m == "None" { "NONE" } else { m };
            writeln!(s, "    {m} = {c}").unwrap();
        }
        enums.push(format!("\"{e}\": {e}"));
    }
    writeln!(
        s,
        "\n\n#: Every code table of the contract (but `SimBound`), by enum name.\n{}",
        wrapped("CODES = {", &enums, "}", 4)
    )
    .unwrap();
    s.push_str(PY_TAIL);
    s
}

/// The Python module's fixed head, up to its constants.
const PY_HEAD: &str = r#""""HERB's IPC payloads as ``ctypes`` structures and its codes as ``enum.IntEnum``, field for field
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

"#;

/// The Python module's base structure, after its constants.
const PY_BASE: &str = r#"
_u16, _u32, _u64 = ctypes.c_uint16, ctypes.c_uint32, ctypes.c_uint64
_f32, _f64 = ctypes.c_float, ctypes.c_double


class _Struct(ctypes.Structure):
    """A contract structure: iceoryx2 registers it under ``herb::v<PROTOCOL_VERSION>::<class name>``."""

    @classmethod
    def type_name(cls) -> str:
        return f"herb::v{PROTOCOL_VERSION}::{cls.__name__}"
"#;

/// The Python module's fixed tail.
const PY_TAIL: &str = r#"

def code_name(member: enum.IntEnum) -> str:
    """The contract's name of a code (``None`` for the ``NONE`` members)."""
    return "None" if member.name == "NONE" else member.name
"#;

fn constants() -> String {
    format!(
        "| constant | value |\n| --- | --- |\n| `PROTOCOL_VERSION` | {PROTOCOL_VERSION} |\n| `DOF` | {DOF} |\n| `HEIGHTMAP_MAX_CELLS` | {HEIGHTMAP_MAX_CELLS} |\n| `MAX_JOB_OBJECTS` | {MAX_JOB_OBJECTS} |\n| `NO_OBJECT` | {NO_OBJECT} (0x{NO_OBJECT:X}) |\n| `NO_JOINT` | {NO_JOINT} (0x{NO_JOINT:X}) |\n| `HEIGHT_RANGE_M` | {} .. {} m |\n| `MAX_JOINT_ABS_RAD` | {MAX_JOINT_ABS_RAD} rad |\n| `MAX_JOINT_SPEED` | {MAX_JOINT_SPEED} rad/s |\n| `MAX_FUTURE_STAMP_NS` | {MAX_FUTURE_STAMP_NS} ns |\n| `GRIPPER_REPEAT_NS` | {GRIPPER_REPEAT_NS} ns |\n| `HEARTBEAT_PERIOD_NS` | {HEARTBEAT_PERIOD_NS} ns |\n| `ARM_STATUS_PERIOD_NS` | {ARM_STATUS_PERIOD_NS} ns |\n| `CELL_M_RANGE` | {} .. {} m |\n",
        HEIGHT_RANGE_M.0, HEIGHT_RANGE_M.1, CELL_M_RANGE.0, CELL_M_RANGE.1
    )
}

fn services() -> String {
    let sv = Services::new("herb").unwrap();
    let mut s = String::from(
        "| service (prefix `herb`) | pattern | payload | publisher(s) | subscribers | max publishers | max subscribers | history | queue per subscriber | borrowed per subscriber | max nodes | safe overflow |\n| --- | --- | --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n",
    );
    for (name, payload, from, to) in [
        (sv.joint_state(), "JointState", "arm adapter", "herbd"),
        (sv.joint_command(), "JointCommand", "herbd", "arm adapter"),
        (sv.gripper_state(), "GripperState", "arm adapter", "herbd"),
        (
            sv.arm_status(),
            "ArmStatus",
            "arm adapter",
            "herbd, clients",
        ),
        (
            sv.gripper_command(),
            "GripperCommand",
            "herbd",
            "arm adapter",
        ),
        (
            sv.heightmap(),
            "HeightmapFrame",
            "camera adapter",
            "herbd, clients",
        ),
        (sv.status(), "Status", "herbd", "clients"),
        (
            sv.decision(),
            "DecisionReport",
            "herbd (decision thread)",
            "clients (viewers)",
        ),
        (
            sv.sim_outcome(),
            "SimOutcome",
            "loopback (sim only)",
            "tests, clients",
        ),
        (
            sv.sim_reset(),
            "SimReset",
            "clients (`herbctl reset`)",
            "loopback (sim only)",
        ),
    ] {
        let q = qos(&name);
        writeln!(
            s,
            "| `{name}` | publish-subscribe | `{payload}` | {from} | {to} | {} | {} | {} | {} | {} | {} | {} |",
            q.max_publishers,
            q.max_subscribers,
            q.history_size,
            q.subscriber_max_buffer_size,
            q.subscriber_max_borrowed_samples,
            q.max_nodes,
            if q.safe_overflow { "yes" } else { "no" }
        )
        .unwrap();
    }
    writeln!(
        s,
        "| `{}` | request-response | `PackJobRequest` -> `PackJobReply` | clients | herbd (the one server) | - | - | - | - | - | - | - |",
        sv.pack_job()
    )
    .unwrap();
    writeln!(
        s,
        "| `{}` | request-response | `CancelJobRequest` -> `CancelJobReply` | clients | herbd (the one server) | - | - | - | - | - | - | - |",
        sv.cancel_job()
    )
    .unwrap();
    writeln!(
        s,
        "| `{}` | request-response | `ConfirmPickRequest` -> `ConfirmPickReply` | clients | herbd (the one server) | - | - | - | - | - | - | - |",
        sv.confirm_pick()
    )
    .unwrap();
    let q = REQUEST_QOS;
    writeln!(
        s,
        "\nEach request-response service: at most {} clients, {} server, {} nodes; {} active requests per client, a response buffer of {}, {} loaned requests, {} borrowed responses per pending response; safe overflow for requests and responses: {}.",
        q.max_clients,
        q.max_servers,
        q.max_nodes,
        q.max_active_requests_per_client,
        q.max_response_buffer_size,
        q.max_loaned_requests,
        q.max_borrowed_responses_per_pending_response,
        if q.safe_overflow { "yes" } else { "no" }
    )
    .unwrap();
    s
}

/// The text between `<!-- NAME:begin -->` and `<!-- NAME:end -->`.
fn block<'a>(doc: &'a str, name: &str) -> (usize, usize, &'a str) {
    let (b, e) = (
        format!("<!-- {name}:begin -->\n"),
        format!("<!-- {name}:end -->"),
    );
    let i = doc
        .find(&b)
        .unwrap_or_else(|| panic!("CONTRACT.md has no {name} block"))
        + b.len();
    let j = i + doc[i..]
        .find(&e)
        .unwrap_or_else(|| panic!("{name} block not closed"));
    (i, j, &doc[i..j])
}

#[test]
fn the_contract_document_matches_the_types() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("CONTRACT.md");
    let mut doc = std::fs::read_to_string(&path).expect("ipc/CONTRACT.md");
    let update = std::env::var_os("HERB_UPDATE_CONTRACT").is_some();
    let mut stale = Vec::new();
    for (name, want) in [
        ("layout", layout_table(&layouts())),
        ("codes", codes()),
        ("constants", constants()),
        ("services", services()),
    ] {
        let (i, j, have) = block(&doc, name);
        if have != want {
            if update {
                doc.replace_range(i..j, &want);
            } else {
                stale.push(format!("{name}:\n{want}"));
            }
        }
    }
    if update {
        std::fs::write(&path, doc).unwrap();
    }
    assert!(
        stale.is_empty(),
        "ipc/CONTRACT.md is out of date; the types say:\n{}\n(HERB_UPDATE_CONTRACT=1 rewrites the blocks)",
        stale.join("\n")
    );
}

/// The layout each wire version fixes: the version and a digest (FNV-1a, 64 bits) of every
/// structure's fields (name, type, offset, size), size and alignment. A layout changed under
/// the same version fails here: raise `PROTOCOL_VERSION` (ipc/src/base.rs) and the type names,
/// then write the pair this test prints.
const WIRE_LAYOUT: (u32, u64) = (2, 0xa8cc_6d5e_fdbb_1eb9);

/// [`WIRE_LAYOUT`]'s digest of `payloads`.
fn layout_digest(payloads: &[Payload]) -> u64 {
    let mut text = String::new();
    for p in payloads {
        for f in &p.fields {
            writeln!(
                text,
                "{} {} {} {} {}",
                p.name, f.name, f.ty, f.offset, f.size
            )
            .unwrap();
        }
        writeln!(text, "{} {} {}", p.name, p.align, p.size).unwrap();
    }
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn a_layout_change_raises_the_wire_version() {
    let digest = layout_digest(&layouts());
    assert!(
        WIRE_LAYOUT == (PROTOCOL_VERSION, digest),
        "the contract's layout is not the one wire version {} fixed: a changed layout needs a new \
         version (PROTOCOL_VERSION and every type name), then WIRE_LAYOUT = ({}, 0x{digest:016x})",
        WIRE_LAYOUT.0,
        if WIRE_LAYOUT.1 == digest {
            WIRE_LAYOUT.0
        } else {
            WIRE_LAYOUT.0 + 1
        },
    );
}

/// The Python client's payloads are the types' (generated; `HERB_UPDATE_CONTRACT=1` rewrites).
#[test]
fn the_python_payloads_match_the_types() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../clients/python/herb_client/payloads.py");
    let want = python(&layouts());
    let have = std::fs::read_to_string(&path).unwrap_or_default();
    if have != want && std::env::var_os("HERB_UPDATE_CONTRACT").is_some() {
        std::fs::write(&path, &want).unwrap();
        return;
    }
    assert!(
        have == want,
        "clients/python/herb_client/payloads.py is out of date (HERB_UPDATE_CONTRACT=1 rewrites it)"
    );
}

/// The first column of the hand-written table whose header row starts with `| {first} |`.
fn first_column(doc: &str, first: &str) -> Vec<String> {
    let head = format!("| {first} |");
    let mut rows = doc.lines().skip_while(|l| !l.starts_with(&head)).skip(2);
    let mut out = Vec::new();
    for l in rows.by_ref() {
        if !l.starts_with('|') {
            break;
        }
        out.push(l.split('|').nth(1).unwrap_or("").trim().to_string());
    }
    out
}

/// The hand-written tables name every code: each `RejectReason` has its `detail`, each
/// `Fault` what herbd does.
#[test]
fn the_reasons_and_faults_tables_name_every_code() {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("CONTRACT.md")).unwrap();
    let reasons = first_column(&doc, "reason");
    assert_eq!(reasons.len(), 11, "{reasons:?}");
    for c in 0..64 {
        if let Some(r) = RejectReason::from_code(c) {
            let name = format!("`{r:?}`");
            assert!(
                reasons.contains(&name),
                "{name} missing from the reasons table"
            );
        }
    }
    let faults = first_column(&doc, "fault");
    assert!(faults.len() >= 10, "{faults:?}");
    let faults = faults.join(", ");
    for c in 0..64 {
        if let Some(f) = Fault::from_code(c) {
            if f == Fault::None {
                continue;
            }
            let name = format!("`{f:?}`");
            assert!(
                faults.contains(&name),
                "{name} missing from the faults table"
            );
        }
    }
}
