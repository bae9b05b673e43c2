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
//! (`job/tests/`) drive it with scripted inputs and a fake clock.
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
    InOrder, JobState, JobWait, JointState, MAX_FUTURE_STAMP_NS, MAX_JOB_OBJECTS, NO_JOINT,
    NO_OBJECT, PackJobRequest, RejectReason, Status, StatusEvent,
};
use herb_robot::kinematics::DOF;
use herb_robot::motion::{Excess, Setpoint, excess_of};

mod cycle;
mod inputs;
mod publish;
pub mod record;
mod recovery;
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
    /// Braking: `cursor` into the brake buffer once it arrived (`None` while it is computed);
    /// `then` what follows the brake.
    Braking {
        cursor: Option<usize>,
        seg: usize,
        active_cursor: usize,
        then: AfterBrake,
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
    /// The daemon stops (SIGINT, SIGTERM): the arm at rest, nothing more planned or streamed,
    /// jobs refused; the loop may exit. A job that ran is reported halted where it stopped
    /// (`recovered`: one taken up from the journal that had not resumed, commanding nothing).
    Stopped {
        recovered: bool,
    },
}

/// What follows a brake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AfterBrake {
    /// Hold, faulted, until every input is fresh again (a fault's brake).
    Hold,
    /// The retreat of a cancelled job.
    Retreat,
    /// The daemon stops ([`Phase::Stopped`]).
    Stop,
}

/// How far a job got: its objects, their packing order, the current object and the counts.
/// The running job's; between jobs the last one's, which statuses go on reporting.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Progress {
    /// The job's objects as submitted.
    objects: [u16; MAX_JOB_OBJECTS],
    /// `order` holds the job's packing order (else the objects as submitted).
    ordered: bool,
    order: [u16; MAX_JOB_OBJECTS],
    count: usize,
    /// The current object, in `order`.
    index: usize,
    /// Objects placed.
    done: usize,
    /// Time the job held objects at the lift pose waiting for decisions (ns).
    wait_ns: u64,
    /// Missed grasps of the current object.
    missed: u32,
}

impl Progress {
    /// No job yet.
    const NONE: Progress = Progress {
        objects: [0; MAX_JOB_OBJECTS],
        ordered: false,
        order: [0; MAX_JOB_OBJECTS],
        count: 0,
        index: 0,
        done: 0,
        wait_ns: 0,
        missed: 0,
    };
}

/// One job: everything that belongs to it alone, built whole when it is accepted
/// ([`Job::job_request`]) or taken up from the journal ([`Job::recover`]), and dropped when it
/// ends ([`Job::finish`]): nothing of a job is reset by hand for the next.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Run {
    job_id: u64,
    progress: Progress,
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
    /// The current object's `Decided` was sent.
    announced: bool,
    /// The job waits for a confirmation before each grasp
    /// ([`PackJobRequest::CONFIRM_PICKS`]).
    confirm_picks: bool,
    /// The current try of the current object's pick is confirmed.
    confirmed: bool,
    /// herbd asked for the current try's object (`AwaitingObject` sent) and no confirmation
    /// was accepted since: only now is one taken ([`Job::confirm_request`]).
    awaiting: bool,
    /// The last confirmation accepted (object index, try): a repeat of it is answered as
    /// accepted again and changes nothing.
    last_confirmed: Option<(u32, u32)>,
    /// A client cancelled it: it brakes, retreats and ends `JobCancelled`. Carried by the job,
    /// not by one phase: a cancelled job still passes through the motion's phases (its brake,
    /// its retreat's stream, a fault on the way up).
    cancelled: bool,
}

impl Run {
    /// A job just accepted or taken up: `progress` so far, nothing decided, nothing asked.
    fn new(job_id: u64, progress: Progress, confirm_picks: bool) -> Self {
        Self {
            job_id,
            progress,
            placement: None,
            decision_ns: 0,
            deciding: None,
            decide_due: false,
            decide_since: 0,
            decision_failed: None,
            announced: false,
            confirm_picks,
            confirmed: false,
            awaiting: false,
            last_confirmed: None,
            cancelled: false,
        }
    }
}

/// The job state machine. Built once; no method allocates.
pub struct Job {
    /// What the machine is built with.
    p: JobParams,
    inputs: Inputs,
    /// Where the machine stands; what belongs to one phase only is in its variant. Every change
    /// goes through [`Job::set_phase`].
    phase: Phase,
    /// The job that runs (`None` between jobs).
    run: Option<Run>,
    /// The last job's progress, reported between jobs.
    last: Progress,
    // what outlives a job: the gripper, the box, the last word on faults
    /// The gripper holds the current (or, after a job, the last) object.
    holding: bool,
    /// The object in the gripper is held turned by a half turn (from its pick's plan).
    flip: bool,
    /// Capture stamp of the gripper state that reported the last release: a decision waits
    /// for a heightmap newer than it.
    release_stamp: u64,
    fault: Fault,
    /// The joint outside its limits the last `OutsideLimits` or `BeyondArmLimits` fault named.
    excess: Option<Excess>,
    // trajectory buffers: two, moved between the machine and the planner, never allocated
    active: Option<Box<MotionPlan>>,
    spare: Option<Box<MotionPlan>>,
    brake: Option<Box<MotionPlan>>,
    out: Commands,
    /// When the daemon's stop was first seen (0: not stopping yet).
    stop_since: u64,
}

