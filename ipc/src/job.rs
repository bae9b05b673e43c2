//! Jobs: the status herbd publishes, its codes (state, event, fault), and the pack-job,
//! cancel and pick-confirmation requests with their replies.

use crate::base::*;
use iceoryx2::prelude::*;

wire_enum! {
    /// Where a job is.
    pub enum JobState ("state") {
        /// No job.
        Idle = 0,
        /// Packing.
        Running = 1,
        /// Braking to a standstill after a fault or a stop request.
        Braking = 2,
        /// Stopped on a fault; resumes when the fault clears.
        Faulted = 3,
        /// Every object placed.
        Done = 4,
        /// Ended early (an object could not be placed).
        Failed = 5,
        /// Ended on a client's request ([`CancelJobRequest`]).
        Cancelled = 6,
    }
}

wire_enum! {
    /// What a [`Status`] message reports.
    pub enum StatusEvent ("event") {
        /// Periodic (10 Hz) state report.
        Heartbeat = 0,
        /// A job was accepted and ordered.
        Accepted = 1,
        /// An object's placement was decided (`pose`, `decision_ns`).
        Decided = 2,
        /// An object was released at its placement.
        Placed = 3,
        /// A fault (`fault`) was detected; the arm brakes.
        Fault = 4,
        /// The brake finished: the arm stands still.
        Braked = 5,
        /// The fault cleared and the job goes on.
        Resumed = 6,
        /// Every object was placed.
        JobDone = 7,
        /// The job ended early (`fault` says why).
        JobFailed = 8,
        /// `herbd` is stopping (signal); the last message it sends.
        Shutdown = 9,
        /// The job was cancelled ([`CancelJobRequest`]): the arm braked and retreated (or, if it
        /// was faulted, stands where it stopped); objects not yet placed stay unpacked.
        JobCancelled = 10,
        /// An object was given up (`fault` says why, e.g. [`Fault::MissedGrasp`] after its
        /// retries): it stays unpacked and the job goes on with the next one. It may still be at
        /// the pick station: an operator takes it away.
        Skipped = 11,
        /// A job submitted with [`PackJobRequest::CONFIRM_PICKS`] needs the object
        /// (`object_type`, `object_index`, try `attempt`) at the pick station: the arm goes to
        /// its pre-grasp pose and waits there, above the station, until a client confirms with a
        /// [`ConfirmPickRequest`] for this object and attempt; only then does it descend and
        /// close the gripper. Sent at each try of each object's pick.
        AwaitingObject = 12,
    }
}

wire_enum! {
    /// Why the daemon stopped or failed.
    pub enum Fault ("fault") {
        /// None.
        None = 0 => "none",
        /// Joint states stopped arriving.
        JointStateTimeout = 1 => "adapter silent: no joint state from the arm adapter",
        /// Gripper states stopped arriving.
        GripperStateTimeout = 2 => "no gripper state from the arm adapter",
        /// Heightmaps stopped arriving.
        HeightmapTimeout = 3 => "no heightmap from the camera",
        /// The gripper did not reach the commanded state in time.
        Gripper = 4 => "the gripper did not reach its commanded state in time",
        /// A waypoint was out of reach (inverse kinematics).
        Unreachable = 5 => "a waypoint is out of the arm's reach",
        /// The placement decision failed (policy, bad heightmap).
        Decision = 6 => "the placement decision failed",
        /// Trajectory generation failed.
        Motion = 7 => "trajectory generation failed",
        /// A stop was requested (SIGINT/SIGTERM).
        Stop = 8 => "herbd is stopping",
        /// The object was lost from the gripper (e.g. the adapter restarted); it is picked again.
        ObjectLost = 9 => "the object was lost from the gripper",
        /// The placement lattice held no feasible placement for the next object (the box is
        /// full for it): the job ends, failed, with this reason.
        NoFeasiblePlacement = 10 => "no feasible placement for the next object",
        /// herbd restarted (crashed or was killed) with this job unfinished and found it in its
        /// job journal: the job resumes from the measured robot state, or is abandoned when
        /// configured so (`journal.on_restart = "abandon"`).
        Restarted = 11 => "herbd restarted with this job unfinished",
        /// Joint states stopped: the adapter says the robot is disabled.
        RobotDisabled = 12 => "robot disabled",
        /// Joint states stopped: the adapter says the robot's emergency stop is pressed.
        RobotEStop = 13 => "robot e-stopped",
        /// Joint states stopped: the adapter says the robot reports an error.
        RobotError = 14 => "robot in error",
        /// Joint states stopped: the adapter lost its middleware's master (ROS 1).
        MasterLost = 15 => "ROS master lost",
        /// Joint states stopped: the adapter says the robot stopped reporting.
        RobotSilent = 16 => "robot silent: no state reaches the adapter",
        /// The gripper closed on nothing (or did not grip in time): it is opened, and the pick is
        /// tried again or the object skipped (`[recovery]`).
        MissedGrasp = 17 => "missed grasp",
        /// Joint states stopped: the adapter refused a command too far from the measured position
        /// (its jump guard) and halted the arm; the job resumes from the measured state.
        CommandRefused = 18 => "the adapter refused a command far from the arm",
        /// A measured joint is outside herbd's configured position limits (but inside the
        /// arm's own): `limit_joint`, `limit_position_rad` and `limit_bound_rad` say which, where
        /// and which limit. With `[limits] outside = "recover"` (the default) herbd brings the
        /// joint back inside slowly before the job's next motion and the job goes on; with
        /// `"refuse"` a job is refused (`NotReady`) and a running one holds until the arm is
        /// moved inside by hand.
        OutsideLimits = 19 => "a joint is outside herbd's limits",
        /// A measured joint is outside the arm's own position limits (the robot's, wider than
        /// herbd's): nothing is commanded; move the arm inside by hand.
        BeyondArmLimits = 20 => "a joint is beyond the arm's own limits",
    }
}

