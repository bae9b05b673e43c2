//! The packing cell's geometry in the robot base frame, and the gripper waypoints of one
//! pick-and-place: shared by `herbd` (which plans them) and the loopback (which needs the same
//! box and pick-station poses to simulate them).
//!
//! Frames: Baxter's `base` (z up); the box frame B (origin at the centre of the box's inner
//! floor, x along the long side, `herb_core::frames`) sits at `box_origin` turned by `box_yaw`.
//! Objects wait at the pick station in their canonical resting orientation (`herb_core`
//! catalog), centred on `pick_origin` (a point on the station's surface), turned by
//! `pick_yaw`. Grasps are top-down at the object's top, `grasp_depth` below it.

use crate::kinematics::{Arm, DOF, IkError, IkOptions, LEFT_TOP_DOWN_NOMINAL, top_down};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Box and pick-station poses in `base`, and the approach geometry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CellConfig {
    /// Origin of the box frame B (centre of the inner floor) in `base` (m).
    pub box_origin: [f64; 3],
    /// Yaw of B about `base` z (rad).
    pub box_yaw: f64,
    /// Centre of the pick station's surface in `base` (m).
    pub pick_origin: [f64; 3],
    /// Yaw of objects at the pick station (rad).
    pub pick_yaw: f64,
    /// How far below an object's top the gripper endpoint closes (m); at most half the
    /// object's height is used.
    pub grasp_depth: f64,
    /// Clearance of a carried object's bottom over the success volume's top (rim + 13 cm)
    /// and over the pick station during sideways moves (m).
    pub transit_clearance: f64,
}

impl Default for CellConfig {
    fn default() -> Self {
        Self {
            box_origin: [0.58, 0.28, -0.25],
            box_yaw: 0.0,
            pick_origin: [0.45, 0.65, -0.25],
            pick_yaw: 0.0,
            grasp_depth: 0.02,
            transit_clearance: 0.03,
        }
    }
}

/// A `[cell]` table that cannot be used ([`CellConfig::validate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellError {
    /// A pose with a number that is not finite.
    #[error("cell: poses must be finite")]
    NotFinite,
    /// `grasp_depth` out of range (m).
    #[error("cell.grasp_depth {0} outside 0..=0.1 m")]
    GraspDepth(f64),
    /// `transit_clearance` out of range (m).
    #[error("cell.transit_clearance {0} outside 0..=0.3 m")]
    TransitClearance(f64),
}

impl From<CellError> for herb_process::config_file::Invalid {
    /// The `[cell]` table's error, as a configuration error.
    fn from(e: CellError) -> Self {
        Self::Other(e.to_string())
    }
}

impl CellConfig {
    /// Checks that every number is finite and the depths are in range.
    pub fn validate(&self) -> Result<(), CellError> {
        let yaws = [self.box_yaw, self.pick_yaw];
        let mut all = self.box_origin.iter().chain(&self.pick_origin).chain(&yaws);
        if all.any(|v| !v.is_finite()) {
            return Err(CellError::NotFinite);
        }
        if !(0.0..=0.1).contains(&self.grasp_depth) {
            return Err(CellError::GraspDepth(self.grasp_depth));
        }
        if !(0.0..=0.3).contains(&self.transit_clearance) {
            return Err(CellError::TransitClearance(self.transit_clearance));
        }
        Ok(())
    }

    /// The box frame B in `base`.
    pub fn box_pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.box_origin[0], self.box_origin[1], self.box_origin[2]),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.box_yaw),
        )
    }

    /// Pose in `base` of an object of height `h` resting at the pick station (canonical
    /// origin = centre of its bounding box).
    pub fn pick_object_pose(&self, h: f64) -> Isometry3<f64> {
        let o = self.pick_origin;
        Isometry3::from_parts(
            Translation3::new(o[0], o[1], o[2] + 0.5 * h),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.pick_yaw),
        )
    }

    /// The gripper endpoint at the grasp of an object of height `h` at the pick station
    /// (`base`, m): on the object's axis, [`Self::depth`] below its top.
    pub fn grasp_point(&self, h: f64) -> Vector3<f64> {
        self.pick_object_pose(h).translation.vector
            + Vector3::new(0.0, 0.0, 0.5 * h - self.depth(h))
    }

    /// Depth of the grasp below the top of an object of height `h`.
    pub fn depth(&self, h: f64) -> f64 {
        self.grasp_depth.min(0.5 * h)
    }

    /// Tool z (in `base`) for sideways moves while carrying an object of height `h`, whose
    /// bottom must clear `clear_top` above the box floor (the success volume's top,
    /// `herb_core::frames::SUCCESS_TOP_Z`) and the pick station by `transit_clearance`.
    pub fn transit_z(&self, h: f64, clear_top: f64) -> f64 {
        let floor = self.box_origin[2] + clear_top;
        floor.max(self.pick_origin[2] + h) + self.transit_clearance + h - self.depth(h)
    }
}

/// The six gripper poses of one pick-and-place, and the joint targets reaching them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoints {
    /// Above the pick station, at transit height.
    pub pre_grasp: [f64; DOF],
    /// Closing position at the pick station.
    pub grasp: [f64; DOF],
    /// Above the placement, at transit height.
    pub pre_place: [f64; DOF],
    /// Release position.
    pub place: [f64; DOF],
    /// Gripper yaw at the grasp (rad, in `base`).
    pub grasp_yaw: f64,
    /// Gripper yaw at the release.
    pub place_yaw: f64,
    /// The object is held turned by a half turn ([`pick_waypoints`]).
    pub flip: bool,
}

