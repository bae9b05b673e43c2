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

#[test]
fn bad_requests_are_answered_with_reason_and_detail_and_counted() {
    let mut r = Rig::new();
    let ok = |r: &Rig| {
        let mut q = PackJobRequest::new(5, &[1, 2, 3]);
        q.header = Header::at(1, r.now);
        q
    };
    let mut v0 = ok(&r);
    v0.header.version = 0;
    let mut id0 = ok(&r);
    id0.job_id = 0;
    let mut empty = ok(&r);
    empty.count = 0;
    let mut too_many = ok(&r);
    too_many.count = 65;
    let mut huge = ok(&r);
    huge.count = u32::MAX;
    let mut unknown = ok(&r);
    unknown.objects[2] = CATALOG as u16;
    let cases = [
        (v0, (RejectReason::Malformed, 0)),
        (id0, (RejectReason::Malformed, 0)),
        (empty, (RejectReason::Empty, 0)),
        (too_many, (RejectReason::TooMany, 65)),
        (huge, (RejectReason::TooMany, u32::MAX)),
        (unknown, (RejectReason::UnknownObject, 2)),
    ];
    for (req, want) in &cases {
        assert_eq!(r.request(req), *want, "{req:?}");
    }
    assert_eq!(r.job.rejected_requests(), cases.len() as u64);
    assert_eq!(r.job.rejected_inputs(), 0, "requests are counted apart");
    assert_eq!(r.phase(), Phase::Idle);
    assert_eq!(r.count(|o| matches!(o, Out::Plan(_))), 0, "nothing ordered");
    assert!(r.events().is_empty(), "no status but heartbeats");
}

#[test]
fn a_malformed_request_while_busy_gets_its_reason_not_busy() {
    let mut r = Rig::started(&[1]);
    assert_eq!(r.submit(8, &[]), (RejectReason::Empty, 0));
    assert_eq!(r.submit(8, &[1, 99]), (RejectReason::UnknownObject, 1));
    assert_eq!(r.submit(8, &[1]), (RejectReason::Busy, 0));
}

#[test]
fn not_ready_without_joint_state_gripper_state_or_a_recent_heightmap() {
    // Never heard from the arm.
    let mut r = Rig::new();
    r.job = Job::new(params(), buffer(), buffer());
    let joint = Fault::JointStateTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, joint));
    // Joint states stale (100 ms), then fresh again.
    let mut r = Rig::new();
    r.js_up = false;
    r.ticks(100);
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, joint));
    r.js_up = true;
    r.tick();
    assert_eq!(r.submit(2, &[1]), (RejectReason::None, 0));
    // Gripper states stale (200 ms).
    let mut r = Rig::new();
    r.gs_up = false;
    r.ticks(199);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::None, 0),
        "199 ms is fresh"
    );
    let mut r = Rig::new();
    r.gs_up = false;
    r.ticks(200);
    let grip = Fault::GripperStateTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, grip));
    // No heightmap for 2 s: the camera counts too.
    let mut r = Rig::new();
    r.camera_up = false;
    r.ticks(2000);
    let camera = Fault::HeightmapTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, camera));
    assert_eq!(r.job.rejected_requests(), 1);
}

#[test]
fn a_second_job_while_one_runs_is_busy_and_not_queued() {
    let mut r = Rig::started(&[1]);
    r.ticks(2);
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
    r.until_event(5000, StatusEvent::JobDone);
    r.ticks(200);
    assert_eq!(
        r.count(|o| *o == Out::Plan("order")),
        1,
        "job 8 never started"
    );
    assert!(r.statuses().iter().all(|s| s.job_id != 8));
}

#[test]
fn a_job_while_braking_or_faulted_is_busy() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(200);
    r.respond();
    r.ticks(2); // streaming
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(200, "brake", is_brake);
    assert!(matches!(r.phase(), Phase::Braking { .. }));
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
    r.respond();
    r.until_event(50, StatusEvent::Braked);
    assert!(matches!(r.phase(), Phase::Faulted { .. }));
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
}

#[test]
fn a_job_after_a_stop_is_shutting_down() {
    let mut r = Rig::new();
    r.stop = true;
    r.tick();
    assert!(r.finished);
    assert_eq!(r.submit(1, &[1]), (RejectReason::ShuttingDown, 0));
    // A malformed one still hears what is wrong with it.
    assert_eq!(r.submit(0, &[1]), (RejectReason::Malformed, 0));
}

#[test]
fn an_accepted_job_replies_orders_reports_and_holds_the_measured_position() {
    let mut r = Rig::new();
    r.q[3] += 0.25; // the arm is somewhere
    r.tick();
    let mark = r.fx.out.len();
    assert_eq!(r.submit(7, &[4, 5, 6]), (RejectReason::None, 0));
    let out = &r.fx.out[mark..];
    assert_eq!(
        out[0],
        Out::Reply {
            job_id: 7,
            reason: RejectReason::None,
            detail: 0
        }
    );
    assert_eq!(out[1], Out::Plan("order"));
    let Out::Status(s) = out[2] else {
        panic!("{out:?}")
    };
    assert_eq!(
        (event(&s), s.job_id, s.objects_total, s.state, s.fault),
        (
            StatusEvent::Accepted,
            7,
            3,
            JobState::Running as u32,
            Fault::None as u32
        )
    );
    let Request::Order {
        job_id,
        objects,
        count,
        ..
    } = r.take()
    else {
        panic!("an order")
    };
    assert_eq!((job_id, &objects[..count]), (7, &[4u16, 5, 6][..]));
    let mark = r.fx.out.len();
    r.tick();
    assert_eq!(r.joints_since(mark), vec![Setpoint::at_rest(r.q)]);
}

// ---------------------------------------------------------------------------------------
// Ordering
// ---------------------------------------------------------------------------------------

#[test]
fn ordered_starts_the_pick_and_asks_for_the_decision_at_once() {
    let mut r = Rig::new();
    r.auto = false;
    r.decide_after = None;
    r.submit(7, &[4, 5, 6]);
    r.ticks(5);
    assert_eq!(r.phase(), Phase::Ordering);
    let resp = answer(r.take());
    r.deliver(resp);
    // The decision is asked for on the job's order (reversed by the script), on a heightmap
    // newer than the last release (none yet)...
    let d = r.take_decision();
    assert_eq!((d.job_id, d.index, d.after_stamp_ns), (7, 0, 0));
    assert_eq!(d.remaining(), &[6, 5, 4]);
    // ...and the pick is planned meanwhile, from rest where the arm stands.
    let Request::Plan {
        index,
        object,
        from,
        motion,
        ..
    } = r.take()
    else {
        panic!("a plan")
    };
    assert_eq!((index, object, from, motion), (0, 6, r.q, Motion::Pick));
    assert_eq!(r.phase(), Phase::Planning);
}

#[test]
fn ordered_for_another_job_is_ignored() {
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.deliver(Response::Ordered {
        job_id: 6,
        order: [9; MAX_JOB_OBJECTS],
        count: 1,
    });
    r.ticks(3);
    assert_eq!(r.phase(), Phase::Ordering);
    assert_eq!(r.job.order[0], 0);
}

#[test]
fn order_failed_fails_the_job_with_decision() {
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.take();
    r.deliver(Response::OrderFailed { job_id: 7 });
    let s = r.last(StatusEvent::JobFailed);
    assert_eq!(
        (s.job_id, s.state, s.fault),
        (7, JobState::Failed as u32, Fault::Decision as u32)
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(3);
    assert!(r.joints_since(mark).is_empty(), "no command without a job");
}

#[test]
fn order_failed_for_another_job_or_after_ordering_is_ignored() {
    // A stale reply for an earlier job.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.deliver(Response::OrderFailed { job_id: 6 });
    assert_eq!(r.phase(), Phase::Ordering);
    // One for this job, once it is ordered (the planner answers each order once; a repeat
    // is a bug elsewhere, and must not fail a job mid-motion).
    let resp = answer(r.take());
    r.deliver(resp);
    r.deliver(Response::OrderFailed { job_id: 7 });
    assert_eq!(r.phase(), Phase::Planning);
    assert!(!r.events().contains(&StatusEvent::JobFailed));
}

// ---------------------------------------------------------------------------------------
// Deciding while the arm picks
// ---------------------------------------------------------------------------------------

#[test]
fn the_next_decision_is_asked_for_on_a_frame_newer_than_the_release() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    // The first object's decision, by hand.
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(decided(&d));
    r.until_event(5000, StatusEvent::Placed);
    r.until(1000, "decision request", |o| matches!(o, Out::Decide(1)));
    let d = r.take_decision();
    assert_eq!(d.index, 1);
    assert!(r.job.release_stamp > 0);
    assert_eq!(d.after_stamp_ns, r.job.release_stamp);
}

