//! Unit tests of the job state machine: scripted adapter, camera and planner, a fake clock.
//!
//! [`Rig`] plays the loop's shell at 1 kHz: each tick it advances the clock, feeds the states
//! of a perfect arm (it is where it was last commanded) and gripper, and a camera frame every
//! 100 ms, answers the planner's requests when `auto` is on, and ticks the machine. Tests turn
//! each source off, answer the planner by hand, or inject inputs directly.

use super::*;
use crate::config::Config;
use herb_ipc::PROTOCOL_VERSION;
use std::collections::VecDeque;

mod cycle;
mod publish;
mod recovery;
mod requests;

const MS: u64 = 1_000_000;
const PERIOD: u64 = MS;
const CATALOG: usize = 24;
/// Samples per scripted plan segment.
const SEG: usize = 200;
/// The scripted decision latency.
const DECISION_NS: u64 = 400_000;
const FRAME_EVERY: u64 = 100 * MS;

/// One output of the machine, as the shell would publish it.
#[derive(Debug, Clone, PartialEq)]
enum Out {
    Reply {
        job_id: u64,
        reason: RejectReason,
        detail: u32,
    },
    CancelReply {
        job_id: u64,
        reason: RejectReason,
    },
    ConfirmReply {
        job_id: u64,
        reason: RejectReason,
    },
    Status(Status),
    Joint(Setpoint),
    Gripper {
        job_id: u64,
        action: GripperAction,
        object_type: u32,
    },
    /// A planner request was handed over (its kind).
    Plan(&'static str),
    /// A decision request was handed over (the object's index).
    Decide(u32),
}

fn kind(r: &Request) -> &'static str {
    match r {
        Request::Order { .. } => "order",
        Request::Plan { .. } => "plan",
        Request::Brake { .. } => "brake",
        Request::Retreat { .. } => "retreat",
    }
}

/// Records the outputs; the planner's ring refuses requests while `refuse` is set, the
/// decision worker's while `refuse_decisions` is.
#[derive(Default)]
struct Fx {
    out: Vec<Out>,
    sent: VecDeque<Request>,
    refuse: bool,
    /// Decision requests handed over, with the time they were sent (set by the rig).
    decisions: VecDeque<DecisionRequest>,
    refuse_decisions: bool,
}

impl Effects for Fx {
    fn reply(&mut self, job_id: u64, reason: RejectReason, detail: u32) {
        self.out.push(Out::Reply {
            job_id,
            reason,
            detail,
        });
    }
    fn cancel_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.out.push(Out::CancelReply { job_id, reason });
    }
    fn confirm_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.out.push(Out::ConfirmReply { job_id, reason });
    }
    fn status(&mut self, status: &Status) {
        self.out.push(Out::Status(*status));
    }
    fn joint(&mut self, command: &Setpoint) {
        self.out.push(Out::Joint(*command));
    }
    fn gripper(&mut self, job_id: u64, action: GripperAction, object_type: u32) {
        self.out.push(Out::Gripper {
            job_id,
            action,
            object_type,
        });
    }
    fn plan(&mut self, request: Request) -> Result<(), Request> {
        if self.refuse {
            return Err(request);
        }
        self.out.push(Out::Plan(kind(&request)));
        self.sent.push_back(request);
        Ok(())
    }
    fn decide(&mut self, request: DecisionRequest) -> Result<(), DecisionRequest> {
        if self.refuse_decisions {
            return Err(request);
        }
        self.out.push(Out::Decide(request.index));
        self.decisions.push_back(request);
        Ok(())
    }
}

/// The scripted decision of object `index`.
fn pose_of(index: u32) -> [f32; 4] {
    [0.1 * (index + 1) as f32, 0.2, 0.05, 0.3]
}

/// The scripted decision worker's answer to `r`.
fn decided(r: &DecisionRequest) -> DecisionResponse {
    DecisionResponse {
        job_id: r.job_id,
        index: r.index,
        object: r.remaining().first().copied().unwrap_or(0),
        outcome: Ok(pose_of(r.index)),
        allowed: crate::plan::NOT_A_SEARCH,
        decision_ns: DECISION_NS,
    }
}

