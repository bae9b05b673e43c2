//! `herbd`'s control loop: one thread, a fixed period with absolute deadlines, and per cycle
//! drain inputs -> advance the job state machine ([`crate::job`]) -> publish its outputs.
//! This module is the shell around the pure machine: timing, ports and statistics.
//!
//! Nothing in a cycle allocates, blocks or formats text: inputs are read in place from shared
//! memory, work that allocates runs on the planner thread ([`crate::planner`]) and reaches the
//! loop as preallocated buffers over wait-free rings, statistics go into preallocated
//! histograms that are handed to the reporter thread by swapping boxes. The exceptions are
//! iceoryx2's own bookkeeping when a peer connects or disconnects, and the one `Arc` it
//! allocates per received pack-job request: events, not cycles.
//!
//! The job state machine, its faults and its guarantees are described in [`crate::job`].

use crate::config::Config;
use crate::decision::DecisionLink;
use crate::job::{Effects, Job, JobParams, JobRecord};
use crate::plan::{DecisionRequest, MotionPlan, Request};
use crate::planner::PlannerLink;
use crate::record::{DecisionRec, FRAME_META, LoopRec, OutDigest, Recorder, RespRec, Sent};
use hdrhistogram::Histogram;
use herb_ipc::bus::{Bus, CancelServer, ConfirmServer, JobServer, Pub, Sub};
use herb_ipc::{
    ArmStatus, CancelJobReply, CancelJobRequest, ConfirmPickReply, ConfirmPickRequest,
    GripperAction, GripperCommand, GripperState, Header, HeightmapFrame, JointCommand, JointState,
    PackJobReply, PackJobRequest, Payload, RejectReason, Status, StatusEvent, monotonic_ns,
};
use herb_process::rt::{ThreadCounters, set_timer_slack, sleep_until};
use herb_robot::motion::Setpoint;
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::prelude::ipc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Largest value the loop's histograms hold (ns): 10 s.
const HIST_MAX_NS: u64 = 10_000_000_000;
/// Significant digits kept by the loop's histograms.
const HIST_SIGFIG: u8 = 3;
/// Statistics boxes in flight between the loop and the reporter, each way.
const STATS_RING: usize = 4;
/// Emptied statistics boxes handed to the loop at start.
const STATS_SPARES: usize = 2;
/// Statuses the log's ring holds (events, not heartbeats) while the writer catches up.
const LOG_RING: usize = 4096;

/// Loop statistics for one reporting interval, in preallocated histograms (ns).
#[derive(Debug, Clone)]
pub struct LoopStats {
    /// Time from wake-up to the end of the cycle's work.
    pub cycle_ns: Histogram<u64>,
    /// Wake-up lateness relative to the deadline.
    pub jitter_ns: Histogram<u64>,
    /// Decision latency (one decision of the decision worker: a policy's `Decider::decide`
    /// call, or a search).
    pub decision_ns: Histogram<u64>,
    /// Time jobs that ended in the interval held objects at the lift pose waiting for their
    /// decisions (ms).
    pub decision_wait_ms: u64,
    /// Jobs that ended in the interval.
    pub jobs: u64,
    /// Deadlines missed (cycles skipped) in the interval.
    pub misses: u64,
    /// Cycles in the interval.
    pub cycles: u64,
    /// The interval's longest cycle, taken apart (where a slow cycle spent its time).
    pub slowest: SlowCycle,
}

/// One cycle's work taken apart: how long each stage took and what the loop thread met on
/// the way (page faults, blocking, preemption). Kept for the longest cycle of each interval.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SlowCycle {
    /// The cycle's number since start.
    pub cycle: u64,
    /// Its work, wake-up to end (ns).
    pub work_ns: u64,
    /// Its stages (ns): the sensor inputs read, the planner's and the decision worker's
    /// answers and the clients' requests handled, the job machine's tick with its outputs
    /// published, the journal and the statistics.
    pub stages_ns: [u64; 4],
    /// What the loop thread met during the cycle: page faults, voluntary context switches
    /// (it blocked: on a lock, on I/O) and involuntary ones (it was preempted).
    pub met: ThreadCounters,
}

