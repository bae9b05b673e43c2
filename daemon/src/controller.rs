//! `herbd`'s control loop: one thread, a fixed period with absolute deadlines, and per cycle
//! drain inputs -> advance the job state machine -> publish commands.
//!
//! Nothing in a cycle allocates, blocks or formats text: inputs are read in place from shared
//! memory, work that allocates runs on the planner thread ([`crate::planner`]) and reaches the
//! loop as preallocated buffers over wait-free rings, statistics go into preallocated
//! histograms that are handed to the reporter thread by swapping boxes. The exceptions are
//! iceoryx2's own bookkeeping when a peer connects or disconnects, and the one `Arc` it
//! allocates per received pack-job request: events, not cycles.
//!
//! # Job state machine, per object
//!
//! wait for a heightmap stamped after the last release -> planner decides and plans
//! (Beam-3 order at job start; policy; z; waypoints; IK; Ruckig) -> stream the samples, one per
//! cycle -> at the grasp, close the gripper and wait until it holds -> stream -> at the
//! placement, open and wait -> report -> retreat -> next object.
//!
//! # Faults
//!
//! Joint states, gripper states or heightmaps older than their timeouts are a fault: a moving
//! arm brakes (a Ruckig brake from the last commanded state), a status reports the fault, and
//! the job holds. When every input has been fresh for `resume_after_s`, the job resumes from
//! the measured configuration: an object still held is placed, an object lost from the
//! gripper (the adapter restarted) is picked again, otherwise the current object starts over.
//! A second job while one runs is rejected (`Busy`), not queued: a client resubmits.
//! No joint command leaves the configured limits: every sample is checked before it is
//! published, and one outside is replaced by holding the last command (counted).

use crate::config::Config;
use crate::planner::{MotionPlan, PlannerLink, Request, Response};
use hdrhistogram::Histogram;
use herb_ipc::bus::{Bus, JobServer, Pub, Sub};
use herb_ipc::{
    Fault, GripperAction, GripperCommand, GripperState, Header, HeightmapFrame, InOrder, JobState,
    JointCommand, JointState, MAX_JOB_OBJECTS, NO_OBJECT, PackJobReply, RejectReason, Status,
    StatusEvent, monotonic_ns,
};
use herb_robot::kinematics::DOF;
use herb_robot::motion::Setpoint;
use herb_robot::rt::{set_timer_slack, sleep_until};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Loop statistics for one reporting interval, in preallocated histograms (ns).
#[derive(Debug, Clone)]
pub struct LoopStats {
    /// Time from wake-up to the end of the cycle's work.
    pub cycle_ns: Histogram<u64>,
    /// Wake-up lateness relative to the deadline.
    pub jitter_ns: Histogram<u64>,
    /// Decision latency (one `herb_decide::Decider::decide` call).
    pub decision_ns: Histogram<u64>,
    /// Deadlines missed (cycles skipped) in the interval.
    pub misses: u64,
    /// Cycles in the interval.
    pub cycles: u64,
}

impl LoopStats {
    /// Empty statistics (values from 1 ns to 10 s at 3 significant digits; no resizing).
    pub fn new() -> Self {
        let h = || Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("valid bounds");
        Self {
            cycle_ns: h(),
            jitter_ns: h(),
            decision_ns: h(),
            misses: 0,
            cycles: 0,
        }
    }

    /// Empties every histogram and counter.
    pub fn reset(&mut self) {
        self.cycle_ns.reset();
        self.jitter_ns.reset();
        self.decision_ns.reset();
        self.misses = 0;
        self.cycles = 0;
    }

