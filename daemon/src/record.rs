//! Run logs: everything that reaches the job state machine and the decision core, written off
//! the loop, so that `herbctl replay` can re-run a run bit for bit and `herbctl explain` can
//! say why an object went where it did.
//!
//! # What is recorded
//!
//! - A header: format, herbd's version, the CPU, the effective configuration (TOML) and the
//!   digests of the catalog, the policy and the sequence model.
//! - Per loop cycle, in the order the loop fed them to the machine ([`crate::job`]): the
//!   cycle's time, every joint and gripper state (raw bytes, publisher, receive time), every
//!   heightmap frame's header and grid, every planner response (its digest and measured
//!   decision latency), every job and cancel request, the stop flag, and a digest of the
//!   machine's outputs in that cycle.
//! - From the planner thread: for every request, the heightmap it was served with (the cells
//!   of each distinct frame once per segment).
//!
//! # Format
//!
//! A segment file starts with [`MAGIC`] and the format version, then records of
//! `kind: u8 | len: u32 | payload | crc32: u32` (little-endian; the CRC covers kind, length and
//! payload), so a tail torn by a crash is found and reported. Segments rotate at
//! `segment_mb`, only between jobs: a later segment starts with the machine's
//! [`JobSnapshot`] and replays on its own; the oldest are deleted beyond `keep_mb`.
//!
//! # Off the loop
//!
//! The loop pushes fixed-size [`LoopRec`]s into a preallocated wait-free ring (no allocation,
//! no I/O; a full ring drops records, counted and marked by a [`LoopRec::Gap`]); a writer
//! thread encodes, writes, flushes every 100 ms and rotates.

use crate::digest::Fnv;
use crate::job::JobSnapshot;
use crate::plan::Request;
use herb_ipc::{
    ArmStatus, CancelJobRequest, GripperAction, GripperState, HeightmapFrame, JointState,
    MAX_JOB_OBJECTS, PackJobRequest, Payload, RejectReason, Status,
};
use herb_robot::kinematics::DOF;
use herb_robot::motion::Setpoint;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// The first bytes of a segment file.
pub const MAGIC: &[u8; 8] = b"HERBRUN\0";
/// The format version after [`MAGIC`].
pub const FORMAT: u32 = 1;
/// A frame's header and grid: the bytes of a [`HeightmapFrame`] before its cells.
pub const FRAME_META: usize = std::mem::offset_of!(HeightmapFrame, data);
/// Records the loop's ring holds (about 8 s of a 1 kHz loop with its two states per cycle).
const LOOP_RING: usize = 32 * 1024;
/// How often the writer drains the rings and flushes.
const WRITER_PERIOD: Duration = Duration::from_millis(100);

/// A planner response as recorded: its digest ([`crate::plan::Response::digest`]) and the
/// decision latency measured with it (a replay injects it: time is not reproducible).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RespRec {
    /// Digest of the response.
    pub digest: u64,
    /// Measured decision latency (ns; 0 when none).
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
    /// A pack-job request.
    Job(PackJobRequest),
    /// A cancel request.
    Cancel(CancelJobRequest),
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
                after_stamp_ns,
                from,
                place_only,
                repick,
                pose,
                ..
            } => {
                h.u64(7)
                    .u64(*index as u64)
                    .u64(*object as u64)
                    .u64(*after_stamp_ns)
                    .u64(*place_only as u64);
                // Logs written before re-picks existed hash the same.
                if *repick {
                    h.u64(1);
                }
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
    /// The digest.
    pub fn finish(&self) -> u64 {
        self.0.finish()
    }
}

// ---------------------------------------------------------------------------------------------
// Encoding
// ---------------------------------------------------------------------------------------------

/// Record kinds on disk.
mod kind {
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
}

/// Little-endian encoding of record payloads.
#[derive(Default)]
struct Enc(Vec<u8>);

impl Enc {
    fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u128(&mut self, v: u128) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }
    fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.0.extend_from_slice(b);
        self
    }
    fn str(&mut self, s: &str) -> &mut Self {
        self.bytes(s.as_bytes())
    }
}