#[test]
fn no_fresh_heightmap_within_fresh_heightmap_timeout_faults() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    let since = r.now;
    let t = params().timeouts.fresh_heightmap_ns;
    // The worker answers every request: no frame newer than the release came in time.
    let mut asked = 0;
    while r.now <= since + t + 2 * PERIOD && !r.events().contains(&StatusEvent::Fault) {
        r.tick();
        while !r.fx.decisions.is_empty() {
            let d = r.take_decision();
            asked += 1;
            r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
        }
    }
    assert!(asked > 1, "asked again after each timeout ({asked})");
    let s = r.last(StatusEvent::Fault);
    assert_eq!(s.fault, Fault::HeightmapTimeout as u32);
    assert!(r.now > since + t, "not before the timeout");
    // Held at the lift pose, at rest: faulted at once, no brake.
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn the_workers_heightmap_timeout_asks_again_silently() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
    assert!(!r.events().contains(&StatusEvent::Fault), "no fault event");
    assert_eq!(
        r.job.status(StatusEvent::Heartbeat).fault,
        Fault::None as u32,
        "nor fault"
    );
    // and asks again
    r.tick();
    assert_eq!(r.fx.decisions.len(), 1);
    assert_eq!(r.fx.decisions[0].index, 0);
}

#[test]
fn a_full_planner_ring_keeps_waiting_and_retries() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    let resp = answer(r.take());
    r.fx.refuse = true;
    r.deliver(resp);
    r.ticks(20);
    assert_eq!(r.phase(), Phase::Starting);
    assert!(r.job.spare.is_some(), "the buffer stays home");
    r.fx.refuse = false;
    r.tick();
    assert_eq!(r.phase(), Phase::Planning);
}

#[test]
fn a_full_decision_ring_asks_again_on_a_later_tick() {
    let mut r = Rig::new();
    r.fx.refuse_decisions = true;
    r.decide_after = None;
    r.submit(7, &[1]);
    r.ticks(20);
    assert!(r.fx.decisions.is_empty());
    r.fx.refuse_decisions = false;
    r.tick();
    assert_eq!(r.fx.decisions.len(), 1, "asked once the ring has room");
}

#[test]
fn decided_is_reported_with_pose_and_latency_while_the_pick_streams() {
    let mut r = Rig::started(&[4, 5]);
    r.until_event(5000, StatusEvent::Decided);
    let s = r.last(StatusEvent::Decided);
    assert_eq!(
        (s.job_id, s.object_type, s.object_index, s.decision_ns),
        (7, 5, 0, DECISION_NS)
    );
    assert_eq!(s.pose, pose_of(0));
    assert!(matches!(r.phase(), Phase::Streaming { seg: 0, .. }));
}

/// Runs the rig to the end of the job; the time it held an object waiting, from the final
/// status.
fn run_to_done(r: &mut Rig) -> Status {
    r.until_event(40_000, StatusEvent::JobDone);
    r.last(StatusEvent::JobDone)
}

#[test]
fn a_decision_before_the_lift_costs_no_wait() {
    let mut r = Rig::started(&[1, 2, 3]);
    let mut waited = false;
    while !r.events().contains(&StatusEvent::JobDone) {
        r.tick();
        waited |= matches!(r.phase(), Phase::AwaitDecision { .. });
        assert!(r.now < 10_000 * MS + 60_000 * MS, "the job ends");
    }
    let done = r.last(StatusEvent::JobDone);
    assert_eq!((done.objects_done, done.decision_wait_ms), (3, 0));
    // The place is asked for at the lift, with the decision already in: one planning round
    // trip, not a wait.
    assert!(!waited || r.job.wait_ns < 5 * PERIOD);
    // Every object: decided once, picked, then placed where decided.
    let placed: Vec<_> = r
        .statuses()
        .into_iter()
        .filter(|s| event(s) == StatusEvent::Placed)
        .map(|s| s.pose)
        .collect();
    assert_eq!(placed, vec![pose_of(0), pose_of(1), pose_of(2)]);
}

#[test]
fn a_decision_after_the_lift_holds_the_object_there_and_counts_the_wait() {
    let mut r = Rig::started(&[1, 2]);
    // The pick (three scripted segments and a grasp) takes well under 2 s; the decision 2 s.
    r.decide_after = Some(2000);
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS, "never held waiting");
    }
    let Phase::AwaitDecision { since } = r.phase() else {
        unreachable!()
    };
    assert!(r.job.holding, "held at the lift pose");
    assert!(!r.events().contains(&StatusEvent::Decided));
    // Held still: commands at rest where the lift ended, and nothing planned meanwhile.
    let (mark, q, plans) = (r.fx.out.len(), r.q, r.count(is_plan));
    r.ticks(100);
    let held = r.joints_since(mark);
    assert!(!held.is_empty());
    assert!(
        held.iter()
            .all(|c| c.position == q && c.velocity == [0.0; DOF])
    );
    assert_eq!(r.count(is_plan), plans);
    r.until_event(3000, StatusEvent::Decided);
    let first_wait_ms = (r.now - since) / MS;
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 2);
    assert!(
        done.decision_wait_ms as u64 >= first_wait_ms && first_wait_ms > 0,
        "the wait is counted: {} ms reported, {first_wait_ms} ms for the first object",
        done.decision_wait_ms
    );
}

#[test]
fn new_heightmaps_during_a_decision_ask_for_nothing_more() {
    let mut r = Rig::started(&[1]);
    r.decide_after = Some(1500);
    r.until_event(5000, StatusEvent::Decided);
    // About 15 frames came in meanwhile: one request, decided on the frame the worker took.
    assert_eq!(r.count(|o| matches!(o, Out::Decide(_))), 1);
    assert_eq!(run_to_done(&mut r).objects_done, 1);
}

#[test]
fn a_failed_decision_before_the_grasp_ends_the_job_at_the_next_standstill_gripper_open() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::NoFeasiblePlacement));
    r.until_event(2000, StatusEvent::JobFailed);
    let s = r.last(StatusEvent::JobFailed);
    assert_eq!(s.fault, Fault::NoFeasiblePlacement as u32);
    assert_eq!(r.count(is_close), 0, "never grasped");
    assert!(!r.holding);
    assert_eq!(r.job.out.cmd.velocity, [0.0; DOF], "at rest");
    assert_eq!(r.phase(), Phase::Idle);
}

#[test]
fn a_failed_decision_after_the_grasp_ends_the_job_at_the_lift_pose_holding_the_object() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    r.until(2000, "close", is_close);
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::Decision));
    r.until_event(2000, StatusEvent::JobFailed);
    assert_eq!(r.last(StatusEvent::JobFailed).fault, Fault::Decision as u32);
    assert!(r.holding, "held, not dropped");
    assert_eq!(r.job.out.cmd.velocity, [0.0; DOF], "at rest after the lift");
    assert!(!r.events().contains(&StatusEvent::Placed));
}

#[test]
fn a_hung_decision_fails_the_job_after_the_decision_timeout() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let asked = r.now;
    r.until_event(30_000, StatusEvent::JobFailed);
    assert_eq!(r.last(StatusEvent::JobFailed).fault, Fault::Decision as u32);
    assert!(r.now >= asked + params().decision_timeout_ns);
    assert!(r.holding, "held at the lift pose");
    // The late answer changes nothing.
    let d = r.take_decision();
    let n = r.statuses().len();
    r.deliver_decision(decided(&d));
    r.ticks(5);
    assert!(
        !r.statuses()[n..]
            .iter()
            .any(|s| event(s) == StatusEvent::Decided)
    );
}

