//! Jerk-limited joint trajectories with Ruckig (the official `ruckig` crate, C++ through cxx).
//!
//! Ruckig's Rust wrapper allocates on every call (it copies vectors across the FFI), so it is
//! never called from the control loop. The planner thread computes a trajectory with
//! [`MotionPlanner::point_to_point`] or [`MotionPlanner::brake`] and samples it at the loop
//! period into a preallocated [`Setpoints`] buffer; the loop streams one sample per cycle.
//!
//! Every sample is checked against the configured joint limits before it is accepted: a
//! point-to-point trajectory that leaves them is an error (never clamped). A brake may clamp a
//! sample to a limit (a joint already moving fast toward its limit cannot do better); the
//! clamps are counted and reported.

use crate::kinematics::DOF;
use ruckig::{
    ControlInterface, InputParameter, Result as RResult, Ruckig, Synchronization, Trajectory,
};
use serde::{Deserialize, Serialize};

/// Joint limits: position (the configured range, usually inside the URDF's), velocity,
/// acceleration and jerk, per joint `s0 .. w2`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointLimits {
    /// Lower angles (rad).
    pub lower: [f64; DOF],
    /// Upper angles (rad).
    pub upper: [f64; DOF],
    /// Speed limits (rad/s).
    pub velocity: [f64; DOF],
    /// Acceleration limits (rad/s^2).
    pub acceleration: [f64; DOF],
    /// Jerk limits (rad/s^3).
    pub jerk: [f64; DOF],
}

impl Default for JointLimits {
    fn default() -> Self {
        Self::baxter_left()
    }
}

impl JointLimits {
    /// Baxter's left arm: the URDF position limits shrunk by 0.05 rad, 60 % of the URDF speed
    /// limits, and accelerations/jerks chosen for smooth motion (Rethink publishes none).
    pub fn baxter_left() -> Self {
        let j = crate::kinematics::LEFT_ARM;
        Self {
            lower: j.map(|s| s.lower + 0.05),
            upper: j.map(|s| s.upper - 0.05),
            velocity: j.map(|s| 0.6 * s.max_velocity),
            acceleration: [2.0, 2.0, 2.0, 2.0, 4.0, 4.0, 4.0],
            jerk: [10.0, 10.0, 10.0, 10.0, 20.0, 20.0, 20.0],
        }
    }

    /// Checks that every limit is finite, positive where it must be, and that each position
    /// range is non-empty and inside `hard` (e.g. the URDF limits).
    pub fn validate(
        &self,
        hard_lower: &[f64; DOF],
        hard_upper: &[f64; DOF],
    ) -> Result<(), LimitsError> {
        for joint in 0..DOF {
            let (lo, hi) = (self.lower[joint], self.upper[joint]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(LimitsError::EmptyRange { joint, lo, hi });
            }
            if lo < hard_lower[joint] || hi > hard_upper[joint] {
                return Err(LimitsError::OutsideArm {
                    joint,
                    lo,
                    hi,
                    arm_lo: hard_lower[joint],
                    arm_hi: hard_upper[joint],
                });
            }
            for (what, value) in [
                ("velocity", self.velocity[joint]),
                ("acceleration", self.acceleration[joint]),
                ("jerk", self.jerk[joint]),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return Err(LimitsError::NotPositive { joint, what, value });
                }
            }
        }
        Ok(())
    }

    /// [`Self::validate`] against the URDF limits of Baxter's left arm.
    pub fn validate_baxter_left(&self) -> Result<(), LimitsError> {
        let j = crate::kinematics::LEFT_ARM;
        self.validate(&j.map(|s| s.lower), &j.map(|s| s.upper))
    }

    /// True when every angle of `q` is within the position limits.
    pub fn contains(&self, q: &[f64; DOF]) -> bool {
        (0..DOF).all(|i| q[i] >= self.lower[i] && q[i] <= self.upper[i])
    }

    /// The joint of `q` farthest outside the position limits, if any is outside (a non-finite
    /// angle counts as outside, by an infinite excess).
    pub fn excess(&self, q: &[f64; DOF]) -> Option<Excess> {
        excess_of(q, &self.lower, &self.upper)
    }

    /// `q` with every joint outside the position limits moved `margin` inside the limit it is
    /// beyond (at most half its range); the joints inside are unchanged.
    pub fn pulled_inside(&self, q: &[f64; DOF], margin: f64) -> [f64; DOF] {
        let mut out = *q;
        for (j, v) in out.iter_mut().enumerate() {
            let m = margin.min(0.5 * (self.upper[j] - self.lower[j])).max(0.0);
            if *v < self.lower[j] {
                *v = self.lower[j] + m;
            } else if *v > self.upper[j] {
                *v = self.upper[j] - m;
            }
        }
        out
    }
}

