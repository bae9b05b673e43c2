//! The run log's data model and codec: what the loop records ([`LoopRec`]) and how it reads back
//! ([`Entry`]), the run's header, the snapshot a later segment starts from, the digest of a
//! cycle's outputs, and the byte layout of all of them. No I/O here: the writer
//! ([`super::writer`]) and the reader ([`super::reader`]) move these bytes to and from files.
//!
//! A segment file starts with [`MAGIC`] and [`FORMAT`], then records of
//! `kind: u8 | len: u32 | payload | crc32: u32` (little-endian; the CRC covers kind, length and
//! payload), and ends with an end record when the writer closed it: a segment without one was
//! cut short (herbd killed, the disk full), wherever the cut fell.

use super::error::SnapshotError;
use crate::digest::Fnv;
use crate::job::{Commands, Inputs, JobRecord, JobSnapshot};
use crate::plan::{DecisionRequest, Motion, Request};
use herb_ipc::{
    ArmBlocker, ArmStatus, CancelJobRequest, ConfirmPickRequest, Fault, GripperAction,
    GripperState, HeightmapFrame, InOrder, JointState, PackJobRequest, Payload, RejectReason,
    Status,
};
use herb_robot::motion::Setpoint;
use std::io::Write;

/// The first bytes of a segment file.
pub const MAGIC: &[u8; 8] = b"HERBRUN\0";
/// The format version after [`MAGIC`] (2: a snapshot holds the job's record in the job
/// journal's encoding; 3: decisions come from their own worker, recorded apart from the
/// planner's responses, and the frames are the decisions'; 4: pick confirmations, and the
/// statuses' limit, attempt and request-count fields; 5: a segment ends with an end record;
/// 6: wire version 2, the statuses' `waiting_for` in their digests).
pub const FORMAT: u32 = 6;
/// A frame's header and grid: the bytes of a [`HeightmapFrame`] before its cells.
pub const FRAME_META: usize = std::mem::offset_of!(HeightmapFrame, data);

/// The requests handed over before a snapshot, in the planner's and the decision worker's
/// numbering (a later segment's replay numbers on from them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sent {
    /// Planner requests.
    pub requests: u64,
    /// Decision requests.
    pub decisions: u64,
}

/// A planner response as recorded: its digest ([`crate::plan::Response::digest`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RespRec {
    /// Digest of the response.
    pub digest: u64,
}

/// A decision as recorded: its digest ([`crate::plan::DecisionResponse::digest`]), what its
/// budget allowed (a replay runs that count of rollouts) and its measured latency (a replay
/// injects it: time is not reproducible).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecisionRec {
    /// Digest of the response.
    pub digest: u64,
    /// Rollouts the search finished ([`crate::plan::NOT_A_SEARCH`] for a policy).
    pub allowed: u32,
    /// Measured decision latency (ns).
    pub decision_ns: u64,
}

/// What the loop records, in the order it feeds the machine. Fixed size, `Copy`: pushed into a
/// preallocated ring without allocating.
#[derive(Debug, Clone, Copy)]
pub enum LoopRec {
    /// A cycle begins at `now`.
    Cycle {
        /// The cycle's start (ns, monotonic).
        now: u64,
    },
    /// A joint state.
    Js {
        /// iceoryx2 publisher id.
        publisher: u128,
        /// Clock when received.
        received: u64,
        /// The payload.
        m: JointState,
    },
    /// A gripper state.
    Gs {
        /// iceoryx2 publisher id.
        publisher: u128,
        /// Clock when received.
        received: u64,
        /// The payload.
        m: GripperState,
    },
    /// The arm adapter's status.
    Arm {
        /// iceoryx2 publisher id.
        publisher: u128,
        /// Clock when received.
        received: u64,
        /// The payload.
        m: ArmStatus,
    },
    /// A heightmap frame's header and grid ([`FRAME_META`] bytes).
    Frame([u8; FRAME_META]),
    /// A planner response.
    Resp(RespRec),
    /// A decision worker's response.
    Decision(DecisionRec),
    /// A pack-job request.
    Job(PackJobRequest),
    /// A cancel request.
    Cancel(CancelJobRequest),
    /// A pick confirmation.
    Confirm(ConfirmPickRequest),
    /// The cycle's tick: the stop flag it saw, and the digest of all its outputs.
    Tick {
        /// Stop requested.
        stop: bool,
        /// [`OutDigest`] of the cycle's outputs.
        digest: u64,
    },
    /// The next snapshot (from the snapshot ring) goes here: a new segment may start.
    Snapshot,
    /// Records were dropped (the writer fell behind): the log is incomplete from here.
    Gap {
        /// How many.
        dropped: u64,
    },
}

