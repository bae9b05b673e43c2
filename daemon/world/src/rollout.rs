//! One rollout: a candidate placement of the next object settled in a clone of a world, then
//! the lattice BLBF rule for every later object, each settled, until one ends outside, finds
//! no feasible placement, or all are placed; its return is the sum of the placements' rewards
//! ([`RewardMode::reward`]). The search (`herb-search`) ranks its candidates by it; the
//! lookahead teacher of the evaluation (`herb_sim::teacher`) too.

use crate::{PackingWorld, ReleaseNoise, RewardMode};
use herb_core::TypeIdx;
use herb_core::error::Result;
use herb_core::lattice::{Lattice, Placement};
use rand_chacha::ChaCha8Rng;
use rapier3d::math::Rotation;

/// What the rollout after one candidate placement achieved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CandidateOutcome {
    /// The candidate placement.
    pub placement: Placement,
    /// Reward of the candidate's own placement.
    pub reward: f32,
    /// Return of the rollout: the candidate's reward plus those of the lattice BLBF placements
    /// that followed it.
    pub ret: f32,
    /// Objects of the remaining sequence placed inside, the candidate's included.
    pub packed: usize,
    /// Every remaining object was placed inside.
    pub success: bool,
    /// Sum of C over the rollout's placements that ended inside (to relabel the return for
    /// another reward: `CS(alpha)` return = `alpha * sum_c + (1 - alpha) * sum_s - failed`).
    pub sum_c: f32,
    /// Sum of S (0 or 1) over the rollout's placements that ended inside.
    pub sum_s: f32,
    /// Where and why the rollout failed (an object outside, or no feasible placement), when
    /// it did.
    pub failure: Option<RolloutFailure>,
}

impl CandidateOutcome {
    /// The rollout ended with a failure (an object outside, or no feasible placement).
    pub fn failed(&self) -> bool {
        self.failure.is_some()
    }
}

/// Where and why a rollout failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RolloutFailure {
    /// The step of the rollout (0: the candidate, 1: the next object...).
    pub step: usize,
    /// The bound crossed by the object found outside (e.g. `"+x wall"`), `None` when the
    /// lattice held no feasible placement.
    pub bound: Option<&'static str>,
    /// The object found outside was in the world before the rollout (pushed out).
    pub by_earlier: bool,
}

/// Simulates `first` for `remaining[0]` on a clone of `world`, then the lattice BLBF rule for
/// the rest of `remaining`, until an object ends outside, has no feasible placement, or all
/// are placed.
pub fn rollout(
    lattice: &mut Lattice,
    reward: RewardMode,
    world: &PackingWorld,
    remaining: &[TypeIdx],
    first: Placement,
) -> Result<CandidateOutcome> {
    let o = rollout_until(lattice, reward, world, remaining, first, None, None)?;
    Ok(o.expect("a rollout without a deadline always finishes"))
}

/// [`rollout`] that gives up when `deadline` passes (checked before each placement): `None`
/// then, the rollout unfinished. With `noise`, each object (the candidate's included) is
/// released off its placement by an offset drawn from the generator, as a gripper would.
pub fn rollout_until(
    lattice: &mut Lattice,
    reward: RewardMode,
    world: &PackingWorld,
    remaining: &[TypeIdx],
    first: Placement,
    deadline: Option<std::time::Instant>,
    mut noise: Option<(ReleaseNoise, &mut ChaCha8Rng)>,
) -> Result<Option<CandidateOutcome>> {
    let mut w = world.clone();
    let mut out = CandidateOutcome {
        placement: first,
        reward: 0.0,
        ret: 0.0,
        packed: 0,
        success: false,
        sum_c: 0.0,
        sum_s: 0.0,
        failure: None,
    };
    let earlier = w.placed().len();
    for (i, &ty) in remaining.iter().enumerate() {
        if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            return Ok(None);
        }
        let p = if i == 0 {
            first
        } else {
            lattice.compute(w.heightmap(), w.catalog(), ty);
            match lattice.blbf() {
                Some(p) => p,
                None => {
                    out.ret -= 1.0;
                    out.failure = Some(RolloutFailure {
                        step: i,
                        bound: None,
                        by_earlier: false,
                    });
                    return Ok(Some(out));
                }
            }
        };
        let o = match noise.as_mut() {
            None => w.place(ty, p.x, p.y, p.theta())?,
            Some((n, rng)) => {
                let rot = Rotation::from_rotation_z(p.theta());
                let pose = w.checked_release_pose(ty, p.x, p.y, rot)?;
                w.place_pose(ty, n.apply(pose, &mut **rng))?
            }
        };
        let r = reward.reward(&o);
        if i == 0 {
            out.reward = r;
        }
        out.ret += r;
        if !o.inside {
            out.failure = Some(RolloutFailure {
                step: i,
                bound: o.violation.map(|v| v.0),
                by_earlier: o.first_outside.is_some_and(|j| j < earlier),
            });
            return Ok(Some(out));
        }
        out.sum_c += o.compactness;
        out.sum_s += o.stable as u8 as f32;
        out.packed += 1;
    }
    out.success = true;
    Ok(Some(out))
}