/// The joint of `q` farthest outside `lower ..= upper`, if any.
pub fn excess_of(q: &[f64; DOF], lower: &[f64; DOF], upper: &[f64; DOF]) -> Option<Excess> {
    let mut worst: Option<Excess> = None;
    for j in 0..DOF {
        let (v, bound) = if !q[j].is_finite() {
            (f64::INFINITY, upper[j])
        } else if q[j] < lower[j] {
            (lower[j] - q[j], lower[j])
        } else if q[j] > upper[j] {
            (q[j] - upper[j], upper[j])
        } else {
            continue;
        };
        if worst.is_none_or(|w| v > w.by()) {
            worst = Some(Excess {
                joint: j,
                position: q[j],
                bound,
            });
        }
    }
    worst
}

/// A joint outside a position range: which, where, and the limit it is beyond.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excess {
    /// Joint index (`s0 .. w2`).
    pub joint: usize,
    /// Its angle (rad).
    pub position: f64,
    /// The limit it is beyond (rad).
    pub bound: f64,
}

impl Excess {
    /// How far beyond the limit (rad, positive; infinite for a non-finite angle).
    pub fn by(&self) -> f64 {
        if self.position.is_finite() {
            (self.position - self.bound).abs()
        } else {
            f64::INFINITY
        }
    }
}

/// The position limits of Baxter's left arm itself (its URDF's), wider than herbd's
/// configured ones ([`JointLimits::baxter_left`] shrinks them by 0.05 rad).
pub fn baxter_left_arm_range() -> ([f64; DOF], [f64; DOF]) {
    let j = crate::kinematics::LEFT_ARM;
    (j.map(|s| s.lower), j.map(|s| s.upper))
}

/// Joint limits that cannot be used ([`JointLimits::validate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitsError {
    /// An empty or non-finite position range.
    #[error("joint {joint}: position range [{lo}, {hi}] is empty or not finite")]
    EmptyRange {
        /// Joint index.
        joint: usize,
        /// Its lower limit (rad).
        lo: f64,
        /// Its upper limit (rad).
        hi: f64,
    },
    /// A position range outside the arm's own.
    #[error(
        "joint {joint}: position range [{lo}, {hi}] leaves the arm's limits [{arm_lo}, {arm_hi}]"
    )]
    OutsideArm {
        /// Joint index.
        joint: usize,
        /// Its lower limit (rad).
        lo: f64,
        /// Its upper limit (rad).
        hi: f64,
        /// The arm's lower limit (rad).
        arm_lo: f64,
        /// The arm's upper limit (rad).
        arm_hi: f64,
    },
    /// A speed, acceleration or jerk limit that is not a positive number.
    #[error("joint {joint}: {what} limit {value} must be finite and > 0")]
    NotPositive {
        /// Joint index.
        joint: usize,
        /// `velocity`, `acceleration` or `jerk`.
        what: &'static str,
        /// The limit.
        value: f64,
    },
}

impl From<LimitsError> for herb_process::config_file::Invalid {
    /// The `[limits]` table's error, as a configuration error.
    fn from(e: LimitsError) -> Self {
        Self::Other(format!("limits: {e}"))
    }
}

/// One sample: position, velocity, acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Setpoint {
    /// Angles (rad).
    pub position: [f64; DOF],
    /// Speeds (rad/s).
    pub velocity: [f64; DOF],
    /// Accelerations (rad/s^2).
    pub acceleration: [f64; DOF],
}