/// The digest of a cycle's outputs, as the machine gave them ([`crate::job::Effects`]), before
/// the shell adds headers and loop counters. herbd and the replay compute it the same way.
#[derive(Debug, Clone, Copy, Default)]
pub struct OutDigest(Fnv);

impl OutDigest {
    /// Starts a cycle.
    pub fn new() -> Self {
        Self::default()
    }
    /// A pack-job reply.
    pub fn reply(&mut self, job_id: u64, reason: RejectReason, detail: u32) {
        self.0
            .u64(1)
            .u64(job_id)
            .u64(reason as u64)
            .u64(detail as u64);
    }
    /// A cancel reply.
    pub fn cancel_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.0.u64(2).u64(job_id).u64(reason as u64);
    }
    /// A pick confirmation's reply.
    pub fn confirm_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.0.u64(12).u64(job_id).u64(reason as u64);
    }
    /// A status (the machine's fields).
    pub fn status(&mut self, s: &Status) {
        self.0.u64(3).bytes(s.as_bytes());
    }
    /// A joint command.
    pub fn joint(&mut self, c: &Setpoint) {
        self.0.u64(4);
        for v in c.position.iter().chain(&c.velocity).chain(&c.acceleration) {
            self.0.f64(*v);
        }
    }
    /// A gripper command.
    pub fn gripper(&mut self, job_id: u64, action: GripperAction, object_type: u32) {
        self.0
            .u64(5)
            .u64(job_id)
            .u64(action as u64)
            .u64(object_type as u64);
    }
    /// A planner request handed over.
    pub fn request(&mut self, r: &Request) {
        let h = &mut self.0;
        match r {
            Request::Order {
                job_id,
                objects,
                count,
                ordered,
            } => {
                h.u64(6).u64(*job_id);
                for o in &objects[..*count] {
                    h.u64(*o as u64);
                }
                // Logs written before recovered jobs existed hash the same.
                if *ordered {
                    h.u64(1);
                }
            }
            Request::Plan {
                index,
                object,
                from,
                motion,
                pose,
                ..
            } => {
                h.u64(7).u64(*index as u64).u64(*object as u64);
                match motion {
                    Motion::Pick => h.u64(0),
                    Motion::Place { flip } => h.u64(1).u64(*flip as u64),
                    Motion::PickAndPlace => h.u64(2),
                };
                for v in from {
                    h.f64(*v);
                }
                for v in pose {
                    h.u64(v.to_bits() as u64);
                }
            }
            Request::Brake { state, .. } => {
                h.u64(8);
                for v in state
                    .position
                    .iter()
                    .chain(&state.velocity)
                    .chain(&state.acceleration)
                {
                    h.f64(*v);
                }
            }
            Request::Retreat { from, held, .. } => {
                h.u64(9).u64(held.map_or(u64::MAX, |t| t as u64));
                for v in from {
                    h.f64(*v);
                }
            }
        }
    }
    /// A decision request handed over.
    pub fn decision_request(&mut self, r: &DecisionRequest) {
        self.0
            .u64(10)
            .u64(r.job_id)
            .u64(r.index as u64)
            .u64(r.after_stamp_ns);
        for o in r.remaining() {
            self.0.u64(*o as u64);
        }
    }
    /// The digest.
    pub fn finish(&self) -> u64 {
        self.0.finish()
    }
}