/// Decoding; every getter fails (`None`) past the end.
struct Dec<'a>(&'a [u8]);

impl<'a> Dec<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Some(a)
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.take(1)?[0])
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn u128(&mut self) -> Option<u128> {
        Some(u128::from_le_bytes(self.take(16)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_bits(self.u64()?))
    }
    fn bool(&mut self) -> Option<bool> {
        Some(self.u8()? != 0)
    }
    fn bytes(&mut self) -> Option<&'a [u8]> {
        let n = self.u32()? as usize;
        self.take(n)
    }
    fn str(&mut self) -> Option<String> {
        String::from_utf8(self.bytes()?.to_vec()).ok()
    }
    fn payload<T: Payload>(&mut self) -> Option<T> {
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
    fn encode(&self) -> Vec<u8> {
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
    fn decode(b: &[u8]) -> Option<Self> {
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

/// This machine's CPU: model name and a digest of its flags (tract picks kernels by them).
pub fn cpu_identity() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split(':').nth(1))
            .map(|v| v.trim().to_string())
            .unwrap_or_default()
    };
    format!(
        "{}; flags {:016x}",
        field("model name"),
        crate::digest::of(field("flags").as_bytes())
    )
}

/// The digest of a catalog: every type's id and the extents of its shape.
pub fn catalog_digest(c: &herb_sim::Catalog) -> u64 {
    let mut h = Fnv::new();
    for i in 0..c.len() {
        let t = herb_sim::TypeIdx(i as u16);
        h.bytes(c.spec(t).id.as_bytes());
        let e = c.shape(t).extents();
        for v in [e.x, e.y, e.z] {
            h.u64(v.to_bits() as u64);
        }
    }
    h.finish()
}

/// The header of a run of `cfg` with `catalog`: the configuration with its model paths and the
/// BoxED folder made absolute (a replay from another folder finds them) and without a run log
/// of its own, and the digests of what it loads.
pub fn header_for(
    cfg: &crate::config::Config,
    catalog: &herb_sim::Catalog,
) -> Result<RunHeader, String> {
    use herb_decide::PolicySpec;
    let abs = |p: &Path| std::fs::canonicalize(p).map_err(|e| format!("{}: {e}", p.display()));
    let file = |p: &Path| {
        std::fs::read(p)
            .map(|b| crate::digest::of(&b))
            .map_err(|e| format!("{}: {e}", p.display()))
    };
    let mut c = cfg.clone();
    c.record.dir = None;
    c.models.sequence = abs(&cfg.models.sequence)?;
    let policy = match cfg.models.policy_file() {
        None => 0,
        Some(p) => {
            c.models.policy = PolicySpec::Onnx(abs(&p)?);
            file(&p)?
        }
    };
    c.models.boxed = herb_sim::paths::boxed_root(cfg.models.boxed.as_deref())
        .map(|p| std::fs::canonicalize(&p).unwrap_or(p));
    let started_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    Ok(RunHeader {
        herbd: format!(
            "herbd {} ({})",
            env!("CARGO_PKG_VERSION"),
            if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
        ),
        cpu: cpu_identity(),
        started_unix_s,
        config_toml: toml::to_string(&c).map_err(|e| format!("configuration: {e}"))?,
        catalog: catalog_digest(catalog),
        policy,
        sequence: file(&cfg.models.sequence)?,
        segment: 0,
    })
}

