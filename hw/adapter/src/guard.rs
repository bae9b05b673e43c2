//! The adapter's last line against a jump: a joint command reaches the robot only when it was
//! planned after the robot last became ready, and its target is near the measured position.
//!
//! herbd never plans from a stale state (after any interruption it resumes from a state measured
//! after it); this guard makes the same promise hold on the adapter's side, whatever herbd sends.
//! Two rules, checked for every command the adapter is about to pass on:
//!
//! 1. **Planned after the robot became ready.** While the robot cannot move (disabled, e-stop,
//!    master lost...), nothing is sent; when it can again, a command stamped before that moment
//!    is refused. A setpoint herbd held through the interruption can never be replayed.
//! 2. **Near the measured position.** Per joint, `|target - measured| <= bound`, with
//!    `bound = speed limit x (periods / command rate + tracking lag)` (see [`GuardSettings`]):
//!    the travel of a few command periods at the joint's speed limit plus how far a normally
//!    tracking arm trails its command (its lag, a time, at that speed). A normal trajectory never comes near it; a jump to a
//!    setpoint from before a sag is refused.
//!
//! Refused commands are counted. A command refused for its distance means herbd and the arm
//! disagree: the adapter then withholds joint state for [`REFUSAL_HOLD_NS`] (saying
//! `ArmBlocker::CommandRefused`), so that herbd halts and resumes from the measured state.

use herb_ipc::DOF;

/// After a command refused for its distance, joint state is withheld this long (ns): longer
/// than herbd's joint-state timeout (100 ms by default), so that herbd halts.
pub const REFUSAL_HOLD_NS: u64 = 300_000_000;

/// How the per-joint bound is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardSettings {
    /// Farthest a command's target may be from the measured position, per joint (rad).
    pub bound_rad: [f64; DOF],
    /// A measured position older than this (ns) is no measurement: commands wait for a newer
    /// one.
    pub max_measured_age_ns: u64,
}

impl GuardSettings {
    /// `bound_i = velocity_i x (periods / rate_hz + lag_s)`: the travel of `periods` command
    /// periods at the joint's speed limit (herbd's `[limits] velocity`, the same file) plus
    /// how far the arm trails its command at that speed (`lag_s`).
    pub fn from_limits(velocity: &[f64; DOF], rate_hz: f64, periods: f64, lag_s: f64) -> Self {
        Self {
            bound_rad: velocity.map(|v| v * (periods / rate_hz + lag_s)),
            max_measured_age_ns: 100_000_000,
        }
    }
}

/// Why a command did not reach the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// The robot cannot move now.
    NotReady,
    /// The command was stamped before the robot last became ready.
    PlannedBeforeReady {
        /// The command's stamp (ns).
        stamp_ns: u64,
        /// When the robot became ready (ns).
        ready_since_ns: u64,
    },
    /// No measured position recent enough to compare with.
    NoMeasurement,
    /// The target is too far from the measured position.
    TooFar {
        /// The joint (index in herbd's order).
        joint: usize,
        /// Its distance from the measured position (rad).
        offset_rad: f64,
        /// Its bound (rad).
        bound_rad: f64,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotReady => write!(f, "the robot cannot move"),
            Self::PlannedBeforeReady {
                stamp_ns,
                ready_since_ns,
            } => write!(
                f,
                "planned {:.3} s before the robot became ready",
                ready_since_ns.saturating_sub(*stamp_ns) as f64 * 1e-9
            ),
            Self::NoMeasurement => write!(f, "no recent measured position"),
            Self::TooFar {
                joint,
                offset_rad,
                bound_rad,
            } => write!(
                f,
                "joint {joint}: target {offset_rad:.4} rad from the measured position (bound {bound_rad:.4})"
            ),
        }
    }
}

/// The guard's state: readiness epoch, counters.
#[derive(Debug, Clone)]
pub struct JumpGuard {
    settings: GuardSettings,
    ready_since: Option<u64>,
    /// Commands refused.
    pub refused: u64,
    /// Largest offset of a passed command from the measured position, per joint (rad): the
    /// tracking lag actually seen, to set the bound from.
    pub max_offset_rad: [f64; DOF],
}

impl JumpGuard {
    /// A guard with `settings`; the robot counts as not ready until [`JumpGuard::set_ready`].
    pub fn new(settings: GuardSettings) -> Self {
        Self {
            settings,
            ready_since: None,
            refused: 0,
            max_offset_rad: [0.0; DOF],
        }
    }

    /// Its settings.
    pub fn settings(&self) -> &GuardSettings {
        &self.settings
    }