#[test]
fn a_cancel_while_waiting_for_a_decision_retreats_and_ignores_the_late_decision() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    assert_eq!(r.cancel(7), RejectReason::None);
    r.until_event(2000, StatusEvent::JobCancelled);
    let d = r.take_decision();
    r.deliver_decision(decided(&d));
    r.ticks(5);
    assert!(!r.events().contains(&StatusEvent::Decided));
    assert_eq!(r.phase(), Phase::Idle);
}

#[test]
fn a_stop_while_waiting_for_a_decision_lets_herbd_exit_at_once() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    r.stop = true;
    r.tick();
    assert!(r.finished, "at rest: nothing to brake");
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn a_worker_that_never_finds_a_frame_faults_at_the_fresh_heightmap_timeout() {
    // The loop sees frames (their headers are fine) but the decision worker rejects every one
    // (a bad cell): its 500 ms waits must not restart the loop's fresh-heightmap clock.
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.tick(); // ordered: the pick starts, the decision is asked for
    let start = r.now;
    let t = params().timeouts.fresh_heightmap_ns;
    while !r.events().contains(&StatusEvent::Fault) {
        assert!(
            r.now < start + t + 1000 * MS,
            "no fault after {} ms",
            (r.now - start) / MS
        );
        if !r.fx.decisions.is_empty() {
            let d = r.take_decision();
            r.ticks(500); // the worker's wait
            r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
        }
        r.tick();
    }
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::HeightmapTimeout as u32
    );
    assert!(r.now > start + t);
}

#[test]
fn planner_failures_fail_the_job_with_their_fault() {
    for fault in [
        Fault::Unreachable,
        Fault::Decision,
        Fault::Motion,
        Fault::NoFeasiblePlacement,
    ] {
        let mut r = Rig::started(&[1]);
        r.auto = false;
        r.tick();
        r.respond();
        r.until_plan(50);
        let Request::Plan { buf, .. } = r.take() else {
            panic!()
        };
        r.deliver(Response::Failed { fault, buf });
        let s = r.last(StatusEvent::JobFailed);
        assert_eq!(
            (s.job_id, s.state, s.fault),
            (7, JobState::Failed as u32, fault as u32)
        );
        assert_eq!(r.phase(), Phase::Idle);
        assert!(
            r.job.spare.is_some() && r.job.active.is_some(),
            "buffers home"
        );
        // Both buffers home: the next job plans.
        r.auto = true;
        assert_eq!(r.submit(8, &[1]), (RejectReason::None, 0));
        r.until_event(5000, StatusEvent::JobDone);
    }
}

#[test]
fn a_plan_arriving_after_a_fault_is_recycled_and_the_resume_waits_for_it() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    assert!(matches!(r.phase(), Phase::Planning));
    // The adapter goes away while the planner works.
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    let resume = params().timeouts.resume_after_ns / PERIOD;
    r.ticks(resume as usize + 10);
    assert!(
        matches!(r.phase(), Phase::Faulted { .. }),
        "no resume while the plan is out"
    );
    let late = r.take();
    let resp = answer(late);
    r.deliver(resp);
    assert!(
        matches!(r.phase(), Phase::Faulted { .. }),
        "a late plan is not used"
    );
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::Resumed));
    // Starts the pick over; the decision asked for before the fault comes now.
    r.auto = true;
    r.decide_after = Some(1);
    r.until_event(5000, StatusEvent::JobDone);
    assert_eq!(
        r.events(),
        vec![
            StatusEvent::Accepted,
            StatusEvent::Fault,
            StatusEvent::Braked,
            StatusEvent::Resumed,
            StatusEvent::Decided,
            StatusEvent::Placed,
            StatusEvent::JobDone
        ]
    );
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

#[test]
fn samples_are_streamed_one_per_tick_bit_for_bit_and_segment_ends_are_at_rest() {
    let (mut r, samples) = streaming();
    let mark = r.fx.out.len();
    r.ticks(SEG + 1);
    let sent = r.joints_since(mark);
    assert_eq!(&sent[..SEG], &samples[..SEG]);
    // The segment's end: same position, at rest.
    assert_eq!(sent[SEG], Setpoint::at_rest(samples[SEG - 1].position));
    // Then the next segment (no action at the first one's end).
    let mark = r.fx.out.len();
    r.tick();
    assert_eq!(r.joints_since(mark), vec![samples[SEG]]);
}

#[test]
fn close_is_sent_at_once_with_the_object_type_and_the_arm_waits_at_rest() {
    let (mut r, _) = streaming();
    r.grasps = false; // the gripper closes on nothing
    r.until(3000, "close", is_close);
    let Some(Out::Gripper {
        job_id,
        object_type,
        ..
    }) =
        r.fx.out
            .iter()
            .rev()
            .find(|o| matches!(o, Out::Gripper { .. }))
    else {
        panic!()
    };
    assert_eq!((*job_id, *object_type), (7, 3));
    let Phase::Gripper { action, .. } = r.phase() else {
        panic!("{:?}", r.phase())
    };
    assert_eq!(action, GripperAction::Close);
    let mark = r.fx.out.len();
    r.ticks(50);
    let held = r.joints_since(mark);
    assert!(held.iter().all(|c| *c == Setpoint::at_rest(r.q)), "at rest");
}

#[test]
fn close_waits_for_a_state_stamped_after_the_command() {
    let (mut r, _) = streaming();
    r.gs_lag = 3 * MS; // the adapter's states describe the gripper 3 ms ago
    r.until(3000, "close", is_close);
    let Phase::Gripper { since, .. } = r.phase() else {
        panic!()
    };
    // The gripper is closed and holding from the next state on, but those states are stamped
    // before the command until the lag has passed.
    let mut left = 0;
    while matches!(r.phase(), Phase::Gripper { .. }) {
        r.tick();
        left += 1;
        assert!(left < 100);
    }
    assert_eq!(
        r.now - since,
        3 * MS,
        "left the wait at the first state stamped at `since`"
    );
    assert!(r.job.holding);
}

#[test]
fn open_reports_placed_and_the_release_stamp_gates_the_next_plan() {
    let mut r = Rig::started(&[1, 2]);
    r.gs_lag = 2 * MS;
    r.until_event(5000, StatusEvent::Placed);
    let s = r.last(StatusEvent::Placed);
    assert_eq!(
        (s.objects_done, s.object_index, s.object_type, s.decision_ns),
        (1, 0, 2, DECISION_NS)
    );
    assert_eq!(s.pose, [0.1, 0.2, 0.05, 0.3]);
    // The release is when the open gripper was observed, not when it was reported.
    assert_eq!(r.job.release_stamp, r.now - 2 * MS);
    assert!(!r.job.holding);
    assert_eq!(r.job.index, 1);
}

#[test]
fn a_missed_grasp_opens_and_picks_again_at_the_same_placement_without_a_new_decision() {
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    let Phase::Gripper { since, .. } = r.phase() else {
        panic!()
    };
    let t = params().timeouts.gripper_action_ns;
    while r.now < since + t {
        r.tick();
    }
    assert!(matches!(r.phase(), Phase::Gripper { .. }), "not yet");
    r.grasps = true; // the operator puts the object there
    r.tick();
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        herb_ipc::Fault::MissedGrasp as u32
    );
    assert!(matches!(r.phase(), Phase::Regrasp { .. }));
    r.until(100, "open", is_open);
    r.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    let decided = r.events().iter().filter(|e| **e == Decided).count();
    assert_eq!(decided, 1, "announced once: {:?}", r.events());
    let s = r.last(JobDone);
    assert_eq!(
        (s.objects_done, s.fault),
        (1, herb_ipc::Fault::MissedGrasp as u32)
    );
    assert_eq!(r.count(is_brake), 0, "the arm was at rest");
}

#[test]
fn grasps_missed_past_the_retries_skip_the_object_and_the_job_goes_on() {
    let mut r = Rig::started(&[1, 2]);
    r.grasps = false;
    r.until_event(20_000, StatusEvent::Skipped);
    let s = r.last(StatusEvent::Skipped);
    assert_eq!(s.fault, Fault::MissedGrasp as u32);
    r.grasps = true;
    r.until_event(10_000, StatusEvent::JobDone);
    let ev = r.events();
    let misses = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Fault && s.fault == Fault::MissedGrasp as u32)
        .count();
    assert_eq!(misses, 1 + params().grasp_retries as usize, "{ev:?}");
    let done = r.last(StatusEvent::JobDone);
    assert_eq!((done.objects_done, done.objects_total), (1, 2));
    // The next job starts from an open gripper.
    let mark = r.fx.out.len();
    assert_eq!(r.submit(8, &[3]), (RejectReason::None, 0));
    r.tick();
    assert!(r.fx.out[mark..].iter().any(is_open), "opened at the start");
}