fn encode_snapshot(requests_before: u64, s: &JobSnapshot) -> Vec<u8> {
    let mut e = Enc::default();
    e.u64(requests_before);
    let opt_order = |e: &mut Enc, o: Option<(u128, u64, u64)>| match o {
        Some((p, q, t)) => {
            e.u8(1).u128(p).u64(q).u64(t);
        }
        None => {
            e.u8(0);
        }
    };
    match &s.js {
        Some(m) => e.u8(1).bytes(m.as_bytes()),
        None => e.u8(0),
    };
    e.u64(s.js_at);
    opt_order(&mut e, s.js_order);
    match &s.gs {
        Some(m) => e.u8(1).bytes(m.as_bytes()),
        None => e.u8(0),
    };
    e.u64(s.gs_at);
    opt_order(&mut e, s.gs_order);
    e.u64(s.hm_rx_at)
        .u64(s.hm_stamp)
        .u64(s.rejected)
        .u64(s.job_id);
    for o in s.order {
        e.u32(o as u32);
    }
    e.u64(s.count)
        .u64(s.index)
        .u64(s.done)
        .u64(s.release_stamp)
        .u8(s.holding as u8)
        .u32(s.fault);
    for row in &s.cmd {
        for v in row {
            e.f64(*v);
        }
    }
    e.u8(s.commanding as u8)
        .u32(s.grip.0)
        .u32(s.grip.1)
        .u8(s.grip.2 as u8)
        .u64(s.grip.3)
        .u64(s.last_heartbeat)
        .u64(s.limit_holds)
        .u8(s.stopping as u8);
    // Appended later: a snapshot without it reads as "nothing said yet".
    e.u32(s.arm.0).u64(s.arm.1);
    opt_order(&mut e, s.arm.2);
    e.0
}

fn decode_snapshot(b: &[u8]) -> Option<(u64, JobSnapshot)> {
    let mut d = Dec(b);
    let before = d.u64()?;
    fn opt_order(d: &mut Dec) -> Option<Option<(u128, u64, u64)>> {
        Some(match d.u8()? {
            0 => None,
            _ => Some((d.u128()?, d.u64()?, d.u64()?)),
        })
    }
    let js = match d.u8()? {
        0 => None,
        _ => Some(d.payload::<JointState>()?),
    };
    let js_at = d.u64()?;
    let js_order = opt_order(&mut d)?;
    let gs = match d.u8()? {
        0 => None,
        _ => Some(d.payload::<GripperState>()?),
    };
    let gs_at = d.u64()?;
    let gs_order = opt_order(&mut d)?;
    let (hm_rx_at, hm_stamp, rejected, job_id) = (d.u64()?, d.u64()?, d.u64()?, d.u64()?);
    let mut order = [0u16; MAX_JOB_OBJECTS];
    for o in &mut order {
        *o = d.u32()? as u16;
    }
    let (count, index, done, release_stamp) = (d.u64()?, d.u64()?, d.u64()?, d.u64()?);
    let (holding, fault) = (d.bool()?, d.u32()?);
    let mut cmd = [[0.0; DOF]; 3];
    for row in &mut cmd {
        for v in row.iter_mut() {
            *v = d.f64()?;
        }
    }
    let commanding = d.bool()?;
    let grip = (d.u32()?, d.u32()?, d.bool()?, d.u64()?);
    let (last_heartbeat, limit_holds, stopping) = (d.u64()?, d.u64()?, d.bool()?);
    let arm = if d.0.is_empty() {
        (0, 0, None)
    } else {
        (d.u32()?, d.u64()?, opt_order(&mut d)?)
    };
    Some((
        before,
        JobSnapshot {
            js,
            js_at,
            js_order,
            gs,
            gs_at,
            gs_order,
            hm_rx_at,
            hm_stamp,
            rejected,
            job_id,
            order,
            count,
            index,
            done,
            release_stamp,
            holding,
            fault,
            cmd,
            commanding,
            grip,
            last_heartbeat,
            arm,
            limit_holds,
            stopping,
        },
    ))
}