/// The decision worker's answer to `r` when it fails with `fault`.
fn failed_decision(r: &DecisionRequest, fault: Fault) -> DecisionResponse {
    DecisionResponse {
        outcome: Err(fault),
        ..decided(r)
    }
}

fn event(s: &Status) -> StatusEvent {
    StatusEvent::from_code(s.event).expect("a defined event")
}

fn params() -> JobParams {
    let cfg = Config::default();
    JobParams {
        timeouts: JobTimeouts::from(&cfg.timeouts),
        lower: cfg.limits.lower,
        upper: cfg.limits.upper,
        catalog_len: CATALOG,
        grasp_retries: cfg.recovery.grasp_retries,
        decision_timeout_ns: secs_to_ns(cfg.decision.timeout_s),
        arm_range: herb_robot::motion::baxter_left_arm_range(),
        outside: cfg.recovery.outside_limits,
    }
}

fn buffer() -> Box<MotionPlan> {
    Box::new(MotionPlan::with_capacity(1000))
}

/// A scripted plan from `from`: per segment, `SEG` samples moving joint 0 by 1 mrad each at
/// 1 rad/s (forth, back, forth...), then the segment's action. Pick: to the station, grasp
/// (close), lift; place: carry, place (open), retreat; pick and place: both.
fn fill(buf: &mut MotionPlan, from: [f64; DOF], motion: Motion) {
    buf.reset();
    let segs: &[Option<GripperAction>] = match motion {
        Motion::Pick => &[None, Some(GripperAction::Close), None],
        Motion::Place { .. } => &[None, Some(GripperAction::Open), None],
        Motion::PickAndPlace => &[
            None,
            Some(GripperAction::Close),
            None,
            Some(GripperAction::Open),
            None,
        ],
    };
    let mut q = from;
    for (k, then) in segs.iter().enumerate() {
        // back and forth, so that long jobs stay inside the limits
        let step = if k % 2 == 0 { 0.001 } else { -0.001 };
        for _ in 0..SEG {
            q[0] += step;
            let mut s = Setpoint::at_rest(q);
            s.velocity[0] = 1.0;
            s.acceleration[0] = 0.5;
            buf.setpoints.push(s).expect("room");
        }
        buf.push_segment(*then);
    }
}

/// The scripted planner's answer to `r`; `order` reverses the objects (Beam-3 reorders).
fn answer(r: Request) -> Response {
    match r {
        Request::Order {
            job_id,
            objects,
            count,
            ordered,
        } => {
            // A recovered job's order is kept as given.
            let mut order = objects;
            if !ordered {
                order[..count].reverse();
            }
            Response::Ordered {
                job_id,
                order,
                count,
            }
        }
        Request::Plan {
            index,
            object,
            from,
            motion,
            pose,
            mut buf,
        } => {
            fill(&mut buf, from, motion);
            buf.index = index;
            buf.object = object;
            if motion != Motion::Pick {
                buf.pose = pose;
            }
            if let Motion::Place { flip } = motion {
                buf.flip = flip;
            }
            Response::Planned(buf)
        }
        Request::Retreat { from, mut buf, .. } => {
            buf.reset();
            let mut q = from;
            for _ in 0..SEG {
                q[1] -= 0.001;
                let mut s = Setpoint::at_rest(q);
                s.velocity[1] = -1.0;
                buf.setpoints.push(s).expect("room");
            }
            buf.push_segment(None);
            Response::Planned(buf)
        }
        Request::Brake { state, mut buf } => {
            buf.reset();
            let mut s = state;
            for k in (0..3).rev() {
                s.velocity[0] = k as f64 * 0.3;
                s.acceleration[0] = -1.0;
                if k == 0 {
                    s.acceleration[0] = 0.0;
                }
                buf.setpoints.push(s).expect("room");
            }
            buf.push_segment(None);
            Response::Braked(buf)
        }
    }
}

