//! Simulation only: the loopback's outcomes and the request that empties its box.

use crate::base::*;
use iceoryx2::prelude::*;

/// A request to empty the simulated box (sim-only service, to the loopback; a real cell's box is
/// emptied by hand). The loopback acts on it only while it holds no object and nothing settles,
/// and confirms by publishing a heightmap with no object in the box.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::SimReset")]
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

/// Simulated outcome of a release (sim-only service, published by the loopback for tests and
/// evaluation; a real cell has no such service).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::SimOutcome")]
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
#[type_name("herb::v2::CommandChecks")]
pub struct CommandChecks {
    /// Largest joint-limit excess seen in received commands (rad; 0 when none).
    pub max_limit_excess_rad: f64,
    /// Joint commands received.
    pub received: u64,
    /// Joint commands rejected (out of limits, malformed).
    pub rejected: u64,
}

/// Names of the success volume's bounds, by [`SimObject::bound`] code (0: inside).
pub const SIM_BOUNDS: [&str; 7] = [
    "inside", "-x wall", "+x wall", "-y wall", "+y wall", "floor", "top",
];

/// One object in the simulated box (part of [`SimOutcome`]). Frame B, metres, radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::SimObject")]
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
    /// Where its canonical origin ended (m): with `rotation`, the pose it settled at, to set
    /// beside the pose it was decided at.
    pub origin: [f32; 3],
    /// Its orientation, a unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
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
            finite_all("placed.origin", &o.origin)?;
            finite_all("placed.rotation", &o.rotation)?;
        }
        Ok(())
    }

    /// The objects listed in [`Self::placed`].
    pub fn objects_listed(&self) -> &[SimObject] {
        &self.placed[..(self.objects as usize).min(MAX_JOB_OBJECTS)]
    }
}
