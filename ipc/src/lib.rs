//! HERB's IPC contract (`ipc/CONTRACT.md`; processes: `ARCHITECTURE.md`): every payload exchanged
//! between `herbd`, the hardware adapters and the clients, the service names, one validation
//! function per payload, the codes' operator words, and the iceoryx2 ports with the contract's
//! QoS ([`bus`]).
//!
//! Every payload is `#[repr(C)]`, fixed size, without heap or pointers, derives iceoryx2's
//! `ZeroCopySend` with an explicit, versioned type name, and starts with a [`Header`]
//! (protocol version, sequence number, monotonic stamp). All-zero bytes are a valid value of
//! every payload (numbers only), which lets large payloads be initialised in place in shared
//! memory ([`zeroed_in_place`]).
//!
//! Units: SI (m, rad, s); stamps are `CLOCK_MONOTONIC` nanoseconds, comparable between the
//! processes of one machine. Poses in [`Status`] are in the box frame B (z up, origin at the
//! centre of the inner floor); joint values are Baxter left-arm joints `s0 .. w2`.
//!
//! A receiver calls the payload's `validate` before using any field; an invalid payload is
//! counted and dropped, never acted on. [`Invalid`] names the field and the reason and does not
//! allocate, so a real-time loop can validate and count without formatting.

#![warn(missing_docs)]

pub mod bus;

use iceoryx2::prelude::*;
use std::mem::MaybeUninit;

/// Protocol version carried in every header; a receiver rejects any other.
pub const PROTOCOL_VERSION: u32 = 1;
/// Arm joints carried in joint messages (Baxter left arm).
pub const DOF: usize = 7;
/// Most cells a [`HeightmapFrame`] can carry (the 224 x 224 observation grid).
pub const HEIGHTMAP_MAX_CELLS: usize = 224 * 224;
/// Most objects in one [`PackJobRequest`].
pub const MAX_JOB_OBJECTS: usize = 64;
/// `object_type` value meaning "none".
pub const NO_OBJECT: u32 = u32::MAX;
/// Lowest and highest valid heightmap value (m), as `herb_sim::Heightmap::validate`.
pub const HEIGHT_RANGE_M: (f32, f32) = (-0.05, 1.0);
/// Largest plausible joint angle magnitude (rad); tighter limits are the receiver's.
pub const MAX_JOINT_ABS_RAD: f64 = 2.0 * std::f64::consts::PI;
/// Largest plausible joint speed (rad/s).
pub const MAX_JOINT_SPEED: f64 = 20.0;
/// `herbd` refuses a joint or gripper state stamped more than this past the start of the cycle
/// that reads it (ns), unless the clock, read when it was received, is already past the stamp.
pub const MAX_FUTURE_STAMP_NS: u64 = 1_000_000;
/// `herbd` repeats its current [`GripperCommand`] this often while a job runs (ns).
pub const GRIPPER_REPEAT_NS: u64 = 100_000_000;
/// `herbd` publishes a [`StatusEvent::Heartbeat`] this often (ns).
pub const HEARTBEAT_PERIOD_NS: u64 = 100_000_000;
/// The range of a heightmap's cell side (m) a frame may carry.
pub const CELL_M_RANGE: (f32, f32) = (0.0005, 0.02);
/// An arm adapter publishes its [`ArmStatus`] at least this often (ns).
pub const ARM_STATUS_PERIOD_NS: u64 = 100_000_000;

/// `CLOCK_MONOTONIC` now, in nanoseconds.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Initialises `slot` to all-zero bytes (a valid value of every payload here) and returns it.
/// Used to fill loaned shared memory in place without building the value on the stack.
pub fn zeroed_in_place<T: Payload>(slot: &mut MaybeUninit<T>) -> &mut T {
    // SAFETY: `Payload` is implemented only for the `repr(C)` number-only types of this crate,
    // for which all-zero bytes are a valid value.
    unsafe {
        slot.as_mut_ptr().write_bytes(0, 1);
        slot.assume_init_mut()
    }
}