#[test]
fn the_gripper_command_repeats_every_100_ms_while_a_job_runs() {
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    let first = r.now;
    let mut at = vec![];
    while r.now < first + 350 * MS {
        let mark = r.fx.out.len();
        r.tick();
        if r.fx.out[mark..]
            .iter()
            .any(|o| matches!(o, Out::Gripper { .. }))
        {
            at.push(r.now - first);
        }
    }
    assert_eq!(at, vec![100 * MS, 200 * MS, 300 * MS]);
}

#[test]
fn the_last_placement_reports_job_done_then_the_job_id_is_cleared() {
    let mut r = Rig::started(&[1, 2, 3]);
    r.until_event(10000, StatusEvent::JobDone);
    let s = r.last(StatusEvent::JobDone);
    assert_eq!(
        (s.job_id, s.state, s.objects_done, s.objects_total),
        (7, JobState::Done as u32, 3, 3)
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(150);
    assert!(r.joints_since(mark).is_empty(), "no command after the job");
    let hb = r.fx.out[mark..]
        .iter()
        .find_map(|o| match o {
            Out::Status(s) => Some(*s),
            _ => None,
        })
        .expect("a heartbeat");
    assert_eq!((hb.job_id, hb.state), (0, JobState::Idle as u32));
}

#[test]
fn a_three_object_job_reports_the_golden_event_sequence() {
    let mut r = Rig::started(&[10, 11, 12]);
    r.until_event(10000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        r.events(),
        vec![
            Accepted, Decided, Placed, Decided, Placed, Decided, Placed, JobDone
        ]
    );
    let types: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == Placed)
        .map(|s| s.object_type)
        .collect();
    assert_eq!(types, vec![12, 11, 10], "in the planner's order");
    let closes = r.count(|o| {
        matches!(
            o,
            Out::Gripper {
                action: GripperAction::Close,
                ..
            }
        )
    });
    assert!(closes >= 3);
    assert_eq!(r.job.limit_holds(), 0);
}

// ---------------------------------------------------------------------------------------
// Faults, and the adapter coming back
// ---------------------------------------------------------------------------------------

#[test]
fn a_stale_joint_state_halts_at_once_and_nothing_is_commanded_until_the_resume() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.sag = 0.05e-3; // 0.05 rad/s while unpowered
    let mark = r.fx.out.len();
    r.until_event(200, StatusEvent::Braked);
    let s = r.last(StatusEvent::Fault);
    assert_eq!(s.fault, Fault::JointStateTimeout as u32);
    assert_eq!(
        r.count(is_brake),
        0,
        "the arm is not seen: no brake streamed"
    );
    assert!(matches!(r.phase(), Phase::Faulted { .. }));
    // Faulted: not one joint command, however long it lasts.
    let faulted = r.fx.out.len();
    r.ticks(2000);
    assert!(r.joints_since(faulted).is_empty(), "nothing while faulted");
    let sagged = r.q;
    assert!((sagged[1] - r.joints_since(mark).last().unwrap().position[1]) > 0.09);
    // Back: the first command is the measured (sagged) position, after the window.
    r.js_up = true;
    let back = r.fx.out.len();
    r.until_event(5000, StatusEvent::Resumed);
    let first = r.joints_since(back);
    let first = first.first().expect("commands after the resume");
    assert_eq!(first.position, sagged, "from the state measured after it");
    r.until_event(5000, StatusEvent::JobDone);
}

#[test]
fn joint_states_stopped_are_named_by_the_adapter_and_the_name_follows_it() {
    for (said, fault) in [
        (ArmBlocker::Disabled, Fault::RobotDisabled),
        (ArmBlocker::EStop, Fault::RobotEStop),
        (ArmBlocker::MasterLost, Fault::MasterLost),
        (ArmBlocker::RobotSilent, Fault::RobotSilent),
        (ArmBlocker::RobotError, Fault::RobotError),
    ] {
        let (mut r, _) = streaming();
        r.arm = Some(ArmBlocker::None);
        r.ticks(2);
        r.arm = Some(said);
        r.js_up = false;
        r.until_event(200, StatusEvent::Braked);
        assert_eq!(r.last(StatusEvent::Fault).fault, fault as u32);
        assert_eq!(r.count(is_brake), 0);
        // Refused while it lasts, with the reason in the detail.
        r.ticks(10);
        assert_eq!(
            r.submit(9, &[1]),
            (RejectReason::Busy, 0),
            "a job is still on"
        );
    }
    // An e-stop released into a disable: said once more.
    let (mut r, _) = streaming();
    r.arm = Some(ArmBlocker::EStop);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.arm = Some(ArmBlocker::Disabled);
    r.ticks(50);
    let faults: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Fault)
        .map(|s| s.fault)
        .collect();
    assert_eq!(
        faults,
        vec![Fault::RobotEStop as u32, Fault::RobotDisabled as u32]
    );
    // The adapter silent too (no status for 300 ms): JointStateTimeout, i.e. adapter silent.
    let mut r = Rig::new();
    r.arm = None;
    r.js_up = false;
    r.ticks(400);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::NotReady, Fault::JointStateTimeout as u32)
    );
    // Idle with the robot disabled: refused with the reason, which heartbeats carry too.
    let mut r = Rig::new();
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.ticks(200);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::NotReady, Fault::RobotDisabled as u32)
    );
    let hb =
        r.fx.out
            .iter()
            .rev()
            .find_map(|o| match o {
                Out::Status(s) if event(s) == StatusEvent::Heartbeat => Some(*s),
                _ => None,
            })
            .unwrap();
    assert_eq!(hb.fault, Fault::RobotDisabled as u32);
    r.js_up = true;
    r.arm = Some(ArmBlocker::None);
    r.ticks(200);
    assert_eq!(r.submit(2, &[1]), (RejectReason::None, 0));
}

#[test]
fn a_gripper_state_timeout_brakes_a_seen_arm_then_commands_nothing() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(300, "brake", is_brake);
    r.until_event(300, StatusEvent::Braked);
    let after = r.fx.out.len();
    r.ticks(500);
    assert!(r.joints_since(after).is_empty(), "nothing while faulted");
}

#[test]
fn stale_gripper_state_and_stale_heightmap_are_faults_and_joint_state_comes_first() {
    let (mut r, _) = streaming();
    r.gs_up = false;
    r.until_event(300, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::GripperStateTimeout as u32
    );

    // (waiting for the next object's frame: longer than a scripted plan)
    let mut r = Rig::started(&[1, 2]);
    r.until_event(5000, StatusEvent::Decided);
    r.camera_up = false;
    r.until_event(2500, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::HeightmapTimeout as u32
    );

    // All three stale at once: the joint state is named.
    let (mut r, _) = streaming();
    r.js_up = false;
    r.gs_up = false;
    r.camera_up = false;
    r.until_event(2500, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::JointStateTimeout as u32
    );
}