impl Setpoint {
    /// Standing still at `q`.
    pub fn at_rest(q: [f64; DOF]) -> Self {
        Self {
            position: q,
            ..Self::default()
        }
    }
}

/// A preallocated buffer of samples at the loop period.
#[derive(Debug, Clone)]
pub struct Setpoints {
    samples: Vec<Setpoint>,
}

impl Setpoints {
    /// Room for `capacity` samples; pushing more is an error, never a reallocation.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            samples: Vec::with_capacity(capacity),
        }
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Sample `i`.
    pub fn get(&self, i: usize) -> Option<&Setpoint> {
        self.samples.get(i)
    }

    /// All samples.
    pub fn as_slice(&self) -> &[Setpoint] {
        &self.samples
    }

    /// Forgets the samples (keeps the memory).
    pub fn clear(&mut self) {
        self.samples.clear();
    }

    /// Appends a sample; an error (`TooLong`) when the buffer is full, never a reallocation.
    pub fn push(&mut self, s: Setpoint) -> Result<(), MotionError> {
        if self.samples.len() == self.samples.capacity() {
            return Err(MotionError::TooLong {
                capacity: self.samples.capacity(),
            });
        }
        self.samples.push(s);
        Ok(())
    }
}

/// Why a trajectory was not produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// A start or target outside the position limits, or a non-finite state.
    #[error("joint {joint}: {what} {value} outside the limits or not finite")]
    BadState {
        /// Which state.
        what: &'static str,
        /// Joint index.
        joint: usize,
        /// Its value.
        value: f64,
    },
    /// Ruckig refused the input or failed.
    #[error("ruckig: {0}")]
    Ruckig(String),
    /// A sample left the position limits (point-to-point only).
    #[error("sample {sample}, joint {joint}: {value} rad leaves the position limits")]
    LeavesLimits {
        /// Sample index.
        sample: usize,
        /// Joint index.
        joint: usize,
        /// Angle.
        value: f64,
    },
    /// The trajectory needs more samples than the buffer holds.
    #[error("trajectory longer than the buffer ({capacity} samples)")]
    TooLong {
        /// Buffer capacity.
        capacity: usize,
    },
}

/// Computes and samples trajectories (planner thread only: allocates).
pub struct MotionPlanner {
    ruckig: Ruckig,
    input: InputParameter,
    traj: Trajectory,
    limits: JointLimits,
    dt: f64,
}

impl std::fmt::Debug for MotionPlanner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MotionPlanner")
            .field("limits", &self.limits)
            .field("dt", &self.dt)
            .finish()
    }
}

/// Position tolerance for samples at a limit (rad): Ruckig's own numerical slack.
const LIMIT_EPS: f64 = 1e-9;

impl MotionPlanner {
    /// A planner for `limits`, sampling every `dt` seconds (the loop period).
    pub fn new(limits: JointLimits, dt: f64) -> Self {
        let mut input = InputParameter::new(DOF);
        input.max_velocity = limits.velocity.to_vec();
        input.max_acceleration = limits.acceleration.to_vec();
        input.max_jerk = limits.jerk.to_vec();
        Self {
            ruckig: Ruckig::new_direct_and_offline(DOF),
            input,
            traj: Trajectory::new_direct(DOF),
            limits,
            dt,
        }
    }

    /// The limits.
    pub fn limits(&self) -> &JointLimits {
        &self.limits
    }

    fn check(&self, what: &'static str, q: &[f64; DOF]) -> Result<(), MotionError> {
        match (0..DOF).find(|&i| {
            !(q[i].is_finite() && q[i] >= self.limits.lower[i] && q[i] <= self.limits.upper[i])
        }) {
            Some(joint) => Err(MotionError::BadState {
                what,
                joint,
                value: q[joint],
            }),
            None => Ok(()),
        }
    }