struct Rig {
    job: Job,
    fx: Fx,
    now: u64,
    /// The arm's configuration (it follows the commands exactly).
    q: [f64; DOF],
    closed: bool,
    holding: bool,
    /// A commanded close grasps the object.
    grasps: bool,
    /// Gripper states are stamped this long before they are fed.
    gs_lag: u64,
    js_up: bool,
    gs_up: bool,
    camera_up: bool,
    /// Frames carry this stamp instead of the time of capture.
    frame_stamp: Option<u64>,
    last_frame: u64,
    js_seq: u64,
    gs_seq: u64,
    frame: Box<HeightmapFrame>,
    stop: bool,
    /// Answer planner requests at the start of the next tick.
    auto: bool,
    /// Answer decision requests this many ticks after they were sent (`None`: by hand).
    decide_after: Option<u64>,
    /// When each pending decision request was sent (parallel to `fx.decisions`).
    decision_sent: VecDeque<u64>,
    finished: bool,
    /// What the arm adapter says each tick (`None`: it says nothing).
    arm: Option<ArmBlocker>,
    arm_seq: u64,
    /// While joint states are withheld the arm sags this much per tick on s1 (rad).
    sag: f64,
}

impl Rig {
    fn new() -> Self {
        let cfg = Config::default();
        let q = std::array::from_fn(|i| 0.5 * (cfg.limits.lower[i] + cfg.limits.upper[i]));
        let mut frame: Box<HeightmapFrame> = Box::new(HeightmapFrame {
            header: Header::at(0, 0),
            nx: 10,
            ny: 10,
            cell_m: 0.01,
            objects: 0,
            data: [0.0; herb_ipc::HEIGHTMAP_MAX_CELLS],
        });
        frame.header.version = PROTOCOL_VERSION;
        let mut r = Self {
            job: Job::new(params(), buffer(), buffer()),
            fx: Fx::default(),
            now: 10_000 * MS,
            q,
            closed: false,
            holding: false,
            grasps: true,
            gs_lag: 0,
            js_up: true,
            gs_up: true,
            camera_up: true,
            frame_stamp: None,
            last_frame: 0,
            js_seq: 0,
            gs_seq: 0,
            frame,
            stop: false,
            auto: true,
            decide_after: Some(1),
            decision_sent: VecDeque::new(),
            finished: false,
            arm: None,
            arm_seq: 0,
            sag: 0.0,
        };
        r.ticks(3);
        r
    }

    fn js(&mut self, stamp: u64) -> JointState {
        self.js_seq += 1;
        JointState {
            header: Header::at(self.js_seq, stamp),
            position: self.q,
            velocity: [0.0; DOF],
        }
    }

    fn gs(&mut self, stamp: u64) -> GripperState {
        self.gs_seq += 1;
        GripperState {
            header: Header::at(self.gs_seq, stamp),
            closed: self.closed as u32,
            holding: self.holding as u32,
            object_type: NO_OBJECT,
            reserved: 0,
        }
    }

    fn feed(&mut self) {
        let now = self.now;
        if let Some(b) = self.arm {
            self.arm_seq += 1;
            let m = ArmStatus {
                header: Header::at(self.arm_seq, now),
                blocker: b as u32,
                reserved: 0,
                commands_refused: 0,
            };
            self.job.arm_status(3, &m, now, now);
        }
        if !self.js_up {
            self.q[1] += self.sag;
        }
        if self.js_up {
            let m = self.js(now);
            self.job.joint_state(1, &m, now, now);
        }
        if self.gs_up {
            let m = self.gs(now - self.gs_lag);
            self.job.gripper_state(2, &m, now, now);
        }
        if self.camera_up && now - self.last_frame >= FRAME_EVERY {
            self.last_frame = now;
            self.frame.header.seq += 1;
            self.frame.header.stamp_ns = self.frame_stamp.unwrap_or(now);
            self.job.heightmap(&self.frame, now);
        }
    }

