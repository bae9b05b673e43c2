//! The job state machine: what `herbd` does with a pack job, as a pure function of its inputs.
//!
//! [`Job`] owns no port, reads no clock and allocates nothing after [`Job::new`]. The loop
//! ([`crate::controller`]) is a thin shell around it: each cycle it reads the clock once (`now`,
//! the cycle's start) and feeds the machine, in this order,
//!
//! 1. every joint state ([`Job::joint_state`]), gripper state ([`Job::gripper_state`]) and
//!    heightmap frame ([`Job::heightmap`]) that arrived,
//! 2. every planner response ([`Job::planner_response`]), then every decision
//!    ([`Job::decision_response`]),
//! 3. every pack-job request ([`Job::job_request`]), then every cancel request
//!    ([`Job::cancel_request`]),
//! 4. one [`Job::tick`] (stop request, health, one step of the current phase, commands),
//!
//! and the machine answers through [`Effects`]: replies, status events, joint and gripper
//! commands, planner and decision requests, in the order the shell must publish them. Unit tests
//! (`job/tests.rs`) drive it with scripted inputs and a fake clock.
//!
//! # Per object
//!
//! The pick starts as soon as the object is known and the arm is free, and the placement is
//! decided meanwhile, off the loop and off the planner (the decision worker,
//! [`crate::decision`], on a heightmap stamped after the last release):
//!
//! ask for the decision, and the planner for the pick (Beam-3 order at job start; waypoints; IK;
//! Ruckig) -> stream the samples, one per tick -> at the grasp, close the gripper and wait until
//! it holds -> lift -> once the decision is in (`Decided`), plan the place; if the arm got there
//! first it holds the object at the lift pose and waits, and that wait is counted
//! (`Status::decision_wait_ms`) -> stream -> at the placement, open and wait -> report ->
//! retreat -> next object. A decision that fails (`NoFeasiblePlacement`, `Decision`) or does
//! not come within `decision.timeout_s` ends the job, failed, at the arm's next standstill (an
//! object already grasped is lifted first and stays held).
//!
//! # Faults
//!
//! Joint states, gripper states or heightmaps older than their timeouts are a fault, a status
//! reports it, and the job holds. Joint states that stop are named by the arm adapter's own
//! status ([`herb_ipc::ArmStatus`]): robot disabled, e-stop, robot error, master lost, robot
//! silent; with no recent status from the adapter, `JointStateTimeout` (the adapter is silent).
//! With the arm unseen, nothing is commanded from then on: no brake is streamed (the adapter
//! does not pass commands on while it withholds state; the robot holds by itself). With the arm
//! seen, a moving arm brakes (a Ruckig brake from the last commanded state) and then nothing is
//! commanded. **While a job is faulted, no joint command is sent**, so nothing planned before an
//! interruption can reach the robot after it. When every input has been fresh for
//! `resume_after_s`, the job resumes from the configuration measured then: an object still held
//! is placed; an object lost from the gripper (the adapter restarted) or decided but not yet
//! grasped is picked and placed where it was decided (one decision and one `Decided` per
//! object, whatever the faults and restarts); an object not decided yet is decided then.
//!
//! A grasp that does not hold within `gripper_action_s` is a missed grasp
//! ([`Fault::MissedGrasp`]): the gripper opens, and the pick is tried again with the same
//! placement (no new decision) up to `grasp_retries` times; then the object is skipped
//! ([`StatusEvent::Skipped`]) and the job goes on. A job starts with the gripper opened unless
//! it holds something.
//! A second job while one runs is rejected (`Busy`), not queued: a client resubmits.
//! No joint command leaves the configured limits: every sample is checked before it is
//! published, and one outside is replaced by holding the last command (counted).
//!
//! # Restart
//!
//! [`Job::journal`] describes the running job for the job journal ([`crate::journal`]); a
//! daemon that restarts takes the unfinished job up again with [`Job::recover`]: it reports
//! the fault [`Fault::Restarted`], gives the planner the job's order, commands nothing until
//! every input has been fresh for `resume_after_s`, then resumes from the measured state. An
//! object in the gripper is placed where it was decided; an object not in the gripper is
//! picked; one the journal says was held, now out of the gripper with the arm standing at its
//! release configuration, was released there before the crash: it is counted placed.

use crate::config::OutsideLimits;
use crate::config::{Timeouts, secs_to_ns};
use crate::plan::{DecisionRequest, DecisionResponse, Motion, MotionPlan, Request, Response};
use herb_ipc::{
    ARM_STATUS_PERIOD_NS, ArmBlocker, ArmStatus, CancelJobRequest, ConfirmPickRequest, Fault,
    GRIPPER_REPEAT_NS, GripperAction, GripperState, HEARTBEAT_PERIOD_NS, Header, HeightmapFrame,
    InOrder, JobState, JointState, MAX_FUTURE_STAMP_NS, MAX_JOB_OBJECTS, NO_JOINT, NO_OBJECT,
    PackJobRequest, RejectReason, Status, StatusEvent,
};
use herb_robot::kinematics::DOF;
use herb_robot::motion::{Excess, Setpoint, excess_of};

pub mod record;
pub use record::{JobRecord, JobRecordError, ObjectPhase, Placement};

/// The job's timeouts (ns), from the `[timeouts]` section of the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JobTimeouts {
    /// A joint state older than this while a job runs is a fault (`joint_state_s`).
    pub joint_state_ns: u64,
    /// A gripper state older than this is a fault (`gripper_state_s`).
    pub gripper_state_ns: u64,
    /// No heightmap received for this long is a fault (`heightmap_s`).
    pub heightmap_ns: u64,
    /// The gripper must reach a commanded state within this (`gripper_action_s`).
    pub gripper_action_ns: u64,
    /// Inputs must be fresh this long before a faulted job resumes (`resume_after_s`).
    pub resume_after_ns: u64,
    /// Longest wait for a heightmap stamped after the last release (`fresh_heightmap_s`).
    pub fresh_heightmap_ns: u64,
}

impl From<&Timeouts> for JobTimeouts {
    fn from(t: &Timeouts) -> Self {
        Self {
            joint_state_ns: secs_to_ns(t.joint_state_s),
            gripper_state_ns: secs_to_ns(t.gripper_state_s),
            heightmap_ns: secs_to_ns(t.heightmap_s),
            gripper_action_ns: secs_to_ns(t.gripper_action_s),
            resume_after_ns: secs_to_ns(t.resume_after_s),
            fresh_heightmap_ns: secs_to_ns(t.fresh_heightmap_s),
        }
    }
}

/// What the machine is built with (constant while it runs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobParams {
    /// Timeouts.
    pub timeouts: JobTimeouts,
    /// Lowest joint command (rad).
    pub lower: [f64; DOF],
    /// Highest joint command (rad).
    pub upper: [f64; DOF],
    /// Object types in the catalog (a request naming another is rejected).
    pub catalog_len: usize,
    /// Picks tried again after a missed grasp before the object is skipped.
    pub grasp_retries: u32,
    /// A decision not back this long after it was asked for faults the job
    /// (`decision.timeout_s`).
    pub decision_timeout_ns: u64,
    /// The arm's own position limits (lower, upper; rad), wider than `lower`..`upper`: a joint
    /// measured beyond them is never moved.
    pub arm_range: ([f64; DOF], [f64; DOF]),
    /// What a joint measured outside `lower`..`upper` (inside `arm_range`) means
    /// (`recovery.outside_limits`).
    pub outside: OutsideLimits,
}

impl JobParams {
    /// The parameters `cfg` gives, for a catalog of `catalog_len` types.
    pub fn from_config(cfg: &crate::config::Config, catalog_len: usize) -> Self {
        Self {
            timeouts: JobTimeouts::from(&cfg.timeouts),
            lower: cfg.limits.lower,
            upper: cfg.limits.upper,
            catalog_len,
            grasp_retries: cfg.recovery.grasp_retries,
            decision_timeout_ns: secs_to_ns(cfg.decision.timeout_s),
            arm_range: herb_robot::motion::baxter_left_arm_range(),
            outside: cfg.recovery.outside_limits,
        }
    }
}