    /// Sets Ruckig's input for a time-synchronised move from rest at `from` to rest at `to`.
    fn rest_to_rest(&mut self, from: &[f64; DOF], to: &[f64; DOF]) {
        let z = vec![0.0; DOF];
        self.input.control_interface = ControlInterface::Position;
        self.input.synchronization = Synchronization::Time;
        self.input.current_position = from.to_vec();
        self.input.current_velocity = z.clone();
        self.input.current_acceleration = z.clone();
        self.input.target_position = to.to_vec();
        self.input.target_velocity = z.clone();
        self.input.target_acceleration = z;
    }

    fn calculate(&mut self) -> Result<f64, MotionError> {
        match self.ruckig.calculate(&mut self.input, &mut self.traj) {
            RResult::Working | RResult::Finished => Ok(self.traj.get_duration()),
            e => Err(MotionError::Ruckig(format!("{e:?}"))),
        }
    }

    /// Appends the time-optimal, time-synchronised rest-to-rest trajectory from `from` to `to`
    /// to `out`, sampled at `dt, 2 dt, ...` and ending exactly at `to` at rest. Returns its
    /// duration (s). Both ends must be inside the position limits.
    pub fn point_to_point(
        &mut self,
        from: &[f64; DOF],
        to: &[f64; DOF],
        out: &mut Setpoints,
    ) -> Result<f64, MotionError> {
        self.check("start", from)?;
        self.check("target", to)?;
        self.rest_to_rest(from, to);
        let duration = self.calculate()?;
        let start = out.len();
        self.sample(duration, out, |_, _| {})?;
        // The last sample is the target itself, at rest.
        if let Some(last) = out.samples.last_mut() {
            *last = Setpoint::at_rest(*to);
        }
        for (k, s) in out.samples[start..].iter().enumerate() {
            for j in 0..DOF {
                let v = s.position[j];
                if v < self.limits.lower[j] - LIMIT_EPS || v > self.limits.upper[j] + LIMIT_EPS {
                    return Err(MotionError::LeavesLimits {
                        sample: k,
                        joint: j,
                        value: v,
                    });
                }
            }
        }
        for s in &mut out.samples[start..] {
            for j in 0..DOF {
                s.position[j] = s.position[j].clamp(self.limits.lower[j], self.limits.upper[j]);
            }
        }
        Ok(duration)
    }

    /// Appends the slow move that brings a start outside the position limits back inside
    /// (`from` as measured, e.g. an arm that sagged while disabled): every joint outside goes,
    /// at `speed` times its speed, acceleration and jerk limits (0 < `speed` <= 1), to `margin`
    /// inside the limit it is beyond, rest to rest; the joints inside stay where they are. No
    /// sample goes farther out than `from`, nor past the target. `from` must be finite and
    /// inside `hard` (the arm's own limits). Returns the duration (s), or `None` with nothing
    /// appended when `from` is inside the limits already.
    pub fn into_limits(
        &mut self,
        from: &[f64; DOF],
        hard: (&[f64; DOF], &[f64; DOF]),
        speed: f64,
        margin: f64,
        out: &mut Setpoints,
    ) -> Result<Option<f64>, MotionError> {
        if let Some(e) = excess_of(from, hard.0, hard.1) {
            return Err(MotionError::BadState {
                what: "start (beyond the arm's own limits)",
                joint: e.joint,
                value: e.position,
            });
        }
        if self.limits.contains(from) {
            return Ok(None);
        }
        if !(speed.is_finite() && speed > 0.0 && speed <= 1.0) {
            return Err(MotionError::Ruckig(format!(
                "speed fraction {speed} outside (0, 1]"
            )));
        }
        let to = self.limits.pulled_inside(from, margin);
        let scaled = |v: &[f64; DOF]| v.iter().map(|x| x * speed).collect::<Vec<_>>();
        self.input.max_velocity = scaled(&self.limits.velocity);
        self.input.max_acceleration = scaled(&self.limits.acceleration);
        self.input.max_jerk = scaled(&self.limits.jerk);
        self.rest_to_rest(from, &to);
        let result = self.calculate();
        self.input.max_velocity = self.limits.velocity.to_vec();
        self.input.max_acceleration = self.limits.acceleration.to_vec();
        self.input.max_jerk = self.limits.jerk.to_vec();
        let duration = result?;
        let start = out.len();
        self.sample(duration, out, |_, _| {})?;
        if let Some(last) = out.samples.last_mut() {
            *last = Setpoint::at_rest(to);
        }
        // Toward the limit only: every sample between the start and the target.
        for (k, s) in out.samples[start..].iter_mut().enumerate() {
            for j in 0..DOF {
                let (lo, hi) = (from[j].min(to[j]), from[j].max(to[j]));
                let v = s.position[j];
                if v < lo - LIMIT_EPS || v > hi + LIMIT_EPS {
                    return Err(MotionError::LeavesLimits {
                        sample: k,
                        joint: j,
                        value: v,
                    });
                }
                s.position[j] = v.clamp(lo, hi);
            }
        }
        Ok(Some(duration))
    }

