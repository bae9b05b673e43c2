//! Invalid payloads change nothing herbd does (proptest). Two job state
//! machines (`herb_daemon::job::Job`, what herbd's loop runs) are driven by the same script to
//! the middle of a job, with the arm moving; one of them is then handed a payload built from
//! arbitrary bytes (a joint state, gripper state, heightmap, pack-job or cancel request) that
//! fails validation. Over the next cycles both publish exactly the same joint commands, gripper
//! commands, planner and decision requests and statuses, except that the rejection is counted
//! (`rejected_inputs` for a sensor input, `rejected_requests` for a request) and a rejected
//! request gets its reply, with a reason.
//!
//! Budget: `PROPTEST_CASES` cases per property (256 by default, what CI runs);
//! `scripts/fuzz.sh` runs more.

use herb_daemon::config::Config;
use herb_daemon::job::{Effects, Job, JobParams};
use herb_daemon::plan::{
    DecisionRequest, DecisionResponse, Motion, MotionPlan, NOT_A_SEARCH, Request, Response,
};
use herb_ipc::{
    CancelJobRequest, GripperAction, GripperState, Header, HeightmapFrame, JointState, NO_OBJECT,
    PackJobRequest, Payload, RejectReason, Status,
};
use herb_robot::kinematics::DOF;
use herb_robot::motion::Setpoint;
use proptest::prelude::*;

const MS: u64 = 1_000_000;
const CATALOG: usize = 24;

/// An output of the machine, as herbd's loop would publish it.
#[derive(Debug, Clone, PartialEq)]
enum Out {
    Reply(u64, RejectReason),
    CancelReply(u64, RejectReason),
    /// A status, its rejection counter set aside.
    Status(Status),
    Joint(Setpoint),
    Gripper(u64, GripperAction, u32),
    Plan(&'static str),
    Decide(u32),
}

#[derive(Default)]
struct Fx {
    out: Vec<Out>,
    pending: Vec<Request>,
    decisions: Vec<DecisionRequest>,
}

impl Effects for Fx {
    fn reply(&mut self, job_id: u64, reason: RejectReason, _detail: u32) {
        self.out.push(Out::Reply(job_id, reason));
    }
    fn cancel_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.out.push(Out::CancelReply(job_id, reason));
    }
    fn confirm_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.out.push(Out::CancelReply(job_id, reason));
    }
    fn status(&mut self, s: &Status) {
        let mut s = *s;
        s.rejected_inputs = 0;
        s.rejected_requests = 0;
        self.out.push(Out::Status(s));
    }
    fn joint(&mut self, c: &Setpoint) {
        self.out.push(Out::Joint(*c));
    }
    fn gripper(&mut self, job_id: u64, a: GripperAction, t: u32) {
        self.out.push(Out::Gripper(job_id, a, t));
    }
    fn plan(&mut self, r: Request) -> Result<(), Request> {
        self.out.push(Out::Plan(match &r {
            Request::Order { .. } => "order",
            Request::Plan { .. } => "plan",
            Request::Brake { .. } => "brake",
            Request::Retreat { .. } => "retreat",
        }));
        self.pending.push(r);
        Ok(())
    }
    fn decide(&mut self, r: DecisionRequest) -> Result<(), DecisionRequest> {
        self.out.push(Out::Decide(r.index));
        self.decisions.push(r);
        Ok(())
    }
}

/// A scripted decision worker (fixture): every object in the box's middle.
fn decided(r: DecisionRequest) -> DecisionResponse {
    DecisionResponse {
        job_id: r.job_id,
        index: r.index,
        object: r.remaining().first().copied().unwrap_or(0),
        outcome: Ok([0.0, 0.0, 0.05, 0.0]),
        allowed: NOT_A_SEARCH,
        decision_ns: 1000,
    }
}