#[test]
fn a_fault_at_rest_is_braked_at_once_without_a_brake() {
    // Ordering.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    // Waiting for a heightmap.
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.camera_up = false;
    r.frame_stamp = Some(0);
    r.gs_up = false;
    r.until_event(300, StatusEvent::Braked);
    // At the gripper.
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn a_failed_brake_or_a_full_ring_enters_faulted_where_it_stands() {
    let (mut r, _) = streaming();
    r.auto = false;
    r.ticks(2);
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(200, "brake", is_brake);
    let Request::Brake { buf, .. } = r.take() else {
        panic!()
    };
    r.deliver(Response::Failed {
        fault: Fault::Motion,
        buf,
    });
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert!(matches!(r.phase(), Phase::Faulted { .. }));

    let (mut r, _) = streaming();
    r.ticks(2);
    r.fx.refuse = true;
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until_event(200, StatusEvent::Braked);
    assert_eq!(r.count(is_brake), 0);
    assert!(r.job.spare.is_some(), "the brake buffer stays home");
}

#[test]
fn invalid_future_and_out_of_order_states_and_bad_frames_are_rejected_not_latched() {
    let mut r = Rig::new();
    r.js_up = false;
    r.gs_up = false;
    let now = r.now;
    let before = r.job.inputs.js;
    let mut bad = r.js(now);
    bad.position[2] = f64::NAN;
    r.job.joint_state(1, &bad, now, now);
    let future = r.js(now + MAX_FUTURE_STAMP_NS + 1);
    r.job.joint_state(1, &future, now, now);
    let old = JointState {
        header: Header::at(1, now),
        ..r.js(now)
    };
    r.job.joint_state(1, &old, now, now); // seq goes back
    assert_eq!(r.job.inputs.js, before);
    assert_eq!(r.job.rejected_inputs(), 3);
    // 1 ms ahead is allowed; later is allowed only if the clock at receipt is past it.
    let ahead = r.js(now + MAX_FUTURE_STAMP_NS);
    r.job.joint_state(1, &ahead, now, now);
    let late = r.js(now + 5 * MS);
    r.job.joint_state(1, &late, now, now + 5 * MS);
    assert_eq!(r.job.inputs.js, Some(late));
    assert_eq!(r.job.rejected_inputs(), 3);
    // Gripper states likewise.
    let mut g = r.gs(now);
    g.holding = 2;
    r.job.gripper_state(2, &g, now, now);
    assert_eq!(r.job.rejected_inputs(), 4);
    // A frame with a bad grid or header.
    let stamp = r.job.inputs.hm_stamp;
    r.frame.nx = 0;
    r.frame.header.stamp_ns = now + 1;
    let f = r.frame.clone();
    r.job.heightmap(&f, now);
    assert_eq!((r.job.rejected_inputs(), r.job.inputs.hm_stamp), (5, stamp));
}

#[test]
fn the_adapter_back_resumes_after_the_window_from_the_measured_position() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.q[1] += 0.1; // moved while away
    r.js_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    assert_eq!(r.now - back, params().timeouts.resume_after_ns);
    assert_eq!(r.job.out.cmd, Setpoint::at_rest(r.q));
    r.until_event(5000, StatusEvent::JobDone);
}

#[test]
fn a_flapping_adapter_restarts_the_resume_window() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    r.ticks(400);
    r.js_up = false;
    r.ticks(150); // stale again
    r.js_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    assert_eq!(r.now - back, params().timeouts.resume_after_ns);
}

#[test]
fn a_resume_while_holding_replans_only_the_placement_at_the_same_pose() {
    let mut r = Rig::started(&[1]);
    r.until(3000, "close", is_close);
    r.ticks(3); // holding, carrying
    assert!(r.job.holding);
    r.auto = false;
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until_event(200, StatusEvent::Fault);
    r.respond(); // the brake
    r.until_event(50, StatusEvent::Braked);
    r.gs_up = true;
    r.until_plan(1000);
    assert_eq!(r.events().last(), Some(&StatusEvent::Resumed));
    let Request::Plan { motion, pose, .. } = r.take() else {
        panic!()
    };
    assert_eq!(motion, Motion::Place { flip: false });
    assert_eq!(pose, [0.1, 0.2, 0.05, 0.3]);
    let resp = answer(Request::Plan {
        index: 0,
        object: 1,
        from: r.q,
        motion,
        pose,
        buf: buffer(),
    });
    // (the buffer in flight is the rig's; a fresh one stands in for it)
    r.deliver(resp);
    r.auto = true;
    r.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        r.events(),
        vec![Accepted, Decided, Fault, Braked, Resumed, Placed, JobDone],
        "no second Decided"
    );
    assert_eq!(r.last(Placed).pose, [0.1, 0.2, 0.05, 0.3]);
}

#[test]
fn an_object_lost_while_away_is_reported_and_picked_again_for_its_placement() {
    let mut r = Rig::started(&[1]);
    r.until(3000, "close", is_close);
    r.ticks(3);
    r.js_up = false;
    r.gs_up = false;
    r.until_event(300, StatusEvent::Braked);
    // The adapter restarts: the gripper is open, the object fell; closing grasps nothing.
    r.closed = false;
    r.holding = false;
    r.grasps = false;
    r.js_up = true;
    r.gs_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    let ev = r.events();
    assert_eq!(
        &ev[ev.len() - 2..],
        &[StatusEvent::Resumed, StatusEvent::Fault]
    );
    assert_eq!(r.last(StatusEvent::Fault).fault, Fault::ObjectLost as u32);
    assert!(back > 0);
    r.grasps = true; // the object, back at the pick station, is there to grasp
    r.until_event(5000, StatusEvent::JobDone);
    // Picked again and placed where it was decided: one decision, announced once.
    let decided: Vec<Status> = r
        .statuses()
        .into_iter()
        .filter(|s| event(s) == StatusEvent::Decided)
        .collect();
    assert_eq!(decided.len(), 1);
    assert_eq!(r.last(StatusEvent::Placed).pose, decided[0].pose);
}

#[test]
fn a_resume_after_the_last_placement_finishes_the_job() {
    let mut r = Rig::started(&[1]);
    r.until_event(5000, StatusEvent::Placed);
    r.ticks(2); // retreating
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    r.until_event(5000, StatusEvent::JobDone);
    let ev = r.events();
    assert_eq!(
        &ev[ev.len() - 2..],
        &[StatusEvent::Resumed, StatusEvent::JobDone]
    );
}

// ---------------------------------------------------------------------------------------
// Stop
// ---------------------------------------------------------------------------------------

#[test]
fn a_stop_while_streaming_brakes_then_finishes_without_a_fault_event() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.auto = false;
    r.stop = true;
    r.tick();
    assert!(!r.finished, "braking");
    assert_eq!(r.fx.out.iter().filter(|o| is_brake(o)).count(), 1);
    assert!(!r.events().contains(&StatusEvent::Fault));
    r.respond();
    let mut n = 0;
    while !r.finished {
        r.tick();
        n += 1;
        assert!(n < 20);
    }
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert_eq!(r.last(StatusEvent::Braked).fault, Fault::Stop as u32);
}

#[test]
fn a_stop_while_idle_halts_nothing_and_finishes_idle() {
    // Nothing runs: nothing is halted, and the shutdown reports the idle state.
    let mut r = Rig::new();
    r.stop = true;
    r.tick();
    assert!(r.finished);
    assert_eq!(r.events(), vec![]);
    let s = r.job.status(StatusEvent::Shutdown);
    assert_eq!((s.job_id, s.object_type), (0, NO_OBJECT));
    assert_eq!(s.state, JobState::Idle as u32);
}

#[test]
fn a_stop_while_planning_drops_the_late_plan_and_blocks_resume() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    r.stop = true;
    r.tick();
    assert!(r.finished);
    r.respond();
    assert!(!r.events().contains(&StatusEvent::Decided));
    let mark = r.fx.out.len();
    r.ticks(1000);
    assert!(!r.events().contains(&StatusEvent::Resumed));
    assert_eq!(r.count(is_plan), 1);
    assert!(
        r.joints_since(mark)
            .iter()
            .all(|c| c.velocity == [0.0; DOF])
    );
}

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

#[test]
fn cancel_requests_are_answered_with_their_reason() {
    let mut r = Rig::new();
    assert_eq!(r.cancel(0), RejectReason::Malformed);
    assert_eq!(r.cancel(7), RejectReason::NoSuchJob, "no job runs");
    r.submit(7, &[1]);
    assert_eq!(r.cancel(8), RejectReason::NoSuchJob, "another job runs");
    assert_eq!(r.job.rejected_requests(), 3);
    assert_eq!(r.cancel(7), RejectReason::None);
    assert_eq!(
        r.cancel(7),
        RejectReason::None,
        "a repeat is accepted again"
    );
    r.until_event(3000, StatusEvent::JobCancelled);
    assert_eq!(r.count(is_retreat), 1, "and changes nothing");
    assert_eq!(r.cancel(7), RejectReason::NoSuchJob, "over");
    let mut r = Rig::started(&[1]);
    r.stop = true;
    r.tick();
    assert_eq!(r.cancel(7), RejectReason::ShuttingDown);
}