/// Record kinds on disk.
pub(super) mod kind {
    pub const HEADER: u8 = 1;
    pub const SNAPSHOT: u8 = 2;
    pub const CYCLE: u8 = 3;
    pub const JS: u8 = 4;
    pub const GS: u8 = 5;
    pub const FRAME: u8 = 6;
    pub const RESP: u8 = 7;
    pub const JOB: u8 = 8;
    pub const CANCEL: u8 = 9;
    pub const TICK: u8 = 10;
    pub const GAP: u8 = 11;
    pub const PLAN_FRAME: u8 = 12;
    pub const FRAME_CELLS: u8 = 13;
    pub const ARM: u8 = 14;
    pub const DECISION: u8 = 15;
    pub const CONFIRM: u8 = 16;
    /// The segment was closed by its writer (empty payload; format 5 on).
    pub const END: u8 = 17;
}

/// Little-endian encoding of record payloads.
#[derive(Default)]
pub(super) struct Enc(pub(super) Vec<u8>);

impl Enc {
    pub(super) fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    pub(super) fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub(super) fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub(super) fn u128(&mut self, v: u128) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub(super) fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }
    pub(super) fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.0.extend_from_slice(b);
        self
    }
    pub(super) fn str(&mut self, s: &str) -> &mut Self {
        self.bytes(s.as_bytes())
    }
}

/// Decoding; every getter fails (`None`) past the end.
pub(super) struct Dec<'a>(pub(super) &'a [u8]);

impl<'a> Dec<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Some(a)
    }
    pub(super) fn u8(&mut self) -> Option<u8> {
        Some(self.take(1)?[0])
    }
    pub(super) fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    pub(super) fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    pub(super) fn u128(&mut self) -> Option<u128> {
        Some(u128::from_le_bytes(self.take(16)?.try_into().ok()?))
    }
    pub(super) fn f64(&mut self) -> Option<f64> {
        Some(f64::from_bits(self.u64()?))
    }
    pub(super) fn bool(&mut self) -> Option<bool> {
        Some(self.u8()? != 0)
    }
    pub(super) fn bytes(&mut self) -> Option<&'a [u8]> {
        let n = self.u32()? as usize;
        self.take(n)
    }
    pub(super) fn str(&mut self) -> Option<String> {
        String::from_utf8(self.bytes()?.to_vec()).ok()
    }
    pub(super) fn payload<T: Payload>(&mut self) -> Option<T> {
        T::from_bytes(self.bytes()?)
    }
}

/// The run's identity, written at the top of every segment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunHeader {
    /// herbd's version and build profile.
    pub herbd: String,
    /// The CPU (model name and a digest of its feature flags).
    pub cpu: String,
    /// Wall-clock start of the run (s since the Unix epoch).
    pub started_unix_s: u64,
    /// The effective configuration, TOML (model paths made absolute).
    pub config_toml: String,
    /// The catalog's digest ([`catalog_digest`]).
    pub catalog: u64,
    /// Digest of the policy file (0 for BLBF).
    pub policy: u64,
    /// Digest of the sequence model file.
    pub sequence: u64,
    /// Segment number (0 for the first).
    pub segment: u64,
}

impl RunHeader {
    pub(super) fn encode(&self) -> Vec<u8> {
        let mut e = Enc::default();
        e.str(&self.herbd)
            .str(&self.cpu)
            .u64(self.started_unix_s)
            .str(&self.config_toml)
            .u64(self.catalog)
            .u64(self.policy)
            .u64(self.sequence)
            .u64(self.segment);
        e.0
    }
    pub(super) fn decode(b: &[u8]) -> Option<Self> {
        let mut d = Dec(b);
        Some(Self {
            herbd: d.str()?,
            cpu: d.str()?,
            started_unix_s: d.u64()?,
            config_toml: d.str()?,
            catalog: d.u64()?,
            policy: d.u64()?,
            sequence: d.u64()?,
            segment: d.u64()?,
        })
    }
}

