//! The job's twin ([`TwinKind::Job`](crate::TwinKind::Job)): the objects released so far,
//! each replayed where it was released and fitted to the next heightmap, compared with the
//! camera's, and fused into the heightmap the candidates are found on where the two agree.

use crate::Search;
use herb_core::catalog::TypeIdx;
use herb_core::error::Result;
use herb_core::heightmap::Heightmap;
use herb_world::{PackingWorld, offset_pose};
use rapier3d::math::Pose;
use std::time::{Duration, Instant};

/// Offsets (m) in x and in y of a replayed release that the job's twin may try, each with each.
pub const JOB_FIT_XY_M: [f32; 5] = [-0.008, -0.004, 0.0, 0.004, 0.008];
/// Offsets (degrees) of a replayed release's yaw that the job's twin may try.
pub const JOB_FIT_YAW_DEG: [f32; 3] = [-4.0, 0.0, 4.0];
/// A replayed release whose settled heightmap is this near the camera's (mean |difference|
/// over the cells, m) explains it: the fit stops there.
pub const JOB_FIT_GOOD_M: f64 = 0.0005;
/// A cell of the job's twin disagrees with the heightmap when their heights differ by more.
pub const JOB_CELL_OFF_M: f32 = 0.01;
/// The job's twin is used while at most this share of the heightmap's cells disagree.
pub const JOB_MAX_OFF: f32 = 0.2;

/// How the job's twin compared with the decision's heightmap ([`TwinKind::Job`](crate::TwinKind::Job)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobAgreement {
    /// Objects in the job's twin.
    pub objects: usize,
    /// Mean |twin - heightmap| over the cells (m).
    pub mean_diff_m: f32,
    /// Share of the cells off by more than [`JOB_CELL_OFF_M`].
    pub off: f32,
    /// The rollouts ran in it (else in the heightmap twin).
    pub used: bool,
    /// Time spent fitting the last released object (part of the decision's time and budget).
    pub fit: Duration,
}

/// The job's twin between decisions ([`TwinKind::Job`](crate::TwinKind::Job)).
#[derive(Debug, Clone)]
pub(crate) struct JobTwin {
    /// The objects released so far, fitted.
    pub(crate) world: PackingWorld,
    /// The remaining objects at the last decision: the next decision continues the job when
    /// its remaining objects are these without the first (that one was released).
    pub(crate) remaining: Vec<TypeIdx>,
    /// The release pose decided last.
    pub(crate) release: Option<(TypeIdx, Pose)>,
}

impl Search {
    /// Brings the job's twin up to `heightmap`; whether it agrees with it (then the rollouts
    /// run in it). The decision continues the job when `remaining` is the last decision's
    /// without its first object: that object was released where it was decided, and is
    /// replayed there, moved by the offset that best explains `heightmap`, or left out when the
    /// box without it explains `heightmap` better (it was skipped after a missed grasp). The
    /// same remaining objects again (a pick tried again) add nothing; anything else starts a
    /// new job from an empty box.
    pub(crate) fn follow_job(
        &mut self,
        heightmap: &Heightmap,
        remaining: &[TypeIdx],
    ) -> Result<bool> {
        let continues = |j: &JobTwin| j.remaining.get(1..) == Some(remaining);
        let mut fit = Duration::ZERO;
        match self.job.take() {
            Some(mut j) if continues(&j) => {
                if let Some((ty, pose)) = j.release.take() {
                    let t0 = Instant::now();
                    j.world = fit_release(&j.world, ty, pose, heightmap)?;
                    fit = t0.elapsed();
                }
                self.job = Some(j);
            }
            Some(j) if j.remaining == remaining => self.job = Some(j),
            _ => {
                self.job = Some(JobTwin {
                    world: PackingWorld::new(self.catalog.clone(), self.cfg.clone())?,
                    remaining: Vec::new(),
                    release: None,
                })
            }
        }
        let Some(j) = self.job.as_mut() else {
            return Ok(false);
        };
        j.remaining.clear();
        j.remaining.extend_from_slice(remaining);
        j.release = None;
        let (sum, off) = compare(j.world.heightmap(), heightmap);
        let cells = heightmap.data().len().max(1);
        let agreement = JobAgreement {
            objects: j.world.placed().len(),
            mean_diff_m: (sum / cells as f64) as f32,
            off: off as f32 / cells as f32,
            used: off as f32 <= JOB_MAX_OFF * cells as f32,
            fit,
        };
        self.report.job = Some(agreement);
        Ok(agreement.used)
    }
}