#[test]
fn a_cancel_while_moving_brakes_retreats_and_reports_cancelled() {
    let (mut r, _) = streaming();
    r.ticks(3);
    assert_eq!(r.cancel(7), RejectReason::None);
    assert_eq!(r.count(is_brake), 1, "brakes at once");
    r.auto = false;
    r.tick();
    r.respond(); // the brake
    r.until(50, "retreat", is_retreat);
    let Request::Retreat { from, held, buf } = r.take() else {
        panic!()
    };
    assert_eq!(
        (from, held),
        (r.q, None),
        "from where it stopped, holding nothing"
    );
    let resp = answer(Request::Retreat { from, held, buf });
    let Response::Planned(p) = &resp else {
        panic!()
    };
    let up = p.setpoints.as_slice().to_vec();
    r.deliver(resp);
    let mark = r.fx.out.len();
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert_eq!(
        r.joints_since(mark)[..SEG],
        up[..],
        "the retreat, sample for sample"
    );
    use StatusEvent::*;
    assert_eq!(r.events(), vec![Accepted, Decided, Braked, JobCancelled]);
    let s = r.last(JobCancelled);
    assert_eq!(
        (s.job_id, s.state, s.fault, s.objects_done),
        (
            7,
            JobState::Cancelled as u32,
            herb_ipc::Fault::None as u32,
            0
        )
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(20);
    assert!(r.joints_since(mark).is_empty(), "no command after the job");
    // Both buffers are home: the next job runs.
    r.auto = true;
    assert_eq!(r.submit(8, &[2]), (RejectReason::None, 0));
    r.until_event(5000, JobDone);
}

#[test]
fn a_cancel_at_rest_retreats_without_a_brake() {
    // Holding the next object at the lift pose, waiting for its decision.
    let mut r = Rig::started(&[1, 2]);
    r.until_event(5000, StatusEvent::Placed);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    r.cancel(7);
    assert_eq!(r.count(is_retreat), 1);
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert_eq!(r.last(StatusEvent::JobCancelled).objects_done, 1);
    // At the gripper, holding the object: the retreat takes its height into account.
    let (mut r, _) = streaming();
    r.until(3000, "close", is_close);
    r.auto = false;
    r.tick(); // holding
    r.cancel(7);
    let Request::Retreat { held, .. } = r.take() else {
        panic!()
    };
    assert_eq!(held, Some(3));
    assert_eq!(r.count(is_brake), 0);
    // Ordering.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.cancel(7);
    assert!(matches!(r.phase(), Phase::Retreating { asked: true }));
    r.auto = true;
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert!(!r.events().contains(&StatusEvent::Decided));
}

#[test]
fn a_cancel_while_planning_waits_for_the_plan_then_retreats() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.auto = false;
    r.tick();
    r.respond(); // ordered
    r.until_plan(50);
    r.cancel(7);
    r.ticks(5);
    assert_eq!(
        r.count(is_retreat),
        0,
        "the only spare buffer is with the planner"
    );
    r.respond(); // the plan comes back: not used
    assert!(!r.events().contains(&StatusEvent::Decided));
    assert_eq!(r.count(is_retreat), 1);
    r.auto = true;
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
}

#[test]
fn a_cancel_of_a_faulted_job_ends_it_where_it_stands() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    r.cancel(7);
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::JobCancelled));
    assert_eq!(r.count(is_retreat), 0);
    let s = r.last(StatusEvent::JobCancelled);
    assert_eq!(
        s.fault,
        Fault::JointStateTimeout as u32,
        "the last fault stays reported"
    );
}

#[test]
fn a_failed_or_empty_retreat_still_ends_the_job_cancelled() {
    // The planner cannot lift the arm: cancelled where it stands, with the reason.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.take();
    r.cancel(7);
    let Request::Retreat { buf, .. } = r.take() else {
        panic!()
    };
    r.deliver(Response::Failed {
        fault: Fault::Unreachable,
        buf,
    });
    let s = r.last(StatusEvent::JobCancelled);
    assert_eq!(s.fault, Fault::Unreachable as u32);
    // Already at the transit height: no segment, cancelled at once.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.take();
    r.cancel(7);
    let Request::Retreat { mut buf, .. } = r.take() else {
        panic!()
    };
    buf.reset();
    r.deliver(Response::Planned(buf));
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::JobCancelled));
}

// ---------------------------------------------------------------------------------------
// Outputs
// ---------------------------------------------------------------------------------------

#[test]
fn a_command_outside_the_limits_is_held_and_counted() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    let Response::Planned(mut p) = answer(r.take()) else {
        panic!()
    };
    // Sample 2 past the upper limit of joint 0.
    let mut s = p.setpoints.as_slice().to_vec();
    s[2].position[0] = params().upper[0] + 0.01;
    p.setpoints.clear();
    for x in s {
        p.setpoints.push(x).unwrap();
    }
    r.deliver(Response::Planned(p));
    let mark = r.fx.out.len();
    r.ticks(3);
    assert_eq!(
        r.joints_since(mark).len(),
        2,
        "the third sample is not sent"
    );
    assert_eq!(r.job.limit_holds(), 1);
}

#[test]
fn heartbeats_every_100_ms_carry_the_state() {
    let mut r = Rig::new();
    let mut beats = vec![];
    for _ in 0..1000 {
        let mark = r.fx.out.len();
        r.tick();
        for o in &r.fx.out[mark..] {
            if let Out::Status(s) = o
                && event(s) == StatusEvent::Heartbeat
            {
                beats.push((r.now, s.state));
            }
        }
    }
    assert_eq!(beats.len(), 10);
    assert!(
        beats
            .windows(2)
            .all(|w| w[1].0 - w[0].0 == HEARTBEAT_PERIOD_NS)
    );
    assert!(beats.iter().all(|b| b.1 == JobState::Idle as u32));
}

#[test]
fn outputs_of_a_tick_come_status_then_joint_then_gripper_then_heartbeat() {
    let (mut r, _) = streaming();
    r.grasps = false;
    // Find the tick that reaches the grasp.
    loop {
        let mark = r.fx.out.len();
        r.tick();
        let out = r.fx.out[mark..].to_vec();
        if out.iter().any(is_close) {
            let j = out.iter().position(|o| matches!(o, Out::Joint(_))).unwrap();
            let g = out
                .iter()
                .position(|o| matches!(o, Out::Gripper { .. }))
                .unwrap();
            assert!(j < g, "{out:?}");
            if let Some(h) = out.iter().position(|o| matches!(o, Out::Status(_))) {
                assert!(g < h, "the heartbeat comes last: {out:?}");
            }
            break;
        }
    }
    // A Placed status comes before the tick's joint command.
    let mut r = Rig::started(&[1, 2]);
    loop {
        let mark = r.fx.out.len();
        r.tick();
        let out = r.fx.out[mark..].to_vec();
        if let Some(p) = out
            .iter()
            .position(|o| matches!(o, Out::Status(s) if event(s) == StatusEvent::Placed))
        {
            let j = out.iter().position(|o| matches!(o, Out::Joint(_))).unwrap();
            assert!(p < j, "{out:?}");
            break;
        }
    }
}

#[test]
fn a_restored_snapshot_behaves_as_the_original() {
    let mut a = Rig::started(&[1, 2]);
    a.until_event(10_000, StatusEvent::JobDone);
    a.ticks(37);
    let snap = a.job.snapshot().expect("idle");
    let mut b = Rig::new();
    b.job.restore(&snap);
    assert_eq!(b.job.snapshot(), Some(snap));
    // Same clock, same arm, same inputs from here: the same outputs.
    (b.now, b.q, b.js_seq, b.gs_seq, b.last_frame) = (a.now, a.q, a.js_seq, a.gs_seq, a.last_frame);
    b.frame.header = a.frame.header;
    let (ma, mb) = (a.fx.out.len(), b.fx.out.len());
    for r in [&mut a, &mut b] {
        assert_eq!(r.submit(9, &[3, 4]), (RejectReason::None, 0));
        r.until_event(10_000, StatusEvent::JobDone);
    }
    assert_eq!(a.fx.out[ma..], b.fx.out[mb..]);
    // Not while a job runs.
    assert!(Rig::started(&[1]).job.snapshot().is_none());
}

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