fn encode_loop(r: &LoopRec) -> (u8, Vec<u8>) {
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
            e.u64(r.digest).u64(r.decision_ns);
            kind::RESP
        }
        LoopRec::Job(r) => {
            e.bytes(r.as_bytes());
            kind::JOB
        }
        LoopRec::Cancel(r) => {
            e.bytes(r.as_bytes());
            kind::CANCEL
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

/// Writes one record (kind, length, payload, CRC).
fn write_record(w: &mut impl Write, k: u8, payload: &[u8]) -> std::io::Result<u64> {
    let len = (payload.len() as u32).to_le_bytes();
    let mut crc = crc32fast::Hasher::new();
    crc.update(&[k]);
    crc.update(&len);
    crc.update(payload);
    w.write_all(&[k])?;
    w.write_all(&len)?;
    w.write_all(payload)?;
    w.write_all(&crc.finalize().to_le_bytes())?;
    Ok(9 + payload.len() as u64)
}

// ---------------------------------------------------------------------------------------------
// The loop's side and the writer thread
// ---------------------------------------------------------------------------------------------

/// The loop's end of the recorder: pushes never block or allocate.
pub struct Recorder {
    tx: rtrb::Producer<LoopRec>,
    snaps: rtrb::Producer<(u64, JobSnapshot)>,
    want_snapshot: Arc<AtomicBool>,
    dropped: u64,
}

impl Recorder {
    /// Records `r` (dropped and counted if the writer is behind).
    pub fn push(&mut self, r: LoopRec) {
        if self.dropped > 0 {
            match self.tx.push(LoopRec::Gap {
                dropped: self.dropped,
            }) {
                Ok(()) => self.dropped = 0,
                Err(_) => {
                    self.dropped += 1;
                    return;
                }
            }
        }
        if self.tx.push(r).is_err() {
            self.dropped += 1;
        }
    }

    /// The writer asks for a snapshot (its segment is full): the loop gives one between jobs.
    pub fn wants_snapshot(&self) -> bool {
        self.want_snapshot.load(Ordering::Relaxed)
    }

    /// Records the machine's snapshot, taken with `requests_before` planner requests sent so
    /// far: the writer starts a new segment with it.
    pub fn snapshot(&mut self, requests_before: u64, s: JobSnapshot) {
        if self.snaps.push((requests_before, s)).is_ok() {
            self.want_snapshot.store(false, Ordering::Relaxed);
            self.push(LoopRec::Snapshot);
        }
    }
}

/// Where and how much to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The folder of the segment files.
    pub dir: PathBuf,
    /// A segment is closed, between jobs, past this size (bytes).
    pub segment_bytes: u64,
    /// The oldest segments are deleted beyond this total (bytes).
    pub keep_bytes: u64,
}

/// A frame the planner was served with, on its way to the writer.
type PlanFrame = (u64, Option<Box<[u8]>>);

/// A running recorder: the loop's end, the planner's frame log, and the writer thread.
pub struct Recording {
    /// For the loop.
    pub recorder: Recorder,
    /// For the planner thread ([`crate::planner::spawn`]).
    pub frames: crate::planner::FrameLog,
    /// The writer; set `stop` and join it after the loop ended. Returns the segment files.
    pub writer: std::thread::JoinHandle<Result<Vec<PathBuf>, String>>,
    /// Tells the writer to drain, flush, sync and end.
    pub stop: Arc<AtomicBool>,
}

/// A frame's bytes for the log: header and grid, then the used cells.
fn frame_bytes(f: &HeightmapFrame) -> Box<[u8]> {
    let all = f.as_bytes();
    let cells = f.cells().len() * 4;
    all[..FRAME_META + cells].into()
}