/// Where the machine's outputs go, in the order they must be published. The shell numbers
/// every message from one sequence counter in call order and stamps it with the cycle's start.
pub trait Effects {
    /// Answers the pack-job request being handled ([`Job::job_request`]).
    fn reply(&mut self, job_id: u64, reason: RejectReason, detail: u32);
    /// Answers the cancel request being handled ([`Job::cancel_request`]).
    fn cancel_reply(&mut self, job_id: u64, reason: RejectReason);
    /// Answers the pick confirmation being handled ([`Job::confirm_request`]).
    fn confirm_reply(&mut self, job_id: u64, reason: RejectReason);
    /// Publishes a status. Its header, `cycles`, `deadline_misses` and `max_cycle_ns` are the
    /// shell's to fill; `rejected_inputs` and `rejected_requests` count the machine's
    /// rejections only.
    fn status(&mut self, status: &Status);
    /// Publishes a joint command (already checked against the limits).
    fn joint(&mut self, command: &Setpoint);
    /// Publishes a gripper command.
    fn gripper(&mut self, job_id: u64, action: GripperAction, object_type: u32);
    /// Hands a request to the planner; gives it back when the planner's ring is full.
    #[allow(clippy::result_large_err)] // moved, not copied around: the machine takes it back
    fn plan(&mut self, request: Request) -> Result<(), Request>;
    /// Hands a request to the decision worker; gives it back when its ring is full.
    #[allow(clippy::result_large_err)] // moved, not copied around: the machine takes it back
    fn decide(&mut self, request: DecisionRequest) -> Result<(), DecisionRequest>;
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    Ordering,
    /// The current object's pick is to be asked for (when a trajectory buffer is home).
    Starting,
    /// A plan is being made.
    Planning,
    /// Holding the current object at the lift pose until its decision comes (since `since`).
    AwaitDecision {
        since: u64,
    },
    Streaming {
        seg: usize,
        cursor: usize,
    },
    Gripper {
        action: GripperAction,
        seg: usize,
        since: u64,
    },
    /// A job fed by a person: above the pick station at the end of segment `seg` (the
    /// pre-grasp), waiting for the confirmation that the object is there before descending.
    AwaitOperator {
        seg: usize,
    },
    /// Braking: `cursor` into the brake buffer once it arrived (`None` while it is computed).
    Braking {
        cursor: Option<usize>,
        seg: usize,
        active_cursor: usize,
    },
    /// Holding after a fault, commanding no joint: resumes once every input has been fresh
    /// since `healthy_since` for `resume_after_s`. `recovered`: the job was taken up from the
    /// journal and has not resumed yet (nothing at all is commanded until it does).
    Faulted {
        healthy_since: Option<u64>,
        recovered: bool,
    },
    /// A grasp missed: the gripper opens (commanded at `since`), then the pick is tried again
    /// or the object skipped.
    Regrasp {
        since: u64,
    },
    /// A job taken up from the journal after a restart: `asked` once the planner has its
    /// order; then it waits, faulted, for fresh inputs.
    Recovering {
        asked: bool,
    },
    /// A job taken up from the journal to be ended, not resumed: the next tick reports the
    /// fault and fails the job.
    Abandoning,
    /// A cancelled job's retreat: `asked` once the planner has the request.
    Retreating {
        asked: bool,
    },
}

/// The job state machine. Built once; no method allocates.
pub struct Job {
    /// What the machine is built with.
    p: JobParams,
    inputs: Inputs,
    // the job; what belongs to one phase only is in its `Phase` variant
    phase: Phase,
    job_id: u64,
    /// The job's objects as submitted.
    objects: [u16; MAX_JOB_OBJECTS],
    /// `order` holds this job's packing order.
    ordered: bool,
    order: [u16; MAX_JOB_OBJECTS],
    count: usize,
    index: usize,
    done: usize,
    release_stamp: u64,
    holding: bool,
    /// The current object's decided placement (journaled: a restart does not decide it again)
    /// and, once its place is planned, its release configuration.
    placement: Option<Placement>,
    /// The latency of the current object's decision (its `Placed` repeats it).
    decision_ns: u64,
    /// A decision request is out: the object index it is for, and when it was sent.
    deciding: Option<(usize, u64)>,
    /// A decision is to be asked for on a later tick (the worker's ring was full, or it saw
    /// no fresh heightmap in time).
    decide_due: bool,
    /// When the current object began waiting for its decision (the fresh-heightmap clock).
    decide_since: u64,
    /// The current object's decision failed: the job ends at the arm's next standstill.
    decision_failed: Option<Fault>,
    /// The object in the gripper is held turned by a half turn (from its pick's plan).
    flip: bool,
    /// Time this job held objects at the lift pose waiting for decisions (ns).
    wait_ns: u64,
    /// Missed grasps of the current object.
    missed: u32,
    /// The current object's `Decided` was sent.
    announced: bool,
    fault: Fault,
    /// A client cancelled the job: brake, retreat, report `JobCancelled`.
    cancelling: bool,
    // trajectory buffers: two, moved between the machine and the planner, never allocated
    active: Option<Box<MotionPlan>>,
    spare: Option<Box<MotionPlan>>,
    brake: Option<Box<MotionPlan>>,
    out: Commands,
    /// The daemon is stopping (SIGINT, SIGTERM): brake, refuse jobs, exit.
    stopping: bool,
    /// The joint outside its limits the last `OutsideLimits` or `BeyondArmLimits` fault named.
    excess: Option<Excess>,
    /// The job waits for a confirmation before each grasp
    /// ([`PackJobRequest::CONFIRM_PICKS`]).
    confirm_picks: bool,
    /// The current try of the current object's pick is confirmed.
    confirmed: bool,
}

/// The machine's latched inputs: the newest valid sample of each source, the order checks that
/// admitted them, and how many were rejected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// The latest joint state.
    pub js: Option<JointState>,
    /// Its stamp.
    pub js_at: u64,
    /// Order of the joint states (per publisher: sequence and stamp grow).
    pub js_order: InOrder,
    /// The latest gripper state.
    pub gs: Option<GripperState>,
    /// Its stamp.
    pub gs_at: u64,
    /// Order of the gripper states.
    pub gs_order: InOrder,
    /// The arm adapter's latest word on why it withholds state.
    pub arm_blocker: ArmBlocker,
    /// Its stamp.
    pub arm_at: u64,
    /// Order of the arm adapter's statuses.
    pub arm_order: InOrder,
    /// When the newest valid heightmap was received (the cycle's start).
    pub hm_rx_at: u64,
    /// The newest valid heightmap's capture stamp.
    pub hm_stamp: u64,
    /// Sensor inputs rejected (invalid, from the future, out of order).
    pub rejected: u64,
    /// Client requests refused (pack jobs, cancels, pick confirmations).
    pub rejected_requests: u64,
}

impl Default for Inputs {
    /// Nothing received yet.
    fn default() -> Self {
        Self {
            js: None,
            js_at: 0,
            js_order: InOrder::default(),
            gs: None,
            gs_at: 0,
            gs_order: InOrder::default(),
            arm_blocker: ArmBlocker::None,
            arm_at: 0,
            arm_order: InOrder::default(),
            hm_rx_at: 0,
            hm_stamp: 0,
            rejected: 0,
            rejected_requests: 0,
        }
    }
}

/// What the machine commands: the last joint command, the gripper command and when it was
/// published, the heartbeat, and the commands held at the limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Commands {
    /// The last joint command (what a brake starts from).
    pub cmd: Setpoint,
    /// The gripper command.
    pub grip_cmd: GripperAction,
    /// The object it names (`NO_OBJECT`: none).
    pub grip_object: u32,
    /// The gripper command changed: it is published at the next tick.
    pub grip_due: bool,
    /// When the gripper command was last published.
    pub grip_sent_at: u64,
    /// When the last heartbeat was published.
    pub last_heartbeat: u64,
    /// Commands outside the joint limits replaced by holding the last one.
    pub limit_holds: u64,
    /// The configuration measured when the job started or last resumed: a command may lie
    /// outside the joint limits only between it and them (the way back in from an arm that
    /// sagged past a limit), never farther out.
    pub from: [f64; DOF],
}

impl Default for Commands {
    /// Nothing commanded yet: the gripper open.
    fn default() -> Self {
        Self {
            cmd: Setpoint::default(),
            grip_cmd: GripperAction::Open,
            grip_object: NO_OBJECT,
            grip_due: false,
            grip_sent_at: 0,
            last_heartbeat: 0,
            limit_holds: 0,
            from: [0.0; DOF],
        }
    }
}

