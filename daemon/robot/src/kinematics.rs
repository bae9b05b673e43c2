//! Baxter left-arm kinematics: forward kinematics from the published URDF, and inverse
//! kinematics by damped least squares within the joint limits.
//!
//! # Source
//!
//! Joint origins, axes and limits of the left arm are copied as facts from Rethink Robotics'
//! `baxter_common`, `baxter_description/urdf/baxter_simple.urdf` (joints `left_torso_arm_mount`,
//! `left_s0` .. `left_w2`, `left_hand`, `left_gripper_base`, `left_endpoint`). Frames: the
//! chain starts at Baxter's `base` frame (`torso` coincides with it) and ends at
//! `left_gripper` (the gripper endpoint, 2.5 cm beyond `left_hand`). URDF conventions: a
//! joint's transform is `Trans(xyz) * Rz(yaw) * Ry(pitch) * Rx(roll)`, then a rotation by the
//! joint angle about its axis (z for all seven). Metres and radians.
//!
//! # Inverse kinematics
//!
//! Damped least squares on the geometric Jacobian (position and orientation error together,
//! orientation as a rotation vector), seeded from the current configuration, each step
//! clamped to the joint limits. A target it cannot reach within the tolerances is reported as
//! [`IkError::Unreachable`] with the remaining error, never returned as a clamped pose.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

/// Joints of the arm: the count the joint messages carry, defined once in `herb_ipc`.
pub use herb_ipc::DOF;

/// One revolute joint of the chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSpec {
    /// URDF name.
    pub name: &'static str,
    /// Origin translation in the parent link (m).
    pub xyz: [f64; 3],
    /// Origin rotation (roll, pitch, yaw; rad).
    pub rpy: [f64; 3],
    /// Lower limit (rad).
    pub lower: f64,
    /// Upper limit (rad).
    pub upper: f64,
    /// Velocity limit (rad/s).
    pub max_velocity: f64,
}

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// `left_torso_arm_mount` (fixed): `base`/`torso` to `left_arm_mount`. The yaw is the URDF's
/// 0.7854 as published (not exactly pi/4).
#[allow(clippy::approx_constant)]
pub const LEFT_ARM_MOUNT: ([f64; 3], [f64; 3]) =
    ([0.024645, 0.219645, 0.118588], [0.0, 0.0, 0.7854]);

/// A joint of the table below: name, origin (xyz, rpy), limits and velocity limit.
const fn joint(
    name: &'static str,
    xyz: [f64; 3],
    rpy: [f64; 3],
    lower: f64,
    upper: f64,
    max_velocity: f64,
) -> JointSpec {
    JointSpec {
        name,
        xyz,
        rpy,
        lower,
        upper,
        max_velocity,
    }
}

/// The seven joints `left_s0` .. `left_w2` (axis z each), as the URDF gives them: name, origin
/// xyz (m) and rpy (rad), lower and upper limit (rad), velocity limit (rad/s).
#[rustfmt::skip]
pub const LEFT_ARM: [JointSpec; DOF] = [
    joint("left_s0", [0.055695, 0.0, 0.011038], [0.0, 0.0, 0.0], -1.70167993878, 1.70167993878, 1.5),
    joint("left_s1", [0.069, 0.0, 0.27035], [-HALF_PI, 0.0, 0.0], -2.147, 1.047, 1.5),
    joint("left_e0", [0.102, 0.0, 0.0], [HALF_PI, 0.0, HALF_PI], -3.05417993878, 3.05417993878, 1.5),
    joint("left_e1", [0.069, 0.0, 0.26242], [-HALF_PI, -HALF_PI, 0.0], -0.05, 2.618, 1.5),
    joint("left_w0", [0.10359, 0.0, 0.0], [HALF_PI, 0.0, HALF_PI], -3.059, 3.059, 4.0),
    joint("left_w1", [0.01, 0.0, 0.2707], [-HALF_PI, -HALF_PI, 0.0], -HALF_PI, 2.094, 4.0),
    joint("left_w2", [0.115975, 0.0, 0.0], [HALF_PI, 0.0, HALF_PI], -3.059, 3.059, 4.0),
];

/// `left_hand` (0.11355 m along the wrist's z) plus `left_endpoint` (0.025 m): wrist to
/// gripper endpoint.
pub const LEFT_TOOL_Z_M: f64 = 0.11355 + 0.025;

