//! # herb-search: deciding by searching
//!
//! The placement lattice's candidates ranked by a prior, the best first each rolled out to the
//! job's end (`herb_world::rollout`) in a twin of the box, and the candidate of the best return chosen. A
//! [`Policy`] of the decision core (`herb_decide::Decider`, which checks the heightmap once and
//! adds the release height): herbd decides with it, and so does Table I's search row. herbd's
//! one way to the physics engine (`herb-world`).
//!
//! Deciding by searching: the placement lattice's candidates ranked by a prior, the best first
//! each rolled out to the job's end (the candidate placed and settled, then the remaining
//! objects by lattice BLBF, each settled), in a twin of the box built from its heightmap
//! ([`PackingWorld::twin`]), and the candidate of the best return chosen.
//!
//! Its inputs are what herbd has in a real cell: the latest heightmap, the object to place, the
//! job's remaining objects in order, the catalog. It is **anytime**: it stops when its budget
//! ends (a count of rollouts, reproducible, or a deadline) and returns the best candidate whose
//! rollout finished, or the prior's first when none did. It never returns an infeasible
//! placement: every candidate is one of the lattice's feasible placements. A rollout of a
//! rollout budget is the same in every run; what a deadline allowed is reported
//! ([`SearchReport`]) so that it can be replayed exactly as a count.

#![warn(missing_docs)]

pub use herb_world::{CandidateOutcome, PackingWorld, ReleaseNoise, RewardMode, WorldConfig};

use herb_core::catalog::{SharedCatalog, TypeIdx};
use herb_core::error::Result;
use herb_core::heightmap::Heightmap;
use herb_core::lattice::{Lattice, Placement};
use herb_core::zestimate::{ZScratch, release_pose_on};
use herb_decide::DecideError;
use herb_decide::policy::{DecisionInput, PlanarPose, Policy};
use herb_world::rollout::rollout_until;
use rapier3d::math::{Pose, Rotation};
use std::time::{Duration, Instant};

mod job;
mod rollouts;
mod settings;

pub use job::{
    JOB_CELL_OFF_M, JOB_FIT_GOOD_M, JOB_FIT_XY_M, JOB_FIT_YAW_DEG, JOB_MAX_OFF, JobAgreement,
};
pub use settings::{
    Budget, CHECK_RELEASES, DEFAULT_GAP, DEFAULT_K, DEFAULT_RELEASE_CHECK,
    DEFAULT_RELEASE_ERROR_DEG, DEFAULT_RELEASE_ERROR_MM, LIVE_CHECKS, RELEASE_CHECK_WINDOW,
    ReleaseCheck, RobustRollouts, SUPPORT_RULE_SHARE, SearchSettings, TwinKind, support_rule,
};

use job::{JobTwin, fuse};
use rollouts::{demote_unsupported, release_check, roll_out};

/// What one decision's search did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SearchReport {
    /// Feasible candidates the lattice offered.
    pub candidates: usize,
    /// Each finished rollout, in the prior's order (candidate index in the lattice's list
    /// and its outcome).
    pub finished: Vec<(usize, CandidateOutcome)>,
    /// Rollouts started but not counted: cut by the deadline, or finished (on another thread)
    /// after an earlier candidate was cut.
    pub cut: usize,
    /// The chosen candidate's index in the lattice's list.
    pub chosen: Option<usize>,
    /// Wall time of the decision.
    pub elapsed: Duration,
    /// With [`TwinKind::Job`]: how the job's twin compared with the heightmap.
    pub job: Option<JobAgreement>,
    /// Threads the rollouts ran on.
    pub threads: usize,
    /// With a rigid pile: the best candidates rolled out again on the live pile (at most
    /// [`LIVE_CHECKS`]).
    pub live_checked: usize,
    /// Of those, the ones whose rollout failed there (an object pushed out, or one that went
    /// out where the rigid pile held it): passed over for the next best.
    pub live_rejected: usize,
    /// With the release check: the candidates it tried, and those it passed over (one of the
    /// four releases left the object outside).
    pub release_checked: usize,
    /// See [`Self::release_checked`].
    pub release_rejected: usize,
    /// With the support rule: the finished candidates it ranked as failures (above the rim, on
    /// too little of their footprint; [`SearchSettings::min_support`]).
    pub unsupported: usize,
    /// With [`TwinKind::Job`]: where the job's twin will replay the chosen placement's release
    /// at the next decision (the one release pose, [`release_pose_on`]: the z estimate on this
    /// heightmap plus the world's clearance, herbd's `[models] clearance_m`).
    pub replayed_release: Option<Pose>,
}

/// The search (see the module docs): its lattices and the last decision's report.
#[derive(Debug, Clone)]
pub struct Search {
    settings: SearchSettings,
    catalog: SharedCatalog,
    cfg: WorldConfig,
    lattice: Lattice,
    /// One scratch lattice per rollout thread.
    rollouts: Vec<Lattice>,
    report: SearchReport,
    job: Option<JobTwin>,
    zscratch: ZScratch,
    /// The heightmap the candidates are found on when the job's twin agrees ([`fuse`]).
    fused: Option<Heightmap>,
    /// The camera's heightmap filtered ([`SearchSettings::median`]), kept between decisions.
    filtered: Option<Heightmap>,
}