    /// One cycle: clock, inputs, planner answers (when `auto`), tick; the arm and gripper
    /// then follow the commands.
    fn tick(&mut self) {
        self.now += PERIOD;
        self.feed();
        if self.auto {
            self.respond();
        }
        self.answer_decisions();
        let mark = self.fx.out.len();
        self.finished = self.job.tick(self.now, self.stop, &mut self.fx);
        for o in &self.fx.out[mark..] {
            match o {
                Out::Joint(c) => self.q = c.position,
                Out::Gripper { action, .. } => {
                    self.closed = *action == GripperAction::Close;
                    self.holding = self.closed && self.grasps;
                }
                _ => {}
            }
        }
    }

    fn ticks(&mut self, n: usize) {
        for _ in 0..n {
            self.tick();
        }
    }

    /// Ticks until `pred` holds for an output of a tick (at most `max` ticks); panics else.
    fn until(&mut self, max: usize, what: &str, pred: impl Fn(&Out) -> bool) {
        for _ in 0..max {
            let mark = self.fx.out.len();
            self.tick();
            if self.fx.out[mark..].iter().any(&pred) {
                return;
            }
        }
        panic!("no {what} within {max} ticks; events: {:?}", self.events());
    }

    fn until_event(&mut self, max: usize, ev: StatusEvent) {
        self.until(
            max,
            &format!("{ev:?}"),
            |o| matches!(o, Out::Status(s) if event(s) == ev),
        );
    }

    /// Answers every planner request pending now (the scripted planner; a request made while
    /// answering, as the pick's after its order, waits for the next call).
    fn respond(&mut self) {
        for _ in 0..self.fx.sent.len() {
            let Some(r) = self.fx.sent.pop_front() else {
                break;
            };
            let resp = answer(r);
            self.job.planner_response(resp, self.now, &mut self.fx);
        }
    }

    /// Ticks until a plan request is pending (at once if one is), at most `max` ticks.
    fn until_plan(&mut self, max: usize) {
        if !self
            .fx
            .sent
            .iter()
            .any(|r| matches!(r, Request::Plan { .. }))
        {
            self.until(max, "plan", is_plan);
        }
    }

    /// Notes when new decision requests were sent, and answers those due (`decide_after`).
    fn answer_decisions(&mut self) {
        while self.decision_sent.len() < self.fx.decisions.len() {
            self.decision_sent.push_back(self.now);
        }
        let Some(after) = self.decide_after else {
            return;
        };
        while let Some(&at) = self.decision_sent.front() {
            if self.now < at + after * PERIOD {
                break;
            }
            self.decision_sent.pop_front();
            let r = self.fx.decisions.pop_front().expect("parallel queues");
            let d = decided(&r);
            self.job.decision_response(d, self.now, &mut self.fx);
        }
    }

    /// The oldest pending decision request (manual decisions).
    fn take_decision(&mut self) -> DecisionRequest {
        self.decision_sent.pop_front();
        self.fx
            .decisions
            .pop_front()
            .expect("a pending decision request")
    }

    /// Hands the decision `d` to the machine now.
    fn deliver_decision(&mut self, d: DecisionResponse) {
        self.job.decision_response(d, self.now, &mut self.fx);
    }

    /// Hands `resp` to the machine now.
    fn deliver(&mut self, resp: Response) {
        self.job.planner_response(resp, self.now, &mut self.fx);
    }

    /// The oldest pending request (manual planner).
    fn take(&mut self) -> Request {
        self.fx.sent.pop_front().expect("a pending planner request")
    }

    fn request(&mut self, r: &PackJobRequest) -> (RejectReason, u32) {
        let mark = self.fx.out.len();
        self.job.job_request(r, self.now, &mut self.fx);
        let replies: Vec<_> = self.fx.out[mark..]
            .iter()
            .filter_map(|o| match o {
                Out::Reply { reason, detail, .. } => Some((*reason, *detail)),
                _ => None,
            })
            .collect();
        assert_eq!(replies.len(), 1, "one reply per request");
        replies[0]
    }

    fn submit(&mut self, job_id: u64, objects: &[u16]) -> (RejectReason, u32) {
        let mut r = PackJobRequest::new(job_id, objects);
        r.header = Header::at(1, self.now);
        self.request(&r)
    }