impl Fault {
    /// The arm's joint states stopped (the robot disabled or e-stopped itself, errored, went
    /// silent, its middleware's master was lost, or its adapter refused a command or went
    /// silent): the robot halted by itself, not by herbd's brake, and herbd commands nothing
    /// until it is back.
    pub fn arm_unseen(self) -> bool {
        matches!(
            self,
            Self::JointStateTimeout
                | Self::RobotDisabled
                | Self::RobotEStop
                | Self::RobotError
                | Self::MasterLost
                | Self::RobotSilent
                | Self::CommandRefused
        )
    }
}

/// Job progress, per-object results and faults from `herbd`, to any client.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::Status")]
pub struct Status {
    /// Header.
    pub header: Header,
    /// The job (0 when idle).
    pub job_id: u64,
    /// [`StatusEvent`] code.
    pub event: u32,
    /// [`JobState`] code.
    pub state: u32,
    /// [`Fault`] code (the current or last fault).
    pub fault: u32,
    /// Objects in the job.
    pub objects_total: u32,
    /// Objects released so far.
    pub objects_done: u32,
    /// The object this event is about (index in the packing order).
    pub object_index: u32,
    /// Its catalog type index, or [`NO_OBJECT`].
    pub object_type: u32,
    /// Time this job has held objects at the lift pose waiting for their placements'
    /// decisions so far, ms (the pick starts before the decision; 0 when every decision came
    /// before its grasp was done).
    pub decision_wait_ms: u32,
    /// Placement in the box frame: x, y, z (m) of the object's canonical origin, yaw (rad).
    pub pose: [f32; 4],
    /// Decision latency of this object, ns: herbd's one decision call (check and copy the
    /// heightmap, observation, policy, z estimate), not the wait for a frame.
    pub decision_ns: u64,
    /// Loop cycles run.
    pub cycles: u64,
    /// Deadlines missed by the loop (cycles that overran and were skipped).
    pub deadline_misses: u64,
    /// Sensor inputs received and dropped: invalid, from the future or out of order joint
    /// states, gripper states, arm statuses and heightmap frames (a heightmap frame with a bad
    /// cell is counted on receipt). Requests are counted apart (`rejected_requests`).
    pub rejected_inputs: u64,
    /// Worst cycle time since start (ns).
    pub max_cycle_ns: u64,
    /// Client requests refused: pack jobs (malformed, busy, not ready, holding...), cancels
    /// and pick confirmations answered with a reason other than `None`.
    pub rejected_requests: u64,
    /// With `fault` [`Fault::OutsideLimits`] or [`Fault::BeyondArmLimits`]: the joint (0..7,
    /// `s0 s1 e0 e1 w0 w1 w2`) that was outside when it was found; else [`NO_JOINT`].
    pub limit_joint: u32,
    /// Its measured angle then (rad); 0 without `limit_joint`.
    pub limit_position_rad: f32,
    /// The limit it was beyond (rad, herbd's or the arm's as `fault` says); 0 without
    /// `limit_joint`.
    pub limit_bound_rad: f32,
    /// The try of the current object's pick this event is about (0: the first; a missed grasp
    /// adds one).
    pub attempt: u32,
    /// What the running job waits for now ([`JobWait`] code), in every status and heartbeat:
    /// a client that (re)connects at any time sees the wait, not only the event that began it.
    pub waiting_for: u32,
    /// Reserved, zero.
    pub reserved: u32,
}
payload!(Status);