fn origin(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// A serial arm of revolute joints about their local z axes.
#[derive(Debug, Clone)]
pub struct Arm {
    mount: Isometry3<f64>,
    origins: [Isometry3<f64>; DOF],
    tool: Isometry3<f64>,
    specs: [JointSpec; DOF],
}

/// IK settings.
#[derive(Debug, Clone, Copy)]
pub struct IkOptions {
    /// Position tolerance (m).
    pub position_tol_m: f64,
    /// Orientation tolerance (rad).
    pub angle_tol_rad: f64,
    /// Iterations at most.
    pub max_iterations: usize,
    /// Damping (m).
    pub damping: f64,
    /// Largest joint step per iteration (rad).
    pub max_step_rad: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            position_tol_m: 1e-4,
            angle_tol_rad: 1e-3,
            max_iterations: 300,
            damping: 0.02,
            max_step_rad: 0.2,
        }
    }
}

/// Why IK gave no solution.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IkError {
    /// Not reached within the tolerances (out of reach, or blocked by the joint limits).
    #[error(
        "target unreachable: {position_error_m:.4} m and {angle_error_rad:.4} rad left after {iterations} iterations"
    )]
    Unreachable {
        /// Position error left (m).
        position_error_m: f64,
        /// Orientation error left (rad).
        angle_error_rad: f64,
        /// Iterations run.
        iterations: usize,
    },
    /// A non-finite target or seed.
    #[error("non-finite target or seed")]
    NotFinite,
}

impl Arm {
    /// Baxter's left arm, `base` to `left_gripper`.
    pub fn baxter_left() -> Self {
        Self {
            mount: origin(LEFT_ARM_MOUNT.0, LEFT_ARM_MOUNT.1),
            origins: LEFT_ARM.map(|j| origin(j.xyz, j.rpy)),
            tool: origin([0.0, 0.0, LEFT_TOOL_Z_M], [0.0; 3]),
            specs: LEFT_ARM,
        }
    }

    /// The same arm with narrower position limits (e.g. the configured ones), which IK then
    /// keeps to. Each range must lie inside the URDF's (checked by the caller's config).
    pub fn with_limits(mut self, lower: &[f64; DOF], upper: &[f64; DOF]) -> Self {
        for (i, s) in self.specs.iter_mut().enumerate() {
            s.lower = lower[i];
            s.upper = upper[i];
        }
        self
    }

    /// `left_torso_arm_mount`: `base` to the first joint's parent link.
    pub fn mount(&self) -> &Isometry3<f64> {
        &self.mount
    }

    /// Each joint's origin in its parent link (before its rotation about local z).
    pub fn origins(&self) -> &[Isometry3<f64>; DOF] {
        &self.origins
    }

    /// The last link to the gripper endpoint.
    pub fn tool(&self) -> &Isometry3<f64> {
        &self.tool
    }

    /// The joints.
    pub fn joints(&self) -> &[JointSpec; DOF] {
        &self.specs
    }

    /// True when every angle is within its limits.
    pub fn within_limits(&self, q: &[f64; DOF]) -> bool {
        q.iter()
            .zip(&self.specs)
            .all(|(&a, j)| a >= j.lower && a <= j.upper)
    }

    /// Pose of the gripper endpoint in `base` for joint angles `q`.
    pub fn fk(&self, q: &[f64; DOF]) -> Isometry3<f64> {
        let mut t = self.mount;
        for (o, &a) in self.origins.iter().zip(q) {
            t = t * o * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        }
        t * self.tool
    }