impl Search {
    /// A search over `catalog`'s objects, its twins built with the world configuration `cfg`
    /// without the evaluation's errors ([`WorldConfig::without_errors`]: a twin is never told
    /// of them; the robust search's assumed error is its own setting).
    pub fn new(catalog: SharedCatalog, cfg: WorldConfig, settings: SearchSettings) -> Self {
        let cfg = cfg.without_errors();
        Self {
            lattice: settings.lattice(&catalog),
            rollouts: (0..settings.threads.max(1))
                .map(|_| settings.lattice(&catalog))
                .collect(),
            zscratch: ZScratch::for_catalog(&catalog, cfg.heightmap_cell_m),
            settings,
            catalog,
            cfg,
            report: SearchReport::default(),
            job: None,
            fused: None,
            filtered: None,
        }
    }

    /// Its name in tables: the budget and the twin, e.g. `search (8 rollouts, job)`.
    pub fn label(&self) -> String {
        let budget = match self.settings.budget {
            Budget::Rollouts(r) => format!("{r} rollouts"),
            Budget::Time(d) => format!("{:.2} s", d.as_secs_f64()),
        };
        format!("search ({budget}, {})", self.settings.twin.name())
    }

    /// The settings.
    pub fn settings(&self) -> &SearchSettings {
        &self.settings
    }

    /// Sets the budget of the next decisions (a replay runs a recorded count of rollouts
    /// where a deadline stopped the run).
    pub fn set_budget(&mut self, budget: Budget) {
        self.settings.budget = budget;
    }

    /// What the last decision did.
    pub fn report(&self) -> &SearchReport {
        &self.report
    }

    /// Starts a new job: the job's twin forgets what it replayed ([`TwinKind::Job`]). Without
    /// it a job is told apart by its remaining objects alone, which a new job can repeat.
    pub fn new_job(&mut self) {
        self.job = None;
    }

    /// The job's twin, when the last decision's rollouts ran in it ([`TwinKind::Job`]).
    pub fn job_twin(&self) -> Option<&PackingWorld> {
        let used = self.report.job.is_some_and(|j| j.used);
        self.job.as_ref().filter(|_| used).map(|j| &j.world)
    }

