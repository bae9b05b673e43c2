//! The candidates' rollouts on the search's threads, the robust search's samples combined,
//! the release check's four releases, and the support rule's ranking.

use crate::settings::{ROBUST_SEED, ReleaseCheck, SearchSettings};
use herb_core::catalog::TypeIdx;
use herb_core::error::Result;
use herb_core::frames::BOX_HEIGHT;
use herb_core::lattice::{Lattice, Placement};
use herb_world::rollout::rollout_until;
use herb_world::{CandidateOutcome, PackingWorld, offset_pose};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rapier3d::math::Rotation;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// The support rule ([`SearchSettings::min_support`]) on `ranked` (candidate index into
/// `candidates`, return; best first): the return of each candidate standing above the rim on
/// less than `min_support` of its footprint lowered by 1, then sorted again (ties to the
/// prior's order). Returns how many were lowered.
pub(crate) fn demote_unsupported(
    ranked: &mut [(usize, f32)],
    candidates: &[Placement],
    min_support: f32,
) -> usize {
    let mut n = 0;
    for (c, ret) in ranked.iter_mut() {
        let p = &candidates[*c];
        if p.top > BOX_HEIGHT && p.support < min_support {
            *ret -= 1.0;
            n += 1;
        }
    }
    if n > 0 {
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    }
    n
}

/// One candidate's rollout: `None` never started (the deadline came first), `Some(None)` cut by
/// the deadline, else its outcome.
type Rolled = Option<Option<CandidateOutcome>>;

/// The rollout of each of `firsts`, in order, on as many threads as `lattices` (one scratch
/// lattice each). The unit handed out is one rollout: a candidate's, or, robust, one of its
/// samples ([`combine`] makes the candidate's outcome of them), in order, candidates first; so
/// two threads share the work of a few costly candidates too. Each rollout is the same whichever
/// thread runs it.
pub(crate) fn roll_out(
    lattices: &mut [Lattice],
    settings: &SearchSettings,
    world: &PackingWorld,
    remaining: &[TypeIdx],
    firsts: &[Placement],
    deadline: Option<Instant>,
) -> Result<Vec<Rolled>> {
    let robust = settings.robust.filter(|r| !r.noise.is_zero());
    let samples = robust.map_or(1, |r| r.samples.max(1));
    let tasks = firsts.len() * samples;
    let next = AtomicUsize::new(0);
    // One thread's share: the next rollout not yet taken, until none is left or the deadline.
    let work = |lattice: &mut Lattice| -> Result<Vec<(usize, Option<CandidateOutcome>)>> {
        let mut mine = Vec::new();
        loop {
            let t = next.fetch_add(1, Ordering::Relaxed);
            if t >= tasks || deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(mine);
            }
            let (c, i) = (t / samples, t % samples);
            let mut rng = ChaCha8Rng::seed_from_u64(ROBUST_SEED ^ i as u64);
            let noise = robust.map(|r| (r.noise, &mut rng));
            let o = rollout_until(
                lattice,
                settings.reward,
                world,
                remaining,
                firsts[c],
                deadline,
                noise,
            )?;
            mine.push((t, o));
        }
    };
    let threads = lattices.len().clamp(1, tasks.max(1));
    let results: Vec<Result<_>> = if threads == 1 {
        vec![work(&mut lattices[0])]
    } else {
        std::thread::scope(|s| {
            let workers: Vec<_> = lattices[..threads]
                .iter_mut()
                .map(|lattice| s.spawn(|| work(lattice)))
                .collect();
            workers
                .into_iter()
                .map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .collect()
        })
    };
    let mut each: Vec<Rolled> = vec![None; tasks];
    for r in results {
        for (t, o) in r? {
            each[t] = Some(o);
        }
    }
    Ok(each.chunks(samples).map(combine).collect())
}

/// A candidate's outcome of its rollouts (one, or, robust, its samples in order): never
/// started when none started; cut when one was cut or never started; else, robust, the mean
/// return of the samples, and the sample whose return is lowest standing for the rest, a
/// success only when every sample succeeded.
fn combine(rolled: &[Rolled]) -> Rolled {
    if rolled.iter().all(Option::is_none) {
        return None;
    }
    let mut done = Vec::with_capacity(rolled.len());
    for r in rolled {
        match r {
            Some(Some(o)) => done.push(*o),
            _ => return Some(None),
        }
    }
    if let [o] = done[..] {
        return Some(Some(o));
    }
    let sum: f32 = done.iter().map(|o| o.ret).sum();
    let all = done.iter().all(|o| o.success);
    let worst = done
        .iter()
        .copied()
        .reduce(|w, o| if o.ret < w.ret { o } else { w });
    Some(worst.map(|mut o| {
        o.ret = sum / done.len() as f32;
        o.success = all;
        o
    }))
}

/// How many of the release check's four releases of `ty` at `p` ([`ReleaseCheck::offsets`]),
/// each on a clone of `world` from the world's own release pose, leave it inside the box.
pub(crate) fn release_check(
    world: &PackingWorld,
    ty: TypeIdx,
    p: Placement,
    check: &ReleaseCheck,
) -> Result<usize> {
    let rot = Rotation::from_rotation_z(p.theta());
    let mut inside = 0;
    for [dx, dy, dyaw] in check.offsets() {
        let mut w = world.clone();
        let pose = w.checked_release_pose(ty, p.x, p.y, rot)?;
        inside += w.place_pose(ty, offset_pose(pose, dx, dy, dyaw))?.inside as usize;
    }
    Ok(inside)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn standing(top: f32, support: f32) -> Placement {
        Placement {
            x: 0.0,
            y: 0.0,
            yaw: 0,
            rest_z: 0.0,
            top,
            support,
            node: (0, 0),
            tight: false,
        }
    }

    /// The support rule ranks a candidate above the rim on too little of its footprint as a
    /// failed rollout, and leaves the others (below the rim, or well supported) as they were.
    #[test]
    fn the_support_rule_ranks_a_thinly_supported_candidate_above_the_rim_as_a_failure() {
        let candidates = [
            standing(BOX_HEIGHT + 0.05, 0.1),
            standing(BOX_HEIGHT + 0.05, 0.5),
            standing(BOX_HEIGHT - 0.01, 0.05),
            standing(BOX_HEIGHT + 0.02, 0.2),
        ];
        let mut ranked = vec![(0, 5.0), (1, 4.5), (2, 4.2), (3, 2.0)];
        assert_eq!(demote_unsupported(&mut ranked, &candidates, 0.3), 2);
        assert_eq!(ranked, vec![(1, 4.5), (2, 4.2), (0, 4.0), (3, 1.0)]);
        // A lower share keeps the 20 % candidate; none demoted keeps the order.
        let mut ranked = vec![(0, 5.0), (3, 2.0)];
        assert_eq!(demote_unsupported(&mut ranked, &candidates, 0.15), 1);
        assert_eq!(ranked, vec![(0, 4.0), (3, 2.0)]);
        let mut ranked = vec![(1, 4.5), (2, 4.2)];
        assert_eq!(demote_unsupported(&mut ranked, &candidates, 0.3), 0);
        assert_eq!(ranked, vec![(1, 4.5), (2, 4.2)]);
    }
}