wire_enum! {
    /// What a running job waits for ([`Status::waiting_for`]).
    pub enum JobWait ("wait") {
        /// Nothing: the job runs on by itself (or no job runs).
        None = 0,
        /// A client's [`ConfirmPickRequest`] for `object_index`, try `attempt`: the job was
        /// submitted with [`PackJobRequest::CONFIRM_PICKS`] and asked for the object
        /// ([`StatusEvent::AwaitingObject`]); the arm goes to, or waits at, its pre-grasp pose
        /// above the station. It lasts through a fault (the confirmation is still taken) and
        /// ends when the confirmation is accepted or the job ends.
        Confirmation = 1,
        /// The placement of object `object_index`: the arm holds it at the lift pose until
        /// its decision comes (`decision_wait_ms` grows meanwhile).
        Decision = 2,
    }
}

/// [`Status::limit_joint`] when no joint is named.
pub const NO_JOINT: u32 = u32::MAX;

/// The names of the left arm's joints, `s0 .. w2`, as ROS and Baxter spell them.
pub const JOINT_NAMES: [&str; DOF] = [
    "left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2",
];

impl Status {
    /// Header, codes, counts and a finite pose.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        if StatusEvent::from_code(self.event).is_none() {
            return Err(Invalid::new("event", Reason::UnknownCode));
        }
        if JobState::from_code(self.state).is_none() {
            return Err(Invalid::new("state", Reason::UnknownCode));
        }
        if Fault::from_code(self.fault).is_none() {
            return Err(Invalid::new("fault", Reason::UnknownCode));
        }
        if self.objects_total as usize > MAX_JOB_OBJECTS || self.objects_done > self.objects_total {
            return Err(Invalid::new("objects_done", Reason::OutOfRange));
        }
        if self.limit_joint != NO_JOINT && self.limit_joint as usize >= DOF {
            return Err(Invalid::new("limit_joint", Reason::OutOfRange));
        }
        if JobWait::from_code(self.waiting_for).is_none() {
            return Err(Invalid::new("waiting_for", Reason::UnknownCode));
        }
        finite_all("limit_position_rad", &[self.limit_position_rad])?;
        finite_all("limit_bound_rad", &[self.limit_bound_rad])?;
        finite_all("pose", &self.pose)
    }

    /// The joint outside its limits this status names, in words, with what to do: e.g.
    /// `left_s1 at 1.0004 rad, 0.0034 rad beyond herbd's limit 0.9970 rad: herbd brings it back
    /// inside slowly before the arm moves on`. `None` when no joint is named.
    pub fn limit_words(&self) -> Option<String> {
        let (j, q, bound) = self.limit_excess()?;
        let fault = Fault::from_code(self.fault).unwrap_or(Fault::None);
        let state = JobState::from_code(self.state).unwrap_or(JobState::Idle);
        let whose = if fault == Fault::BeyondArmLimits {
            "the arm's own limit"
        } else {
            "herbd's limit"
        };
        let todo = match (fault, state) {
            (Fault::BeyondArmLimits, _) => {
                "move the arm inside by hand (herbd never moves it there)"
            }
            (_, JobState::Running | JobState::Braking) => {
                "herbd brings it back inside slowly before the arm moves on"
            }
            _ => {
                "move the arm inside by hand, or let herbd bring it back (herbd.toml [recovery] outside_limits = \"recover\")"
            }
        };
        Some(format!(
            "{} at {q:.4} rad, {:.4} rad beyond {whose} {bound:.4} rad: {todo}",
            JOINT_NAMES[j],
            (q - bound).abs()
        ))
    }

    /// The joint outside its limits this status names, if any: (joint index, measured angle,
    /// the limit), rad.
    pub fn limit_excess(&self) -> Option<(usize, f32, f32)> {
        (self.limit_joint != NO_JOINT && (self.limit_joint as usize) < DOF).then_some((
            self.limit_joint as usize,
            self.limit_position_rad,
            self.limit_bound_rad,
        ))
    }
}