#[test]
fn a_whole_job_with_a_fault_and_a_resume_allocates_nothing() {
    // The counter counts.
    let probe = counting::allocations(|| {
        std::hint::black_box(vec![0u8; 16]);
    });
    assert_eq!(probe, 1);
    let mut r = Rig::started(&[1, 2, 3]);
    // The rig's own records are preallocated, so that every allocation counted is the job's.
    r.fx.out.reserve(100_000);
    r.fx.sent.reserve(16);
    r.fx.decisions.reserve(16);
    r.decision_sent.reserve(16);
    let n = counting::allocations(|| {
        // Into the second object's carry, then the adapter goes away and comes back.
        let mut placed = 0;
        for _ in 0..10_000 {
            let mark = r.fx.out.len();
            r.tick();
            placed += r.fx.out[mark..]
                .iter()
                .filter(|o| matches!(o, Out::Status(s) if s.event == StatusEvent::Placed as u32))
                .count();
            if placed == 1 && matches!(r.phase(), Phase::Streaming { seg: 2, .. }) {
                break;
            }
        }
        r.js_up = false;
        r.ticks(300);
        r.js_up = true;
        for _ in 0..20_000 {
            r.tick();
            if r.phase() == Phase::Idle {
                break;
            }
        }
    });
    use StatusEvent::*;
    let ev = r.events();
    assert!(ev.contains(&Braked) && ev.contains(&Resumed), "{ev:?}");
    assert_eq!(ev.last(), Some(&JobDone), "{ev:?}");
    assert_eq!(n, 0, "allocations during the job");
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

#[test]
fn the_journal_record_follows_the_job_and_ends_with_it() {
    let mut r = Rig::started(&[1, 2]);
    assert_eq!(r.job.journal().phase, ObjectPhase::Ordering);
    assert_eq!(r.job.journal().objects(), &[1, 2]);
    assert_eq!(r.job.journal().order(), None);
    let mut phases = vec![ObjectPhase::Ordering];
    let mut last = r.job.journal();
    while !r.events().contains(&StatusEvent::JobDone) {
        r.tick();
        let j = r.job.journal();
        if j.job_id != 0 && phases.last() != Some(&j.phase) {
            phases.push(j.phase);
        }
        if j.job_id != 0 {
            assert_eq!(j.order(), Some(&[2u16, 1][..]), "the planner's order");
            // A placement is journaled only for the current object, with its release.
            if let Some(p) = j.placement {
                assert_eq!(p.index, j.index);
            }
            if j.phase == ObjectPhase::Carrying {
                assert!(j.holding && j.placement.is_some(), "{j:?}");
            }
        }
        last = j;
        assert!(r.now < 20_000 * MS, "no JobDone");
    }
    use ObjectPhase::*;
    assert_eq!(
        phases,
        vec![
            Ordering, Deciding, Moving, Carrying, Moving, Deciding, Moving, Carrying, Moving
        ]
    );
    assert_eq!(last, JobRecord::NONE);
}

#[test]
fn a_recovered_job_holding_its_object_places_it_where_it_was_decided() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    // Carrying it to its placement (the place planned).
    while a
        .job
        .journal()
        .placement
        .is_none_or(|p| p.release_q.is_none())
    {
        a.tick();
    }
    a.ticks(50);
    let rec = a.job.journal();
    assert!(rec.holding && rec.phase == ObjectPhase::Carrying, "{rec:?}");
    let decided = rec.placement.unwrap().pose;

    let mut b = restarted(&a, &rec, true);
    b.auto = false;
    let mark = b.fx.out.len();
    b.tick();
    // The fault is reported and the planner gets the journal's order, unsearched.
    assert_eq!(
        b.last(StatusEvent::Fault).fault,
        herb_ipc::Fault::Restarted as u32
    );
    let Request::Order {
        objects,
        count,
        ordered,
        ..
    } = b.take()
    else {
        panic!("an order")
    };
    assert!(ordered);
    assert_eq!(&objects[..count], &[2, 1]);
    b.deliver(answer(Request::Order {
        job_id: 7,
        objects,
        count,
        ordered,
    }));
    b.auto = true;
    // Nothing is commanded before the inputs have been fresh for the resume window.
    b.until_event(2000, StatusEvent::Resumed);
    let resumed =
        b.fx.out
            .iter()
            .position(|o| matches!(o, Out::Status(s) if event(s) == StatusEvent::Resumed))
            .unwrap();
    assert!(
        b.fx.out[mark..resumed]
            .iter()
            .all(|o| !matches!(o, Out::Joint(_))),
        "no joint command before the resume"
    );
    assert!(
        b.fx.out[resumed..].iter().any(is_plan),
        "the placement is planned at the resume"
    );
    b.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Placed, Decided, Placed, JobDone]
    );
    let placed: Vec<Status> = b
        .statuses()
        .into_iter()
        .filter(|s| event(s) == Placed)
        .collect();
    assert_eq!(
        placed[0].pose, decided,
        "placed where decided before the crash"
    );
    assert_eq!(
        (placed[0].object_type, placed[1].object_type),
        (2, 1),
        "each object once, in the order"
    );
    assert_eq!(b.last(JobDone).objects_done, 2);
    assert_eq!(b.job.journal(), JobRecord::NONE);
}

#[test]
fn a_restart_while_waiting_for_a_decision_decides_again_and_places_it_as_it_is_held() {
    let mut a = Rig::started(&[1, 2]);
    a.decide_after = None;
    while !matches!(a.phase(), Phase::AwaitDecision { .. }) {
        a.tick();
        assert!(a.now < 20_000 * MS);
    }
    let mut rec = a.job.journal();
    assert!(rec.holding && rec.placement.is_none(), "{rec:?}");
    assert_eq!(rec.phase, ObjectPhase::Carrying);
    // Say its pick took it turned by a half turn: the place must turn it back.
    rec.flip = true;
    let mut b = restarted(&a, &rec, true);
    b.until_event(2000, StatusEvent::Resumed);
    b.auto = false;
    b.until_plan(200);
    let Request::Plan {
        index,
        motion,
        pose,
        ..
    } = b.take()
    else {
        panic!("a plan")
    };
    assert_eq!(
        (index, motion, pose),
        (0, Motion::Place { flip: true }, pose_of(0))
    );
    b.auto = true;
    b.deliver(answer(Request::Plan {
        index,
        object: 2,
        from: b.q,
        motion,
        pose,
        buf: buffer(),
    }));
    b.until_event(8000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Decided, Placed, Decided, Placed, JobDone]
    );
}

#[test]
fn a_release_the_journal_missed_counts_the_object_placed_once() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    a.until(3000, "open", is_open);
    // The crash comes after the open command, before the gripper's answer reached the journal.
    let rec = a.job.journal();
    assert!(rec.holding, "{rec:?}");
    a.closed = false;
    a.holding = false;
    let mut b = restarted(&a, &rec, true);
    b.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Placed, Decided, Placed, JobDone]
    );
    // One decision: only the second object is picked.

    // Away from the release configuration, the same journal means the object was lost: it is
    // picked again.
    let mut c = restarted(&a, &rec, true);
    c.q[0] += 0.1;
    c.until_event(5000, StatusEvent::JobDone);
    assert!(
        c.statuses()
            .iter()
            .any(|s| s.fault == herb_ipc::Fault::ObjectLost as u32)
    );
    // Both objects picked: the first again, picked and placed in one plan where it was decided
    // before the crash (announced then, so only the second's Decided is sent now); the second
    // picked, then placed once decided.
    assert_eq!(
        c.count(is_plan),
        3,
        "the first's pick and place, the second's pick, its place"
    );
    assert_eq!(
        c.events()
            .iter()
            .filter(|e| **e == StatusEvent::Decided)
            .count(),
        1,
        "the first was announced before the crash"
    );
}