/// The machine's state between jobs (no job, no request at the planner, both buffers home,
/// nothing commanded): what a run log's later segment starts from ([`Job::snapshot`],
/// [`Job::restore`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobSnapshot {
    /// The latched inputs.
    pub inputs: Inputs,
    /// The last commands (the gripper's is repeated between jobs too).
    pub commands: Commands,
    /// The last job: its objects, order and counts (what statuses between jobs report); no job
    /// runs (`job_id` 0, phase idle).
    pub job: JobRecord,
    /// The last release's stamp.
    pub release_stamp: u64,
    /// The last fault.
    pub fault: Fault,
    /// Stopping.
    pub stopping: bool,
}

/// A recovered job's arm stands at an object's release configuration when every joint is
/// within this of it (rad).
pub const RELEASE_Q_TOL_RAD: f64 = 0.02;

/// The configuration at which `plan` opens the gripper (the end of its releasing segment).
fn release_q(plan: &MotionPlan) -> Option<[f64; DOF]> {
    let seg = plan
        .segments()
        .iter()
        .find(|s| s.then == Some(GripperAction::Open))?;
    plan.setpoints
        .get(seg.end.checked_sub(1)?)
        .map(|s| s.position)
}

/// Faults that mean the arm's state is not seen (joint states stopped).
fn arm_unseen(f: Fault) -> bool {
    f.arm_unseen()
}

/// A state is not from the future when stamped at most [`MAX_FUTURE_STAMP_NS`] past the
/// cycle's start, or not past the clock when it was received (the loop may have been preempted
/// since the cycle began).
fn not_from_the_future(stamp_ns: u64, now: u64, received_ns: u64) -> bool {
    stamp_ns <= now + MAX_FUTURE_STAMP_NS || stamp_ns <= received_ns
}

impl Job {
    /// A machine without a job, with its two trajectory buffers.
    pub fn new(p: JobParams, a: Box<MotionPlan>, b: Box<MotionPlan>) -> Self {
        Self {
            p,
            inputs: Inputs::default(),
            phase: Phase::Idle,
            job_id: 0,
            objects: [0; MAX_JOB_OBJECTS],
            ordered: false,
            order: [0; MAX_JOB_OBJECTS],
            count: 0,
            index: 0,
            done: 0,
            release_stamp: 0,
            holding: false,
            placement: None,
            decision_ns: 0,
            deciding: None,
            decide_due: false,
            decide_since: 0,
            decision_failed: None,
            flip: false,
            wait_ns: 0,
            missed: 0,
            announced: false,
            fault: Fault::None,
            cancelling: false,
            active: Some(a),
            spare: Some(b),
            brake: None,
            out: Commands::default(),
            stopping: false,
            excess: None,
            confirm_picks: false,
            confirmed: false,
        }
    }