/// Why the waypoints of a placement could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{which} out of reach: {error}")]
pub struct Unreachable {
    /// The waypoint.
    pub which: &'static str,
    /// The inverse-kinematics failure.
    pub error: IkError,
}

/// The joint targets of a pick of an object of height `h`: above the pick station at transit
/// height (for `clear_top`), and the closing position, seeded from `seed`. With `flip` the
/// parallel gripper takes the object turned by a half turn; the release then turns it back
/// ([`place_waypoints`] with the same `flip`).
pub fn pick_waypoints(
    cell: &CellConfig,
    arm: &Arm,
    opts: &IkOptions,
    h: f64,
    seed: &[f64; DOF],
    clear_top: f64,
    flip: bool,
) -> Result<([f64; DOF], [f64; DOF]), Unreachable> {
    let transit = cell.transit_z(h, clear_top);
    let g = cell.grasp_point(h);
    let yaw = cell.pick_yaw + if flip { std::f64::consts::PI } else { 0.0 };
    let pre_grasp = ik_top_down(arm, opts, "pre-grasp", [g.x, g.y, transit, yaw], seed)?;
    let grasp = ik_top_down(arm, opts, "grasp", [g.x, g.y, g.z, yaw], &pre_grasp)?;
    Ok((pre_grasp, grasp))
}

/// The joint targets of releasing an object of height `h`, held as [`pick_waypoints`] with
/// `flip` took it, with its canonical origin at `place` (B frame: x, y, z in m, yaw in rad):
/// above the placement at transit height, and the release position, seeded from `seed`.
#[allow(clippy::too_many_arguments)]
pub fn place_waypoints(
    cell: &CellConfig,
    arm: &Arm,
    opts: &IkOptions,
    h: f64,
    place: [f64; 4],
    seed: &[f64; DOF],
    clear_top: f64,
    flip: bool,
) -> Result<([f64; DOF], [f64; DOF]), Unreachable> {
    let transit = cell.transit_z(h, clear_top);
    let c = cell.box_pose() * Point3::new(place[0], place[1], place[2] + 0.5 * h - cell.depth(h));
    let yaw = cell.box_yaw + place[3] + if flip { std::f64::consts::PI } else { 0.0 };
    let pre_place = ik_top_down(arm, opts, "pre-place", [c.x, c.y, transit, yaw], seed)?;
    let place_q = ik_top_down(arm, opts, "place", [c.x, c.y, c.z, yaw], &pre_place)?;
    Ok((pre_place, place_q))
}

/// The configuration with the gripper pointing down at `xyz_yaw` (in `base`), from `seed` or,
/// failing that, from the nominal top-down configuration; `which` names the waypoint.
fn ik_top_down(
    arm: &Arm,
    opts: &IkOptions,
    which: &'static str,
    [x, y, z, yaw]: [f64; 4],
    seed: &[f64; DOF],
) -> Result<[f64; DOF], Unreachable> {
    let target = top_down(x, y, z, yaw);
    arm.ik(&target, seed, opts)
        .or_else(|_| arm.ik(&target, &LEFT_TOP_DOWN_NOMINAL, opts))
        .map_err(|error| Unreachable { which, error })
}

/// Plans the joint targets for taking an object of height `h` from the pick station and
/// releasing it with its canonical origin at `place` (B frame: x, y, z in m, yaw in rad),
/// seeded from `seed`, moving sideways at [`CellConfig::transit_z`] for `clear_top`. A
/// parallel gripper may take the object turned by a half turn; the grasp and release yaws are
/// chosen together (the first `flip` that reaches all four) so that the object ends at the
/// decided yaw.
pub fn plan_waypoints(
    cell: &CellConfig,
    arm: &Arm,
    opts: &IkOptions,
    h: f64,
    place: [f64; 4],
    seed: &[f64; DOF],
    clear_top: f64,
) -> Result<Waypoints, Unreachable> {
    let mut last = None;
    for flip in [false, true] {
        let r = pick_waypoints(cell, arm, opts, h, seed, clear_top, flip).and_then(
            |(pre_grasp, grasp)| {
                let (pre_place, place_q) =
                    place_waypoints(cell, arm, opts, h, place, &pre_grasp, clear_top, flip)?;
                let turn = if flip { std::f64::consts::PI } else { 0.0 };
                Ok(Waypoints {
                    pre_grasp,
                    grasp,
                    pre_place,
                    place: place_q,
                    grasp_yaw: cell.pick_yaw + turn,
                    place_yaw: cell.box_yaw + place[3] + turn,
                    flip,
                })
            },
        );
        match r {
            Ok(w) => return Ok(w),
            Err(e) => last = Some(e),
        }
    }
    Err(last.expect("two attempts were made"))
}

/// The joint target that lifts the gripper straight up from configuration `q` to tool height
/// `z` (same x, y and yaw), if the gripper points down there and the lift is reachable.
pub fn lift_to(arm: &Arm, opts: &IkOptions, q: &[f64; DOF], z: f64) -> Option<[f64; DOF]> {
    let p = arm.fk(q);
    let down = p.rotation * Vector3::z();
    if down.z > -0.99 || p.translation.z >= z - 0.005 {
        return None;
    }
    let x_axis = p.rotation * Vector3::x();
    let yaw = x_axis.y.atan2(x_axis.x);
    let t = p.translation.vector;
    arm.ik(&top_down(t.x, t.y, z, yaw), q, opts).ok()
}