    /// Adds `other` into `self` (reporter thread).
    pub fn add(&mut self, other: &LoopStats) {
        let _ = self.cycle_ns.add(&other.cycle_ns);
        let _ = self.jitter_ns.add(&other.jitter_ns);
        let _ = self.decision_ns.add(&other.decision_ns);
        self.misses += other.misses;
        self.cycles += other.cycles;
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
}

/// The loop's IPC ports.
pub struct Ports {
    js: Sub<JointState>,
    gs: Sub<GripperState>,
    hm: Sub<HeightmapFrame>,
    jobs: JobServer,
    cmd: Pub<JointCommand>,
    grip: Pub<GripperCommand>,
    status: Pub<Status>,
    _bus: Bus,
}

impl Ports {
    /// Opens the loop's ports on `bus`.
    pub fn open(bus: Bus) -> Result<Self, herb_ipc::bus::BusError> {
        let s = bus.services().clone();
        Ok(Self {
            js: bus.subscriber(&s.joint_state())?,
            gs: bus.subscriber(&s.gripper_state())?,
            hm: bus.subscriber(&s.heightmap())?,
            jobs: bus.job_server()?,
            cmd: bus.publisher(&s.joint_command())?,
            grip: bus.publisher(&s.gripper_command())?,
            status: bus.publisher(&s.status())?,
            _bus: bus,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    Ordering,
    WaitHeightmap {
        since: u64,
    },
    Planning,
    Streaming {
        seg: usize,
        cursor: usize,
    },
    Gripper {
        action: GripperAction,
        seg: usize,
        since: u64,
    },
    /// Braking: `cursor` into the brake buffer once it arrived (`None` while it is computed).
    Braking {
        cursor: Option<usize>,
        seg: usize,
        active_cursor: usize,
    },
    Faulted {
        healthy_since: Option<u64>,
    },
}

/// Timeouts in ns.
#[derive(Debug, Clone, Copy)]
struct Limits {
    js: u64,
    gs: u64,
    hm: u64,
    grip: u64,
    resume: u64,
    fresh_hm: u64,
}

fn ns(s: f64) -> u64 {
    (s * 1e9) as u64
}

/// The loop's state. Built once; [`Controller::run`] then never allocates.
pub struct Controller {
    ports: Ports,
    planner: PlannerLink,
    shared: Arc<Shared>,
    stats: Box<LoopStats>,
    stats_tx: rtrb::Producer<Box<LoopStats>>,
    stats_rx: rtrb::Consumer<Box<LoopStats>>,
    lim: Limits,
    lower: [f64; DOF],
    upper: [f64; DOF],
    catalog_len: usize,
    period_ns: u64,
    spin_ns: u64,
    report_every: u64,
    // inputs
    js: Option<JointState>,
    js_at: u64,
    /// Order of the joint states (per publisher: sequence and stamp grow).
    js_order: InOrder,
    /// Order of the gripper states.
    gs_order: InOrder,
    gs: Option<GripperState>,
    gs_at: u64,
    hm_rx_at: u64,
    hm_stamp: u64,
    rejected: u64,
    // job
    phase: Phase,
    job_id: u64,
    order: [u16; MAX_JOB_OBJECTS],
    count: usize,
    index: usize,
    done: usize,
    release_stamp: u64,
    holding: bool,
    fault: Fault,
    active: Option<Box<MotionPlan>>,
    spare: Option<Box<MotionPlan>>,
    brake: Option<Box<MotionPlan>>,
    cmd: Setpoint,
    commanding: bool,
    grip_cmd: GripperAction,
    grip_object: u32,
    grip_sent_at: u64,
    // output
    seq: u64,
    last_heartbeat: u64,
    cycles: u64,
    misses: u64,
    max_cycle: u64,
    limit_holds: u64,
    stopping: bool,
}

/// The reporter's ends of the statistics rings.
pub struct StatsLink {
    /// Full statistics from the loop.
    pub rx: rtrb::Consumer<Box<LoopStats>>,
    /// Emptied statistics back to the loop.
    pub tx: rtrb::Producer<Box<LoopStats>>,
}

/// A stamp is not from the future when it is at most 1 ms past the cycle's start `now`, or, if
/// the loop was preempted since, not past the clock when read (read only in that case).
fn not_from_the_future(stamp_ns: u64, now: u64) -> bool {
    stamp_ns <= now + 1_000_000 || stamp_ns <= monotonic_ns()
}

impl Controller {
    /// Builds the loop: two trajectory buffers for `max_trajectory_s`, statistics rings.
    pub fn new(
        cfg: &Config,
        ports: Ports,
        planner: PlannerLink,
        shared: Arc<Shared>,
        catalog_len: usize,
    ) -> (Self, StatsLink) {
        let t = &cfg.timeouts;
        let period_ns = ns(cfg.period_s());
        let samples = (cfg.loop_.max_trajectory_s * cfg.loop_.rate_hz).ceil() as usize;
        let (stats_tx, r_rx) = rtrb::RingBuffer::new(4);
        let (mut r_tx, stats_rx) = rtrb::RingBuffer::new(4);
        // Spare statistics boxes for the swap, allocated now.
        for _ in 0..2 {
            let _ = r_tx.push(Box::new(LoopStats::new()));
        }
        let c = Self {
            ports,
            planner,
            shared,
            stats: Box::new(LoopStats::new()),
            stats_tx,
            stats_rx,
            lim: Limits {
                js: ns(t.joint_state_s),
                gs: ns(t.gripper_state_s),
                hm: ns(t.heightmap_s),
                grip: ns(t.gripper_action_s),
                resume: ns(t.resume_after_s),
                fresh_hm: ns(t.fresh_heightmap_s),
            },
            lower: cfg.limits.lower,
            upper: cfg.limits.upper,
            catalog_len,
            period_ns,
            spin_ns: cfg.loop_.spin_us * 1000,
            report_every: (cfg.loop_.report_interval_s * cfg.loop_.rate_hz).round() as u64,
            js: None,
            js_at: 0,
            js_order: InOrder::default(),
            gs_order: InOrder::default(),
            gs: None,
            gs_at: 0,
            hm_rx_at: 0,
            hm_stamp: 0,
            rejected: 0,
            phase: Phase::Idle,
            job_id: 0,
            order: [0; MAX_JOB_OBJECTS],
            count: 0,
            index: 0,
            done: 0,
            release_stamp: 0,
            holding: false,
            fault: Fault::None,
            active: Some(Box::new(MotionPlan::with_capacity(samples))),
            spare: Some(Box::new(MotionPlan::with_capacity(samples))),
            brake: None,
            cmd: Setpoint::default(),
            commanding: false,
            grip_cmd: GripperAction::Open,
            grip_object: NO_OBJECT,
            grip_sent_at: 0,
            seq: 0,
            last_heartbeat: 0,
            cycles: 0,
            misses: 0,
            max_cycle: 0,
            limit_holds: 0,
            stopping: false,
        };
        (c, StatsLink { rx: r_rx, tx: r_tx })
    }

    /// Runs until a stop is requested and the arm stands still; returns the statistics of
    /// the last, unreported interval.
    pub fn run(mut self) -> Box<LoopStats> {
        set_timer_slack();
        let mut next = monotonic_ns() + self.period_ns;
        loop {
            sleep_until(next, self.spin_ns);
            let wake = monotonic_ns();
            self.stats
                .jitter_ns
                .saturating_record(wake.saturating_sub(next).max(1));
            let finished = self.cycle(wake);
            let end = monotonic_ns();
            let work = end.saturating_sub(wake);
            self.stats.cycle_ns.saturating_record(work.max(1));
            self.max_cycle = self.max_cycle.max(work);
            self.cycles += 1;
            self.stats.cycles += 1;
            self.shared.cycles.store(self.cycles, Ordering::Relaxed);
            if finished {
                self.emit(StatusEvent::Shutdown, NO_OBJECT, [0.0; 4], 0);
                return self.stats;
            }
            next += self.period_ns;
            if end > next {
                // Overrun: skip the deadlines already passed, never burst to catch up.
                let missed = (end - next) / self.period_ns + 1;
                self.misses += missed;
                self.stats.misses += missed;
                next += missed * self.period_ns;
            }
            if self.cycles.is_multiple_of(self.report_every) {
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

    /// One cycle; true when the daemon may exit.
    fn cycle(&mut self, now: u64) -> bool {
        self.drain_inputs(now);
        self.poll_planner(now);
        self.serve_jobs(now);
        if self.shared.stop.load(Ordering::Relaxed) && !self.stopping {
            self.stopping = true;
            self.begin_stop();
        }
        self.check_health(now);
        self.step(now);
        self.publish(now);
        self.stopping && !matches!(self.phase, Phase::Braking { .. })
    }

    fn drain_inputs(&mut self, now: u64) {
        // Valid, not from the future, and after the publisher's last accepted sample.
        while let Ok(Some(s)) = self.ports.js.receive() {
            let m = *s.payload();
            let origin = s.header().publisher_id().value();
            match m.validate() {
                Ok(())
                    if not_from_the_future(m.header.stamp_ns, now)
                        && self.js_order.accept(origin, &m.header) =>
                {
                    self.js = Some(m);
                    self.js_at = m.header.stamp_ns;
                }
                _ => self.rejected += 1,
            }
        }
        while let Ok(Some(s)) = self.ports.gs.receive() {
            let m = *s.payload();
            let origin = s.header().publisher_id().value();
            match m.validate() {
                Ok(())
                    if not_from_the_future(m.header.stamp_ns, now)
                        && self.gs_order.accept(origin, &m.header) =>
                {
                    self.gs = Some(m);
                    self.gs_at = m.header.stamp_ns;
                }
                _ => self.rejected += 1,
            }
        }
        while let Ok(Some(s)) = self.ports.hm.receive() {
            // In place: only the header and grid size are read here.
            let f = s.payload();
            match f.validate_meta() {
                Ok(()) => {
                    self.hm_rx_at = now;
                    self.hm_stamp = self.hm_stamp.max(f.header.stamp_ns);
                }
                Err(_) => self.rejected += 1,
            }
        }
    }

    fn serve_jobs(&mut self, now: u64) {
        while let Ok(Some(req)) = self.ports.jobs.receive() {
            let r = *req.payload();
            // A malformed request is answered with what is wrong with it, whatever the state.
            let verdict = r.validate(self.catalog_len).and_then(|()| {
                if self.stopping {
                    Err((RejectReason::ShuttingDown, 0))
                } else if self.phase != Phase::Idle {
                    Err((RejectReason::Busy, 0))
                } else if !self.inputs_fresh(now) {
                    Err((RejectReason::NotReady, 0))
                } else {
                    Ok(())
                }
            });
            if verdict.is_err() {
                self.rejected += 1;
            }
            self.seq += 1;
            let (reason, detail) = verdict.err().unwrap_or((RejectReason::None, 0));
            let _ = req.send_copy(PackJobReply {
                header: Header::now(self.seq),
                job_id: r.job_id,
                accepted: (reason == RejectReason::None) as u32,
                reason: reason as u32,
                detail,
                reserved: 0,
            });
            if reason == RejectReason::None {
                self.start_job(&r);
            }
        }
    }

    fn start_job(&mut self, r: &herb_ipc::PackJobRequest) {
        let n = r.objects().len();
        let mut objects = [0u16; MAX_JOB_OBJECTS];
        objects[..n].copy_from_slice(r.objects());
        self.job_id = r.job_id;
        self.count = n;
        self.index = 0;
        self.done = 0;
        self.fault = Fault::None;
        self.holding = self.gs.is_some_and(|g| g.holding == 1);
        self.release_stamp = 0;
        let q = self.js.map(|j| j.position).unwrap_or_default();
        self.cmd = Setpoint::at_rest(q);
        self.commanding = true;
        let _ = self.planner.send(Request::Order {
            job_id: r.job_id,
            objects,
            count: n,
        });
        self.phase = Phase::Ordering;
        self.emit(StatusEvent::Accepted, NO_OBJECT, [0.0; 4], 0);
    }

    fn inputs_fresh(&self, now: u64) -> bool {
        self.js.is_some() && self.gs.is_some() && self.stale_input(now).is_none()
    }

    fn stale_input(&self, now: u64) -> Option<Fault> {
        if now.saturating_sub(self.js_at) >= self.lim.js {
            Some(Fault::JointStateTimeout)
        } else if now.saturating_sub(self.gs_at) >= self.lim.gs {
            Some(Fault::GripperStateTimeout)
        } else if now.saturating_sub(self.hm_rx_at) >= self.lim.hm {
            Some(Fault::HeightmapTimeout)
        } else {
            None
        }
    }

    fn check_health(&mut self, now: u64) {
        match self.phase {
            Phase::Idle | Phase::Braking { .. } | Phase::Faulted { .. } => {}
            _ => {
                if let Some(f) = self.stale_input(now) {
                    self.raise(f);
                }
            }
        }
    }

    /// A fault: brake if moving, report, hold.
    fn raise(&mut self, fault: Fault) {
        self.fault = fault;
        self.emit(StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
        self.begin_brake();
    }

    fn begin_brake(&mut self) {
        let moving = self.cmd.velocity.iter().any(|v| *v != 0.0)
            || self.cmd.acceleration.iter().any(|a| *a != 0.0);
        let (seg, cursor) = match self.phase {
            Phase::Streaming { seg, cursor } => (seg, cursor),
            _ => (0, 0),
        };
        if moving && let Some(buf) = self.spare.take() {
            match self.planner.send(Request::Brake {
                state: self.cmd,
                buf,
            }) {
                Ok(()) => {
                    self.phase = Phase::Braking {
                        cursor: None,
                        seg,
                        active_cursor: cursor,
                    };
                    return;
                }
                Err(Request::Brake { buf, .. }) => self.spare = Some(buf),
                Err(_) => {}
            }
        }
        self.enter_faulted();
    }

    fn enter_faulted(&mut self) {
        self.cmd.velocity = [0.0; DOF];
        self.cmd.acceleration = [0.0; DOF];
        self.phase = Phase::Faulted {
            healthy_since: None,
        };
        self.emit(StatusEvent::Braked, self.current_type(), [0.0; 4], 0);
    }

    fn begin_stop(&mut self) {
        match self.phase {
            Phase::Streaming { .. } => {
                self.fault = Fault::Stop;
                self.begin_brake();
            }
            Phase::Braking { .. } => {}
            _ => self.enter_faulted(),
        }
    }

    fn current_type(&self) -> u32 {
        if self.index < self.count {
            self.order[self.index] as u32
        } else {
            NO_OBJECT
        }
    }

    fn recycle(&mut self, buf: Box<MotionPlan>) {
        if self.spare.is_none() {
            self.spare = Some(buf);
        } else if self.active.is_none() {
            self.active = Some(buf);
        } else {
            self.brake = Some(buf);
        }
    }

    fn poll_planner(&mut self, now: u64) {
        while let Ok(resp) = self.planner.rx.pop() {
            match resp {
                Response::Ordered {
                    job_id,
                    order,
                    count,
                } if job_id == self.job_id => {
                    self.order = order;
                    self.count = count;
                    if self.phase == Phase::Ordering {
                        self.phase = Phase::WaitHeightmap { since: now };
                    }
                }
                Response::Ordered { .. } => {}
                Response::OrderFailed { .. } => {
                    self.fault = Fault::Decision;
                    self.finish(false);
                }
                Response::Planned(plan) => {
                    if self.phase == Phase::Planning && !self.stopping {
                        if let Some(old) = self.active.take() {
                            self.recycle(old);
                        }
                        if plan.decision_ns > 0 {
                            self.stats.decision_ns.saturating_record(plan.decision_ns);
                        }
                        let (ty, pose, dns) = (plan.object as u32, plan.pose, plan.decision_ns);
                        self.active = Some(plan);
                        self.phase = Phase::Streaming { seg: 0, cursor: 0 };
                        // A replan of a decided placement (after a resume while holding the
                        // object) carries no new decision and is not announced again.
                        if dns > 0 {
                            self.emit(StatusEvent::Decided, ty, pose, dns);
                        }
                    } else {
                        self.recycle(plan);
                    }
                }
                Response::Braked(buf) => {
                    if let Phase::Braking {
                        seg, active_cursor, ..
                    } = self.phase
                    {
                        self.brake = Some(buf);
                        self.phase = Phase::Braking {
                            cursor: Some(0),
                            seg,
                            active_cursor,
                        };
                    } else {
                        self.recycle(buf);
                    }
                }
                Response::Failed { fault, buf } => {
                    self.recycle(buf);
                    match self.phase {
                        Phase::Planning => {
                            self.fault = fault;
                            if fault == Fault::HeightmapTimeout {
                                self.phase = Phase::WaitHeightmap { since: now };
                            } else {
                                self.finish(false);
                            }
                        }
                        Phase::Braking { .. } => self.enter_faulted(),
                        _ => {}
                    }
                }
            }
        }
    }

    fn finish(&mut self, ok: bool) {
        let ev = if ok {
            StatusEvent::JobDone
        } else {
            StatusEvent::JobFailed
        };
        self.phase = Phase::Idle;
        self.commanding = false;
        self.emit(ev, NO_OBJECT, [0.0; 4], 0);
        self.job_id = 0;
    }

    fn request_plan(&mut self, place_only: bool) {
        let Some(buf) = self.spare.take() else {
            return;
        };
        let pose = self.active.as_ref().map(|p| p.pose).unwrap_or_default();
        let req = Request::Plan {
            index: self.index as u32,
            object: self.order[self.index],
            after_stamp_ns: self.release_stamp,
            from: self.cmd.position,
            place_only,
            pose,
            buf,
        };
        match self.planner.send(req) {
            Ok(()) => self.phase = Phase::Planning,
            Err(Request::Plan { buf, .. }) => self.spare = Some(buf),
            Err(_) => {}
        }
    }

    fn step(&mut self, now: u64) {
        match self.phase {
            Phase::Idle | Phase::Ordering | Phase::Planning => {}
            Phase::WaitHeightmap { since } => {
                if self.stopping {
                    return;
                }
                if self.hm_stamp > self.release_stamp {
                    self.request_plan(false);
                } else if now.saturating_sub(since) > self.lim.fresh_hm {
                    self.raise(Fault::HeightmapTimeout);
                }
            }
            Phase::Streaming { seg, cursor } => self.stream(now, seg, cursor),
            Phase::Gripper { action, seg, since } => {
                let Some(g) = self.gs else { return };
                let reached = match action {
                    GripperAction::Close => g.closed == 1 && g.holding == 1,
                    GripperAction::Open => g.closed == 0,
                };
                if reached && g.header.stamp_ns >= since {
                    match action {
                        GripperAction::Close => self.holding = true,
                        GripperAction::Open => {
                            self.holding = false;
                            self.release_stamp = g.header.stamp_ns;
                            let (ty, pose, dns) = self
                                .active
                                .as_ref()
                                .map(|p| (p.object as u32, p.pose, p.decision_ns))
                                .unwrap_or((NO_OBJECT, [0.0; 4], 0));
                            self.done += 1;
                            self.emit(StatusEvent::Placed, ty, pose, dns);
                            self.index += 1;
                        }
                    }
                    self.next_segment(now, seg + 1);
                } else if now.saturating_sub(since) > self.lim.grip {
                    self.fault = Fault::Gripper;
                    self.emit(StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                    self.finish(false);
                }
            }
            Phase::Braking {
                cursor,
                seg,
                active_cursor,
            } => match cursor {
                None => {
                    // Until the brake is computed (a cycle or two), go on along the plan,
                    // which is within every limit, and hold at its segment end.
                    if let Some(p) = &self.active
                        && let Some(sg) = p.segments().get(seg)
                        && active_cursor < sg.end
                        && let Some(s) = p.setpoints.get(active_cursor)
                    {
                        self.cmd = *s;
                        self.phase = Phase::Braking {
                            cursor: None,
                            seg,
                            active_cursor: active_cursor + 1,
                        };
                    } else {
                        self.cmd.velocity = [0.0; DOF];
                        self.cmd.acceleration = [0.0; DOF];
                    }
                }
                Some(k) => {
                    let next = self
                        .brake
                        .as_ref()
                        .and_then(|b| b.setpoints.get(k).copied());
                    match next {
                        Some(s) => {
                            self.cmd = s;
                            self.phase = Phase::Braking {
                                cursor: Some(k + 1),
                                seg,
                                active_cursor,
                            };
                        }
                        None => {
                            if let Some(b) = self.brake.take() {
                                self.recycle(b);
                            }
                            self.enter_faulted();
                        }
                    }
                }
            },
            Phase::Faulted { healthy_since } => {
                if self.stopping || self.job_id == 0 {
                    return;
                }
                if !self.inputs_fresh(now) {
                    self.phase = Phase::Faulted {
                        healthy_since: None,
                    };
                    return;
                }
                let since = healthy_since.unwrap_or(now);
                self.phase = Phase::Faulted {
                    healthy_since: Some(since),
                };
                // Resume once both trajectory buffers are home (a plan may still be in flight).
                if now - since >= self.lim.resume && self.spare.is_some() {
                    self.resume(now);
                }
            }
        }
    }

    fn resume(&mut self, now: u64) {
        // Re-synchronise to where the arm is.
        if let Some(j) = self.js {
            self.cmd = Setpoint::at_rest(j.position);
        }
        let held = self.gs.is_some_and(|g| g.holding == 1);
        self.emit(StatusEvent::Resumed, self.current_type(), [0.0; 4], 0);
        if self.index >= self.count {
            self.finish(true);
            return;
        }
        if self.holding && !held {
            self.fault = Fault::ObjectLost;
            self.emit(StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
            self.holding = false;
        }
        self.grip_cmd = if self.holding {
            GripperAction::Close
        } else {
            GripperAction::Open
        };
        if self.holding {
            self.request_plan(true);
        } else {
            // Start the object over on a heightmap taken after the resume.
            self.release_stamp = self.release_stamp.max(now);
            self.phase = Phase::WaitHeightmap { since: now };
        }
    }

    fn next_segment(&mut self, now: u64, seg: usize) {
        let n = self.active.as_ref().map_or(0, |p| p.n_segments);
        if seg < n {
            let start = self
                .active
                .as_ref()
                .map_or(0, |p| if seg == 0 { 0 } else { p.segments[seg - 1].end });
            self.phase = Phase::Streaming { seg, cursor: start };
        } else if self.index >= self.count {
            self.finish(true);
        } else {
            self.phase = Phase::WaitHeightmap { since: now };
        }
    }

    fn stream(&mut self, now: u64, seg: usize, cursor: usize) {
        let Some(p) = &self.active else { return };
        let Some(sg) = p.segments().get(seg).copied() else {
            self.next_segment(now, seg);
            return;
        };
        if cursor < sg.end {
            if let Some(s) = p.setpoints.get(cursor) {
                self.cmd = *s;
            }
            self.phase = Phase::Streaming {
                seg,
                cursor: cursor + 1,
            };
            return;
        }
        // At the segment's end, at rest.
        self.cmd.velocity = [0.0; DOF];
        self.cmd.acceleration = [0.0; DOF];
        match sg.then {
            Some(action) => {
                self.grip_cmd = action;
                self.grip_object = if action == GripperAction::Close {
                    p.object as u32
                } else {
                    NO_OBJECT
                };
                self.grip_sent_at = 0; // publish now
                self.phase = Phase::Gripper {
                    action,
                    seg,
                    since: now,
                };
            }
            None => self.next_segment(now, seg + 1),
        }
    }

    fn publish(&mut self, now: u64) {
        if self.commanding {
            let q = self.cmd.position;
            let inside = (0..DOF).all(|i| q[i] >= self.lower[i] && q[i] <= self.upper[i]);
            if inside {
                self.seq += 1;
                let _ = self.ports.cmd.send_copy(JointCommand {
                    header: Header::now(self.seq),
                    position: self.cmd.position,
                    velocity: self.cmd.velocity,
                    acceleration: self.cmd.acceleration,
                });
            } else {
                // Never reached by planned samples (checked by the planner); a guard.
                self.limit_holds += 1;
            }
            if now.saturating_sub(self.grip_sent_at) >= 100_000_000 {
                self.grip_sent_at = now;
                self.seq += 1;
                let _ = self.ports.grip.send_copy(GripperCommand {
                    header: Header::now(self.seq),
                    job_id: self.job_id,
                    action: self.grip_cmd as u32,
                    object_type: self.grip_object,
                });
            }
        }
        if now.saturating_sub(self.last_heartbeat) >= 100_000_000 {
            self.last_heartbeat = now;
            self.emit(StatusEvent::Heartbeat, self.current_type(), [0.0; 4], 0);
        }
    }

    fn state_code(&self) -> JobState {
        match self.phase {
            Phase::Idle => JobState::Idle,
            Phase::Braking { .. } => JobState::Braking,
            Phase::Faulted { .. } => JobState::Faulted,
            _ => JobState::Running,
        }
    }

    fn emit(&mut self, event: StatusEvent, object_type: u32, pose: [f32; 4], decision_ns: u64) {
        self.seq += 1;
        let state = match event {
            StatusEvent::JobDone => JobState::Done,
            StatusEvent::JobFailed => JobState::Failed,
            _ => self.state_code(),
        };
        let _ = self.ports.status.send_copy(Status {
            header: Header::now(self.seq),
            job_id: self.job_id,
            event: event as u32,
            state: state as u32,
            fault: self.fault as u32,
            objects_total: self.count as u32,
            objects_done: self.done.min(self.count) as u32,
            object_index: self.index as u32,
            object_type,
            reserved: 0,
            pose,
            decision_ns,
            cycles: self.cycles,
            deadline_misses: self.misses,
            rejected_inputs: self.rejected + self.planner.rejected_frames(),
            max_cycle_ns: self.max_cycle,
        });
    }
}