    /// A job started and ordered (the scripted planner answers).
    fn started(objects: &[u16]) -> Self {
        let mut r = Self::new();
        assert_eq!(r.submit(7, objects), (RejectReason::None, 0));
        r
    }

    /// Statuses so far, heartbeats left out.
    fn statuses(&self) -> Vec<Status> {
        self.fx
            .out
            .iter()
            .filter_map(|o| match o {
                Out::Status(s) if event(s) != StatusEvent::Heartbeat => Some(*s),
                _ => None,
            })
            .collect()
    }

    fn events(&self) -> Vec<StatusEvent> {
        self.statuses().iter().map(event).collect()
    }

    fn last(&self, ev: StatusEvent) -> Status {
        *self
            .statuses()
            .iter()
            .rev()
            .find(|s| event(s) == ev)
            .unwrap_or_else(|| panic!("no {ev:?} in {:?}", self.events()))
    }

    fn joints_since(&self, mark: usize) -> Vec<Setpoint> {
        self.fx.out[mark..]
            .iter()
            .filter_map(|o| match o {
                Out::Joint(c) => Some(*c),
                _ => None,
            })
            .collect()
    }

    fn count(&self, what: impl Fn(&Out) -> bool) -> usize {
        self.fx.out.iter().filter(|o| what(o)).count()
    }

    fn phase(&self) -> Phase {
        self.job.phase
    }
}

fn is_plan(o: &Out) -> bool {
    *o == Out::Plan("plan")
}

fn is_brake(o: &Out) -> bool {
    *o == Out::Plan("brake")
}

fn is_close(o: &Out) -> bool {
    matches!(
        o,
        Out::Gripper {
            action: GripperAction::Close,
            ..
        }
    )
}

// ---------------------------------------------------------------------------------------
// Job requests
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// Ordering
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// Deciding while the arm picks
// ---------------------------------------------------------------------------------------

/// Runs the rig to the end of the job; the time it held an object waiting, from the final
/// status.
fn run_to_done(r: &mut Rig) -> Status {
    r.until_event(40_000, StatusEvent::JobDone);
    r.last(StatusEvent::JobDone)
}

// ---------------------------------------------------------------------------------------
// Streaming and the gripper
// ---------------------------------------------------------------------------------------

/// A job of one object whose plan arrived; returns the rig and the plan's samples.
fn streaming() -> (Rig, Vec<Setpoint>) {
    let mut r = Rig::started(&[3]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    let resp = answer(r.take());
    let Response::Planned(p) = &resp else {
        panic!()
    };
    let samples = p.setpoints.as_slice().to_vec();
    r.deliver(resp);
    r.auto = true;
    (r, samples)
}

// ---------------------------------------------------------------------------------------
// Faults, and the adapter coming back
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// Stop
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// Cancel
// ---------------------------------------------------------------------------------------

impl Rig {
    fn cancel(&mut self, job_id: u64) -> RejectReason {
        let mut r = CancelJobRequest::new(job_id);
        r.header = Header::at(1, self.now);
        let mark = self.fx.out.len();
        self.job.cancel_request(&r, &mut self.fx);
        let replies: Vec<_> = self.fx.out[mark..]
            .iter()
            .filter_map(|o| match o {
                Out::CancelReply { job_id: j, reason } if *j == job_id => Some(*reason),
                _ => None,
            })
            .collect();
        assert_eq!(replies.len(), 1, "one reply per cancel");
        replies[0]
    }
}

fn is_retreat(o: &Out) -> bool {
    *o == Out::Plan("retreat")
}

// ---------------------------------------------------------------------------------------
// Outputs
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// No allocation
// ---------------------------------------------------------------------------------------

/// Counts the allocations made on a thread while it has counting on (this test binary's
/// allocator; other threads and other times are not counted).
mod counting {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;
    use std::sync::atomic::{AtomicU64, Ordering};

    struct Counting;

    static ALLOCS: AtomicU64 = AtomicU64::new(0);

    thread_local! {
        static ON: Cell<bool> = const { Cell::new(false) };
    }

    fn note() {
        if ON.try_with(|c| c.get()).unwrap_or(false) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
    }

    // SAFETY: forwards to the system allocator unchanged; only counts.
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            note();
            unsafe { System.alloc(layout) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            unsafe { System.dealloc(ptr, layout) }
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            note();
            unsafe { System.realloc(ptr, layout, new_size) }
        }
    }

    #[global_allocator]
    static A: Counting = Counting;

    /// Runs `f` with counting on; the allocations it made on this thread.
    pub fn allocations(f: impl FnOnce()) -> u64 {
        let before = ALLOCS.load(Ordering::Relaxed);
        ON.with(|c| c.set(true));
        f();
        ON.with(|c| c.set(false));
        ALLOCS.load(Ordering::Relaxed) - before
    }
}