    /// Appends a brake from `state` to standstill (every joint stops as fast as its limits
    /// allow, unsynchronised) to `out`. Returns the duration and the number of position
    /// values clamped to a limit.
    pub fn brake(
        &mut self,
        state: &Setpoint,
        out: &mut Setpoints,
    ) -> Result<(f64, usize), MotionError> {
        for (what, v) in [
            ("position", &state.position),
            ("velocity", &state.velocity),
            ("acceleration", &state.acceleration),
        ] {
            if let Some(joint) = v.iter().position(|x| !x.is_finite()) {
                return Err(MotionError::BadState {
                    what,
                    joint,
                    value: v[joint],
                });
            }
        }
        let z = vec![0.0; DOF];
        self.input.control_interface = ControlInterface::Velocity;
        self.input.synchronization = Synchronization::None;
        self.input.current_position = state.position.to_vec();
        // Ruckig rejects a start beyond its limits: cap the state to them (a brake then
        // starts a hair gentler than the measured state).
        self.input.current_velocity = (0..DOF)
            .map(|j| state.velocity[j].clamp(-self.limits.velocity[j], self.limits.velocity[j]))
            .collect();
        self.input.current_acceleration = (0..DOF)
            .map(|j| {
                state.acceleration[j]
                    .clamp(-self.limits.acceleration[j], self.limits.acceleration[j])
            })
            .collect();
        self.input.target_position = state.position.to_vec();
        self.input.target_velocity = z.clone();
        self.input.target_acceleration = z;
        let result = self.calculate();
        self.input.control_interface = ControlInterface::Position;
        self.input.synchronization = Synchronization::Time;
        let duration = result?;
        // A brake that starts outside the limits (on the way back in from a sagged arm) keeps
        // no farther out than its start: clamped to the limits widened to it, never a jump.
        let (mut lower, mut upper) = (self.limits.lower, self.limits.upper);
        for j in 0..DOF {
            lower[j] = lower[j].min(state.position[j]);
            upper[j] = upper[j].max(state.position[j]);
        }
        let mut clamps = 0;
        self.sample(duration, out, |s, _| {
            for j in 0..DOF {
                let c = s.position[j].clamp(lower[j], upper[j]);
                if c != s.position[j] {
                    clamps += 1;
                    s.position[j] = c;
                }
            }
        })?;
        if let Some(last) = out.samples.last_mut() {
            last.velocity = [0.0; DOF];
            last.acceleration = [0.0; DOF];
        }
        Ok((duration, clamps))
    }

    fn sample(
        &self,
        duration: f64,
        out: &mut Setpoints,
        mut fix: impl FnMut(&mut Setpoint, usize),
    ) -> Result<(), MotionError> {
        let n = (duration / self.dt).ceil().max(1.0) as usize;
        for k in 1..=n {
            let t = (k as f64 * self.dt).min(duration);
            let (p, v, a) = self.traj.at_time(t);
            let mut s = Setpoint::default();
            s.position.copy_from_slice(&p[..DOF]);
            s.velocity.copy_from_slice(&v[..DOF]);
            s.acceleration.copy_from_slice(&a[..DOF]);
            fix(&mut s, k);
            out.push(s)?;
        }
        Ok(())
    }
}