impl SlowCycle {
    /// The names of [`SlowCycle::stages_ns`], in order.
    pub const STAGES: [&'static str; 4] = ["inputs", "answers_requests", "tick_publish", "journal"];
}

impl LoopStats {
    /// Empty statistics (values from 1 ns to 10 s at 3 significant digits; no resizing).
    pub fn new() -> Self {
        let h = || Histogram::new_with_bounds(1, HIST_MAX_NS, HIST_SIGFIG).expect("valid bounds");
        Self {
            cycle_ns: h(),
            jitter_ns: h(),
            decision_ns: h(),
            decision_wait_ms: 0,
            jobs: 0,
            misses: 0,
            cycles: 0,
            slowest: SlowCycle::default(),
        }
    }

    /// Empties every histogram and counter.
    pub fn reset(&mut self) {
        self.cycle_ns.reset();
        self.jitter_ns.reset();
        self.decision_ns.reset();
        self.decision_wait_ms = 0;
        self.jobs = 0;
        self.misses = 0;
        self.cycles = 0;
        self.slowest = SlowCycle::default();
    }

    /// Adds `other` into `self` (reporter thread).
    pub fn add(&mut self, other: &LoopStats) {
        let _ = self.cycle_ns.add(&other.cycle_ns);
        let _ = self.jitter_ns.add(&other.jitter_ns);
        let _ = self.decision_ns.add(&other.decision_ns);
        self.decision_wait_ms += other.decision_wait_ms;
        self.jobs += other.jobs;
        self.misses += other.misses;
        self.cycles += other.cycles;
        if other.slowest.work_ns > self.slowest.work_ns {
            self.slowest = other.slowest;
        }
    }
}

impl Default for LoopStats {
    fn default() -> Self {
        Self::new()
    }
}

/// Counters shared with other threads (atomics; the watchdog reads `cycles`).
#[derive(Debug, Default)]
pub struct Shared {
    /// Set by SIGINT/SIGTERM.
    pub stop: AtomicBool,
    /// Cycles run.
    pub cycles: AtomicU64,
    /// Status events the log could not take (its ring was full: the writer fell behind).
    pub log_dropped: AtomicU64,
}

/// The loop's IPC ports.
pub struct Ports {
    js: Sub<JointState>,
    gs: Sub<GripperState>,
    arm: Sub<ArmStatus>,
    hm: Sub<HeightmapFrame>,
    jobs: JobServer,
    cancel: CancelServer,
    confirm: ConfirmServer,
    out: OutPorts,
    _bus: Bus,
}

/// The loop's publishers.
struct OutPorts {
    cmd: Pub<JointCommand>,
    grip: Pub<GripperCommand>,
    status: Pub<Status>,
    /// Every status but heartbeats, to herbd's log writer (the reporter thread), which formats
    /// and writes them off the loop; `None` until [`Controller::new`] links it.
    log: Option<rtrb::Producer<Status>>,
}

impl Ports {
    /// Opens the loop's ports on `bus`.
    pub fn open(bus: Bus) -> Result<Self, herb_ipc::bus::BusError> {
        let s = bus.services().clone();
        Ok(Self {
            js: bus.subscriber(&s.joint_state())?,
            gs: bus.subscriber(&s.gripper_state())?,
            arm: bus.subscriber(&s.arm_status())?,
            hm: bus.subscriber(&s.heightmap())?,
            jobs: bus.job_server()?,
            cancel: bus.cancel_server()?,
            confirm: bus.confirm_server()?,
            out: OutPorts {
                cmd: bus.publisher(&s.joint_command())?,
                grip: bus.publisher(&s.gripper_command())?,
                status: bus.publisher(&s.status())?,
                log: None,
            },
            _bus: bus,
        })
    }
}

/// A pack-job request being answered.
type JobRequest = ActiveRequest<ipc::Service, PackJobRequest, (), PackJobReply, ()>;
/// A cancel request being answered.
type CancelRequest = ActiveRequest<ipc::Service, CancelJobRequest, (), CancelJobReply, ()>;
/// A pick confirmation being answered.
type ConfirmRequest = ActiveRequest<ipc::Service, ConfirmPickRequest, (), ConfirmPickReply, ()>;

/// The loop's counters reported in every status.
#[derive(Debug, Clone, Copy, Default)]
struct LoopCounters {
    cycles: u64,
    misses: u64,
    max_cycle: u64,
}

/// The machine's outputs for one cycle, published as they come: one sequence counter in call
/// order, every header stamped with the cycle's start.
struct Outbox<'a> {
    now: u64,
    seq: &'a mut u64,
    ports: &'a mut OutPorts,
    planner: &'a mut PlannerLink,
    decider: &'a mut DecisionLink,
    decision_ns: &'a mut Histogram<u64>,
    decision_wait_ms: &'a mut u64,
    jobs: &'a mut u64,
    counters: LoopCounters,
    request: Option<JobRequest>,
    cancel: Option<CancelRequest>,
    confirm: Option<ConfirmRequest>,
    /// Digest of the machine's outputs this cycle (run log).
    digest: OutDigest,
    /// Planner and decision requests handed over so far.
    sent: &'a mut Sent,
    /// Statuses the log ring could not take this cycle.
    log_dropped: u64,
}

