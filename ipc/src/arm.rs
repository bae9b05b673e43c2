//! The arm: measured joints and joint commands, the gripper's commands and state, and the arm
//! adapter's own status.

use crate::base::*;
use crate::job::Fault;
use iceoryx2::prelude::*;

/// Measured arm joints, published by the hardware adapter every cycle.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::JointState")]
pub struct JointState {
    /// Header; the stamp is the measurement time.
    pub header: Header,
    /// Joint angles `s0 .. w2` (rad).
    pub position: [f64; DOF],
    /// Joint speeds (rad/s).
    pub velocity: [f64; DOF],
}
payload!(JointState);

impl JointState {
    /// Header, finite values, angles within +-2 pi and speeds within +-20 rad/s.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        within(
            "position",
            &self.position,
            -MAX_JOINT_ABS_RAD,
            MAX_JOINT_ABS_RAD,
        )?;
        within(
            "velocity",
            &self.velocity,
            -MAX_JOINT_SPEED,
            MAX_JOINT_SPEED,
        )
    }
}

/// A joint setpoint, streamed by `herbd` every cycle while it controls the arm.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::JointCommand")]
pub struct JointCommand {
    /// Header; the stamp is the cycle's start.
    pub header: Header,
    /// Joint angles (rad).
    pub position: [f64; DOF],
    /// Joint speeds (rad/s), feed-forward.
    pub velocity: [f64; DOF],
    /// Joint accelerations (rad/s^2), feed-forward.
    pub acceleration: [f64; DOF],
}
payload!(JointCommand);

impl JointCommand {
    /// Header, finite values, and every angle within `[lower[i], upper[i]]` (the receiver's
    /// configured joint limits).
    pub fn validate(&self, lower: &[f64; DOF], upper: &[f64; DOF]) -> Result<(), Invalid> {
        self.header.validate()?;
        finite_all("position", &self.position)?;
        finite_all("velocity", &self.velocity)?;
        finite_all("acceleration", &self.acceleration)?;
        for i in 0..DOF {
            if !(lower[i]..=upper[i]).contains(&self.position[i]) {
                return Err(Invalid::at("position", Reason::OutOfRange, i));
            }
        }
        within(
            "velocity",
            &self.velocity,
            -MAX_JOINT_SPEED,
            MAX_JOINT_SPEED,
        )
    }
}

wire_enum! {
    /// What the gripper should do.
    pub enum GripperAction ("action") {
        /// Open (release).
        Open = 0,
        /// Close (grasp).
        Close = 1,
    }
}

/// A gripper command from `herbd`, published when it changes and repeated every 100 ms.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::GripperCommand")]
pub struct GripperCommand {
    /// Header.
    pub header: Header,
    /// The job this command serves (0 outside a job).
    pub job_id: u64,
    /// [`GripperAction`] code.
    pub action: u32,
    /// The catalog type index `herbd` expects at the pick station, or [`NO_OBJECT`]. Real
    /// grippers ignore it; a simulated pick station (the loopback) spawns this object.
    pub object_type: u32,
}
payload!(GripperCommand);

impl GripperCommand {
    /// Header and action code; `object_type` below `catalog_len` or [`NO_OBJECT`].
    pub fn validate(&self, catalog_len: usize) -> Result<GripperAction, Invalid> {
        self.header.validate()?;
        if self.object_type != NO_OBJECT && self.object_type as usize >= catalog_len {
            return Err(Invalid::new("object_type", Reason::OutOfRange));
        }
        GripperAction::from_code(self.action).ok_or(Invalid::new("action", Reason::UnknownCode))
    }
}

/// The gripper as measured, published by the adapter every cycle.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::GripperState")]
pub struct GripperState {
    /// Header.
    pub header: Header,
    /// 1 when closed, 0 when open.
    pub closed: u32,
    /// 1 when an object is held.
    pub holding: u32,
    /// Type of the held object if known, else [`NO_OBJECT`].
    pub object_type: u32,
    /// Reserved, zero.
    pub reserved: u32,
}
payload!(GripperState);

impl GripperState {
    /// Header and flags.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        flag("closed", self.closed)?;
        flag("holding", self.holding)
    }
}

wire_enum! {
    /// Why the arm adapter withholds joint state (the robot must not be moved), as it tells herbd
    /// on the `arm_status` service.
    pub enum ArmBlocker ("blocker") {
        /// The robot may move: joint states flow.
        None = 0,
        /// The robot is disabled (an operator, or never enabled).
        Disabled = 1,
        /// The robot's emergency stop is pressed (or was, and the robot was not enabled since).
        EStop = 2,
        /// The robot reports an error.
        RobotError = 3,
        /// The adapter lost its middleware's master (ROS 1).
        MasterLost = 4,
        /// The robot stopped reporting its state to the adapter.
        RobotSilent = 5,
        /// The adapter's jump guard refused a command far from the measured position: joint state
        /// is withheld for a moment so that herbd halts and resumes from the measured state.
        CommandRefused = 6,
    }
}

impl ArmBlocker {
    /// The fault herbd reports when joint states stop while the adapter says this.
    pub fn fault(self) -> Fault {
        match self {
            Self::None => Fault::JointStateTimeout,
            Self::Disabled => Fault::RobotDisabled,
            Self::EStop => Fault::RobotEStop,
            Self::RobotError => Fault::RobotError,
            Self::MasterLost => Fault::MasterLost,
            Self::RobotSilent => Fault::RobotSilent,
            Self::CommandRefused => Fault::CommandRefused,
        }
    }
}

/// The arm adapter's own state, published every [`ARM_STATUS_PERIOD_NS`] and at once when
/// it changes: whether it passes joint states and commands on, and if not, why.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::ArmStatus")]
pub struct ArmStatus {
    /// Header.
    pub header: Header,
    /// [`ArmBlocker`] code.
    pub blocker: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint commands the adapter refused because their target was farther from the measured
    /// position than its bound, or planned before the robot became ready (since it started).
    pub commands_refused: u64,
}
payload!(ArmStatus);

impl ArmStatus {
    /// Header and blocker code.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        ArmBlocker::from_code(self.blocker)
            .map(|_| ())
            .ok_or(Invalid::new("blocker", Reason::UnknownCode))
    }
}