    /// Whether the robot can move at `now_ns`. Becoming ready starts a new epoch: commands
    /// stamped before it are refused. True when this call made it ready.
    pub fn set_ready(&mut self, ready: bool, now_ns: u64) -> bool {
        match (ready, self.ready_since) {
            (true, None) => {
                self.ready_since = Some(now_ns);
                true
            }
            (false, Some(_)) => {
                self.ready_since = None;
                false
            }
            _ => false,
        }
    }

    /// Checks a command (`stamp_ns`, `target`) against the latest measured position
    /// (`measured`: its stamp and angles) at `now_ns`; counts a refusal.
    pub fn check(
        &mut self,
        stamp_ns: u64,
        target: &[f64; DOF],
        measured: Option<(u64, &[f64; DOF])>,
        now_ns: u64,
    ) -> Result<(), Refusal> {
        let r = self.verdict(stamp_ns, target, measured, now_ns);
        match r {
            Ok(offsets) => {
                for (m, o) in self.max_offset_rad.iter_mut().zip(offsets) {
                    *m = m.max(o);
                }
                Ok(())
            }
            Err(e) => {
                self.refused += 1;
                Err(e)
            }
        }
    }

    fn verdict(
        &self,
        stamp_ns: u64,
        target: &[f64; DOF],
        measured: Option<(u64, &[f64; DOF])>,
        now_ns: u64,
    ) -> Result<[f64; DOF], Refusal> {
        let since = self.ready_since.ok_or(Refusal::NotReady)?;
        if stamp_ns < since {
            return Err(Refusal::PlannedBeforeReady {
                stamp_ns,
                ready_since_ns: since,
            });
        }
        let (at, q) = measured.ok_or(Refusal::NoMeasurement)?;
        if now_ns.saturating_sub(at) > self.settings.max_measured_age_ns {
            return Err(Refusal::NoMeasurement);
        }
        let mut offsets = [0.0; DOF];
        for i in 0..DOF {
            let offset = (target[i] - q[i]).abs();
            let bound = self.settings.bound_rad[i];
            // NaN is never within the bound.
            if offset.is_nan() || offset > bound {
                return Err(Refusal::TooFar {
                    joint: i,
                    offset_rad: offset,
                    bound_rad: bound,
                });
            }
            offsets[i] = offset;
        }
        Ok(offsets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn guard() -> JumpGuard {
        JumpGuard::new(GuardSettings::from_limits(&[1.0; DOF], 100.0, 3.0, 0.05))
    }

    #[test]
    fn the_bound_is_a_few_periods_at_the_speed_limit_plus_the_lag() {
        let g = guard();
        for b in g.settings().bound_rad {
            assert!((b - 0.08).abs() < 1e-12, "{b}");
        }
    }

    #[test]
    fn nothing_passes_before_the_robot_is_ready_nor_anything_planned_before_it() {
        let mut g = guard();
        let q = [0.0; DOF];
        assert_eq!(g.check(10, &q, Some((10, &q)), 10), Err(Refusal::NotReady));
        assert!(g.set_ready(true, 1_000));
        assert!(!g.set_ready(true, 2_000), "still the same epoch");
        assert!(matches!(
            g.check(999, &q, Some((1_000, &q)), 1_000),
            Err(Refusal::PlannedBeforeReady { .. })
        ));
        assert_eq!(g.check(1_000, &q, Some((1_000, &q)), 1_000), Ok(()));
        // Interrupted, ready again: the held setpoint of before is refused.
        g.set_ready(false, 5_000);
        assert_eq!(
            g.check(6_000, &q, Some((6_000, &q)), 6_000),
            Err(Refusal::NotReady)
        );
        g.set_ready(true, 7_000);
        assert!(g.check(6_500, &q, Some((7_000, &q)), 7_000).is_err());
        assert_eq!(g.refused, 4);
    }

    #[test]
    fn a_target_far_from_the_measured_position_is_refused_and_a_near_one_passes() {
        let mut g = guard();
        g.set_ready(true, 0);
        let measured = [0.1; DOF];
        let mut near = measured;
        near[6] += 0.079;
        assert_eq!(g.check(5, &near, Some((5, &measured)), 5), Ok(()));
        assert!((g.max_offset_rad[6] - 0.079).abs() < 1e-12);
        let mut sagged = measured;
        sagged[1] += 0.38; // the jump seen on a real arm after a disable
        assert!(matches!(
            g.check(6, &sagged, Some((6, &measured)), 6),
            Err(Refusal::TooFar { joint: 1, .. })
        ));
        let mut nan = measured;
        nan[0] = f64::NAN;
        assert!(g.check(7, &nan, Some((7, &measured)), 7).is_err());
        // A measurement older than 100 ms is none.
        assert_eq!(
            g.check(200_000_000, &measured, Some((0, &measured)), 200_000_000),
            Err(Refusal::NoMeasurement)
        );
        assert_eq!(g.check(8, &measured, None, 8), Err(Refusal::NoMeasurement));
    }
}