impl<'a> Outbox<'a> {
    #[allow(clippy::too_many_arguments)]
    fn new(
        now: u64,
        seq: &'a mut u64,
        ports: &'a mut OutPorts,
        planner: &'a mut PlannerLink,
        decider: &'a mut DecisionLink,
        stats: &'a mut LoopStats,
        counters: LoopCounters,
        sent: &'a mut Sent,
    ) -> Self {
        Self {
            now,
            seq,
            ports,
            planner,
            decider,
            decision_ns: &mut stats.decision_ns,
            decision_wait_ms: &mut stats.decision_wait_ms,
            jobs: &mut stats.jobs,
            counters,
            request: None,
            cancel: None,
            confirm: None,
            digest: OutDigest::new(),
            sent,
            log_dropped: 0,
        }
    }

    fn header(&mut self) -> Header {
        *self.seq += 1;
        Header::at(*self.seq, self.now)
    }
}

impl Effects for Outbox<'_> {
    fn reply(&mut self, job_id: u64, reason: RejectReason, detail: u32) {
        self.digest.reply(job_id, reason, detail);
        let header = self.header();
        if let Some(req) = &self.request {
            let _ = req.send_copy(PackJobReply {
                header,
                job_id,
                accepted: (reason == RejectReason::None) as u32,
                reason: reason as u32,
                detail,
                reserved: 0,
            });
        }
    }

    fn cancel_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.digest.cancel_reply(job_id, reason);
        let header = self.header();
        if let Some(req) = &self.cancel {
            let _ = req.send_copy(CancelJobReply {
                header,
                job_id,
                accepted: (reason == RejectReason::None) as u32,
                reason: reason as u32,
            });
        }
    }

    fn confirm_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.digest.confirm_reply(job_id, reason);
        let header = self.header();
        if let Some(req) = &self.confirm {
            let _ = req.send_copy(ConfirmPickReply {
                header,
                job_id,
                accepted: (reason == RejectReason::None) as u32,
                reason: reason as u32,
            });
        }
    }

    fn status(&mut self, status: &Status) {
        self.digest.status(status);
        let mut s = *status;
        s.header = self.header();
        s.cycles = self.counters.cycles;
        s.deadline_misses = self.counters.misses;
        s.max_cycle_ns = self.counters.max_cycle;
        s.rejected_inputs += self.decider.rejected_frames();
        if s.event == StatusEvent::Decided as u32 && s.decision_ns > 0 {
            self.decision_ns.saturating_record(s.decision_ns);
        }
        if matches!(
            StatusEvent::from_code(s.event),
            Some(StatusEvent::JobDone | StatusEvent::JobFailed | StatusEvent::JobCancelled)
        ) {
            *self.jobs += 1;
            *self.decision_wait_ms += s.decision_wait_ms as u64;
        }
        let _ = self.ports.status.send_copy(s);
        if s.event != StatusEvent::Heartbeat as u32
            && let Some(log) = &mut self.ports.log
            && log.push(s).is_err()
        {
            self.log_dropped += 1;
        }
    }

    fn joint(&mut self, c: &Setpoint) {
        self.digest.joint(c);
        let header = self.header();
        let _ = self.ports.cmd.send_copy(JointCommand {
            header,
            position: c.position,
            velocity: c.velocity,
            acceleration: c.acceleration,
        });
    }

    fn gripper(&mut self, job_id: u64, action: GripperAction, object_type: u32) {
        self.digest.gripper(job_id, action, object_type);
        let header = self.header();
        let _ = self.ports.grip.send_copy(GripperCommand {
            header,
            job_id,
            action: action as u32,
            object_type,
        });
    }

    fn plan(&mut self, request: Request) -> Result<(), Request> {
        self.digest.request(&request);
        self.planner.send(request)?;
        self.sent.requests += 1;
        Ok(())
    }

    fn decide(&mut self, request: DecisionRequest) -> Result<(), DecisionRequest> {
        self.digest.decision_request(&request);
        self.decider.send(request)?;
        self.sent.decisions += 1;
        Ok(())
    }
}