/// A snapshot record: the planner requests sent before it, then the machine's state: the last
/// job's record in its own encoding ([`JobRecord::encode`], shared with the job journal), the
/// latched inputs, the last fault and release, the commands, and the stop flag.
pub(super) fn encode_snapshot(before: Sent, s: &JobSnapshot) -> Vec<u8> {
    let mut e = Enc::default();
    e.u64(before.requests)
        .u64(before.decisions)
        .bytes(&s.job.encode());
    let opt_order = |e: &mut Enc, o: InOrder| match o.last() {
        Some((p, q, t)) => {
            e.u8(1).u128(p).u64(q).u64(t);
        }
        None => {
            e.u8(0);
        }
    };
    let i = &s.inputs;
    match &i.js {
        Some(m) => e.u8(1).bytes(m.as_bytes()),
        None => e.u8(0),
    };
    e.u64(i.js_at);
    opt_order(&mut e, i.js_order);
    match &i.gs {
        Some(m) => e.u8(1).bytes(m.as_bytes()),
        None => e.u8(0),
    };
    e.u64(i.gs_at);
    opt_order(&mut e, i.gs_order);
    e.u32(i.arm_blocker as u32).u64(i.arm_at);
    opt_order(&mut e, i.arm_order);
    e.u64(i.hm_rx_at)
        .u64(i.hm_stamp)
        .u64(i.rejected)
        .u64(i.rejected_requests);
    e.u32(s.fault as u32).u64(s.release_stamp);
    let c = &s.commands;
    for row in [&c.cmd.position, &c.cmd.velocity, &c.cmd.acceleration] {
        for v in row {
            e.f64(*v);
        }
    }
    e.u32(c.grip_cmd as u32)
        .u32(c.grip_object)
        .u8(c.grip_due as u8)
        .u64(c.grip_sent_at)
        .u64(c.last_heartbeat)
        .u64(c.limit_holds);
    for v in &c.from {
        e.f64(*v);
    }
    e.u8(s.stopping as u8);
    e.0
}

/// A snapshot record read back ([`encode_snapshot`]).
pub(super) fn decode_snapshot(b: &[u8]) -> Result<(Sent, JobSnapshot), SnapshotError> {
    let mut d = Dec(b);
    let before = (|| {
        Some(Sent {
            requests: d.u64()?,
            decisions: d.u64()?,
        })
    })()
    .ok_or(SnapshotError::Malformed)?;
    let job = JobRecord::decode(d.bytes().ok_or(SnapshotError::Malformed)?)?;
    decode_machine(&mut d, job)
        .filter(|_| d.0.is_empty())
        .map(|s| (before, s))
        .ok_or(SnapshotError::Malformed)
}

/// The rest of a snapshot record, after the job's.
fn decode_machine(d: &mut Dec, job: JobRecord) -> Option<JobSnapshot> {
    fn opt_order(d: &mut Dec) -> Option<InOrder> {
        Some(InOrder::with_last(match d.u8()? {
            0 => None,
            _ => Some((d.u128()?, d.u64()?, d.u64()?)),
        }))
    }
    let js = match d.u8()? {
        0 => None,
        _ => Some(d.payload::<JointState>()?),
    };
    let (js_at, js_order) = (d.u64()?, opt_order(d)?);
    let gs = match d.u8()? {
        0 => None,
        _ => Some(d.payload::<GripperState>()?),
    };
    let (gs_at, gs_order) = (d.u64()?, opt_order(d)?);
    let (arm_blocker, arm_at, arm_order) =
        (ArmBlocker::from_code(d.u32()?)?, d.u64()?, opt_order(d)?);
    let inputs = Inputs {
        js,
        js_at,
        js_order,
        gs,
        gs_at,
        gs_order,
        arm_blocker,
        arm_at,
        arm_order,
        hm_rx_at: d.u64()?,
        hm_stamp: d.u64()?,
        rejected: d.u64()?,
        rejected_requests: d.u64()?,
    };
    let (fault, release_stamp) = (Fault::from_code(d.u32()?)?, d.u64()?);
    let mut cmd = Setpoint::default();
    for row in [&mut cmd.position, &mut cmd.velocity, &mut cmd.acceleration] {
        for v in row.iter_mut() {
            *v = d.f64()?;
        }
    }
    let commands = Commands {
        cmd,
        grip_cmd: GripperAction::from_code(d.u32()?)?,
        grip_object: d.u32()?,
        grip_due: d.bool()?,
        grip_sent_at: d.u64()?,
        last_heartbeat: d.u64()?,
        limit_holds: d.u64()?,
        from: [0.0; herb_robot::kinematics::DOF],
    };
    let mut commands = commands;
    for v in commands.from.iter_mut() {
        *v = d.f64()?;
    }
    Some(JobSnapshot {
        inputs,
        commands,
        job,
        release_stamp,
        fault,
        stopping: d.bool()?,
    })
}