#[test]
fn an_abandoned_job_ends_failed_without_moving() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    let rec = a.job.journal();
    let mut b = restarted(&a, &rec, false);
    let mark = b.fx.out.len();
    b.ticks(1000);
    use StatusEvent::*;
    assert_eq!(b.events(), vec![Fault, JobFailed]);
    assert_eq!(b.last(JobFailed).fault, herb_ipc::Fault::Restarted as u32);
    assert!(b.joints_since(mark).is_empty());
    assert_eq!(b.count(|o| matches!(o, Out::Plan(_))), 0);
    assert_eq!(b.job.journal(), JobRecord::NONE);
    // The abandoned job's object is still in the gripper: the next job is refused until it is
    // taken out, then runs.
    assert_eq!(b.submit(8, &[3]), (RejectReason::Holding, NO_OBJECT));
    b.holding = false;
    b.closed = false;
    b.ticks(2);
    assert_eq!(b.submit(9, &[3]), (RejectReason::None, 0));
    b.until_event(5000, JobDone);
}

#[test]
fn a_job_is_refused_while_the_gripper_holds_an_object_and_names_it() {
    // Cancelled while carrying: the object stays in the gripper.
    let mut r = Rig::started(&[4]);
    r.until(3000, "close", is_close);
    r.ticks(3);
    assert!(r.job.holding);
    r.job.cancel_request(&CancelJobRequest::new(7), &mut r.fx);
    r.until_event(5000, StatusEvent::JobCancelled);
    assert!(r.holding, "still held");
    // The gripper says what it holds when it knows: else herbd's belief, the cancelled job's
    // current object (type 4).
    assert_eq!(r.submit(8, &[5]), (RejectReason::Holding, 4));
    r.holding = false;
    r.closed = false;
    r.ticks(2);
    assert_eq!(r.submit(9, &[5]), (RejectReason::None, 0));
    r.until_event(5000, StatusEvent::JobDone);
    let placed: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Placed)
        .map(|s| s.object_type)
        .collect();
    assert_eq!(placed, vec![5], "only the new job's object");
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

/// Disabled mid-motion, the arm sags past herbd's limit on s1 (inside the arm's own): enabled
/// again, the job resumes, says which joint is outside, where and which limit (a Fault status,
/// the job still running), streams from where the arm stands (commands between it and the
/// limit pass the guard) and finishes. Configured to refuse, the job holds, says so once, and
/// a new job is refused as not ready, naming the joint, until the arm is moved inside.
#[test]
fn an_arm_sagged_past_a_limit_is_named_and_the_job_resumes_or_holds() {
    let (mut r, _) = streaming();
    r.ticks(5);
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    let upper = r.job.p.upper[1];
    r.q[1] = upper + 0.0034; // sagged past 0.997 to 1.0004
    r.ticks(50);
    r.arm = Some(ArmBlocker::None);
    r.js_up = true;
    r.until_event(2_000, StatusEvent::Resumed);
    r.tick();
    let f = *fault_statuses(&r).last().unwrap();
    assert_eq!(f.fault, Fault::OutsideLimits as u32);
    assert_eq!(f.state, JobState::Running as u32, "not a halt");
    let (joint, q, bound) = f.limit_excess().expect("the joint named");
    assert_eq!(joint, 1);
    assert!((q as f64 - (upper + 0.0034)).abs() < 1e-6 && (bound as f64 - upper).abs() < 1e-6);
    assert!(
        f.limit_words().unwrap().starts_with("left_s1 at "),
        "{:?}",
        f.limit_words()
    );
    let holds = r.job.limit_holds();
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 1);
    assert_eq!(
        r.job.limit_holds(),
        holds,
        "no command held back on the way"
    );

    // Refuse: the job holds where it is, says why once, and the next job is refused.
    let (mut r, _) = streaming();
    r.job.p.outside = OutsideLimits::Refuse;
    r.ticks(5);
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    r.q[1] = upper + 0.0034;
    r.arm = Some(ArmBlocker::None);
    r.js_up = true;
    r.ticks(2_000);
    assert!(!r.events().contains(&StatusEvent::Resumed));
    let said: Vec<u32> = fault_statuses(&r).iter().map(|s| s.fault).collect();
    assert_eq!(
        said,
        vec![Fault::RobotDisabled as u32, Fault::OutsideLimits as u32],
        "said once"
    );
    assert_eq!(r.job.state(), JobState::Faulted);
    // Moved inside by hand: it resumes.
    r.q[1] = upper - 0.01;
    r.until_event(2_000, StatusEvent::Resumed);
    run_to_done(&mut r);
    r.q[1] = upper + 0.0034;
    r.ticks(200);
    assert_eq!(
        r.submit(5, &[1]),
        (RejectReason::NotReady, Fault::OutsideLimits as u32)
    );
    r.ticks(150);
    let hb =
        r.fx.out
            .iter()
            .rev()
            .find_map(|o| match o {
                Out::Status(s) if event(s) == StatusEvent::Heartbeat => Some(*s),
                _ => None,
            })
            .unwrap();
    assert_eq!(
        hb.limit_excess().map(|e| e.0),
        Some(1),
        "the heartbeat names the joint"
    );
    assert_eq!(r.job.rejected_requests(), 1);
    // Beyond the arm's own limit: refused whatever the setting.
    r.job.p.outside = OutsideLimits::Recover;
    r.q[1] = r.job.p.arm_range.1[1] + 0.01;
    r.ticks(150);
    assert_eq!(
        r.submit(6, &[1]),
        (RejectReason::NotReady, Fault::BeyondArmLimits as u32)
    );
}

/// A job fed by a person (`CONFIRM_PICKS`): each try of each pick asks for the object
/// (`AwaitingObject`, with the try), and the arm holds above the station, the gripper not
/// closed, until the confirmation for that object and try comes; a confirmation for another
/// try or object, or for a job that does not ask, is refused (`NotAwaited`). After a missed
/// grasp, the retry asks again.
#[test]
fn a_job_fed_by_hand_waits_above_the_station_for_each_confirmation() {
    let mut r = Rig::new();
    r.grasps = false; // the first grasp misses
    let mut req = PackJobRequest::new(1, &[3]);
    req.flags = PackJobRequest::CONFIRM_PICKS;
    assert_eq!(r.request(&req).0, RejectReason::None);
    r.until_event(500, StatusEvent::AwaitingObject);
    let asked = r.last(StatusEvent::AwaitingObject);
    assert_eq!((asked.object_index, asked.attempt), (0, 0));
    // The arm goes above the station and stays there: no close.
    r.ticks(3 * SEG);
    assert!(
        matches!(r.phase(), Phase::AwaitOperator { .. }),
        "{:?}",
        r.phase()
    );
    let closes = |r: &Rig| {
        r.fx.out
            .iter()
            .filter(|o| {
                matches!(
                    o,
                    Out::Gripper {
                        action: GripperAction::Close,
                        ..
                    }
                )
            })
            .count()
    };
    assert_eq!(closes(&r), 0);
    let confirm = |r: &mut Rig, index: u32, attempt: u32| {
        let c = ConfirmPickRequest::new(r.job.job_id, index, attempt);
        r.job.confirm_request(&c, &mut r.fx);
        match r.fx.out.last() {
            Some(Out::ConfirmReply { reason, .. }) => *reason,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(confirm(&mut r, 0, 1), RejectReason::NotAwaited);
    assert_eq!(confirm(&mut r, 1, 0), RejectReason::NotAwaited);
    r.ticks(50);
    assert_eq!(closes(&r), 0, "still waiting");
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::None);
    r.until_event(10_000, StatusEvent::Fault);
    assert_eq!(r.last(StatusEvent::Fault).fault, Fault::MissedGrasp as u32);
    r.grasps = true;
    // The retry asks again, for try 1, and waits.
    r.until_event(10_000, StatusEvent::AwaitingObject);
    assert_eq!(r.last(StatusEvent::AwaitingObject).attempt, 1);
    let before = closes(&r);
    r.ticks(3 * SEG);
    assert_eq!(closes(&r), before);
    assert_eq!(
        confirm(&mut r, 0, 0),
        RejectReason::NotAwaited,
        "the last try's"
    );
    assert_eq!(confirm(&mut r, 0, 1), RejectReason::None);
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 1);
    assert_eq!(r.job.rejected_requests(), 3);
    // A job that does not ask never waits and refuses confirmations.
    let mut r = Rig::started(&[3]);
    r.ticks(10);
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::NotAwaited);
    run_to_done(&mut r);
    assert!(!r.events().contains(&StatusEvent::AwaitingObject));
}