/// The loop. Built once; [`Controller::run`] then never allocates.
pub struct Controller {
    ports: Ports,
    planner: PlannerLink,
    decider: DecisionLink,
    shared: Arc<Shared>,
    stats: Box<LoopStats>,
    stats_tx: rtrb::Producer<Box<LoopStats>>,
    stats_rx: rtrb::Consumer<Box<LoopStats>>,
    job: Job,
    period_ns: u64,
    spin_ns: u64,
    report_every: u64,
    seq: u64,
    counters: LoopCounters,
    /// The run log's loop end, if recording.
    recorder: Option<Recorder>,
    /// Planner and decision requests sent and responses received (a new run-log segment
    /// starts only when none is outstanding).
    sent: Sent,
    received: Sent,
    /// The job journal's writer ring, if journaling ([`crate::journal`]).
    journal: Option<rtrb::Producer<JobRecord>>,
    /// The last record handed to the writer.
    journaled: JobRecord,
    /// When each stage of the current cycle ended ([`SlowCycle::stages_ns`]).
    marks: [u64; 4],
}

/// The reporter's ends of the statistics rings, and of the log's.
pub struct StatsLink {
    /// Full statistics from the loop.
    pub rx: rtrb::Consumer<Box<LoopStats>>,
    /// Emptied statistics back to the loop.
    pub tx: rtrb::Producer<Box<LoopStats>>,
    /// Every status but heartbeats, in order, to be logged.
    pub events: rtrb::Consumer<Status>,
}

impl Controller {
    /// Builds the loop: the job machine with two trajectory buffers for `max_trajectory_s`,
    /// statistics rings.
    pub fn new(
        cfg: &Config,
        ports: Ports,
        planner: PlannerLink,
        decider: DecisionLink,
        shared: Arc<Shared>,
        catalog_len: usize,
    ) -> (Self, StatsLink) {
        let samples = cfg.trajectory_samples();
        let (stats_tx, r_rx) = rtrb::RingBuffer::new(STATS_RING);
        let (mut r_tx, stats_rx) = rtrb::RingBuffer::new(STATS_RING);
        // Spare statistics boxes for the swap, allocated now.
        for _ in 0..STATS_SPARES {
            let _ = r_tx.push(Box::new(LoopStats::new()));
        }
        let params = JobParams::from_config(cfg, catalog_len);
        let buffer = || Box::new(MotionPlan::with_capacity(samples));
        // The log's ring: a few hundred events' headroom (a job makes a few per object).
        let (log_tx, events) = rtrb::RingBuffer::new(LOG_RING);
        let mut ports = ports;
        ports.out.log = Some(log_tx);
        let c = Self {
            ports,
            planner,
            decider,
            shared,
            stats: Box::new(LoopStats::new()),
            stats_tx,
            stats_rx,
            job: Job::new(params, buffer(), buffer()),
            period_ns: cfg.period_ns(),
            spin_ns: cfg.loop_.spin_us * 1000,
            report_every: (cfg.loop_.report_interval_s * cfg.loop_.rate_hz).round() as u64,
            seq: 0,
            counters: LoopCounters::default(),
            recorder: None,
            sent: Sent::default(),
            received: Sent::default(),
            journal: None,
            journaled: JobRecord::NONE,
            marks: [0; 4],
        };
        (
            c,
            StatsLink {
                rx: r_rx,
                tx: r_tx,
                events,
            },
        )
    }