    /// Geometric Jacobian (rows: linear velocity, angular velocity; in `base`) and the
    /// endpoint pose.
    pub fn jacobian(&self, q: &[f64; DOF]) -> (nalgebra::Matrix6xX<f64>, Isometry3<f64>) {
        let mut frames = [Isometry3::identity(); DOF];
        let mut t = self.mount;
        for (i, (o, &a)) in self.origins.iter().zip(q).enumerate() {
            t *= o;
            frames[i] = t;
            t *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a);
        }
        let end = t * self.tool;
        let p_end = end.translation.vector;
        let mut j = nalgebra::Matrix6xX::zeros(DOF);
        for (i, f) in frames.iter().enumerate() {
            let z = f.rotation * Vector3::z();
            let v = z.cross(&(p_end - f.translation.vector));
            j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
            j.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
        }
        (j, end)
    }

    /// Joint angles placing the gripper endpoint at `target`, starting from `seed` (the
    /// current configuration), within the joint limits.
    pub fn ik(
        &self,
        target: &Isometry3<f64>,
        seed: &[f64; DOF],
        opts: &IkOptions,
    ) -> Result<[f64; DOF], IkError> {
        let finite = target.translation.vector.iter().all(|v| v.is_finite())
            && target.rotation.coords.iter().all(|v| v.is_finite())
            && seed.iter().all(|v| v.is_finite());
        if !finite {
            return Err(IkError::NotFinite);
        }
        let mut q = *seed;
        for (a, j) in q.iter_mut().zip(&self.specs) {
            *a = a.clamp(j.lower, j.upper);
        }
        let (mut pe, mut ae) = (f64::MAX, f64::MAX);
        for it in 0..opts.max_iterations {
            let (j, cur) = self.jacobian(&q);
            let dp = target.translation.vector - cur.translation.vector;
            let dr = (target.rotation * cur.rotation.inverse()).scaled_axis();
            pe = dp.norm();
            ae = dr.norm();
            if pe < opts.position_tol_m && ae < opts.angle_tol_rad {
                return Ok(q);
            }
            let e = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
            // dq = J^T (J J^T + lambda^2 I)^-1 e
            let jjt: Matrix6<f64> = &j * j.transpose() + Matrix6::identity() * opts.damping.powi(2);
            let Some(y) = jjt.cholesky().map(|c| c.solve(&e)) else {
                return Err(IkError::Unreachable {
                    position_error_m: pe,
                    angle_error_rad: ae,
                    iterations: it,
                });
            };
            let dq = j.transpose() * y;
            let scale = (opts.max_step_rad / dq.amax()).min(1.0);
            for ((a, d), spec) in q.iter_mut().zip(dq.iter()).zip(&self.specs) {
                *a = (*a + d * scale).clamp(spec.lower, spec.upper);
            }
        }
        Err(IkError::Unreachable {
            position_error_m: pe,
            angle_error_rad: ae,
            iterations: opts.max_iterations,
        })
    }
}

/// A configuration with the left gripper pointing down in front of the robot (endpoint near
/// `(0.7, 0.25, 0.0)` in `base`), used as a restart seed for top-down IK.
pub const LEFT_TOP_DOWN_NOMINAL: [f64; DOF] = [-0.08, -1.0, -1.19, 1.94, 0.67, 1.03, -0.5];

impl Arm {
    /// IK for a top-down gripper pose at `(x, y, z)` with yaw `yaw`. A parallel gripper is
    /// symmetric under a half turn about its axis, so `yaw + pi` is the same grasp: both are
    /// tried, from `seed` and then from [`LEFT_TOP_DOWN_NOMINAL`]. Returns the first solution,
    /// or the attempt that came closest.
    pub fn ik_top_down(
        &self,
        (x, y, z): (f64, f64, f64),
        yaw: f64,
        seed: &[f64; DOF],
        opts: &IkOptions,
    ) -> Result<[f64; DOF], IkError> {
        let mut best: Option<IkError> = None;
        for s in [seed, &LEFT_TOP_DOWN_NOMINAL] {
            for y_try in [yaw, yaw + std::f64::consts::PI] {
                match self.ik(&top_down(x, y, z, y_try), s, opts) {
                    Ok(q) => return Ok(q),
                    Err(e @ IkError::NotFinite) => return Err(e),
                    Err(
                        e @ IkError::Unreachable {
                            position_error_m, ..
                        },
                    ) => {
                        let better = match best {
                            Some(IkError::Unreachable {
                                position_error_m: b,
                                ..
                            }) => position_error_m < b,
                            _ => true,
                        };
                        if better {
                            best = Some(e);
                        }
                    }
                }
            }
        }
        Err(best.unwrap_or(IkError::NotFinite))
    }
}

/// A top-down gripper pose: endpoint at `(x, y, z)` in `base`, gripper z axis pointing down,
/// turned by `yaw` about the vertical.
pub fn top_down(x: f64, y: f64, z: f64, yaw: f64) -> Isometry3<f64> {
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * down,
    )
}