/// A pack job: an unordered list of catalog type indices. Request of the `pack_job`
/// request-response service.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::PackJobRequest")]
pub struct PackJobRequest {
    /// Header.
    pub header: Header,
    /// Chosen by the client, non-zero; echoed in the reply and every [`Status`].
    pub job_id: u64,
    /// Objects used in `objects`.
    pub count: u32,
    /// Options: [`PackJobRequest::CONFIRM_PICKS`]; other bits must be zero.
    pub flags: u32,
    /// Catalog type indices; the first `count` are used.
    pub objects: [u16; MAX_JOB_OBJECTS],
}
payload!(PackJobRequest);

wire_enum! {
    /// Why a job was rejected.
    pub enum RejectReason ("reason") {
        /// Accepted.
        None = 0,
        /// A job is running; jobs are not queued.
        Busy = 1,
        /// No objects.
        Empty = 2,
        /// More than [`MAX_JOB_OBJECTS`] objects.
        TooMany = 3,
        /// An object index is not in the catalog (`detail`: its position).
        UnknownObject = 4,
        /// The request failed validation (wrong version, zero job id...).
        Malformed = 5,
        /// The daemon is stopping.
        ShuttingDown = 6,
        /// The robot adapter is not connected (no fresh joint and gripper states).
        NotReady = 7,
        /// A cancel named a job that is not running (finished, never started, or another one).
        NoSuchJob = 8,
        /// The gripper holds an object (a cancelled job's, or put there by hand): a job starts
        /// only with an empty gripper, so that nothing but its own objects is ever placed.
        /// `detail`: the held object's catalog type if known, else `NO_OBJECT`. Take it out (the
        /// loopback: `herbctl reset`) and submit again.
        Holding = 9,
        /// A pick confirmation for an object or try the running job does not wait for (another
        /// object, an earlier try, or a job without [`PackJobRequest::CONFIRM_PICKS`]).
        NotAwaited = 10,
    }
}

impl PackJobRequest {
    /// [`Self::flags`] bit: a person feeds the pick station. Before each try of each pick the
    /// arm waits above the station ([`StatusEvent::AwaitingObject`]) until a client confirms
    /// the object is there ([`ConfirmPickRequest`]).
    pub const CONFIRM_PICKS: u32 = 1;

    /// A request for `objects` (at most [`MAX_JOB_OBJECTS`]; more are cut, and then
    /// [`Self::validate`] rejects the count as `TooMany` only if the caller set it so).
    pub fn new(job_id: u64, objects: &[u16]) -> Self {
        let mut o = [0u16; MAX_JOB_OBJECTS];
        let n = objects.len().min(MAX_JOB_OBJECTS);
        o[..n].copy_from_slice(&objects[..n]);
        Self {
            header: Header::now(1),
            job_id,
            count: objects.len().min(u32::MAX as usize) as u32,
            flags: 0,
            objects: o,
        }
    }

    /// The used objects (empty if `count` is out of range).
    pub fn objects(&self) -> &[u16] {
        self.objects.get(..self.count as usize).unwrap_or(&[])
    }

    /// Header, non-zero job id, 1..=[`MAX_JOB_OBJECTS`] objects, each below `catalog_len`.
    /// The error is the [`RejectReason`] with its detail (the offending position).
    pub fn validate(&self, catalog_len: usize) -> Result<(), (RejectReason, u32)> {
        if self.header.validate().is_err()
            || self.job_id == 0
            || self.flags & !Self::CONFIRM_PICKS != 0
        {
            return Err((RejectReason::Malformed, 0));
        }
        if self.count == 0 {
            return Err((RejectReason::Empty, 0));
        }
        if self.count as usize > MAX_JOB_OBJECTS {
            return Err((RejectReason::TooMany, self.count));
        }
        match self
            .objects()
            .iter()
            .position(|&t| t as usize >= catalog_len)
        {
            Some(i) => Err((RejectReason::UnknownObject, i as u32)),
            None => Ok(()),
        }
    }
}

/// The reply to a [`PackJobRequest`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::PackJobReply")]
pub struct PackJobReply {
    /// Header.
    pub header: Header,
    /// The request's job id.
    pub job_id: u64,
    /// 1 when accepted.
    pub accepted: u32,
    /// [`RejectReason`] code.
    pub reason: u32,
    /// Detail for the reason (e.g. the position of an unknown object).
    pub detail: u32,
    /// Reserved, zero.
    pub reserved: u32,
}
payload!(PackJobReply);