    /// Records every input of the machine, and a digest of its outputs per cycle, to a run
    /// log ([`crate::record`]).
    pub fn with_recorder(mut self, r: Recorder) -> Self {
        self.recorder = Some(r);
        self
    }

    /// Hands every change of the job's journal record to `writer` ([`crate::journal::spawn`]).
    pub fn with_journal(mut self, writer: rtrb::Producer<JobRecord>) -> Self {
        self.journal = Some(writer);
        self
    }

    /// Takes up an unfinished job from the journal before the loop runs, to resume it or, with
    /// `resume` false, to end it ([`Job::recover`]).
    pub fn recover(&mut self, r: &JobRecord, resume: bool) {
        self.job.recover(r, resume);
        self.journaled = *r;
    }

    /// Runs until a stop is requested and the arm stands still; returns the statistics of
    /// the last, unreported interval.
    pub fn run(mut self) -> Box<LoopStats> {
        set_timer_slack();
        let mut next = monotonic_ns() + self.period_ns;
        loop {
            sleep_until(next, self.spin_ns);
            let wake = monotonic_ns();
            let met = ThreadCounters::now();
            self.stats
                .jitter_ns
                .saturating_record(wake.saturating_sub(next).max(1));
            let finished = self.cycle(wake);
            let end = monotonic_ns();
            let work = end.saturating_sub(wake);
            self.stats.cycle_ns.saturating_record(work.max(1));
            if work > self.stats.slowest.work_ns {
                let mut at = wake;
                let stages_ns = self.marks.map(|m| {
                    let d = m.saturating_sub(at);
                    at = at.max(m);
                    d
                });
                self.stats.slowest = SlowCycle {
                    cycle: self.counters.cycles,
                    work_ns: work,
                    stages_ns,
                    met: ThreadCounters::now().since(met),
                };
            }
            self.counters.max_cycle = self.counters.max_cycle.max(work);
            self.counters.cycles += 1;
            self.stats.cycles += 1;
            self.shared
                .cycles
                .store(self.counters.cycles, Ordering::Relaxed);
            if finished {
                let status = self.job.status(StatusEvent::Shutdown);
                Outbox::new(
                    end,
                    &mut self.seq,
                    &mut self.ports.out,
                    &mut self.planner,
                    &mut self.decider,
                    &mut self.stats,
                    self.counters,
                    &mut self.sent,
                )
                .status(&status);
                return self.stats;
            }
            next += self.period_ns;
            if end > next {
                // Overrun: skip the deadlines already passed, never burst to catch up.
                let missed = (end - next) / self.period_ns + 1;
                self.counters.misses += missed;
                self.stats.misses += missed;
                next += missed * self.period_ns;
            }
            if self.counters.cycles.is_multiple_of(self.report_every) {
                self.swap_stats();
            }
        }
    }

    fn swap_stats(&mut self) {
        if let Ok(fresh) = self.stats_rx.pop() {
            let full = std::mem::replace(&mut self.stats, fresh);
            if let Err(rtrb::PushError::Full(full)) = self.stats_tx.push(full) {
                // Reporter behind: keep accumulating into the same box.
                self.stats = full;
            }
        }
    }