/// A scripted planner (fixture): orders as given; plans a pick, or a place, as three segments
/// of 300 samples moving joint 0 by 0.1 mrad each (a pick and place as five).
fn answer(r: Request) -> Response {
    match r {
        Request::Order {
            job_id,
            objects,
            count,
            ..
        } => Response::Ordered {
            job_id,
            order: objects,
            count,
        },
        Request::Plan {
            index,
            object,
            from,
            motion,
            pose,
            mut buf,
        } => {
            buf.reset();
            let mut q = from;
            let segments: &[Option<GripperAction>] = match motion {
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
            for &then in segments {
                for _ in 0..300 {
                    q[0] += 1e-4;
                    let mut s = Setpoint::at_rest(q);
                    s.velocity[0] = 0.1;
                    buf.setpoints.push(s).unwrap();
                }
                buf.push_segment(then);
            }
            buf.index = index;
            buf.object = object;
            buf.pose = pose;
            Response::Planned(buf)
        }
        Request::Retreat { mut buf, .. } => {
            buf.reset();
            Response::Planned(buf)
        }
        Request::Brake { state, mut buf } => {
            buf.reset();
            buf.setpoints
                .push(Setpoint::at_rest(state.position))
                .unwrap();
            buf.push_segment(None);
            Response::Braked(buf)
        }
    }
}

/// herbd's job machine with a perfect arm, gripper and camera around it, on a fake clock.
struct Cell {
    job: Job,
    fx: Fx,
    now: u64,
    q: [f64; DOF],
    closed: bool,
    seq: u64,
    frame: Box<HeightmapFrame>,
}

impl Cell {
    /// Started, a one-object job accepted, ordered, planned, and the arm 100 cycles into its
    /// first move.
    fn moving() -> Self {
        let cfg = Config::default();
        let q = std::array::from_fn(|i| 0.5 * (cfg.limits.lower[i] + cfg.limits.upper[i]));
        let samples = 10_000;
        let mut frame =
            Box::new(HeightmapFrame::from_bytes(&vec![0u8; size_of::<HeightmapFrame>()]).unwrap());
        frame.nx = 10;
        frame.ny = 10;
        frame.cell_m = 0.01;
        let mut c = Self {
            job: Job::new(
                JobParams::from_config(&cfg, CATALOG),
                Box::new(MotionPlan::with_capacity(samples)),
                Box::new(MotionPlan::with_capacity(samples)),
            ),
            fx: Fx::default(),
            now: 10_000 * MS,
            q,
            closed: false,
            seq: 0,
            frame,
        };
        // Fresh joint and gripper states and a first heightmap: ready for a job.
        c.ticks(60);
        let mut r = PackJobRequest::new(7, &[1]);
        r.header = Header::at(1, c.now);
        c.job.job_request(&r, c.now, &mut c.fx);
        c.ticks(100);
        assert!(
            c.fx.out.contains(&Out::Plan("plan")),
            "the fixture job is planned"
        );
        c.fx.out.clear();
        c
    }

    fn feed(&mut self) {
        self.seq += 1;
        let (now, seq) = (self.now, self.seq);
        let js = JointState {
            header: Header::at(seq, now),
            position: self.q,
            velocity: [0.0; DOF],
        };
        self.job.joint_state(1, &js, now, now);
        let gs = GripperState {
            header: Header::at(seq, now),
            closed: self.closed as u32,
            holding: self.closed as u32,
            object_type: NO_OBJECT,
            reserved: 0,
        };
        self.job.gripper_state(2, &gs, now, now);
        if seq % 50 == 0 {
            self.frame.header = Header::at(seq, now);
            self.job.heightmap(&self.frame, now);
        }
    }

    fn tick(&mut self) {
        self.now += MS;
        self.feed();
        for r in std::mem::take(&mut self.fx.pending) {
            self.job.planner_response(answer(r), self.now, &mut self.fx);
        }
        for r in std::mem::take(&mut self.fx.decisions) {
            self.job
                .decision_response(decided(r), self.now, &mut self.fx);
        }
        let mark = self.fx.out.len();
        self.job.tick(self.now, false, &mut self.fx);
        for o in &self.fx.out[mark..] {
            match o {
                Out::Joint(c) => self.q = c.position,
                Out::Gripper(_, a, _) => self.closed = *a == GripperAction::Close,
                _ => {}
            }
        }
    }

    fn ticks(&mut self, n: usize) {
        for _ in 0..n {
            self.tick();
        }
    }
}

/// Arbitrary bytes of `T`'s size, or a header-valid base with a few bytes overwritten.
fn bytes_of<T: Payload>() -> impl Strategy<Value = Vec<u8>> {
    let n = size_of::<T>();
    prop_oneof![
        proptest::collection::vec(any::<u8>(), n),
        proptest::collection::vec((0..n, any::<u8>()), 1..12).prop_map(move |edits| {
            let mut b = vec![0u8; n];
            b[..4].copy_from_slice(&1u32.to_ne_bytes());
            b[8] = 1; // seq 1
            b[16] = 1; // stamp 1 ns
            for (i, v) in edits {
                b[i] = v;
            }
            b
        }),
    ]
}

/// Which payload the fuzzed bytes become.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Joint,
    Gripper,
    Frame,
    Job,
    Cancel,
}