impl PackJobReply {
    /// Header, flag and reason code.
    pub fn validate(&self) -> Result<RejectReason, Invalid> {
        reply_reason(&self.header, self.accepted, self.reason)
    }
}

/// A reply's header, `accepted` flag and reason code: the reason is `None` exactly when the
/// request was accepted.
pub(crate) fn reply_reason(
    header: &Header,
    accepted: u32,
    reason: u32,
) -> Result<RejectReason, Invalid> {
    header.validate()?;
    flag("accepted", accepted)?;
    let r = RejectReason::from_code(reason).ok_or(Invalid::new("reason", Reason::UnknownCode))?;
    if (accepted == 1) != (r == RejectReason::None) {
        return Err(Invalid::new("reason", Reason::OutOfRange));
    }
    Ok(r)
}

/// A request to cancel a running job (`herbctl cancel`): `herbd` brakes the arm, retreats it
/// straight up to the transit height (an object held stays in the gripper), and reports
/// [`StatusEvent::JobCancelled`]. Answered by a [`CancelJobReply`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::CancelJobRequest")]
pub struct CancelJobRequest {
    /// Header.
    pub header: Header,
    /// The job to cancel (as in its [`PackJobRequest`]).
    pub job_id: u64,
}
payload!(CancelJobRequest);

impl CancelJobRequest {
    /// A request to cancel job `job_id`, stamped now.
    pub fn new(job_id: u64) -> Self {
        Self {
            header: Header::now(1),
            job_id,
        }
    }

    /// Header and a non-zero job id; the error is `Malformed`.
    pub fn validate(&self) -> Result<(), RejectReason> {
        control_request(&self.header, self.job_id)
    }
}

/// A job-control request's (cancel, confirm) header and job id: `Malformed` unless the header
/// is valid and the id non-zero.
fn control_request(header: &Header, job_id: u64) -> Result<(), RejectReason> {
    if header.validate().is_err() || job_id == 0 {
        return Err(RejectReason::Malformed);
    }
    Ok(())
}

/// The reply to a [`CancelJobRequest`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::CancelJobReply")]
pub struct CancelJobReply {
    /// Header.
    pub header: Header,
    /// The request's job id.
    pub job_id: u64,
    /// 1 when the cancel was accepted (the job is being cancelled).
    pub accepted: u32,
    /// [`RejectReason`] code: `None`, `Malformed`, `ShuttingDown` or `NoSuchJob`.
    pub reason: u32,
}
payload!(CancelJobReply);

impl CancelJobReply {
    /// Header, flag and reason code.
    pub fn validate(&self) -> Result<RejectReason, Invalid> {
        reply_reason(&self.header, self.accepted, self.reason)
    }
}

/// A client's word that the object a job waits for ([`StatusEvent::AwaitingObject`]) is at the
/// pick station: the arm descends and grasps it. Answered by a [`ConfirmPickReply`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::ConfirmPickRequest")]
pub struct ConfirmPickRequest {
    /// Header.
    pub header: Header,
    /// The running job.
    pub job_id: u64,
    /// The object's index in the packing order (the status's `object_index`).
    pub object_index: u32,
    /// The try of its pick (the status's `attempt`).
    pub attempt: u32,
}
payload!(ConfirmPickRequest);

impl ConfirmPickRequest {
    /// A confirmation for object `object_index`, try `attempt`, of job `job_id`, stamped now.
    pub fn new(job_id: u64, object_index: u32, attempt: u32) -> Self {
        Self {
            header: Header::now(1),
            job_id,
            object_index,
            attempt,
        }
    }

    /// Header and a non-zero job id; the error is `Malformed`.
    pub fn validate(&self) -> Result<(), RejectReason> {
        control_request(&self.header, self.job_id)
    }
}

/// The reply to a [`ConfirmPickRequest`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::ConfirmPickReply")]
pub struct ConfirmPickReply {
    /// Header.
    pub header: Header,
    /// The request's job id.
    pub job_id: u64,
    /// 1 when the confirmation was taken (the arm may descend; a repeat is taken again).
    pub accepted: u32,
    /// [`RejectReason`] code: `None`, `Malformed`, `ShuttingDown`, `NoSuchJob` or
    /// `NotAwaited`.
    pub reason: u32,
}
payload!(ConfirmPickReply);

impl ConfirmPickReply {
    /// Header, flag and reason code.
    pub fn validate(&self) -> Result<RejectReason, Invalid> {
        reply_reason(&self.header, self.accepted, self.reason)
    }
}
