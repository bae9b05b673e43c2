//! The cell as a viewer draws it: the arm's kinematic chain, the box and the pick station, in
//! the box frame B, built from the same constants ([`crate::kinematics`]) and `[cell]`
//! configuration herbd plans with. `herbd cell-model` prints it for a running cell, and a run
//! log's replay (`herbd replay --events`) writes it first, from the run's own configuration;
//! `python -m herb_client.view` draws the arm from it and the joint states.
//!
//! A viewer composes, for joint angles `q`: `base_in_box * mount * Π (origin_i * Rz(q_i)) *
//! tool`. [`CellModel::check`] is that composition computed here, at one configuration, so a
//! viewer can verify that it reads the chain as herbd does.

use crate::cell::CellConfig;
use crate::kinematics::{Arm, DOF, LEFT_TOP_DOWN_NOMINAL};
use nalgebra::Isometry3;
use serde::Serialize;

/// Version of [`CellModel`]'s layout; a viewer refuses another.
pub const CELL_MODEL_FORMAT: u32 = 1;

/// A rigid transform: a point `p` of the child maps to `R(quaternion) p + translation` in the
/// parent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Frame {
    /// Translation (m).
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion, `[x, y, z, w]`.
    pub quaternion_xyzw: [f64; 4],
}

impl From<&Isometry3<f64>> for Frame {
    fn from(t: &Isometry3<f64>) -> Self {
        let v = t.translation.vector;
        let q = t.rotation.coords;
        Self {
            translation: [v.x, v.y, v.z],
            quaternion_xyzw: [q.x, q.y, q.z, q.w],
        }
    }
}

/// One revolute joint: its origin in the parent link, then a rotation by its angle about the
/// local z axis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointModel {
    /// URDF name (`left_s0` .. `left_w2`).
    pub name: &'static str,
    /// The joint's origin in its parent link.
    pub origin: Frame,
}

/// herbd's own forward kinematics at one configuration, for a viewer to check its drawing
/// against.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// Joint angles (rad): the nominal top-down configuration.
    pub q: [f64; DOF],
    /// Where the gripper endpoint is then, in B (m).
    pub endpoint_in_box: [f64; 3],
}

/// The arm and the cell in B, for viewers (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellModel {
    /// [`CELL_MODEL_FORMAT`].
    pub format: u32,
    /// Baxter's `base` frame in B.
    pub base_in_box: Frame,
    /// `left_torso_arm_mount`, in `base`.
    pub mount: Frame,
    /// The seven joints, shoulder to wrist.
    pub joints: Vec<JointModel>,
    /// The last link to the gripper endpoint.
    pub tool: Frame,
    /// Centre of the pick station's surface in B (m).
    pub pick_station: [f64; 3],
    /// Yaw of objects at the pick station, in B (rad).
    pub pick_yaw: f64,
    /// The chain composed here at one configuration.
    pub check: Check,
}

impl CellModel {
    /// The model of `arm` in the cell `cell`.
    pub fn new(cell: &CellConfig, arm: &Arm) -> Self {
        let base_in_box = cell.box_pose().inverse();
        let station =
            base_in_box * nalgebra::Point3::from(nalgebra::Vector3::from(cell.pick_origin));
        let q = LEFT_TOP_DOWN_NOMINAL;
        let end = (base_in_box * arm.fk(&q)).translation.vector;
        Self {
            format: CELL_MODEL_FORMAT,
            base_in_box: Frame::from(&base_in_box),
            mount: Frame::from(arm.mount()),
            joints: arm
                .joints()
                .iter()
                .zip(arm.origins())
                .map(|(j, o)| JointModel {
                    name: j.name,
                    origin: Frame::from(o),
                })
                .collect(),
            tool: Frame::from(arm.tool()),
            pick_station: [station.x, station.y, station.z],
            pick_yaw: cell.pick_yaw - cell.box_yaw,
            check: Check {
                q,
                endpoint_in_box: [end.x, end.y, end.z],
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn iso(f: &Frame) -> Isometry3<f64> {
        let [x, y, z, w] = f.quaternion_xyzw;
        Isometry3::from_parts(
            Translation3::from(Vector3::from(f.translation)),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
        )
    }

    /// The model's chain, composed as a viewer composes it, is herbd's forward kinematics in
    /// B, at the check configuration and another, for a box turned in `base`.
    #[test]
    fn the_chain_composed_from_the_model_is_herbds_kinematics_in_the_box_frame() {
        let cell = CellConfig {
            box_yaw: 0.3,
            ..CellConfig::default()
        };
        let arm = Arm::baxter_left();
        let m = CellModel::new(&cell, &arm);
        for q in [m.check.q, [0.1, -0.5, 0.2, 1.0, -0.3, 0.8, 0.4]] {
            let mut t = iso(&m.base_in_box) * iso(&m.mount);
            for (j, a) in m.joints.iter().zip(q) {
                t = t * iso(&j.origin) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
            }
            let got = (t * iso(&m.tool)).translation.vector;
            let want = (cell.box_pose().inverse() * arm.fk(&q)).translation.vector;
            assert!((got - want).norm() < 1e-9, "{got} against {want}");
        }
        let e = Vector3::from(m.check.endpoint_in_box);
        let want = (cell.box_pose().inverse() * arm.fk(&m.check.q))
            .translation
            .vector;
        assert!((e - want).norm() < 1e-12);
        // The pick station, in B: the configured point moved into the box frame.
        let s = cell.box_pose() * nalgebra::Point3::from(Vector3::from(m.pick_station));
        assert!((s.coords - Vector3::from(cell.pick_origin)).norm() < 1e-12);
        assert_eq!(m.joints.len(), DOF);
    }
}