/// Starts recording into `opts.dir` (created if needed): the first segment is opened (and its
/// header written) before this returns, so a bad folder is reported at start.
pub fn start(opts: RecordOptions, header: RunHeader) -> Result<Recording, String> {
    std::fs::create_dir_all(&opts.dir)
        .map_err(|e| format!("run log folder {}: {e}", opts.dir.display()))?;
    let (tx, mut rx) = rtrb::RingBuffer::<LoopRec>::new(LOOP_RING);
    let (snaps, mut snaps_rx) = rtrb::RingBuffer::<(u64, JobSnapshot)>::new(2);
    let (ftx, frx) = mpsc::channel::<PlanFrame>();
    let want = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let mut seg = Segment::open(&opts.dir, &header)?;
    let (want_w, stop_w) = (want.clone(), stop.clone());
    let writer = std::thread::Builder::new()
        .name("herbd-record".into())
        .spawn(move || -> Result<Vec<PathBuf>, String> {
            let mut header = header;
            let mut files = vec![seg.path.clone()];
            loop {
                let last = stop_w.load(Ordering::Relaxed);
                // Frames first: a frame is sent before the response that used it.
                while let Ok((n, f)) = frx.try_recv() {
                    seg.plan_frame(n, f.as_deref())?;
                }
                while let Ok(r) = rx.pop() {
                    if let LoopRec::Snapshot = r {
                        while let Ok((n, f)) = frx.try_recv() {
                            seg.plan_frame(n, f.as_deref())?;
                        }
                        let Ok((before, s)) = snaps_rx.pop() else {
                            continue;
                        };
                        seg.close()?;
                        header.segment += 1;
                        seg = Segment::open(&opts.dir, &header)?;
                        seg.write(kind::SNAPSHOT, &encode_snapshot(before, &s))?;
                        files.push(seg.path.clone());
                        prune(&mut files, opts.keep_bytes);
                        continue;
                    }
                    let (k, p) = encode_loop(&r);
                    seg.write(k, &p)?;
                }
                seg.flush()?;
                if seg.bytes > opts.segment_bytes {
                    want_w.store(true, Ordering::Relaxed);
                }
                if last {
                    seg.close()?;
                    return Ok(files);
                }
                std::thread::sleep(WRITER_PERIOD);
            }
        })
        .map_err(|e| format!("cannot start the run-log writer: {e}"))?;
    let frames: crate::planner::FrameLog = Box::new(move |n, f| {
        let _ = ftx.send((n, f.map(frame_bytes)));
    });
    Ok(Recording {
        recorder: Recorder {
            tx,
            snaps,
            want_snapshot: want,
            dropped: 0,
        },
        frames,
        writer,
        stop,
    })
}

/// Deletes the oldest segments (never the current, last one) while the total exceeds `keep`.
fn prune(files: &mut Vec<PathBuf>, keep: u64) {
    let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    while files.len() > 1 && files.iter().map(|p| size(p)).sum::<u64>() > keep {
        let old = files.remove(0);
        let _ = std::fs::remove_file(&old);
    }
}

/// An open segment file.
struct Segment {
    path: PathBuf,
    w: BufWriter<std::fs::File>,
    bytes: u64,
    seen: HashSet<u64>,
}

impl Segment {
    fn open(dir: &Path, h: &RunHeader) -> Result<Self, String> {
        let path = dir.join(format!("RUN-{}-{:04}.log", h.started_unix_s, h.segment));
        let f =
            std::fs::File::create(&path).map_err(|e| format!("run log {}: {e}", path.display()))?;
        let mut s = Self {
            path,
            w: BufWriter::with_capacity(1 << 20, f),
            bytes: 0,
            seen: HashSet::new(),
        };
        s.raw(MAGIC)?;
        s.raw(&FORMAT.to_le_bytes())?;
        s.write(kind::HEADER, &h.encode())?;
        Ok(s)
    }

    fn err(&self, e: std::io::Error) -> String {
        format!("run log {}: {e}", self.path.display())
    }

    fn raw(&mut self, b: &[u8]) -> Result<(), String> {
        self.w.write_all(b).map_err(|e| self.err(e))?;
        self.bytes += b.len() as u64;
        Ok(())
    }

    fn write(&mut self, k: u8, p: &[u8]) -> Result<(), String> {
        let n = write_record(&mut self.w, k, p).map_err(|e| self.err(e))?;
        self.bytes += n;
        Ok(())
    }

    /// The frame request `n` was served with; its cells the first time in this segment.
    fn plan_frame(&mut self, n: u64, f: Option<&[u8]>) -> Result<(), String> {
        let digest = f.map_or(0, crate::digest::of);
        if let Some(b) = f
            && self.seen.insert(digest)
        {
            let mut e = Enc::default();
            e.u64(digest).bytes(b);
            self.write(kind::FRAME_CELLS, &e.0)?;
        }
        let mut e = Enc::default();
        e.u64(n).u8(f.is_some() as u8).u64(digest);
        self.write(kind::PLAN_FRAME, &e.0)
    }