/// A loop record's kind and payload ([`LoopRec::Snapshot`] is the writer's, never encoded).
pub(super) fn encode_loop(r: &LoopRec) -> (u8, Vec<u8>) {
    let mut e = Enc::default();
    let k = match r {
        LoopRec::Cycle { now } => {
            e.u64(*now);
            kind::CYCLE
        }
        LoopRec::Js {
            publisher,
            received,
            m,
        } => {
            e.u128(*publisher).u64(*received).bytes(m.as_bytes());
            kind::JS
        }
        LoopRec::Gs {
            publisher,
            received,
            m,
        } => {
            e.u128(*publisher).u64(*received).bytes(m.as_bytes());
            kind::GS
        }
        LoopRec::Arm {
            publisher,
            received,
            m,
        } => {
            e.u128(*publisher).u64(*received).bytes(m.as_bytes());
            kind::ARM
        }
        LoopRec::Frame(meta) => {
            e.bytes(meta);
            kind::FRAME
        }
        LoopRec::Resp(r) => {
            e.u64(r.digest);
            kind::RESP
        }
        LoopRec::Decision(r) => {
            e.u64(r.digest).u32(r.allowed).u64(r.decision_ns);
            kind::DECISION
        }
        LoopRec::Job(r) => {
            e.bytes(r.as_bytes());
            kind::JOB
        }
        LoopRec::Cancel(r) => {
            e.bytes(r.as_bytes());
            kind::CANCEL
        }
        LoopRec::Confirm(r) => {
            e.bytes(r.as_bytes());
            kind::CONFIRM
        }
        LoopRec::Tick { stop, digest } => {
            e.u8(*stop as u8).u64(*digest);
            kind::TICK
        }
        LoopRec::Gap { dropped } => {
            e.u64(*dropped);
            kind::GAP
        }
        LoopRec::Snapshot => unreachable!("snapshots are written by the writer"),
    };
    (k, e.0)
}

/// A loop record read back (kinds [`kind::CYCLE`] to [`kind::TICK`] and [`kind::ARM`]); `None`
/// when the payload does not decode.
pub(super) fn decode_loop(k: u8, payload: &[u8]) -> Option<Entry> {
    let mut d = Dec(payload);
    match k {
        kind::CYCLE => d.u64().map(Entry::Cycle),
        kind::JS => Some(Entry::Js(d.u128()?, d.u64()?, d.payload()?)),
        kind::GS => Some(Entry::Gs(d.u128()?, d.u64()?, d.payload()?)),
        kind::ARM => Some(Entry::Arm(d.u128()?, d.u64()?, d.payload()?)),
        kind::FRAME => d.bytes().and_then(|b| b.try_into().ok()).map(Entry::Frame),
        kind::RESP => Some(Entry::Resp(RespRec { digest: d.u64()? })),
        kind::DECISION => Some(Entry::Decision(DecisionRec {
            digest: d.u64()?,
            allowed: d.u32()?,
            decision_ns: d.u64()?,
        })),
        kind::JOB => d.payload().map(Entry::Job),
        kind::CANCEL => d.payload().map(Entry::Cancel),
        kind::CONFIRM => d.payload().map(Entry::Confirm),
        kind::TICK => Some(Entry::Tick(d.bool()?, d.u64()?)),
        _ => None,
    }
}