/// Hands `bytes` as a `kind` payload to `cell` if it fails validation; false if it validates
/// (the case then says nothing).
fn inject(cell: &mut Cell, kind: Kind, bytes: &[u8]) -> bool {
    let now = cell.now;
    match kind {
        Kind::Joint => {
            let m = JointState::from_bytes(bytes).unwrap();
            if m.validate().is_ok() {
                return false;
            }
            cell.job.joint_state(1, &m, now, now);
        }
        Kind::Gripper => {
            let m = GripperState::from_bytes(bytes).unwrap();
            if m.validate().is_ok() {
                return false;
            }
            cell.job.gripper_state(2, &m, now, now);
        }
        Kind::Frame => {
            // Only the header and the grid: the cells are the planner's to check.
            let mut b = vec![0u8; size_of::<HeightmapFrame>()];
            b[..bytes.len()].copy_from_slice(bytes);
            let m = HeightmapFrame::from_bytes(&b).unwrap();
            if m.validate_meta().is_ok() {
                return false;
            }
            cell.job.heightmap(&m, now);
        }
        Kind::Job => {
            let m = PackJobRequest::from_bytes(bytes).unwrap();
            if m.validate(CATALOG).is_ok() {
                return false;
            }
            cell.job.job_request(&m, now, &mut cell.fx);
        }
        Kind::Cancel => {
            let m = CancelJobRequest::from_bytes(bytes).unwrap();
            if m.validate().is_ok() {
                return false;
            }
            cell.job.cancel_request(&m, &mut cell.fx);
        }
    }
    true
}

/// The bytes' strategy for `kind` (a heightmap's first 64 bytes: header and grid).
fn payload(kind: Kind) -> BoxedStrategy<Vec<u8>> {
    match kind {
        Kind::Joint => bytes_of::<JointState>().boxed(),
        Kind::Gripper => bytes_of::<GripperState>().boxed(),
        Kind::Frame => proptest::collection::vec(any::<u8>(), 64).boxed(),
        Kind::Job => bytes_of::<PackJobRequest>().boxed(),
        Kind::Cancel => bytes_of::<CancelJobRequest>().boxed(),
    }
}

fn kind_and_payload() -> impl Strategy<Value = (Kind, Vec<u8>)> {
    prop_oneof![
        Just(Kind::Joint),
        Just(Kind::Gripper),
        Just(Kind::Frame),
        Just(Kind::Job),
        Just(Kind::Cancel),
    ]
    .prop_flat_map(|k| payload(k).prop_map(move |b| (k, b)))
}

proptest! {
    #[test]
    fn an_invalid_payload_mid_motion_changes_no_action((kind, bytes) in kind_and_payload()) {
        let mut fed = Cell::moving();
        let mut control = Cell::moving();
        let before = fed.job.rejected_inputs() + fed.job.rejected_requests();
        prop_assume!(inject(&mut fed, kind, &bytes));
        // Counted once, as a sensor input or as a request, whichever it was.
        let request = matches!(kind, Kind::Job | Kind::Cancel);
        let (inputs, requests) = (fed.job.rejected_inputs(), fed.job.rejected_requests());
        prop_assert_eq!(inputs + requests, before + 1, "counted");
        prop_assert_eq!(requests > 0, request, "counted as a request: {}", request);
        // A rejected request is answered with its reason and nothing else.
        let replies: Vec<Out> = std::mem::take(&mut fed.fx.out);
        prop_assert!(replies.len() <= 1, "{:?}", replies);
        for r in &replies {
            let reason = match r {
                Out::Reply(_, reason) | Out::CancelReply(_, reason) => *reason,
                other => return Err(TestCaseError::fail(format!("{other:?}"))),
            };
            prop_assert_ne!(reason, RejectReason::None);
        }
        fed.ticks(300);
        control.ticks(300);
        prop_assert_eq!(&fed.fx.out, &control.fx.out);
        prop_assert!(fed.fx.out.iter().any(|o| matches!(o, Out::Joint(_))), "the arm moves on");
    }
}