// ---------------------------------------------------------------------------------------
// Restart: the journal record and a job taken up from it
// ---------------------------------------------------------------------------------------

fn is_open(o: &Out) -> bool {
    matches!(
        o,
        Out::Gripper {
            action: GripperAction::Open,
            ..
        }
    )
}

/// A fresh machine (a restarted daemon) with the arm and gripper where `crashed` left them,
/// given `rec` from the journal.
fn restarted(crashed: &Rig, rec: &JobRecord, resume: bool) -> Rig {
    let mut r = Rig::new();
    r.q = crashed.q;
    r.closed = crashed.closed;
    r.holding = crashed.holding;
    r.ticks(3);
    r.job.recover(rec, resume);
    r
}

// ---------------------------------------------------------------------------------------
// Every event once per object and job, whatever happens (property)
// ---------------------------------------------------------------------------------------

/// A disturbance of a job in progress.
#[derive(Debug, Clone, Copy)]
enum Disturbance {
    /// Joint states stop for so many ticks (the adapter says `blocker`, or nothing), the arm
    /// sagging meanwhile.
    Arm(u16, Option<ArmBlocker>),
    /// Gripper states stop for so many ticks.
    Gripper(u16),
    /// The camera stops for so many ticks.
    Camera(u16),
    /// Grasps miss for so many ticks.
    Misses(u16),
    /// herbd is killed and restarted: the job is taken up from its journal.
    Restart,
}