    fn flush(&mut self) -> Result<(), String> {
        self.w.flush().map_err(|e| self.err(e))
    }

    fn close(&mut self) -> Result<(), String> {
        self.flush()?;
        self.w.get_ref().sync_all().map_err(|e| self.err(e))
    }
}

// ---------------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------------

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
    Job(PackJobRequest),
    /// See [`LoopRec`].
    Cancel(CancelJobRequest),
    /// See [`LoopRec`].
    Tick(bool, u64),
}

/// A segment read back.
#[derive(Debug)]
pub struct Log {
    /// The header.
    pub header: RunHeader,
    /// The machine's state at the start, and the planner requests sent before it (a later
    /// segment); `None` for a run's first segment.
    pub snapshot: Option<(u64, JobSnapshot)>,
    /// The loop's records.
    pub entries: Vec<Entry>,
    /// Per planner request number: the digest of the frame it was served with (`None`: none).
    pub plan_frames: BTreeMap<u64, Option<u64>>,
    /// Frames by digest: header, grid and used cells.
    pub frames: HashMap<u64, Box<HeightmapFrame>>,
    /// Why the log ends early, if it does (a torn or corrupt record, dropped records).
    pub incomplete: Option<String>,
}

/// A frame from its logged bytes (header and grid, then the used cells).
fn frame_from(b: &[u8]) -> Option<Box<HeightmapFrame>> {
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

impl Log {
    /// Reads a segment file. A torn or corrupt tail is not an error: what comes before it is
    /// returned, with [`Log::incomplete`] saying where it ends.
    pub fn read(path: &Path) -> Result<Self, String> {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let bad = |what: &str| format!("{}: {what}", path.display());
        if data.len() < 12 || &data[..8] != MAGIC {
            return Err(bad("not a HERB run log"));
        }
        let format = u32::from_le_bytes(data[8..12].try_into().unwrap());
        if format != FORMAT {
            return Err(bad(&format!(
                "run log format {format}, this build reads {FORMAT}"
            )));
        }
        let mut at = 12usize;
        let mut header = None;
        let mut log = Log {
            header: RunHeader {
                herbd: String::new(),
                cpu: String::new(),
                started_unix_s: 0,
                config_toml: String::new(),
                catalog: 0,
                policy: 0,
                sequence: 0,
                segment: 0,
            },
            snapshot: None,
            entries: Vec::new(),
            plan_frames: BTreeMap::new(),
            frames: HashMap::new(),
            incomplete: None,
        };
        let mut cycles = 0u64;
        while at < data.len() {
            let rest = &data[at..];
            if rest.len() < 9 {
                log.incomplete = Some(format!("torn record after cycle {cycles}"));
                break;
            }
            let k = rest[0];
            let len = u32::from_le_bytes(rest[1..5].try_into().unwrap()) as usize;
            if rest.len() < 9 + len {
                log.incomplete = Some(format!("torn record after cycle {cycles}"));
                break;
            }
            let payload = &rest[5..5 + len];
            let crc = u32::from_le_bytes(rest[5 + len..9 + len].try_into().unwrap());
            let mut h = crc32fast::Hasher::new();
            h.update(&rest[..5 + len]);
            if h.finalize() != crc {
                log.incomplete = Some(format!("corrupt record (CRC) after cycle {cycles}"));
                break;
            }
            at += 9 + len;
            let mut d = Dec(payload);
            let entry = match k {
                kind::HEADER => {
                    header = Some(RunHeader::decode(payload).ok_or_else(|| bad("bad header"))?);
                    None
                }
                kind::SNAPSHOT => {
                    log.snapshot =
                        Some(decode_snapshot(payload).ok_or_else(|| bad("bad snapshot"))?);
                    None
                }
                kind::CYCLE => {
                    cycles += 1;
                    d.u64().map(Entry::Cycle)
                }
                kind::JS => (|| Some(Entry::Js(d.u128()?, d.u64()?, d.payload()?)))(),
                kind::GS => (|| Some(Entry::Gs(d.u128()?, d.u64()?, d.payload()?)))(),
                kind::ARM => (|| Some(Entry::Arm(d.u128()?, d.u64()?, d.payload()?)))(),
                kind::FRAME => d.bytes().and_then(|b| b.try_into().ok()).map(Entry::Frame),
                kind::RESP => (|| {
                    Some(Entry::Resp(RespRec {
                        digest: d.u64()?,
                        decision_ns: d.u64()?,
                    }))
                })(),
                kind::JOB => d.payload().map(Entry::Job),
                kind::CANCEL => d.payload().map(Entry::Cancel),
                kind::TICK => (|| Some(Entry::Tick(d.bool()?, d.u64()?)))(),
                kind::GAP => {
                    let n = d.u64().unwrap_or(0);
                    log.incomplete = Some(format!(
                        "{n} records dropped after cycle {cycles} (the writer fell behind)"
                    ));
                    break;
                }
                kind::PLAN_FRAME => {
                    let (n, has, digest) = (
                        d.u64().ok_or_else(|| bad("bad plan frame"))?,
                        d.bool().ok_or_else(|| bad("bad plan frame"))?,
                        d.u64().ok_or_else(|| bad("bad plan frame"))?,
                    );
                    log.plan_frames.insert(n, has.then_some(digest));
                    None
                }
                kind::FRAME_CELLS => {
                    let digest = d.u64().ok_or_else(|| bad("bad frame"))?;
                    let f = d
                        .bytes()
                        .and_then(frame_from)
                        .ok_or_else(|| bad("bad frame"))?;
                    log.frames.insert(digest, f);
                    None
                }
                other => return Err(bad(&format!("unknown record kind {other}"))),
            };
            match (k, entry) {
                (kind::CYCLE..=kind::TICK, None) => {
                    return Err(bad(&format!("malformed record of kind {k}")));
                }
                (_, Some(e)) => log.entries.push(e),
                _ => {}
            }
        }
        log.header = header.ok_or_else(|| bad("no header"))?;
        Ok(log)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use herb_ipc::Header;

    fn js(seq: u64) -> JointState {
        JointState {
            header: Header::at(seq, 1000 + seq),
            position: [0.1 * seq as f64; DOF],
            velocity: [f64::from_bits(0x7ff8_0000_0000_0042); DOF],
        }
    }

    fn header() -> RunHeader {
        RunHeader {
            herbd: "test".into(),
            cpu: cpu_identity(),
            started_unix_s: 42,
            config_toml: "[loop]\nrate_hz = 1000.0\n".into(),
            catalog: 1,
            policy: 2,
            sequence: 3,
            segment: 0,
        }
    }

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("herb-record-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_recording_reads_back_record_for_record_and_bit_for_bit() {
        let d = dir("rt");
        let rec = start(
            RecordOptions {
                dir: d.clone(),
                segment_bytes: 1 << 30,
                keep_bytes: 1 << 30,
            },
            header(),
        )
        .unwrap();
        let Recording {
            mut recorder,
            frames,
            writer,
            stop,
        } = rec;
        let mut frame: Box<HeightmapFrame> =
            HeightmapFrame::from_bytes(&vec![0u8; std::mem::size_of::<HeightmapFrame>()])
                .unwrap()
                .into();
        frame.nx = 3;
        frame.ny = 2;
        frame.data[5] = 0.25;
        for i in 1..=50u64 {
            recorder.push(LoopRec::Cycle { now: i * 1000 });
            recorder.push(LoopRec::Js {
                publisher: 7,
                received: i,
                m: js(i),
            });
            recorder.push(LoopRec::Tick {
                stop: i == 50,
                digest: i * 3,
            });
        }
        recorder.push(LoopRec::Resp(RespRec {
            digest: 9,
            decision_ns: 400_000,
        }));
        frames(0, Some(&frame));
        frames(1, None);
        frames(2, Some(&frame));
        std::thread::sleep(Duration::from_millis(50));
        stop.store(true, Ordering::Relaxed);
        let files = writer.join().unwrap().unwrap();
        assert_eq!(files.len(), 1);
        let log = Log::read(&files[0]).unwrap();
        assert_eq!(log.header, header());
        assert!(log.incomplete.is_none());
        assert_eq!(log.entries.len(), 151);
        let Entry::Js(p, r, m) = log.entries[1] else {
            panic!("{:?}", log.entries[1])
        };
        assert_eq!((p, r), (7, 1));
        assert_eq!(m.as_bytes(), js(1).as_bytes(), "NaN payloads kept");
        assert!(matches!(log.entries[149], Entry::Tick(true, 150)));
        assert!(matches!(
            log.entries[150],
            Entry::Resp(RespRec {
                digest: 9,
                decision_ns: 400_000
            })
        ));
        // Frames: two requests served with the same frame, stored once.
        assert_eq!(log.frames.len(), 1);
        assert_eq!(log.plan_frames.get(&1), Some(&None));
        let f0 = log.plan_frames[&0].unwrap();
        assert_eq!(log.plan_frames[&2], Some(f0));
        assert_eq!(log.frames[&f0].cells(), frame.cells());

        // A torn tail: what comes before it is read, and the log says where it ends.
        let data = std::fs::read(&files[0]).unwrap();
        let torn = d.join("torn.log");
        std::fs::write(&torn, &data[..data.len() - 3]).unwrap();
        let log = Log::read(&torn).unwrap();
        assert!(log.incomplete.unwrap().contains("torn"));
        // A flipped bit: a CRC error.
        let mut bad = data.clone();
        let n = bad.len();
        bad[n - 30] ^= 1;
        std::fs::write(&torn, &bad).unwrap();
        assert!(
            Log::read(&torn)
                .unwrap()
                .incomplete
                .unwrap()
                .contains("CRC")
        );
        // Not a log.
        std::fs::write(&torn, b"hello").unwrap();
        assert!(Log::read(&torn).unwrap_err().contains("not a HERB run log"));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn segments_rotate_between_jobs_and_the_oldest_are_deleted() {
        let d = dir("rot");
        let Recording {
            mut recorder,
            writer,
            stop,
            ..
        } = start(
            RecordOptions {
                dir: d.clone(),
                segment_bytes: 20_000,
                keep_bytes: 50_000,
            },
            header(),
        )
        .unwrap();
        let cfg = crate::config::Config::default();
        let buf = || Box::new(crate::plan::MotionPlan::with_capacity(1));
        let params = crate::job::JobParams {
            timeouts: (&cfg.timeouts).into(),
            lower: cfg.limits.lower,
            upper: cfg.limits.upper,
            catalog_len: 24,
            grasp_retries: 1,
        };
        let snap = crate::job::Job::new(params, buf(), buf())
            .snapshot()
            .expect("idle");
        let mut rotations = 0;
        for i in 1..=2000u64 {
            recorder.push(LoopRec::Cycle { now: i });
            recorder.push(LoopRec::Js {
                publisher: 1,
                received: i,
                m: js(i),
            });
            if recorder.wants_snapshot() {
                recorder.snapshot(i, snap);
                rotations += 1;
            }
            if i % 100 == 0 {
                std::thread::sleep(Duration::from_millis(120));
            }
        }
        stop.store(true, Ordering::Relaxed);
        let files = writer.join().unwrap().unwrap();
        assert!(rotations >= 3, "{rotations}");
        let on_disk: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
        let closed: u64 = files[..files.len() - 1]
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        assert_eq!(on_disk.len(), files.len());
        assert!(on_disk.len() < rotations + 1, "old segments deleted");
        assert!(
            closed <= 50_000,
            "closed segments within keep_bytes: {closed}"
        );
        // A later segment starts from its snapshot.
        let last = Log::read(files.last().unwrap()).unwrap();
        let (before, s) = last.snapshot.expect("a snapshot");
        assert!(before > 0);
        assert_eq!(s, snap);
        assert!(last.header.segment >= 3);
        let _ = std::fs::remove_dir_all(&d);
    }
}