/// The common first field of every payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::Header")]
pub struct Header {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Per-publisher sequence number, starting at 1.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` ns when the content was produced (for a heightmap: captured).
    pub stamp_ns: u64,
}

impl Header {
    /// A header for message `seq` stamped `stamp_ns` (`CLOCK_MONOTONIC`).
    pub fn at(seq: u64, stamp_ns: u64) -> Self {
        Self {
            version: PROTOCOL_VERSION,
            reserved: 0,
            seq,
            stamp_ns,
        }
    }

    /// A header for message `seq`, stamped now.
    pub fn now(seq: u64) -> Self {
        Self::at(seq, monotonic_ns())
    }

    /// Checks the version and that seq and stamp are set.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.version != PROTOCOL_VERSION {
            return Err(Invalid::new("header.version", Reason::WrongVersion));
        }
        if self.seq == 0 {
            return Err(Invalid::new("header.seq", Reason::OutOfRange));
        }
        if self.stamp_ns == 0 {
            return Err(Invalid::new("header.stamp_ns", Reason::OutOfRange));
        }
        Ok(())
    }
}

/// Why a payload was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// A protocol version other than [`PROTOCOL_VERSION`].
    WrongVersion,
    /// NaN or infinite.
    NotFinite,
    /// A number outside its range.
    OutOfRange,
    /// A length or count that does not fit the payload or the grid.
    BadLength,
    /// An enumeration code that is not defined.
    UnknownCode,
}

/// A rejected payload: which field, and why. Does not allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Invalid {
    /// The field (dotted path).
    pub field: &'static str,
    /// The reason.
    pub reason: Reason,
    /// The offending index for array fields (0 otherwise).
    pub index: u32,
}

impl Invalid {
    /// A rejection of `field` for `reason`.
    pub const fn new(field: &'static str, reason: Reason) -> Self {
        Self {
            field,
            reason,
            index: 0,
        }
    }

    const fn at(field: &'static str, reason: Reason, index: usize) -> Self {
        Self {
            field,
            reason,
            index: index as u32,
        }
    }
}

impl std::fmt::Display for Invalid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}[{}]: {:?}", self.field, self.index, self.reason)
    }
}

impl std::error::Error for Invalid {}

/// A payload of this crate: `repr(C)`, numbers only (all-zero bytes are a valid value), and no
/// padding (every field starts where the previous ends; `ipc/tests/contract_doc.rs` checks it
/// for every payload).
pub trait Payload: ZeroCopySend + Copy + std::fmt::Debug + 'static {
    /// The header.
    fn header(&self) -> &Header;

    /// The payload's bytes as on the wire (for run logs).
    fn as_bytes(&self) -> &[u8] {
        // SAFETY: a payload is `repr(C)`, made of numbers and without padding, so every one of
        // its `size_of` bytes is initialised.
        unsafe { std::slice::from_raw_parts((self as *const Self).cast::<u8>(), size_of::<Self>()) }
    }

    /// A payload from bytes written by [`Payload::as_bytes`]; `None` if the length differs.
    /// Any bytes make a value (all numbers; enums travel as `u32` codes): validate it.
    fn from_bytes(b: &[u8]) -> Option<Self> {
        if b.len() != size_of::<Self>() {
            return None;
        }
        // SAFETY: the length matches and every bit pattern is a valid payload (numbers only).
        Some(unsafe { std::ptr::read_unaligned(b.as_ptr().cast::<Self>()) })
    }
}

macro_rules! payload {
    ($t:ty) => {
        impl Payload for $t {
            fn header(&self) -> &Header {
                &self.header
            }
        }
    };
}

fn finite_all<T: Copy + Into<f64>>(field: &'static str, v: &[T]) -> Result<(), Invalid> {
    match v.iter().position(|x| !(*x).into().is_finite()) {
        Some(i) => Err(Invalid::at(field, Reason::NotFinite, i)),
        None => Ok(()),
    }
}

fn within<T: Copy + Into<f64>>(
    field: &'static str,
    v: &[T],
    lo: f64,
    hi: f64,
) -> Result<(), Invalid> {
    finite_all(field, v)?;
    match v.iter().position(|x| !(lo..=hi).contains(&(*x).into())) {
        Some(i) => Err(Invalid::at(field, Reason::OutOfRange, i)),
        None => Ok(()),
    }
}

fn flag(field: &'static str, v: u32) -> Result<(), Invalid> {
    if v <= 1 {
        Ok(())
    } else {
        Err(Invalid::new(field, Reason::UnknownCode))
    }
}

/// Measured arm joints, published by the hardware adapter every cycle.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::JointState")]
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
#[type_name("herb::v1::JointCommand")]
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

/// Declares a wire enum: `repr(u32)` with the codes 0, 1, 2... in the order written (checked
/// at compile time), and its `from_code`, so that each enum lists its variants once.
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident ($what:literal) {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u32)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $code,)+
        }

        impl $name {
            #[doc = concat!("The ", $what, " for a wire code, if defined.")]
            pub fn from_code(c: u32) -> Option<Self> {
                [$(Self::$variant),+].get(c as usize).copied()
            }
        }

        const _: () = {
            let mut next = 0u32;
            $(
                assert!($code == next, "wire codes are 0, 1, 2... in order");
                next += 1;
            )+
            let _ = next;
        };
    };
    // Each variant with a few words for an operator: `describe()` returns them.
    (
        $(#[$meta:meta])*
        pub enum $name:ident ($what:literal) {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal => $words:literal,)+
        }
    ) => {
        wire_enum! {
            $(#[$meta])*
            pub enum $name ($what) {
                $($(#[$vmeta])* $variant = $code,)+
            }
        }

        impl $name {
            /// What it means, in a few words for an operator.
            pub fn describe(self) -> &'static str {
                match self {
                    $(Self::$variant => $words,)+
                }
            }
        }
    };
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
#[type_name("herb::v1::GripperCommand")]
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
#[type_name("herb::v1::GripperState")]
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
#[type_name("herb::v1::ArmStatus")]
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

/// A heightmap of the box interior from the camera adapter (or the loopback): row-major, row 0
/// at +y, column 0 at -x, cells of `cell_m` centred on the box (`herb_sim::GridSpec`).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::HeightmapFrame")]
pub struct HeightmapFrame {
    /// Header; the stamp is the capture time.
    pub header: Header,
    /// Columns (along B x).
    pub nx: u32,
    /// Rows (along B y).
    pub ny: u32,
    /// Cell side (m).
    pub cell_m: f32,
    /// Objects in the box when captured, if the source knows (the loopback), else 0.
    pub objects: u32,
    /// Heights above the inner floor (m); the first `nx * ny` values are used.
    pub data: [f32; HEIGHTMAP_MAX_CELLS],
}
payload!(HeightmapFrame);

impl HeightmapFrame {
    /// The used cells.
    pub fn cells(&self) -> &[f32] {
        &self.data[..(self.nx as usize * self.ny as usize).min(HEIGHTMAP_MAX_CELLS)]
    }

    /// Header, grid size and cell side only (cheap; for a loop that only tracks freshness).
    pub fn validate_meta(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        let n = self.nx as u64 * self.ny as u64;
        if self.nx == 0 || self.ny == 0 || n > HEIGHTMAP_MAX_CELLS as u64 {
            return Err(Invalid::new("nx*ny", Reason::BadLength));
        }
        within(
            "cell_m",
            &[self.cell_m],
            CELL_M_RANGE.0 as f64,
            CELL_M_RANGE.1 as f64,
        )
    }

    /// [`Self::validate_meta`] plus every used cell finite and within [`HEIGHT_RANGE_M`].
    pub fn validate(&self) -> Result<(), Invalid> {
        self.validate_meta()?;
        let (lo, hi) = HEIGHT_RANGE_M;
        within("data", self.cells(), lo as f64, hi as f64)
    }
}

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
#[type_name("herb::v1::Status")]
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
}
payload!(Status);

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
#[type_name("herb::v1::PackJobRequest")]
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
#[type_name("herb::v1::PackJobReply")]
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
fn reply_reason(header: &Header, accepted: u32, reason: u32) -> Result<RejectReason, Invalid> {
    header.validate()?;
    flag("accepted", accepted)?;
    let r = RejectReason::from_code(reason).ok_or(Invalid::new("reason", Reason::UnknownCode))?;
    if (accepted == 1) != (r == RejectReason::None) {
        return Err(Invalid::new("reason", Reason::OutOfRange));
    }
    Ok(r)
}

/// A request to empty the simulated box (sim-only service, to the loopback; a real cell's box is
/// emptied by hand). The loopback acts on it only while it holds no object and nothing settles,
/// and confirms by publishing a heightmap with no object in the box.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::SimReset")]
pub struct SimReset {
    /// Header; the stamp is the request's time.
    pub header: Header,
}
payload!(SimReset);

impl SimReset {
    /// The header.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()
    }
}

/// A request to cancel a running job (`herbctl cancel`): `herbd` brakes the arm, retreats it
/// straight up to the transit height (an object held stays in the gripper), and reports
/// [`StatusEvent::JobCancelled`]. Answered by a [`CancelJobReply`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::CancelJobRequest")]
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
        if self.header.validate().is_err() || self.job_id == 0 {
            return Err(RejectReason::Malformed);
        }
        Ok(())
    }
}

/// The reply to a [`CancelJobRequest`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::CancelJobReply")]
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
#[type_name("herb::v1::ConfirmPickRequest")]
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
        if self.header.validate().is_err() || self.job_id == 0 {
            return Err(RejectReason::Malformed);
        }
        Ok(())
    }
}

/// The reply to a [`ConfirmPickRequest`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::ConfirmPickReply")]
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

/// Simulated outcome of a release (sim-only service, published by the loopback for tests and
/// evaluation; a real cell has no such service).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::SimOutcome")]
pub struct SimOutcome {
    /// Header.
    pub header: Header,
    /// The job whose gripper command released the object (0 outside a job): a subscriber
    /// receiving the last outcome from history tells an earlier job's from its own.
    pub job_id: u64,
    /// Objects in the box after this release.
    pub objects: u32,
    /// The released object's catalog type.
    pub object_type: u32,
    /// 1 when every object is inside the success volume.
    pub all_inside: u32,
    /// 1 when the released object is stable (tilt within the threshold).
    pub stable: u32,
    /// Tilt of the released object after settling (rad).
    pub tilt_rad: f32,
    /// Compactness C of the box after settling.
    pub compactness: f32,
    /// Release pose of the object's canonical origin in B: x, y, z (m), yaw (rad).
    pub release: [f32; 4],
    /// What the simulated arm found of the joint commands it received so far.
    pub commands: CommandChecks,
    /// Every object in the box after this release, in placement order (the first
    /// `min(objects, MAX_JOB_OBJECTS)`): where it ended and whether it is inside.
    pub placed: [SimObject; MAX_JOB_OBJECTS],
}
payload!(SimOutcome);

/// What the simulated arm found of the joint commands it received (part of [`SimOutcome`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::CommandChecks")]
pub struct CommandChecks {
    /// Largest joint-limit excess seen in received commands (rad; 0 when none).
    pub max_limit_excess_rad: f64,
    /// Joint commands received.
    pub received: u64,
    /// Joint commands rejected (out of limits, malformed).
    pub rejected: u64,
}

/// Candidates a [`DecisionReport`] lists at most (the placement lattice's size).
pub const MAX_REPORTED_CANDIDATES: usize = 64;

/// One candidate placement a search rolled out (part of [`DecisionReport`]). Frame B, metres,
/// radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::CandidateReport")]
pub struct CandidateReport {
    /// B x of the object's canonical origin.
    pub x: f32,
    /// B y.
    pub y: f32,
    /// Yaw about B z.
    pub yaw: f32,
    /// The rollout's return (the configured reward's, CS0.6 by default).
    pub ret: f32,
    /// Objects the rollout placed inside, the candidate's included.
    pub packed: u32,
    /// Bit 0: the rollout placed every object inside; bit 1: the candidate chosen.
    pub flags: u32,
}

/// How a placement was decided, for viewers (published by herbd's decision thread after each
/// decision; informational: the job's course is in [`Status`]).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::DecisionReport")]
pub struct DecisionReport {
    /// Header; the stamp is the decision's end.
    pub header: Header,
    /// The job.
    pub job_id: u64,
    /// The object's index in the packing order.
    pub object_index: u32,
    /// Its catalog type index.
    pub object_type: u32,
    /// 0: a placement policy; 1: the search.
    pub method: u32,
    /// Feasible candidates the placement lattice offered (the search's; 0 for a policy).
    pub feasible: u32,
    /// Rollouts the search's budget allowed (finished).
    pub allowed: u32,
    /// Candidates listed in `candidates`.
    pub count: u32,
    /// The placement decided: x, y, z (m), yaw (rad); zeros when there is none.
    pub pose: [f32; 4],
    /// 1 when a placement was decided.
    pub decided: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The decision's latency, ns.
    pub decision_ns: u64,
    /// The candidates rolled out, in the prior's order (the first `count`).
    pub candidates: [CandidateReport; MAX_REPORTED_CANDIDATES],
}
payload!(DecisionReport);

impl DecisionReport {
    /// Header, codes, counts and finite numbers.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        flag("method", self.method)?;
        flag("decided", self.decided)?;
        if self.count as usize > MAX_REPORTED_CANDIDATES {
            return Err(Invalid::new("count", Reason::BadLength));
        }
        finite_all("pose", &self.pose)?;
        for c in self.candidates_listed() {
            finite_all("candidates", &[c.x, c.y, c.yaw, c.ret])?;
        }
        Ok(())
    }

    /// The candidates listed (the first `count`).
    pub fn candidates_listed(&self) -> &[CandidateReport] {
        &self.candidates[..(self.count as usize).min(MAX_REPORTED_CANDIDATES)]
    }
}

/// Names of the success volume's bounds, by [`SimObject::bound`] code (0: inside).
pub const SIM_BOUNDS: [&str; 7] = [
    "inside", "-x wall", "+x wall", "-y wall", "+y wall", "floor", "top",
];

/// One object in the simulated box (part of [`SimOutcome`]). Frame B, metres, radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::SimObject")]
pub struct SimObject {
    /// Catalog type.
    pub object_type: u32,
    /// 0 when inside the success volume; else the bound it crosses most ([`SIM_BOUNDS`]).
    pub bound: u32,
    /// By how much it crosses that bound (m; 0 when inside).
    pub over_m: f32,
    /// Heading of its canonical x axis about z (rad).
    pub yaw_rad: f32,
    /// Lowest corner of its bounds (m).
    pub lo: [f32; 3],
    /// Highest corner of its bounds (m).
    pub hi: [f32; 3],
}

impl SimObject {
    /// The bound's name, `inside` when it is.
    pub fn bound_name(&self) -> &'static str {
        SIM_BOUNDS.get(self.bound as usize).copied().unwrap_or("?")
    }
}

impl SimOutcome {
    /// Header, flags and finite numbers, every listed object's bound code known.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        flag("all_inside", self.all_inside)?;
        flag("stable", self.stable)?;
        finite_all("tilt_rad", &[self.tilt_rad])?;
        finite_all("compactness", &[self.compactness])?;
        finite_all("release", &self.release)?;
        finite_all(
            "commands.max_limit_excess_rad",
            &[self.commands.max_limit_excess_rad],
        )?;
        for o in self.objects_listed() {
            if o.bound as usize >= SIM_BOUNDS.len() {
                return Err(Invalid::new("placed.bound", Reason::UnknownCode));
            }
            finite_all("placed.over_m", &[o.over_m, o.yaw_rad])?;
            finite_all("placed.lo", &o.lo)?;
            finite_all("placed.hi", &o.hi)?;
        }
        Ok(())
    }

    /// The objects listed in [`Self::placed`].
    pub fn objects_listed(&self) -> &[SimObject] {
        &self.placed[..(self.objects as usize).min(MAX_JOB_OBJECTS)]
    }
}

/// Service names under a configurable prefix (default [`Services::DEFAULT_PREFIX`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Services {
    prefix: String,
}

/// A prefix that cannot name services.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "IPC prefix {0:?}: use 1-100 characters of [A-Za-z0-9_-/.], not starting or ending with '/'"
)]
pub struct BadPrefix(pub String);

impl Services {
    /// The default prefix.
    pub const DEFAULT_PREFIX: &'static str = "herb";

    /// Names under `prefix`.
    pub fn new(prefix: &str) -> Result<Self, BadPrefix> {
        let ok = (1..=100).contains(&prefix.len())
            && !prefix.starts_with('/')
            && !prefix.ends_with('/')
            && prefix
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_-/.".contains(c));
        if ok {
            Ok(Self {
                prefix: prefix.to_owned(),
            })
        } else {
            Err(BadPrefix(prefix.to_owned()))
        }
    }

    /// The prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    fn name(&self, leaf: &str) -> String {
        format!("{}/{leaf}", self.prefix)
    }

    /// pub-sub [`HeightmapFrame`], camera adapter -> herbd, clients.
    pub fn heightmap(&self) -> String {
        self.name("heightmap")
    }
    /// pub-sub [`JointState`], adapter -> herbd.
    pub fn joint_state(&self) -> String {
        self.name("joint_state")
    }
    /// pub-sub [`ArmStatus`], arm adapter -> herbd, clients.
    pub fn arm_status(&self) -> String {
        self.name("arm_status")
    }
    /// pub-sub [`JointCommand`], herbd -> adapter.
    pub fn joint_command(&self) -> String {
        self.name("joint_command")
    }
    /// pub-sub [`GripperCommand`], herbd -> adapter.
    pub fn gripper_command(&self) -> String {
        self.name("gripper_command")
    }
    /// pub-sub [`GripperState`], adapter -> herbd.
    pub fn gripper_state(&self) -> String {
        self.name("gripper_state")
    }
    /// pub-sub [`Status`], herbd -> clients.
    pub fn status(&self) -> String {
        self.name("status")
    }
    /// request-response [`PackJobRequest`] / [`PackJobReply`], clients -> herbd.
    pub fn pack_job(&self) -> String {
        self.name("pack_job")
    }
    /// request-response [`CancelJobRequest`] / [`CancelJobReply`], clients -> herbd.
    pub fn cancel_job(&self) -> String {
        self.name("cancel_job")
    }
    /// request-response [`ConfirmPickRequest`] / [`ConfirmPickReply`], clients -> herbd.
    pub fn confirm_pick(&self) -> String {
        self.name("confirm_pick")
    }
    /// pub-sub [`SimOutcome`], loopback -> tests (sim only).
    pub fn sim_outcome(&self) -> String {
        self.name("sim/outcome")
    }
    /// pub-sub [`DecisionReport`], herbd's decision thread -> clients (viewers).
    pub fn decision(&self) -> String {
        self.name("decision")
    }
    /// pub-sub [`SimReset`], clients -> loopback (sim only).
    pub fn sim_reset(&self) -> String {
        self.name("sim/reset")
    }
}

impl Default for Services {
    fn default() -> Self {
        Self {
            prefix: Self::DEFAULT_PREFIX.to_owned(),
        }
    }
}

/// The order of one service's samples. From one publisher, each sample's sequence number and
/// stamp must be greater than the last accepted one's; a new publisher (a restarted adapter,
/// whose sequence starts over) is accepted and becomes the reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InOrder {
    last: Option<(u128, u64, u64)>,
}

impl InOrder {
    /// The last accepted sample: publisher, sequence number, stamp (for a run log's snapshot).
    pub fn last(&self) -> Option<(u128, u64, u64)> {
        self.last
    }

    /// An order check that last accepted `last` (a snapshot's).
    pub fn with_last(last: Option<(u128, u64, u64)>) -> Self {
        Self { last }
    }

    /// Whether a sample from `publisher` (iceoryx2's unique publisher id) with `header` comes
    /// after the last accepted one; a sample that repeats or goes back in sequence or stamp is
    /// refused (the caller drops and counts it) and changes nothing.
    pub fn accept(&mut self, publisher: u128, header: &Header) -> bool {
        let ok = match self.last {
            Some((p, seq, stamp)) if p == publisher => header.seq > seq && header.stamp_ns >= stamp,
            _ => true,
        };
        if ok {
            self.last = Some((publisher, header.seq, header.stamp_ns));
        }
        ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn js() -> JointState {
        JointState {
            header: Header::now(1),
            position: [0.1; DOF],
            velocity: [0.0; DOF],
        }
    }

    #[test]
    fn payload_bytes_round_trip_bit_for_bit() {
        let mut m = js();
        m.position[2] = f64::from_bits(0x7ff8_dead_beef_0001); // a NaN with a payload
        let b = m.as_bytes();
        assert_eq!(b.len(), size_of::<JointState>());
        let back = JointState::from_bytes(b).unwrap();
        assert_eq!(back.position[2].to_bits(), 0x7ff8_dead_beef_0001);
        assert_eq!(back.as_bytes(), b);
        assert!(JointState::from_bytes(&b[1..]).is_none(), "wrong length");
    }

    #[test]
    fn joint_state_rejects_nan_version_and_range() {
        assert_eq!(js().validate(), Ok(()));
        let mut m = js();
        m.position[3] = f64::NAN;
        assert_eq!(
            m.validate(),
            Err(Invalid::at("position", Reason::NotFinite, 3))
        );
        let mut m = js();
        m.header.version = 2;
        assert_eq!(m.validate().unwrap_err().reason, Reason::WrongVersion);
        let mut m = js();
        m.velocity[0] = 100.0;
        assert_eq!(m.validate().unwrap_err().reason, Reason::OutOfRange);
        let mut m = js();
        m.header.seq = 0;
        assert_eq!(m.validate().unwrap_err().field, "header.seq");
    }

    #[test]
    fn joint_command_checks_the_receivers_limits() {
        let c = JointCommand {
            header: Header::now(5),
            position: [0.5; DOF],
            velocity: [0.0; DOF],
            acceleration: [0.0; DOF],
        };
        assert_eq!(c.validate(&[-1.0; DOF], &[1.0; DOF]), Ok(()));
        let mut upper = [1.0; DOF];
        upper[6] = 0.4;
        assert_eq!(
            c.validate(&[-1.0; DOF], &upper),
            Err(Invalid::at("position", Reason::OutOfRange, 6))
        );
        let mut bad = c;
        bad.acceleration[2] = f64::INFINITY;
        assert_eq!(
            bad.validate(&[-1.0; DOF], &[1.0; DOF]).unwrap_err().reason,
            Reason::NotFinite
        );
    }

    #[test]
    fn heightmap_frame_lengths_and_values() {
        let mut slot = Box::new(MaybeUninit::<HeightmapFrame>::uninit());
        let f = zeroed_in_place(&mut slot);
        assert_eq!(f.validate_meta().unwrap_err().field, "header.version");
        f.header = Header::now(1);
        assert_eq!(f.validate().unwrap_err().reason, Reason::BadLength);
        f.nx = 300;
        f.ny = 300; // 90000 cells > capacity
        f.cell_m = 0.0015625;
        assert_eq!(f.validate().unwrap_err().reason, Reason::BadLength);
        f.nx = 222;
        f.ny = 146;
        assert_eq!(f.validate(), Ok(()));
        assert_eq!(f.cells().len(), 222 * 146);
        f.data[222 * 146 - 1] = f32::NAN;
        assert_eq!(
            f.validate(),
            Err(Invalid::at("data", Reason::NotFinite, 222 * 146 - 1))
        );
        // Cells past nx * ny are not looked at.
        f.data[222 * 146 - 1] = 0.1;
        f.data[222 * 146] = f32::NAN;
        assert_eq!(f.validate(), Ok(()));
        f.data[5] = 2.0;
        assert_eq!(f.validate().unwrap_err().reason, Reason::OutOfRange);
        f.cell_m = f32::NAN;
        assert_eq!(f.validate_meta().unwrap_err().field, "cell_m");
    }

    #[test]
    fn pack_job_rejections() {
        assert_eq!(PackJobRequest::new(7, &[1, 2, 3]).validate(24), Ok(()));
        assert_eq!(
            PackJobRequest::new(7, &[]).validate(24),
            Err((RejectReason::Empty, 0))
        );
        assert_eq!(
            PackJobRequest::new(7, &[1, 24, 3]).validate(24),
            Err((RejectReason::UnknownObject, 1))
        );
        assert_eq!(
            PackJobRequest::new(0, &[1]).validate(24),
            Err((RejectReason::Malformed, 0))
        );
        let big: Vec<u16> = (0..65).map(|i| (i % 24) as u16).collect();
        assert_eq!(
            PackJobRequest::new(7, &big).validate(24),
            Err((RejectReason::TooMany, 65))
        );
        let mut r = PackJobRequest::new(7, &[1]);
        r.count = 1000;
        assert!(r.objects().is_empty());
        assert_eq!(r.validate(24), Err((RejectReason::TooMany, 1000)));
    }

    #[test]
    fn reply_status_and_gripper_codes() {
        let mut r = PackJobReply {
            header: Header::now(1),
            job_id: 3,
            accepted: 1,
            reason: 0,
            detail: 0,
            reserved: 0,
        };
        assert_eq!(r.validate(), Ok(RejectReason::None));
        r.reason = RejectReason::Busy as u32;
        assert!(r.validate().is_err(), "accepted with a reason");
        r.accepted = 0;
        assert_eq!(r.validate(), Ok(RejectReason::Busy));
        r.reason = RejectReason::NotReady as u32;
        assert_eq!(r.validate(), Ok(RejectReason::NotReady));
        r.reason = 99;
        assert_eq!(r.validate().unwrap_err().reason, Reason::UnknownCode);

        let g = GripperCommand {
            header: Header::now(1),
            job_id: 3,
            action: 1,
            object_type: 5,
        };
        assert_eq!(g.validate(24), Ok(GripperAction::Close));
        assert!(GripperCommand { action: 2, ..g }.validate(24).is_err());
        assert!(
            GripperCommand {
                object_type: 24,
                ..g
            }
            .validate(24)
            .is_err()
        );
        assert!(
            GripperCommand {
                object_type: NO_OBJECT,
                ..g
            }
            .validate(24)
            .is_ok()
        );

        let mut slot = MaybeUninit::<Status>::uninit();
        let s = zeroed_in_place(&mut slot);
        s.header = Header::now(1);
        assert_eq!(s.validate(), Ok(()));
        s.event = 42;
        assert_eq!(s.validate().unwrap_err().field, "event");
        s.event = 0;
        s.objects_done = 3;
        assert_eq!(s.validate().unwrap_err().field, "objects_done");
    }

    #[test]
    fn type_names_are_explicit_and_versioned() {
        // SAFETY: type_name has no preconditions for these types; it is unsafe only because
        // the trait as a whole is.
        let names = unsafe {
            [
                HeightmapFrame::type_name(),
                JointState::type_name(),
                JointCommand::type_name(),
                Status::type_name(),
                PackJobRequest::type_name(),
            ]
        };
        assert_eq!(
            names,
            [
                "herb::v1::HeightmapFrame",
                "herb::v1::JointState",
                "herb::v1::JointCommand",
                "herb::v1::Status",
                "herb::v1::PackJobRequest"
            ]
        );
    }

    #[test]
    fn service_prefix() {
        let s = Services::new("test/a1").unwrap();
        assert_eq!(s.joint_state(), "test/a1/joint_state");
        assert!(Services::new("").is_err());
        assert!(Services::new("/abs").is_err());
        assert!(Services::new("a b").is_err());
        assert_eq!(Services::default().status(), "herb/status");
    }

    #[test]
    fn samples_in_order_per_publisher_and_a_new_publisher_starts_over() {
        let h = |seq, stamp_ns| Header {
            seq,
            stamp_ns,
            ..Header::now(seq)
        };
        let mut o = InOrder::default();
        assert!(o.accept(7, &h(1, 100)));
        assert!(o.accept(7, &h(2, 100)), "same stamp, later sequence");
        assert!(!o.accept(7, &h(2, 200)), "repeated sequence");
        assert!(!o.accept(7, &h(1, 300)), "sequence backwards");
        assert!(!o.accept(7, &h(3, 50)), "stamp backwards");
        assert!(o.accept(7, &h(3, 300)), "refusals changed nothing");
        assert!(o.accept(9, &h(1, 400)), "a restarted publisher starts over");
        assert!(!o.accept(9, &h(1, 500)));
    }
}