/// Writes into `out` the twin's heightmap where it is within [`JOB_CELL_OFF_M`] of the camera's,
/// and the camera's elsewhere. In a world that is its own model the two are equal, and so is
/// `out`. All three on one grid (the twin's is the camera's grid).
pub(crate) fn fuse(twin: &Heightmap, camera: &Heightmap, out: &mut Heightmap) {
    if out.spec() != camera.spec() {
        *out = camera.clone();
    }
    for ((o, &t), &c) in out
        .data_mut()
        .iter_mut()
        .zip(twin.data())
        .zip(camera.data())
    {
        *o = if (t - c).abs() <= JOB_CELL_OFF_M {
            t
        } else {
            c
        };
    }
}

/// The sum of |a - b| over the cells (m), and the cells that differ by more than
/// [`JOB_CELL_OFF_M`].
fn compare(a: &Heightmap, b: &Heightmap) -> (f64, usize) {
    a.data()
        .iter()
        .zip(b.data())
        .fold((0.0, 0), |(sum, off), (x, y)| {
            let d = (x - y).abs();
            (sum + d as f64, off + (d > JOB_CELL_OFF_M) as usize)
        })
}

/// `world` with `ty` released at `pose` moved by the offset of [`JOB_FIT_XY_M`] x
/// [`JOB_FIT_XY_M`] x [`JOB_FIT_YAW_DEG`] whose settled heightmap is nearest `seen` (mean
/// |difference| over the cells), found by a climb: from no offset, to the best of the six
/// next offsets (one step in x, in y or in yaw) while it is nearer, until none is or the
/// release explains `seen` ([`JOB_FIT_GOOD_M`]). Ties keep the earlier. `world` itself when
/// it is nearer still (the object was never released: a pick skipped after a missed grasp).
/// Deterministic, so that a replay rebuilds the same twin.
fn fit_release(
    world: &PackingWorld,
    ty: TypeIdx,
    pose: Pose,
    seen: &Heightmap,
) -> Result<PackingWorld> {
    let cells = seen.data().len().max(1) as f64;
    let (nx, nyaw) = (JOB_FIT_XY_M.len(), JOB_FIT_YAW_DEG.len());
    let mut tried = [false; JOB_FIT_XY_M.len() * JOB_FIT_XY_M.len() * JOB_FIT_YAW_DEG.len()];
    let released = |at: [usize; 3]| -> Result<(PackingWorld, f64)> {
        let [ix, iy, iyaw] = at;
        let mut w = world.clone();
        let (dx, dy) = (JOB_FIT_XY_M[ix], JOB_FIT_XY_M[iy]);
        let dyaw = JOB_FIT_YAW_DEG[iyaw].to_radians();
        w.place_pose(ty, offset_pose(pose, dx, dy, dyaw))?;
        let d = compare(w.heightmap(), seen).0 / cells;
        Ok((w, d))
    };
    let index = |[ix, iy, iyaw]: [usize; 3]| (iyaw * nx + iy) * nx + ix;
    let mut at = [nx / 2, nx / 2, nyaw / 2];
    tried[index(at)] = true;
    let (mut best, mut best_diff) = released(at)?;
    while best_diff > JOB_FIT_GOOD_M {
        let mut step = None;
        for (axis, len) in [(0, nx), (1, nx), (2, nyaw)] {
            for next in [
                at[axis].checked_sub(1),
                Some(at[axis] + 1).filter(|&i| i < len),
            ] {
                let Some(i) = next else { continue };
                let mut to = at;
                to[axis] = i;
                if std::mem::replace(&mut tried[index(to)], true) {
                    continue;
                }
                let (w, d) = released(to)?;
                if d < best_diff {
                    (best, best_diff, step) = (w, d, Some(to));
                }
            }
        }
        match step {
            Some(to) => at = to,
            None => break,
        }
    }
    if compare(world.heightmap(), seen).0 / cells < best_diff {
        return Ok(world.clone());
    }
    Ok(best)
}