/// The longest herbd's stop waits for a moving arm to brake to a standstill (ns): a brake at
/// Baxter's limits takes under a second; a brake that has not ended by then (its plan stuck
/// behind a long one at the planner) is cut, the arm held where the last command put it, so
/// that herbd exits within 2 s of SIGTERM whatever it is doing.
pub const STOP_LIMIT_NS: u64 = 1_500_000_000;

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
            run: None,
            last: Progress::NONE,
            holding: false,
            flip: false,
            release_stamp: 0,
            fault: Fault::None,
            excess: None,
            active: Some(a),
            spare: Some(b),
            brake: None,
            out: Commands::default(),
            stop_since: 0,
        }
    }

    /// The rest of a cycle: the stop request (`stop`, seen once), input health, one step of
    /// the current phase, then the commands and the heartbeat. True when the daemon may exit
    /// (stopped: the arm no longer braking).
    pub fn tick(&mut self, now: u64, stop: bool, fx: &mut impl Effects) -> bool {
        if stop && !self.stopping() {
            self.stop_since = now;
            self.begin_stop(fx);
        }
        self.check_health(now, fx);
        self.step(now, fx);
        if self.stopping()
            && !matches!(self.phase, Phase::Stopped { .. })
            && now.saturating_sub(self.stop_since) > STOP_LIMIT_NS
        {
            // The stop's brake did not end in time: held where it is.
            self.halt(fx, AfterBrake::Stop);
        }
        self.publish(now, fx);
        matches!(self.phase, Phase::Stopped { .. })
    }

    /// The state reported in statuses.
    pub fn state(&self) -> JobState {
        match self.phase {
            Phase::Idle => JobState::Idle,
            Phase::Braking { .. } => JobState::Braking,
            Phase::Faulted { .. } => JobState::Faulted,
            // A job stopped with the daemon is halted where it stood.
            Phase::Stopped { .. } if self.run.is_some() => JobState::Faulted,
            Phase::Stopped { .. } => JobState::Idle,
            _ => JobState::Running,
        }
    }

    /// The daemon stops: braking for the stop, or stopped.
    fn stopping(&self) -> bool {
        matches!(
            self.phase,
            Phase::Stopped { .. }
                | Phase::Braking {
                    then: AfterBrake::Stop,
                    ..
                }
        )
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
                | Phase::Stopped { recovered: true }
        )
    }

    /// Commands are published: a job runs, and it is not a recovered one that has not resumed
    /// yet (between jobs, and until a job taken up from the journal resumes, nothing is).
    fn commanding(&self) -> bool {
        self.run.is_some() && !self.recovered()
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

    /// Every change of phase goes through here: the one place to watch (or check) the
    /// machine's transitions.
    fn set_phase(&mut self, phase: Phase) {
        self.phase = phase;
    }

    /// The running job's id (0 between jobs).
    fn job_id(&self) -> u64 {
        self.run.map_or(0, |r| r.job_id)
    }

    /// How far the running job got; between jobs, the last one.
    fn progress(&self) -> &Progress {
        self.run.as_ref().map_or(&self.last, |r| &r.progress)
    }

    fn current_type(&self) -> u32 {
        let p = self.progress();
        if p.index < p.count {
            p.order[p.index] as u32
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

    /// Ends the job with `end` (`JobDone`, `JobFailed` or `JobCancelled`): reported, then
    /// dropped (its progress kept for the statuses between jobs).
    fn finish(&mut self, fx: &mut impl Effects, end: StatusEvent) {
        self.set_phase(if self.stopping() {
            Phase::Stopped { recovered: false }
        } else {
            Phase::Idle
        });
        self.emit(fx, end, NO_OBJECT, [0.0; 4], 0);
        if let Some(r) = self.run.take() {
            self.last = r.progress;
        }
    }

    /// Drops the current object's decision and stops waiting for one (a late answer is then
    /// stale).
    fn forget_decision(&mut self) {
        if let Some(r) = &mut self.run {
            r.deciding = None;
            r.decide_due = false;
            r.decision_failed = None;
        }
    }

    /// The current object's placement, decided already.
    fn decided_pose(&self) -> Option<[f32; 4]> {
        let r = self.run.as_ref()?;
        r.placement
            .filter(|p| p.index as usize == r.progress.index)
            .map(|p| p.pose)
    }

    /// The current object's decision failed (the job ends at the arm's next standstill).
    fn decision_failed(&self) -> Option<Fault> {
        self.run.and_then(|r| r.decision_failed)
    }

    /// The running job was cancelled.
    fn cancelled(&self) -> bool {
        self.run.is_some_and(|r| r.cancelled)
    }

    /// The current object is done with (placed or skipped): the next one is current, with
    /// nothing of this one's decision or tries left.
    fn next_object(&mut self) {
        if let Some(r) = &mut self.run {
            r.progress.index += 1;
            r.progress.missed = 0;
            r.announced = false;
            r.placement = None;
            r.decision_ns = 0;
        }
        self.forget_decision();
    }
}

#[cfg(test)]
mod tests;