    /// A joint state from `publisher` (iceoryx2's id), received at `received_ns`: latched when
    /// valid, not from the future and in order; else counted as rejected.
    pub fn joint_state(&mut self, publisher: u128, m: &JointState, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.js_order.accept(publisher, &m.header) =>
            {
                self.inputs.js = Some(*m);
                self.inputs.js_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// A gripper state, as [`Job::joint_state`].
    pub fn gripper_state(&mut self, publisher: u128, m: &GripperState, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.gs_order.accept(publisher, &m.header) =>
            {
                self.inputs.gs = Some(*m);
                self.inputs.gs_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// The arm adapter's status, as [`Job::joint_state`].
    pub fn arm_status(&mut self, publisher: u128, m: &ArmStatus, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.arm_order.accept(publisher, &m.header) =>
            {
                self.inputs.arm_blocker =
                    ArmBlocker::from_code(m.blocker).unwrap_or(ArmBlocker::None);
                self.inputs.arm_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// A heightmap frame, read in place: only its header and grid are checked here (the
    /// planner checks every cell of the frame it decides on).
    pub fn heightmap(&mut self, f: &HeightmapFrame, now: u64) {
        match f.validate_meta() {
            Ok(()) => {
                self.inputs.hm_rx_at = now;
                self.inputs.hm_stamp = self.inputs.hm_stamp.max(f.header.stamp_ns);
            }
            Err(_) => self.inputs.rejected += 1,
        }
    }

    /// A pack-job request: answered through [`Effects::reply`] (a malformed request gets what
    /// is wrong with it whatever the state; then `ShuttingDown`, `Busy`, `NotReady`), and
    /// started when accepted.
    pub fn job_request(&mut self, r: &PackJobRequest, now: u64, fx: &mut impl Effects) {
        let verdict = r.validate(self.p.catalog_len).and_then(|()| {
            if self.stopping {
                Err((RejectReason::ShuttingDown, 0))
            } else if self.phase != Phase::Idle {
                Err((RejectReason::Busy, 0))
            } else if let Some(why) = self.not_ready(now) {
                Err((RejectReason::NotReady, why as u32))
            } else if let Some(g) = self.inputs.gs.filter(|g| g.holding == 1) {
                // What the gripper holds is the truth: never start a job that would place it.
                let known = (g.object_type != NO_OBJECT).then_some(g.object_type);
                let believed = self.holding.then(|| self.current_type());
                Err((
                    RejectReason::Holding,
                    known.or(believed).unwrap_or(NO_OBJECT),
                ))
            } else {
                Ok(())
            }
        });
        let (reason, detail) = verdict.err().unwrap_or((RejectReason::None, 0));
        if reason != RejectReason::None {
            self.inputs.rejected_requests += 1;
            if matches!(
                Fault::from_code(detail),
                Some(Fault::OutsideLimits | Fault::BeyondArmLimits)
            ) && reason == RejectReason::NotReady
            {
                // Named in the statuses that follow (the client reads the next heartbeat).
                self.excess = self.measured_excess().map(|(_, e)| e);
            }
        }
        fx.reply(r.job_id, reason, detail);
        if reason == RejectReason::None {
            self.start_job(r, fx);
        }
    }

    /// A cancel request: answered through [`Effects::cancel_reply`] (`Malformed`, then
    /// `ShuttingDown`, then `NoSuchJob` unless it names the running job; a repeat is accepted
    /// again). The arm brakes if it moves, then retreats straight up; a job waiting on a fault
    /// is cancelled where it stands. Either way `JobCancelled` ends the job.
    pub fn cancel_request(&mut self, r: &CancelJobRequest, fx: &mut impl Effects) {
        let reason = match r.validate() {
            Err(e) => e,
            Ok(()) if self.stopping => RejectReason::ShuttingDown,
            Ok(()) if self.job_id == 0 || r.job_id != self.job_id => RejectReason::NoSuchJob,
            Ok(()) => RejectReason::None,
        };
        if reason != RejectReason::None {
            self.inputs.rejected_requests += 1;
        }
        fx.cancel_reply(r.job_id, reason);
        if reason != RejectReason::None || self.cancelling {
            return;
        }
        self.cancelling = true;
        match self.phase {
            Phase::Streaming { .. } if self.moving() => self.begin_brake(fx),
            // At rest: retreat now.
            Phase::Ordering
            | Phase::Starting
            | Phase::AwaitDecision { .. }
            | Phase::Streaming { .. }
            | Phase::AwaitOperator { .. }
            | Phase::Gripper { .. } => self.retreat(fx),
            // Planning: when the plan comes back. Braking: when it ends. Faulted: next tick.
            _ => {}
        }
    }

    /// A pick confirmation: answered through [`Effects::confirm_reply`] (`Malformed`,
    /// `ShuttingDown`, `NoSuchJob` unless it names the running job, `NotAwaited` unless the job
    /// asks for confirmations and it names the current object and try; a repeat is accepted
    /// again). Accepted, the arm descends to the grasp once it stands above the station.
    pub fn confirm_request(&mut self, r: &ConfirmPickRequest, fx: &mut impl Effects) {
        let reason = match r.validate() {
            Err(e) => e,
            Ok(()) if self.stopping => RejectReason::ShuttingDown,
            Ok(()) if self.job_id == 0 || r.job_id != self.job_id => RejectReason::NoSuchJob,
            Ok(())
                if !self.confirm_picks
                    || self.cancelling
                    || self.holding
                    || r.object_index as usize != self.index
                    || r.attempt != self.missed =>
            {
                RejectReason::NotAwaited
            }
            Ok(()) => RejectReason::None,
        };
        if reason != RejectReason::None {
            self.inputs.rejected_requests += 1;
        } else {
            self.confirmed = true;
        }
        fx.confirm_reply(r.job_id, reason);
    }

    /// Asks for the retreat of a cancelled job (when a buffer is home; else on a later tick).
    fn retreat(&mut self, fx: &mut impl Effects) {
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        self.phase = Phase::Retreating { asked: false };
        let Some(buf) = self.spare.take() else {
            return;
        };
        let held = self.holding || self.inputs.gs.is_some_and(|g| g.holding == 1);
        let req = Request::Retreat {
            from: self.out.cmd.position,
            held: held.then(|| self.order.get(self.index).copied()).flatten(),
            buf,
        };
        match fx.plan(req) {
            Ok(()) => self.phase = Phase::Retreating { asked: true },
            Err(Request::Retreat { buf, .. }) => self.spare = Some(buf),
            Err(_) => {}
        }
    }

    fn start_job(&mut self, r: &PackJobRequest, fx: &mut impl Effects) {
        let n = r.objects().len();
        let mut objects = [0u16; MAX_JOB_OBJECTS];
        objects[..n].copy_from_slice(r.objects());
        self.job_id = r.job_id;
        self.objects = objects;
        self.ordered = false;
        self.placement = None;
        self.forget_decision();
        self.flip = false;
        self.wait_ns = 0;
        self.count = n;
        self.index = 0;
        self.done = 0;
        self.fault = Fault::None;
        self.cancelling = false;
        self.holding = self.inputs.gs.is_some_and(|g| g.holding == 1);
        self.missed = 0;
        self.announced = false;
        self.release_stamp = 0;
        self.confirm_picks = r.flags & PackJobRequest::CONFIRM_PICKS != 0;
        self.confirmed = false;
        self.excess = None;
        let q = self.inputs.js.map(|j| j.position).unwrap_or_default();
        self.out.cmd = Setpoint::at_rest(q);
        self.out.from = q;
        // A known gripper state to start from: open, unless it holds something (which the job
        // then deals with as its first object's grasp would: it is never dropped here).
        if !self.holding {
            self.out.grip_cmd = GripperAction::Open;
            self.out.grip_object = NO_OBJECT;
            self.out.grip_due = true;
        }
        let _ = fx.plan(Request::Order {
            job_id: r.job_id,
            objects,
            count: n,
            ordered: false,
        });
        self.phase = Phase::Ordering;
        self.emit(fx, StatusEvent::Accepted, NO_OBJECT, [0.0; 4], 0);
        self.say_outside_limits(fx);
    }

    /// The measured arm outside the configured joint limits, and what it means: `None` when
    /// inside (or nothing measured yet); `BeyondArmLimits` past the arm's own limits;
    /// else `OutsideLimits`.
    fn measured_excess(&self) -> Option<(Fault, Excess)> {
        let q = self.inputs.js?.position;
        let (lo, hi) = &self.p.arm_range;
        if let Some(e) = excess_of(&q, lo, hi) {
            return Some((Fault::BeyondArmLimits, e));
        }
        excess_of(&q, &self.p.lower, &self.p.upper).map(|e| (Fault::OutsideLimits, e))
    }

    /// At a job's start or resume with the arm measured outside the joint limits (inside its
    /// own): reported as a fault naming the joint, while the planner brings it back inside
    /// before the first motion; the job goes on.
    fn say_outside_limits(&mut self, fx: &mut impl Effects) {
        if let Some((fault, e)) = self.measured_excess() {
            self.fault = fault;
            self.excess = Some(e);
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
        }
    }

    /// One planner response.
    pub fn planner_response(&mut self, resp: Response, now: u64, fx: &mut impl Effects) {
        match resp {
            Response::Ordered {
                job_id,
                order,
                count,
            } if job_id == self.job_id => {
                self.order = order;
                self.count = count;
                self.ordered = true;
                match self.phase {
                    Phase::Ordering => self.begin_object(fx, now),
                    Phase::Recovering { .. } | Phase::Abandoning => {
                        self.phase = Phase::Faulted {
                            healthy_since: None,
                            recovered: true,
                        }
                    }
                    _ => {}
                }
            }
            Response::Ordered { .. } => {}
            Response::OrderFailed { job_id }
                if job_id == self.job_id
                    && matches!(
                        self.phase,
                        Phase::Ordering | Phase::Recovering { .. } | Phase::Abandoning
                    ) =>
            {
                self.fault = Fault::Decision;
                self.finish(fx, StatusEvent::JobFailed);
            }
            // A stale reply (an earlier job's) changes nothing.
            Response::OrderFailed { .. } => {}
            Response::Planned(plan) if matches!(self.phase, Phase::Retreating { .. }) => {
                if let Some(old) = self.active.take() {
                    self.recycle(old);
                }
                self.active = Some(plan);
                self.phase = Phase::Streaming { seg: 0, cursor: 0 };
            }
            Response::Planned(plan) => {
                let planning = matches!(self.phase, Phase::Planning);
                if planning && !self.stopping && !self.cancelling {
                    if let Some(old) = self.active.take() {
                        self.recycle(old);
                    }
                    // A place (or pick and place) knows where the gripper opens: journaled, so
                    // that a restart tells a released object from a held one.
                    if let Some(q) = release_q(&plan) {
                        self.placement = Some(Placement {
                            index: plan.index as u16,
                            pose: plan.pose,
                            release_q: Some(q),
                        });
                    }
                    self.flip = plan.flip;
                    self.active = Some(plan);
                    self.phase = Phase::Streaming { seg: 0, cursor: 0 };
                } else {
                    self.recycle(plan);
                    if planning && self.cancelling && !self.stopping {
                        self.retreat(fx);
                    }
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
                    Phase::Planning if self.cancelling => self.retreat(fx),
                    Phase::Planning => {
                        self.fault = fault;
                        self.finish(fx, StatusEvent::JobFailed);
                    }
                    Phase::Braking { .. } => self.enter_faulted(fx),
                    // No way up: the arm stays where it stopped.
                    Phase::Retreating { .. } => {
                        self.fault = fault;
                        self.finish(fx, StatusEvent::JobCancelled);
                    }
                    _ => {}
                }
            }
        }
    }

    /// One decision from the worker. A stale one (an earlier job's or object's, or one the
    /// machine stopped waiting for) changes nothing.
    pub fn decision_response(&mut self, d: DecisionResponse, now: u64, fx: &mut impl Effects) {
        let awaited = self.job_id != 0
            && d.job_id == self.job_id
            && self.deciding.is_some_and(|(i, _)| i == d.index as usize)
            && self.index == d.index as usize;
        if !awaited {
            return;
        }
        self.deciding = None;
        match d.outcome {
            Ok(pose) => {
                self.placement = Some(Placement {
                    index: self.index as u16,
                    pose,
                    release_q: None,
                });
                self.decision_ns = d.decision_ns;
                // An object already announced (its place was planned before a fault or a
                // restart) is not announced again: its `Placed` carries the pose.
                if !self.announced {
                    self.announced = true;
                    self.emit(
                        fx,
                        StatusEvent::Decided,
                        self.current_type(),
                        pose,
                        d.decision_ns,
                    );
                }
                if let Phase::AwaitDecision { since } = self.phase {
                    self.wait_ns += now.saturating_sub(since);
                    self.request_place(fx, now);
                }
            }
            // No valid frame newer than the release within the worker's wait: asked again,
            // until the fresh-heightmap timeout (from when the object began waiting) says it
            // is a fault.
            Err(Fault::HeightmapTimeout) => {
                if now.saturating_sub(self.decide_since) > self.p.timeouts.fresh_heightmap_ns {
                    self.decide_since = now;
                    self.raise(fx, Fault::HeightmapTimeout);
                } else {
                    self.decide_due = true;
                }
            }
            Err(f) => self.decision_failed = Some(f),
        }
    }

    /// The rest of a cycle: the stop request (`stop`, seen once), input health, one step of
    /// the current phase, then the commands and the heartbeat. True when the daemon may exit
    /// (stopping, and the arm no longer braking).
    pub fn tick(&mut self, now: u64, stop: bool, fx: &mut impl Effects) -> bool {
        if stop && !self.stopping {
            self.stopping = true;
            self.begin_stop(fx);
        }
        self.check_health(now, fx);
        self.step(now, fx);
        self.publish(now, fx);
        self.stopping && !matches!(self.phase, Phase::Braking { .. })
    }

    /// A status with `event` about no particular object, as the machine stands (the shell's
    /// `Shutdown`).
    pub fn status(&self, event: StatusEvent) -> Status {
        self.status_of(event, NO_OBJECT, [0.0; 4], 0)
    }

    /// The state between jobs, when the machine is idle with both buffers home (else `None`).
    pub fn snapshot(&self) -> Option<JobSnapshot> {
        if self.phase != Phase::Idle || self.active.is_none() || self.spare.is_none() {
            return None;
        }
        Some(JobSnapshot {
            inputs: self.inputs,
            commands: self.out,
            job: self.record(),
            release_stamp: self.release_stamp,
            fault: self.fault,
            stopping: self.stopping,
        })
    }

    /// Takes up the state of `s` (an idle machine's), keeping this machine's buffers and
    /// parameters.
    pub fn restore(&mut self, s: &JobSnapshot) {
        self.inputs = s.inputs;
        self.out = s.commands;
        self.phase = Phase::Idle;
        let r = &s.job;
        self.job_id = r.job_id;
        self.count = (r.count as usize).min(MAX_JOB_OBJECTS);
        self.objects = r.objects;
        self.ordered = r.ordered;
        self.order = r.order;
        self.index = r.index as usize;
        self.done = r.done as usize;
        self.holding = r.holding;
        self.flip = r.flip;
        self.placement = r.placement;
        self.forget_decision();
        self.release_stamp = s.release_stamp;
        self.fault = s.fault;
        self.cancelling = false;
        self.stopping = s.stopping;
        self.announced = false;
        self.missed = 0;
        self.confirm_picks = r.confirm_picks;
        self.confirmed = false;
        self.excess = None;
    }

    /// The state reported in statuses.
    pub fn state(&self) -> JobState {
        match self.phase {
            Phase::Idle => JobState::Idle,
            Phase::Braking { .. } => JobState::Braking,
            Phase::Faulted { .. } => JobState::Faulted,
            _ => JobState::Running,
        }
    }

    /// The job was taken up from the journal and has not resumed yet.
    fn recovered(&self) -> bool {
        matches!(
            self.phase,
            Phase::Recovering { .. }
                | Phase::Abandoning
                | Phase::Faulted {
                    recovered: true,
                    ..
                }
        )
    }

    /// Commands are published: a job runs, and it is not a recovered one that has not resumed
    /// yet (between jobs, and until a job taken up from the journal resumes, nothing is).
    fn commanding(&self) -> bool {
        !matches!(self.phase, Phase::Idle) && !self.recovered()
    }

    /// Sensor inputs rejected so far (invalid, from the future, out of order).
    pub fn rejected_inputs(&self) -> u64 {
        self.inputs.rejected
    }

    /// Client requests refused so far.
    pub fn rejected_requests(&self) -> u64 {
        self.inputs.rejected_requests
    }

    /// Commands outside the joint limits replaced by holding the last one.
    pub fn limit_holds(&self) -> u64 {
        self.out.limit_holds
    }

    /// The job as the machine holds it, whatever its phase (between jobs: the last job's
    /// objects, order and counts, `job_id` 0); the placement only if it is the current
    /// object's. The order is the machine's even before the job is ordered: statuses name the
    /// current object from it.
    fn record(&self) -> JobRecord {
        let phase = match self.phase {
            Phase::Idle => ObjectPhase::Idle,
            Phase::Ordering => ObjectPhase::Ordering,
            Phase::Starting | Phase::Planning | Phase::AwaitDecision { .. } if self.holding => {
                ObjectPhase::Carrying
            }
            Phase::Starting | Phase::Planning | Phase::AwaitDecision { .. } => {
                ObjectPhase::Deciding
            }
            Phase::Streaming { .. } | Phase::Gripper { .. } | Phase::Retreating { .. }
                if self.holding =>
            {
                ObjectPhase::Carrying
            }
            Phase::Streaming { .. }
            | Phase::Gripper { .. }
            | Phase::AwaitOperator { .. }
            | Phase::Regrasp { .. }
            | Phase::Retreating { .. } => ObjectPhase::Moving,
            Phase::Braking { .. }
            | Phase::Faulted { .. }
            | Phase::Recovering { .. }
            | Phase::Abandoning => ObjectPhase::Halted,
        };
        // Past the job's objects the machine reads nothing: kept as zeros.
        let (mut objects, mut order) = ([0; MAX_JOB_OBJECTS], [0; MAX_JOB_OBJECTS]);
        objects[..self.count].copy_from_slice(&self.objects[..self.count]);
        order[..self.count].copy_from_slice(&self.order[..self.count]);
        JobRecord {
            job_id: self.job_id,
            count: self.count as u16,
            objects,
            ordered: self.ordered,
            order,
            index: self.index as u16,
            done: self.done as u16,
            holding: self.holding,
            flip: self.flip,
            phase,
            placement: self.placement.filter(|p| p.index as usize == self.index),
            confirm_picks: self.confirm_picks,
        }
    }

    /// The running job as the journal keeps it ([`JobRecord::NONE`] between jobs and while a
    /// cancelled job retreats: a cancelled job is not taken up again); until the job is
    /// ordered, its order is the objects as submitted. Allocates nothing; the loop compares it
    /// with the last one it handed to the writer.
    pub fn journal(&self) -> JobRecord {
        if self.job_id == 0
            || self.cancelling
            || matches!(self.phase, Phase::Idle | Phase::Retreating { .. })
        {
            return JobRecord::NONE;
        }
        let mut r = self.record();
        if !r.ordered {
            r.order = r.objects;
        }
        r
    }

    /// Takes up the unfinished job `r` from the journal (an idle machine at start, before the
    /// first cycle): the next ticks report [`Fault::Restarted`] and hand the planner the job's
    /// order, then the job waits, faulted and commanding nothing, until its inputs are fresh,
    /// and resumes from the measured state (see the module's "Restart"). With `resume` false,
    /// the first tick reports the fault and ends the job, failed, instead.
    pub fn recover(&mut self, r: &JobRecord, resume: bool) {
        self.job_id = r.job_id;
        self.count = (r.count as usize).min(MAX_JOB_OBJECTS);
        self.objects = r.objects;
        self.ordered = r.ordered;
        // Until the planner answers, statuses name the current object from the submitted list.
        self.order = if r.ordered { r.order } else { r.objects };
        self.index = (r.index as usize).min(self.count);
        self.done = (r.done as usize).min(self.index);
        self.holding = r.holding;
        self.flip = r.flip;
        self.placement = r.placement;
        self.forget_decision();
        // A placement in the journal was announced before the crash.
        self.announced = r.placement.is_some_and(|p| p.index as usize == self.index);
        self.release_stamp = 0;
        self.fault = Fault::Restarted;
        self.cancelling = false;
        self.confirm_picks = r.confirm_picks;
        self.confirmed = false;
        self.phase = if resume {
            Phase::Recovering { asked: false }
        } else {
            Phase::Abandoning
        };
    }

    /// Why a job cannot run now, if it cannot: the stale input's fault (see
    /// [`Job::stale_input`]), or the missing one's.
    fn not_ready(&self, now: u64) -> Option<Fault> {
        if self.inputs.js.is_none() {
            Some(self.joint_fault(now))
        } else if self.inputs.gs.is_none() {
            Some(Fault::GripperStateTimeout)
        } else if let Some(f) = self.stale_input(now) {
            Some(f)
        } else {
            // Outside the arm's own limits: never moved. Outside herbd's only: brought back
            // in by the job's first motion, unless configured to refuse.
            match self.measured_excess() {
                Some((Fault::BeyondArmLimits, _)) => Some(Fault::BeyondArmLimits),
                Some((f, _)) if self.p.outside == OutsideLimits::Refuse => Some(f),
                _ => None,
            }
        }
    }

    /// The fault for joint states that stopped: what the arm adapter says, if it spoke after
    /// the last joint state and recently (within three of its periods; an adapter that says
    /// the robot can move while no joint state comes: the robot is silent); else the adapter
    /// itself is silent (stopped, killed: its last word came before its last joint state).
    fn joint_fault(&self, now: u64) -> Fault {
        let said_recently = self.arm_status_fresh(now) && self.inputs.arm_at > self.inputs.js_at;
        match self.inputs.arm_blocker {
            _ if !said_recently => Fault::JointStateTimeout,
            ArmBlocker::None => Fault::RobotSilent,
            b => b.fault(),
        }
    }

    /// The arm adapter spoke within three of its status periods.
    fn arm_status_fresh(&self, now: u64) -> bool {
        self.inputs.arm_at != 0 && now.saturating_sub(self.inputs.arm_at) < 3 * ARM_STATUS_PERIOD_NS
    }

    fn stale_input(&self, now: u64) -> Option<Fault> {
        if now.saturating_sub(self.inputs.js_at) >= self.p.timeouts.joint_state_ns {
            Some(self.joint_fault(now))
        } else if now.saturating_sub(self.inputs.gs_at) >= self.p.timeouts.gripper_state_ns {
            Some(Fault::GripperStateTimeout)
        } else if now.saturating_sub(self.inputs.hm_rx_at) >= self.p.timeouts.heightmap_ns {
            Some(Fault::HeightmapTimeout)
        } else {
            None
        }
    }

    fn check_health(&mut self, now: u64, fx: &mut impl Effects) {
        match self.phase {
            Phase::Idle
            | Phase::Braking { .. }
            | Phase::Faulted { .. }
            | Phase::Recovering { .. }
            | Phase::Abandoning => {}
            _ => {
                if let Some(f) = self.stale_input(now) {
                    self.raise(fx, f);
                }
            }
        }
    }

    /// A fault: report, brake if moving and the arm is seen, hold.
    fn raise(&mut self, fx: &mut impl Effects, fault: Fault) {
        self.fault = fault;
        self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
        if arm_unseen(fault) {
            // No joint state: the adapter passes no command on; a brake streamed now would
            // only be a setpoint planned before the interruption.
            self.enter_faulted(fx);
        } else {
            self.begin_brake(fx);
        }
    }

    /// The last command moves the arm.
    fn moving(&self) -> bool {
        self.out.cmd.velocity.iter().any(|v| *v != 0.0)
            || self.out.cmd.acceleration.iter().any(|a| *a != 0.0)
    }

    fn begin_brake(&mut self, fx: &mut impl Effects) {
        let moving = self.moving();
        let (seg, cursor) = match self.phase {
            Phase::Streaming { seg, cursor } => (seg, cursor),
            _ => (0, 0),
        };
        if moving && let Some(buf) = self.spare.take() {
            match fx.plan(Request::Brake {
                state: self.out.cmd,
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
        self.enter_faulted(fx);
    }

    fn enter_faulted(&mut self, fx: &mut impl Effects) {
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        self.phase = Phase::Faulted {
            healthy_since: None,
            recovered: self.recovered(),
        };
        self.emit(fx, StatusEvent::Braked, self.current_type(), [0.0; 4], 0);
    }

    fn begin_stop(&mut self, fx: &mut impl Effects) {
        match self.phase {
            Phase::Streaming { .. } => {
                self.fault = Fault::Stop;
                self.begin_brake(fx);
            }
            // Nothing runs: nothing to halt (the shutdown reports the idle state).
            Phase::Braking { .. } | Phase::Idle => {}
            _ => self.enter_faulted(fx),
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

    /// Ends the job with `end` (`JobDone`, `JobFailed` or `JobCancelled`).
    fn finish(&mut self, fx: &mut impl Effects, end: StatusEvent) {
        self.phase = Phase::Idle;
        self.cancelling = false;
        self.forget_decision();
        self.emit(fx, end, NO_OBJECT, [0.0; 4], 0);
        self.job_id = 0;
    }

    /// Drops the current object's decision and stops waiting for one (a late answer is then
    /// stale).
    fn forget_decision(&mut self) {
        self.deciding = None;
        self.decide_due = false;
        self.decision_failed = None;
    }

    /// The current object's placement, decided already.
    fn decided_pose(&self) -> Option<[f32; 4]> {
        self.placement
            .filter(|p| p.index as usize == self.index)
            .map(|p| p.pose)
    }

    /// Starts the current object: its decision is asked for, and its pick planned meanwhile.
    fn begin_object(&mut self, fx: &mut impl Effects, now: u64) {
        self.decision_failed = None;
        self.confirmed = false;
        self.decide_since = now;
        self.ask_decision(fx, now);
        self.phase = Phase::Starting;
        self.request_motion(fx, Motion::Pick);
    }

    /// Asks the decision worker where the current object goes (again on a later tick if its
    /// ring is full).
    fn ask_decision(&mut self, fx: &mut impl Effects, now: u64) {
        let req = DecisionRequest {
            job_id: self.job_id,
            index: self.index as u32,
            order: self.order,
            count: self.count as u32,
            after_stamp_ns: self.release_stamp,
        };
        match fx.decide(req) {
            Ok(()) => {
                self.deciding = Some((self.index, now));
                self.decide_due = false;
            }
            Err(_) => self.decide_due = true,
        }
    }

    /// The picked object is held at the lift pose: its place is planned if its placement is
    /// decided; else the arm holds it there until the decision comes (the wait is counted),
    /// and a failed decision ends the job.
    fn await_decision(&mut self, fx: &mut impl Effects, now: u64) {
        if let Some(f) = self.decision_failed {
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
        } else if self.decided_pose().is_some() {
            self.request_place(fx, now);
        } else {
            if self.deciding.is_none() && !self.decide_due {
                self.decide_since = now;
                self.decide_due = true;
            }
            self.phase = Phase::AwaitDecision { since: now };
        }
    }

    /// Asks for the held object's place at its decided placement.
    fn request_place(&mut self, fx: &mut impl Effects, now: u64) {
        self.phase = Phase::AwaitDecision { since: now };
        self.request_motion(fx, Motion::Place { flip: self.flip });
    }

    /// Asks the planner for the current object's `motion` (a place or a pick and place at its
    /// decided placement) when a trajectory buffer is home; the phase becomes `Planning`, or
    /// stays as it is (`Starting`, `AwaitDecision`) to ask again on a later tick.
    fn request_motion(&mut self, fx: &mut impl Effects, motion: Motion) {
        let pose = match motion {
            Motion::Pick => [0.0; 4],
            Motion::Place { .. } | Motion::PickAndPlace => match self.decided_pose() {
                Some(p) => p,
                None => return,
            },
        };
        let Some(buf) = self.spare.take() else {
            return;
        };
        let req = Request::Plan {
            index: self.index as u32,
            object: self.order[self.index],
            from: self.out.cmd.position,
            motion,
            pose,
            buf,
        };
        match fx.plan(req) {
            Ok(()) => {
                self.phase = Phase::Planning;
                if self.confirm_picks && !self.confirmed && !matches!(motion, Motion::Place { .. })
                {
                    // A pick: the operator is asked for the object now, while the arm comes.
                    self.emit(
                        fx,
                        StatusEvent::AwaitingObject,
                        self.current_type(),
                        [0.0; 4],
                        0,
                    );
                }
            }
            Err(Request::Plan { buf, .. }) => self.spare = Some(buf),
            Err(_) => {}
        }
    }

    fn step(&mut self, now: u64, fx: &mut impl Effects) {
        // The decision runs beside the motion: asked again when due, and given up when it does
        // not come in time (a hung worker never holds the arm).
        let live = self.job_id != 0
            && !self.stopping
            && !self.cancelling
            && matches!(
                self.phase,
                Phase::Starting
                    | Phase::Planning
                    | Phase::Streaming { .. }
                    | Phase::Gripper { .. }
                    | Phase::AwaitOperator { .. }
                    | Phase::Regrasp { .. }
                    | Phase::AwaitDecision { .. }
            );
        if live && self.decision_failed.is_none() && self.decided_pose().is_none() {
            if self.decide_due && self.deciding.is_none() {
                self.ask_decision(fx, now);
            }
            if let Some((_, at)) = self.deciding
                && now.saturating_sub(at) > self.p.decision_timeout_ns
            {
                self.deciding = None;
                self.decision_failed = Some(Fault::Decision);
            }
        }
        match self.phase {
            Phase::Idle | Phase::Ordering | Phase::Planning => {}
            Phase::Starting => {
                if !self.stopping {
                    self.request_motion(fx, Motion::Pick);
                }
            }
            Phase::AwaitDecision { since } => {
                if self.stopping {
                    return;
                }
                if let Some(f) = self.decision_failed {
                    self.wait_ns += now.saturating_sub(since);
                    self.fault = f;
                    self.finish(fx, StatusEvent::JobFailed);
                } else if self.decided_pose().is_some() {
                    self.request_motion(fx, Motion::Place { flip: self.flip });
                    if self.phase == Phase::Planning {
                        self.wait_ns += now.saturating_sub(since);
                    }
                }
            }
            Phase::Streaming { seg, cursor } => self.stream(fx, now, seg, cursor),
            Phase::Gripper { action, seg, since } => self.grip(fx, now, action, seg, since),
            Phase::AwaitOperator { seg } => {
                if self.confirmed && !self.stopping && !self.cancelling {
                    self.next_segment(fx, now, seg + 1);
                }
            }
            Phase::Regrasp { since } => self.regrasp(fx, now, since),
            Phase::Braking {
                cursor,
                seg,
                active_cursor,
            } => self.brake_step(fx, cursor, seg, active_cursor),
            Phase::Retreating { asked: false } => self.retreat(fx),
            Phase::Retreating { asked: true } | Phase::Recovering { asked: true } => {}
            Phase::Abandoning => {
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.finish(fx, StatusEvent::JobFailed);
            }
            Phase::Recovering { asked: false } => {
                let (objects, ordered) = if self.ordered {
                    (self.order, true)
                } else {
                    (self.objects, false)
                };
                let order = Request::Order {
                    job_id: self.job_id,
                    objects,
                    count: self.count,
                    ordered,
                };
                if fx.plan(order).is_ok() {
                    self.phase = Phase::Recovering { asked: true };
                    self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                }
            }
            Phase::Faulted {
                healthy_since,
                recovered,
            } => {
                if self.cancelling {
                    // Cancelled where it stopped (its inputs may be gone: no retreat).
                    self.finish(fx, StatusEvent::JobCancelled);
                    return;
                }
                if self.stopping || self.job_id == 0 {
                    return;
                }
                if let Some(why) = self.not_ready(now) {
                    self.phase = Phase::Faulted {
                        healthy_since: None,
                        recovered,
                    };
                    // The arm adapter said more about the joint states that stopped (or it
                    // changed: an e-stop became a disable): say it once.
                    // (An adapter that says "ready" while its first joint state is on the way
                    // changes nothing.)
                    let ready_said =
                        self.inputs.arm_blocker == ArmBlocker::None && self.arm_status_fresh(now);
                    let limits = matches!(why, Fault::OutsideLimits | Fault::BeyondArmLimits);
                    if (arm_unseen(why) && arm_unseen(self.fault) && !ready_said || limits)
                        && why != self.fault
                    {
                        // A held job that the arm's position keeps from resuming: said once,
                        // naming the joint.
                        self.fault = why;
                        if limits {
                            self.excess = self.measured_excess().map(|(_, e)| e);
                        }
                        self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                    }
                    return;
                }
                let since = healthy_since.unwrap_or(now);
                // Resume once both trajectory buffers are home (a plan may still be in flight).
                let resuming =
                    now - since >= self.p.timeouts.resume_after_ns && self.spare.is_some();
                // A recovered job is the journal's, commanding nothing, until it resumes.
                self.phase = Phase::Faulted {
                    healthy_since: Some(since),
                    recovered: recovered && !resuming,
                };
                if resuming {
                    self.resume(fx, now, recovered);
                }
            }
        }
    }

    fn grip(
        &mut self,
        fx: &mut impl Effects,
        now: u64,
        action: GripperAction,
        seg: usize,
        since: u64,
    ) {
        let Some(g) = self.inputs.gs else { return };
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
                    let dns = self.decision_ns;
                    let (ty, pose) = self
                        .active
                        .as_ref()
                        .map(|p| (p.object as u32, p.pose))
                        .unwrap_or((NO_OBJECT, [0.0; 4]));
                    self.done += 1;
                    self.emit(fx, StatusEvent::Placed, ty, pose, dns);
                    self.index += 1;
                    self.announced = false;
                    self.missed = 0;
                    self.placement = None;
                    self.decision_ns = 0;
                    self.forget_decision();
                }
            }
            self.next_segment(fx, now, seg + 1);
        } else if now.saturating_sub(since) > self.p.timeouts.gripper_action_ns {
            if action == GripperAction::Close && g.holding == 0 {
                // Closed on nothing (or not holding in time): open, then pick again or skip.
                self.fault = Fault::MissedGrasp;
                self.missed += 1;
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.out.grip_cmd = GripperAction::Open;
                self.out.grip_object = NO_OBJECT;
                self.out.grip_due = true;
                self.phase = Phase::Regrasp { since: now };
                return;
            }
            self.fault = Fault::Gripper;
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
            self.finish(fx, StatusEvent::JobFailed);
        }
    }

    /// After a missed grasp: once the gripper reports open, pick again with the same placement
    /// (at most `grasp_retries` times), else skip the object.
    fn regrasp(&mut self, fx: &mut impl Effects, now: u64, since: u64) {
        if self.stopping {
            return;
        }
        let Some(g) = self.inputs.gs else { return };
        let opened = g.closed == 0 && g.header.stamp_ns >= since;
        if !opened {
            if now.saturating_sub(since) > self.p.timeouts.gripper_action_ns {
                self.fault = Fault::Gripper;
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.finish(fx, StatusEvent::JobFailed);
            }
            return;
        }
        if self.cancelling {
            self.retreat(fx);
            return;
        }
        if let Some(f) = self.decision_failed {
            // Its decision failed meanwhile: the job ends here, the gripper open.
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
            return;
        }
        if self.missed <= self.p.grasp_retries {
            // The same object picked again; its decision (made or still coming) stands. A
            // person feeding the station puts it back and confirms this try.
            self.confirmed = false;
            self.phase = Phase::Starting;
            self.request_motion(fx, Motion::Pick);
            return;
        }
        // Given up: skipped with its reason, the job goes on.
        self.emit(fx, StatusEvent::Skipped, self.current_type(), [0.0; 4], 0);
        self.index += 1;
        self.announced = false;
        self.missed = 0;
        self.placement = None;
        self.forget_decision();
        if self.index >= self.count {
            self.finish(fx, StatusEvent::JobDone);
        } else {
            self.begin_object(fx, now);
        }
    }

    fn brake_step(
        &mut self,
        fx: &mut impl Effects,
        cursor: Option<usize>,
        seg: usize,
        active_cursor: usize,
    ) {
        match cursor {
            None => {
                // Until the brake is computed (a cycle or two), go on along the plan, which is
                // within every limit, and hold at its segment end.
                if let Some(p) = &self.active
                    && let Some(sg) = p.segments().get(seg)
                    && active_cursor < sg.end
                    && let Some(s) = p.setpoints.get(active_cursor)
                {
                    self.out.cmd = *s;
                    self.phase = Phase::Braking {
                        cursor: None,
                        seg,
                        active_cursor: active_cursor + 1,
                    };
                } else {
                    self.out.cmd.velocity = [0.0; DOF];
                    self.out.cmd.acceleration = [0.0; DOF];
                }
            }
            Some(k) => {
                let next = self
                    .brake
                    .as_ref()
                    .and_then(|b| b.setpoints.get(k).copied());
                match next {
                    Some(s) => {
                        self.out.cmd = s;
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
                        if self.cancelling && !self.stopping {
                            self.out.cmd.velocity = [0.0; DOF];
                            self.out.cmd.acceleration = [0.0; DOF];
                            self.emit(fx, StatusEvent::Braked, self.current_type(), [0.0; 4], 0);
                            self.retreat(fx);
                        } else {
                            self.enter_faulted(fx);
                        }
                    }
                }
            }
        }
    }

    /// Resumes a faulted job (`recovered`: taken up from the journal, resumed for the first
    /// time; it commands again from here).
    fn resume(&mut self, fx: &mut impl Effects, now: u64, recovered: bool) {
        // Re-synchronise to where the arm is.
        if let Some(j) = self.inputs.js {
            self.out.cmd = Setpoint::at_rest(j.position);
            self.out.from = j.position;
        }
        let held = self.inputs.gs.is_some_and(|g| g.holding == 1);
        self.emit(fx, StatusEvent::Resumed, self.current_type(), [0.0; 4], 0);
        self.resume_from_measured(fx, now, recovered, held);
        if self.phase != Phase::Idle {
            // The arm sagged past a limit while halted: named now, brought back in by the
            // first motion.
            self.say_outside_limits(fx);
        }
    }

    /// The rest of [`Job::resume`]: what the job does next, from the measured state.
    fn resume_from_measured(
        &mut self,
        fx: &mut impl Effects,
        now: u64,
        recovered: bool,
        held: bool,
    ) {
        if recovered && !self.take_up_measured_state(fx, held, now) {
            return;
        }
        if self.index >= self.count {
            self.finish(fx, StatusEvent::JobDone);
            return;
        }
        if self.holding && !held {
            self.fault = Fault::ObjectLost;
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
            self.holding = false;
        }
        // The current object's decided placement, if any: a resume does not decide again.
        let decided = self.decided_pose();
        if held && !self.holding && decided.is_some() {
            // The grasp closed while the job was halted: the current object is in the gripper.
            self.holding = true;
        }
        self.out.grip_cmd = if self.holding {
            GripperAction::Close
        } else {
            GripperAction::Open
        };
        self.out.grip_object = if self.holding {
            self.current_type()
        } else {
            NO_OBJECT
        };
        if self.decision_failed.is_some() {
            // Its decision failed while the job was halted: nothing more to do.
            self.await_decision(fx, now);
        } else if self.holding {
            // Placed where it was decided; or, not decided yet, held until it is.
            self.await_decision(fx, now);
        } else if decided.is_some() {
            // Halted before the grasp, or the object was lost from the gripper: pick it (again)
            // and place it where it was decided (nothing was released since); one decision,
            // announced once.
            self.phase = Phase::Starting;
            self.request_motion(fx, Motion::PickAndPlace);
            if self.phase == Phase::Starting {
                // No buffer home yet: the pick alone, the place once it is held.
                self.request_motion(fx, Motion::Pick);
            }
        } else {
            // Not decided yet: decided on a heightmap taken after the resume (a decision
            // still out is answered first, on an older one: its answer is kept).
            self.release_stamp = self.release_stamp.max(now);
            if self.deciding.is_none() {
                self.begin_object(fx, now);
            } else {
                self.phase = Phase::Starting;
                self.request_motion(fx, Motion::Pick);
            }
        }
    }

    /// A recovered job's first resume: what the journal said, checked against the measured
    /// gripper (`held`) and arm. False when the job cannot go on (it has been ended).
    fn take_up_measured_state(&mut self, fx: &mut impl Effects, held: bool, now: u64) -> bool {
        let placement = self.placement.filter(|p| p.index as usize == self.index);
        let at_release = |p: &Placement| {
            self.inputs.js.is_some_and(|j| {
                p.release_q.is_some_and(|release| {
                    j.position
                        .iter()
                        .zip(&release)
                        .all(|(q, r)| (q - r).abs() <= RELEASE_Q_TOL_RAD)
                })
            })
        };
        match placement {
            // Released at its placement before the journal heard of it: placed.
            Some(p) if self.holding && !held && at_release(&p) => {
                self.holding = false;
                self.release_stamp = now;
                self.done += 1;
                self.emit(fx, StatusEvent::Placed, self.current_type(), p.pose, 0);
                self.index += 1;
                self.announced = false;
                self.placement = None;
            }
            // In the gripper (perhaps closed just before the crash): placed where decided, or,
            // picked before its decision came, held until it is decided (on a heightmap taken
            // after the resume) and placed as the journal says it was taken.
            _ if held => self.holding = true,
            // Not in the gripper: picked (again, as ObjectLost says, if the journal had it held).
            _ => {}
        }
        true
    }

    fn next_segment(&mut self, fx: &mut impl Effects, now: u64, seg: usize) {
        let n = self.active.as_ref().map_or(0, |p| p.n_segments);
        if seg < n {
            let start = self
                .active
                .as_ref()
                .map_or(0, |p| if seg == 0 { 0 } else { p.segments[seg - 1].end });
            self.phase = Phase::Streaming { seg, cursor: start };
        } else if self.cancelling {
            self.finish(fx, StatusEvent::JobCancelled);
        } else if self.holding {
            // Picked: the place once its placement is decided.
            self.await_decision(fx, now);
        } else if self.index >= self.count {
            self.finish(fx, StatusEvent::JobDone);
        } else {
            self.begin_object(fx, now);
        }
    }

    fn stream(&mut self, fx: &mut impl Effects, now: u64, seg: usize, cursor: usize) {
        let Some(p) = &self.active else { return };
        let Some(sg) = p.segments().get(seg).copied() else {
            self.next_segment(fx, now, seg);
            return;
        };
        if cursor < sg.end {
            if let Some(s) = p.setpoints.get(cursor) {
                self.out.cmd = *s;
            }
            self.phase = Phase::Streaming {
                seg,
                cursor: cursor + 1,
            };
            return;
        }
        // At the segment's end, at rest.
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        if let Some(f) = self.decision_failed
            && !self.holding
        {
            // The decision failed and nothing is held: the job ends at this standstill.
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
            return;
        }
        let grasp_next = p
            .segments()
            .get(seg + 1)
            .is_some_and(|n| n.then == Some(GripperAction::Close));
        if sg.then.is_none() && grasp_next && self.confirm_picks && !self.confirmed {
            // Above the station: no descent before the operator says the object is there.
            self.phase = Phase::AwaitOperator { seg };
            return;
        }
        match sg.then {
            Some(action) => {
                self.out.grip_cmd = action;
                self.out.grip_object = if action == GripperAction::Close {
                    p.object as u32
                } else {
                    NO_OBJECT
                };
                self.out.grip_due = true;
                self.phase = Phase::Gripper {
                    action,
                    seg,
                    since: now,
                };
            }
            None => self.next_segment(fx, now, seg + 1),
        }
    }

    fn publish(&mut self, now: u64, fx: &mut impl Effects) {
        if self.commanding() {
            // Faulted, nothing moves the arm: the robot holds by itself, and the next command
            // is planned from the state measured when the job resumes.
            let halted = matches!(self.phase, Phase::Faulted { .. });
            let q = self.out.cmd.position;
            // Inside the limits, or between them and where the arm stood when the job started
            // or resumed (the way back in from a sag past a limit).
            let from = &self.out.from;
            let inside = (0..DOF).all(|i| {
                q[i] >= self.p.lower[i].min(from[i]) && q[i] <= self.p.upper[i].max(from[i])
            });
            if !halted {
                if inside {
                    fx.joint(&self.out.cmd);
                } else {
                    // Never reached by planned samples (checked by the planner); a guard.
                    self.out.limit_holds += 1;
                }
            }
            if self.out.grip_due || now.saturating_sub(self.out.grip_sent_at) >= GRIPPER_REPEAT_NS {
                self.out.grip_due = false;
                self.out.grip_sent_at = now;
                fx.gripper(self.job_id, self.out.grip_cmd, self.out.grip_object);
            }
        }
        if now.saturating_sub(self.out.last_heartbeat) >= HEARTBEAT_PERIOD_NS {
            self.out.last_heartbeat = now;
            // Between jobs, a heartbeat's fault says why a job would be refused now.
            if self.phase == Phase::Idle {
                self.fault = self.not_ready(now).unwrap_or(Fault::None);
                if matches!(self.fault, Fault::OutsideLimits | Fault::BeyondArmLimits) {
                    self.excess = self.measured_excess().map(|(_, e)| e);
                }
            }
            self.emit(fx, StatusEvent::Heartbeat, self.current_type(), [0.0; 4], 0);
        }
    }

    fn status_of(&self, event: StatusEvent, object_type: u32, pose: [f32; 4], dns: u64) -> Status {
        let state = match event {
            StatusEvent::JobDone => JobState::Done,
            StatusEvent::JobFailed => JobState::Failed,
            StatusEvent::JobCancelled => JobState::Cancelled,
            _ => self.state(),
        };
        let mut s = Status {
            header: Header::at(0, 0),
            job_id: self.job_id,
            event: event as u32,
            state: state as u32,
            fault: self.fault as u32,
            objects_total: self.count as u32,
            objects_done: self.done.min(self.count) as u32,
            object_index: self.index as u32,
            object_type,
            decision_wait_ms: (self.wait_ns / 1_000_000).min(u32::MAX as u64) as u32,
            pose,
            decision_ns: dns,
            cycles: 0,
            deadline_misses: 0,
            rejected_inputs: self.inputs.rejected,
            max_cycle_ns: 0,
            rejected_requests: self.inputs.rejected_requests,
            limit_joint: NO_JOINT,
            limit_position_rad: 0.0,
            limit_bound_rad: 0.0,
            attempt: self.missed,
        };
        if matches!(self.fault, Fault::OutsideLimits | Fault::BeyondArmLimits)
            && let Some(e) = self.excess
            && e.position.is_finite()
        {
            s.limit_joint = e.joint as u32;
            s.limit_position_rad = e.position as f32;
            s.limit_bound_rad = e.bound as f32;
        }
        s
    }

    fn emit(
        &self,
        fx: &mut impl Effects,
        event: StatusEvent,
        object_type: u32,
        pose: [f32; 4],
        decision_ns: u64,
    ) {
        fx.status(&self.status_of(event, object_type, pose, decision_ns));
    }
}

#[cfg(test)]
mod tests;