    /// One cycle: feed the machine everything that arrived, in the order documented in
    /// [`crate::job`]; true when the daemon may exit.
    fn cycle(&mut self, now: u64) -> bool {
        if let Some(r) = &mut self.recorder
            && r.wants_snapshot()
            && self.sent == self.received
            && let Some(s) = self.job.snapshot()
        {
            // Between jobs, nothing at the planner: a new segment may start here.
            r.snapshot(self.sent, s);
        }
        let job = &mut self.job;
        let p = &mut self.ports;
        let rec = &mut self.recorder;
        let mut log = |r: LoopRec| {
            if let Some(rec) = rec.as_mut() {
                rec.push(r);
            }
        };
        log(LoopRec::Cycle { now });
        // States are read in place; the clock read after each tells a preempted loop's
        // late sample from one stamped in the future.
        while let Ok(Some(s)) = p.js.receive() {
            let (publisher, received) = (s.header().publisher_id().value(), monotonic_ns());
            let m = s.payload();
            log(LoopRec::Js {
                publisher,
                received,
                m: *m,
            });
            job.joint_state(publisher, m, now, received);
        }
        while let Ok(Some(s)) = p.gs.receive() {
            let (publisher, received) = (s.header().publisher_id().value(), monotonic_ns());
            let m = s.payload();
            log(LoopRec::Gs {
                publisher,
                received,
                m: *m,
            });
            job.gripper_state(publisher, m, now, received);
        }
        while let Ok(Some(s)) = p.arm.receive() {
            let (publisher, received) = (s.header().publisher_id().value(), monotonic_ns());
            let m = s.payload();
            log(LoopRec::Arm {
                publisher,
                received,
                m: *m,
            });
            job.arm_status(publisher, m, now, received);
        }
        while let Ok(Some(s)) = p.hm.receive() {
            let f = s.payload();
            if let Ok(meta) = f.as_bytes()[..FRAME_META].try_into() {
                log(LoopRec::Frame(meta));
            }
            job.heightmap(f, now);
        }
        self.marks[0] = monotonic_ns();
        let mut fx = Outbox::new(
            now,
            &mut self.seq,
            &mut p.out,
            &mut self.planner,
            &mut self.decider,
            &mut self.stats,
            self.counters,
            &mut self.sent,
        );
        while let Ok(resp) = fx.planner.rx.pop() {
            self.received.requests += 1;
            log(LoopRec::Resp(RespRec {
                digest: resp.digest(),
            }));
            job.planner_response(resp, now, &mut fx);
        }
        while let Ok(d) = fx.decider.rx.pop() {
            self.received.decisions += 1;
            log(LoopRec::Decision(DecisionRec {
                digest: d.digest(),
                allowed: d.allowed,
                decision_ns: d.decision_ns,
            }));
            job.decision_response(d, now, &mut fx);
        }
        while let Ok(Some(req)) = p.jobs.receive() {
            let r = *req.payload();
            log(LoopRec::Job(r));
            fx.request = Some(req);
            job.job_request(&r, now, &mut fx);
            fx.request = None;
        }
        while let Ok(Some(req)) = p.cancel.receive() {
            let r = *req.payload();
            log(LoopRec::Cancel(r));
            fx.cancel = Some(req);
            job.cancel_request(&r, &mut fx);
            fx.cancel = None;
        }
        while let Ok(Some(req)) = p.confirm.receive() {
            let r = *req.payload();
            log(LoopRec::Confirm(r));
            fx.confirm = Some(req);
            job.confirm_request(&r, &mut fx);
            fx.confirm = None;
        }
        self.marks[1] = monotonic_ns();
        let stop = self.shared.stop.load(Ordering::Relaxed);
        let finished = job.tick(now, stop, &mut fx);
        log(LoopRec::Tick {
            stop,
            digest: fx.digest.finish(),
        });
        self.marks[2] = monotonic_ns();
        if fx.log_dropped > 0 {
            self.shared
                .log_dropped
                .fetch_add(fx.log_dropped, Ordering::Relaxed);
        }
        if let Some(tx) = &mut self.journal {
            // A full ring (the writer is behind) is retried next cycle.
            let r = job.journal();
            if r != self.journaled && tx.push(r).is_ok() {
                self.journaled = r;
            }
        }
        self.marks[3] = monotonic_ns();
        finished
    }
}