/// Bytes a record takes besides its payload: kind, length and CRC.
pub(super) const FRAMING: usize = 9;

/// Writes one record (kind, length, payload, CRC); the bytes written.
pub(super) fn write_record(w: &mut impl Write, k: u8, payload: &[u8]) -> std::io::Result<u64> {
    let len = (payload.len() as u32).to_le_bytes();
    let mut crc = crc32fast::Hasher::new();
    crc.update(&[k]);
    crc.update(&len);
    crc.update(payload);
    w.write_all(&[k])?;
    w.write_all(&len)?;
    w.write_all(payload)?;
    w.write_all(&crc.finalize().to_le_bytes())?;
    Ok((FRAMING + payload.len()) as u64)
}

/// The record at the start of some bytes, as [`read_record`] finds it.
pub(super) enum Framed<'a> {
    /// A whole record whose CRC matches; it takes [`FRAMING`] + `payload.len()` bytes.
    Record {
        /// Its kind.
        kind: u8,
        /// Its payload.
        payload: &'a [u8],
    },
    /// The bytes end inside the record (a tail torn by a crash).
    Torn,
    /// The CRC does not match.
    Corrupt,
}

/// Reads the record `b` starts with.
pub(super) fn read_record(b: &[u8]) -> Framed<'_> {
    if b.len() < FRAMING {
        return Framed::Torn;
    }
    let k = b[0];
    let len = u32::from_le_bytes(b[1..5].try_into().unwrap()) as usize;
    if b.len() < FRAMING + len {
        return Framed::Torn;
    }
    let crc = u32::from_le_bytes(b[5 + len..FRAMING + len].try_into().unwrap());
    let mut h = crc32fast::Hasher::new();
    h.update(&b[..5 + len]);
    if h.finalize() != crc {
        return Framed::Corrupt;
    }
    Framed::Record {
        kind: k,
        payload: &b[5..5 + len],
    }
}

/// A frame's bytes for the log: header and grid, then the used cells.
pub(super) fn frame_bytes(f: &HeightmapFrame) -> Box<[u8]> {
    let all = f.as_bytes();
    let cells = f.cells().len() * 4;
    all[..FRAME_META + cells].into()
}

/// A frame from its logged bytes (header and grid, then the used cells).
pub(super) fn frame_from(b: &[u8]) -> Option<Box<HeightmapFrame>> {
    if b.len() < FRAME_META || !(b.len() - FRAME_META).is_multiple_of(4) {
        return None;
    }
    let mut all = vec![0u8; std::mem::size_of::<HeightmapFrame>()];
    if b.len() > all.len() {
        return None;
    }
    all[..b.len()].copy_from_slice(b);
    HeightmapFrame::from_bytes(&all).map(Box::new)
}

/// One loop record read back (the machine's inputs, in order).
#[derive(Debug, Clone, Copy)]
pub enum Entry {
    /// See [`LoopRec`].
    Cycle(u64),
    /// See [`LoopRec`].
    Js(u128, u64, JointState),
    /// See [`LoopRec`].
    Gs(u128, u64, GripperState),
    /// See [`LoopRec`].
    Arm(u128, u64, ArmStatus),
    /// See [`LoopRec`].
    Frame([u8; FRAME_META]),
    /// See [`LoopRec`].
    Resp(RespRec),
    /// See [`LoopRec`].
    Decision(DecisionRec),
    /// See [`LoopRec`].
    Job(PackJobRequest),
    /// See [`LoopRec`].
    Cancel(CancelJobRequest),
    /// See [`LoopRec`].
    Confirm(ConfirmPickRequest),
    /// See [`LoopRec`].
    Tick(bool, u64),
}