fn disturbance() -> impl proptest::strategy::Strategy<Value = (u16, Disturbance)> {
    use proptest::prelude::*;
    let blocker = proptest::option::of(prop_oneof![
        Just(ArmBlocker::Disabled),
        Just(ArmBlocker::EStop),
        Just(ArmBlocker::MasterLost),
    ]);
    let kind = prop_oneof![
        (50u16..1500, blocker).prop_map(|(d, b)| Disturbance::Arm(d, b)),
        (50u16..1500).prop_map(Disturbance::Gripper),
        (50u16..3000).prop_map(Disturbance::Camera),
        (100u16..10_000).prop_map(Disturbance::Misses),
        Just(Disturbance::Restart),
    ];
    (0u16..2500, kind)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 48,
        ..proptest::prelude::ProptestConfig::default()
    })]

    /// Under random faults, missed grasps and restarts: per object, at most one `Decided`, one
    /// `Placed` or `Skipped` (never both); per job, at most one end; a job done placed or
    /// skipped every object; what was placed is what the order says.
    #[test]
    fn every_event_is_announced_once_per_object_and_job(
        n in 1usize..4,
        plan in proptest::collection::vec(disturbance(), 1..6),
    ) {
        let objects: Vec<u16> = (0..n as u16).map(|k| k + 2).collect();
        let mut r = Rig::started(&objects);
        r.arm = Some(ArmBlocker::None);
        let mut statuses: Vec<Status> = Vec::new();
        let mut plan = plan;
        plan.sort_by_key(|(at, _)| *at);
        let mut tick = 0u32;
        let mut restore_at: Vec<(u32, Disturbance)> = Vec::new();
        let ended = |s: &[Status]| {
            s.iter().any(|s| {
                matches!(
                    event(s),
                    StatusEvent::JobDone | StatusEvent::JobFailed | StatusEvent::JobCancelled
                )
            })
        };
        while tick < 40_000 {
            while let Some(&(at, d)) = plan.first() {
                if at as u32 > tick {
                    break;
                }
                plan.remove(0);
                match d {
                    Disturbance::Arm(dur, b) => {
                        r.js_up = false;
                        r.sag = 0.05e-3;
                        r.arm = b.or(Some(ArmBlocker::None)).filter(|_| b.is_some());
                        restore_at.push((tick + dur as u32, d));
                    }
                    Disturbance::Gripper(dur) => {
                        r.gs_up = false;
                        restore_at.push((tick + dur as u32, d));
                    }
                    Disturbance::Camera(dur) => {
                        r.camera_up = false;
                        restore_at.push((tick + dur as u32, d));
                    }
                    Disturbance::Misses(dur) => {
                        r.grasps = false;
                        restore_at.push((tick + dur as u32, d));
                    }
                    Disturbance::Restart => {
                        let rec = r.job.journal();
                        if rec == JobRecord::NONE {
                            continue; // no job to take up: nothing to restart into
                        }
                        statuses.extend(r.statuses());
                        let mut b = restarted(&r, &rec, true);
                        b.arm = Some(ArmBlocker::None);
                        b.js_up = r.js_up;
                        b.gs_up = r.gs_up;
                        b.camera_up = r.camera_up;
                        b.grasps = r.grasps;
                        b.fx.out.clear();
                        r = b;
                    }
                }
            }
            restore_at.retain(|&(until, d)| {
                if until > tick {
                    return true;
                }
                match d {
                    Disturbance::Arm(..) => {
                        r.js_up = true;
                        r.sag = 0.0;
                        r.arm = Some(ArmBlocker::None);
                    }
                    Disturbance::Gripper(_) => r.gs_up = true,
                    Disturbance::Camera(_) => r.camera_up = true,
                    Disturbance::Misses(_) => r.grasps = true,
                    Disturbance::Restart => {}
                }
                false
            });
            r.tick();
            tick += 1;
            if plan.is_empty() && restore_at.is_empty() && ended(&r.statuses()) {
                break;
            }
        }
        statuses.extend(r.statuses());
        let mine: Vec<&Status> = statuses.iter().filter(|s| s.job_id == 7).collect();
        let brief: Vec<String> = mine
            .iter()
            .map(|s| format!("{:?}#{} {:?}", event(s), s.object_index, Fault::from_code(s.fault)))
            .collect();
        let count = |ev: StatusEvent, i: u32| {
            mine.iter().filter(|s| event(s) == ev && s.object_index == i).count()
        };
        for i in 0..n as u32 {
            proptest::prop_assert!(count(StatusEvent::Decided, i) <= 1, "object {i}: {:?}", brief);
            let placed = count(StatusEvent::Placed, i);
            let skipped = count(StatusEvent::Skipped, i);
            proptest::prop_assert!(placed + skipped <= 1, "object {i}: {:?}", brief);
        }
        let ends = mine
            .iter()
            .filter(|s| {
                matches!(
                    event(s),
                    StatusEvent::JobDone | StatusEvent::JobFailed | StatusEvent::JobCancelled
                )
            })
            .count();
        proptest::prop_assert!(ends <= 1, "{:?}", brief);
        if let Some(done) = mine.iter().find(|s| event(s) == StatusEvent::JobDone) {
            let placed = mine.iter().filter(|s| event(s) == StatusEvent::Placed).count();
            let skipped = mine.iter().filter(|s| event(s) == StatusEvent::Skipped).count();
            proptest::prop_assert_eq!(placed + skipped, n);
            proptest::prop_assert_eq!(done.objects_done as usize, placed);
        }
    }
}

/// The Fault statuses emitted so far.
fn fault_statuses(r: &Rig) -> Vec<Status> {
    r.statuses()
        .into_iter()
        .filter(|s| event(s) == StatusEvent::Fault)
        .collect()
}