    /// The placement for `remaining[0]` over `heightmap`, `None` when the lattice holds no
    /// feasible placement (or `remaining` is empty). With [`TwinKind::ExactClone`] the rollouts
    /// run in clones of `exact` (given by the evaluation; a twin is built when it is `None`).
    pub fn decide(
        &mut self,
        heightmap: &Heightmap,
        remaining: &[TypeIdx],
        exact: Option<&PackingWorld>,
    ) -> Result<Option<Placement>> {
        let t0 = Instant::now();
        self.report = SearchReport::default();
        let Some(&next) = remaining.first() else {
            return Ok(None);
        };
        let agreed =
            self.settings.twin == TwinKind::Job && self.follow_job(heightmap, remaining)?;
        // The candidates on the job's twin's heightmap where it agrees with the camera's
        // (within JOB_CELL_OFF_M: the decisions replayed, without the camera's noise and
        // dropouts), on the camera's where it does not (what the twin does not know); with the
        // median, on the camera's filtered.
        let camera = if self.settings.median {
            let filtered = self.filtered.get_or_insert_with(|| heightmap.clone());
            heightmap.median3_into(filtered);
            &*filtered
        } else {
            heightmap
        };
        let seen = match (&self.job, agreed) {
            (Some(j), true) => {
                let fused = self.fused.get_or_insert_with(|| heightmap.clone());
                fuse(j.world.heightmap(), camera, fused);
                &*fused
            }
            _ => camera,
        };
        self.lattice.compute(seen, &self.catalog, next);
        let n = self.lattice.candidates().len();
        self.report.candidates = n;
        if n == 0 {
            return Ok(None);
        }
        let (count, deadline) = match self.settings.budget {
            Budget::Rollouts(r) => (r, None),
            Budget::Time(d) => (usize::MAX, Some(t0 + d)),
        };
        let k = self.settings.k.clamp(1, n).min(count);
        let mut best = None;
        if k > 0 {
            let twin;
            let job = self.job.as_ref().filter(|_| agreed).map(|j| &j.world);
            let (world, in_heightmap_twin) = match (self.settings.twin, exact, job) {
                (TwinKind::ExactClone, Some(w), _) => (w, false),
                (TwinKind::Job, _, Some(w)) => (w, false),
                _ => {
                    twin = PackingWorld::twin(self.catalog.clone(), self.cfg.clone(), heightmap)?;
                    (&twin, true)
                }
            };
            let end = remaining
                .len()
                .min(self.settings.horizon.unwrap_or(usize::MAX).max(1));
            let live = world;
            let rigid;
            let world = if self.settings.rigid_pile {
                let mut w = world.clone();
                w.freeze_settled();
                rigid = w;
                &rigid
            } else {
                world
            };
            let firsts = &self.lattice.candidates()[..k];
            let outcomes = roll_out(
                &mut self.rollouts,
                &self.settings,
                world,
                &remaining[..end],
                firsts,
                deadline,
            )?;
            // The finished candidates from the first on, up to the first that did not finish:
            // a count, which a replay's budget of that many rollouts runs again.
            let prefix = outcomes
                .iter()
                .take_while(|o| matches!(o, Some(Some(_))))
                .count();
            for (c, o) in outcomes.iter().enumerate() {
                match o {
                    Some(Some(o)) if c < prefix => self.report.finished.push((c, *o)),
                    Some(_) => self.report.cut += 1,
                    None => {}
                }
            }
            self.report.threads = self.rollouts.len().min(k);
            // The finished candidates by return, best first, ties to the prior's order.
            let mut ranked: Vec<(usize, f32)> = self
                .report
                .finished
                .iter()
                .map(|(c, o)| (*c, o.ret))
                .collect();
            ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            if let Some(min) = self.settings.min_support {
                self.report.unsupported = demote_unsupported(&mut ranked, firsts, min);
            }
            best = ranked.first().map(|r| r.0);
            if self.settings.rigid_pile && !in_heightmap_twin {
                // A rigid pile cannot be pushed: the best candidates are rolled out once more
                // on the live pile, every object released exactly, and the first whose rollout
                // succeeds there is chosen. With the release check, a candidate is first
                // released off its placement four times on the live pile, and passed over when
                // one of those leaves it outside. When none is chosen: the one with the most
                // releases inside, ties to the better return (the best, without the check).
                // Deterministic: a replay checks alike. Not in the heightmap twin, whose pile is
                // rigid in any case (and whose live rollouts are the slowest).
                let check = self.settings.release_check;
                let window = if check.is_some() {
                    RELEASE_CHECK_WINDOW
                } else {
                    LIVE_CHECKS
                };
                let mut fallback: Option<(usize, usize)> = None;
                for &(c, _) in ranked.iter().take(window) {
                    let inside = match check {
                        Some(rc) => {
                            self.report.release_checked += 1;
                            release_check(live, remaining[0], firsts[c], &rc)?
                        }
                        None => CHECK_RELEASES,
                    };
                    if fallback.is_none_or(|(_, n)| inside > n) {
                        fallback = Some((c, inside));
                    }
                    if inside < CHECK_RELEASES {
                        self.report.release_rejected += 1;
                        continue;
                    }
                    if self.report.live_checked == LIVE_CHECKS {
                        break;
                    }
                    let o = rollout_until(
                        &mut self.rollouts[0],
                        self.settings.reward,
                        live,
                        &remaining[..end],
                        firsts[c],
                        None,
                        None,
                    )?;
                    self.report.live_checked += 1;
                    if o.is_some_and(|o| o.success) {
                        fallback = None;
                        best = Some(c);
                        break;
                    }
                    self.report.live_rejected += 1;
                }
                if let Some((c, _)) = fallback {
                    best = Some(c);
                }
            }
        }
        // The best finished candidate; else the prior's first.
        let best = best.unwrap_or(0);
        self.report.chosen = Some(best);
        let chosen = self.lattice.candidates()[best];
        if let Some(job) = &mut self.job {
            // Where the chosen placement will be released (the world's release pose: z
            // estimated on this heightmap, plus the clearance), for the next decision's replay.
            let pose = release_pose_on(
                heightmap,
                self.catalog.shape(next),
                (
                    chosen.x,
                    chosen.y,
                    Rotation::from_rotation_z(chosen.theta()),
                ),
                self.cfg.clearance_m,
                &mut self.zscratch,
            );
            job.release = Some((next, pose));
            self.report.replayed_release = Some(pose);
        }
        self.report.elapsed = t0.elapsed();
        Ok(Some(chosen))
    }
}

/// The search as the decision core's policy: the placement it chooses for the input's
/// remaining objects, over the heightmap the `Decider` checked (the job's twin continued, or
/// one built from that heightmap).
impl Policy for Search {
    fn name(&self) -> &str {
        "search"
    }

    /// A new job: the job's twin starts from an empty box.
    fn begin_episode(&mut self, _seed: u64) {
        self.new_job();
    }

    fn decide(&mut self, input: &DecisionInput) -> herb_decide::Result<PlanarPose> {
        let p = Search::decide(self, input.heightmap, input.remaining, None)
            .map_err(|e| DecideError::Rejected {
                policy: "search".into(),
                reason: e.to_string(),
            })?
            .ok_or(DecideError::NoFeasiblePlacement)?;
        Ok(p.into())
    }

    fn needs_observation(&self) -> bool {
        false
    }
}
