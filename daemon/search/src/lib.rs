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

use herb_core::catalog::{Catalog, SharedCatalog, TypeIdx};
use herb_core::error::{Result, SimError};
use herb_core::frames::BOX_HEIGHT;
use herb_core::heightmap::Heightmap;
use herb_core::lattice::{Lattice, Placement};
use herb_core::zestimate::{ZScratch, release_pose_on};
use herb_decide::DecideError;
use herb_decide::policy::{DecisionInput, PlanarPose, Policy};
use herb_world::offset_pose;
use herb_world::rollout::rollout_until;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rapier3d::math::{Pose, Rotation};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// What the search may spend on one decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// At most this many rollouts (reproducible: tables and tests).
    Rollouts(usize),
    /// Until this long after the decision started (what a robot spends behind its pick).
    Time(Duration),
}

/// Which world the rollouts run in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TwinKind {
    /// A twin built from the heightmap only ([`PackingWorld::twin`]): what works on a real
    /// camera's heightmap.
    Heightmap,
    /// A clone of the evaluation's own world (the lookahead teacher's): the twin's fidelity
    /// bound, for measurements only.
    ExactClone,
    /// The job's own twin: the objects this search decided in the job, replayed as their hulls
    /// at the release poses it decided, each moved by the small offset whose settle looks most
    /// like the heightmap that followed its release ([`JOB_FIT_XY_M`], [`JOB_FIT_YAW_DEG`]).
    /// Used while it agrees with the latest heightmap ([`JOB_MAX_OFF`]); where it does not (a
    /// restart, an object skipped or knocked, a box emptied by hand), the heightmap twin.
    /// Built from what herbd has in a real cell: its own decisions and the camera. The fit runs
    /// at every decision whatever the budget, so that the twin follows the job: one settle of
    /// the object when its decided pose already explains the heightmap
    /// ([`JOB_FIT_GOOD_M`]), else a climb over the offsets, a few settles each step (75 at
    /// most).
    Job,
}

impl TwinKind {
    /// Every kind, by its name.
    pub const ALL: [(&'static str, TwinKind); 3] = [
        ("heightmap", TwinKind::Heightmap),
        ("exact", TwinKind::ExactClone),
        ("job", TwinKind::Job),
    ];

    /// Its name in [`TwinKind::ALL`].
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("?", |(n, _)| n)
    }

    /// The kind named `name` (`heightmap`, `exact` or `job`; `twin` is the heightmap's old
    /// name); the error lists the names.
    pub fn parse(name: &str) -> Result<Self> {
        let name = if name == "twin" { "heightmap" } else { name };
        Self::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, k)| k)
            .ok_or_else(|| {
                SimError::Config(format!("twin {name:?}: expected heightmap, exact or job"))
            })
    }
}

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

/// The search's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSettings {
    /// Candidates considered at most, in the prior's order (1 to the lattice's 64).
    pub k: usize,
    /// The budget per decision.
    pub budget: Budget,
    /// Objects per rollout at most, the candidate's included (`None`: to the job's end).
    pub horizon: Option<usize>,
    /// The reward whose return ranks the candidates.
    pub reward: RewardMode,
    /// The world the rollouts run in.
    pub twin: TwinKind,
    /// Rollouts under a gripper's release error (`None`: each candidate rolled out once, every
    /// object released where it was placed).
    pub robust: Option<RobustRollouts>,
    /// The rollouts' pile is rigid ([`PackingWorld::freeze_settled`]): each object of a
    /// rollout settles alone against the objects before it, which it cannot move, as the
    /// heightmap twin's pile always was. About 4 times as many placements a second in the
    /// exact clone and the job's twin (`docs/benchmarks.md`); `false`: the pile is live, each
    /// settle simulates every object it wakes (for measurements).
    pub rigid_pile: bool,
    /// Threads the rollouts run on (at least 1): the candidates are handed out in the prior's
    /// order, and a decision keeps the longest run of finished candidates from the first, so
    /// that what a deadline allowed is a count that a replay runs again, on any thread count.
    pub threads: usize,
    /// The clearance the candidates (and the rollouts' own placements) leave against what
    /// their push stopped at, in fine lattice cells of 6.25 mm
    /// ([`Lattice::set_push_gap`]; 0: tight).
    pub push_gap: usize,
    /// The clearance from the walls the candidates (and the rollouts' own placements) keep
    /// where they stand above the rim, in fine lattice cells of 6.25 mm
    /// ([`Lattice::set_wall_gap`]; 0: none).
    pub wall_gap: usize,
    /// The release check (`None`: off): the best candidates are each released on the live
    /// pile off their placement by the four corners of an assumed release error, before the
    /// live check, and a candidate that one of those releases leaves outside the box is passed
    /// over ([`ReleaseCheck`]). Not in the heightmap twin.
    pub release_check: Option<ReleaseCheck>,
    /// The support rule (`None`: off): a candidate whose estimated top stands above the box's
    /// rim ([`BOX_HEIGHT`]) and whose footprint rests on less than this share of its cells
    /// ([`Placement::support`]) is one a release a few millimetres off can slide or tip off
    /// the pile, where no wall holds it: its rollout's return is lowered by 1, as a failed
    /// rollout's is, so that it is chosen only when nothing better finished. Off by default;
    /// [`SUPPORT_RULE_SHARE`] is the share measured.
    pub min_support: Option<f32>,
    /// The camera's heightmap filtered by a 3 x 3 median ([`Heightmap::median3_into`]) before
    /// the candidates are found on it, and before the job twin's heights are fused into it
    /// where they agree: the camera's per-cell depth noise otherwise decides the lattice's ties
    /// between positions of the same top, and lifts every footprint's resting height by its
    /// highest noisy cell. The job twin's agreement and the release heights are still read
    /// from the camera's own heightmap. Off by default.
    pub median: bool,
}

/// The release check ([`SearchSettings::release_check`]): a candidate's release offset by
/// `(+e, +e, +a)`, `(-e, -e, +a)`, `(+e, -e, -a)` and `(-e, +e, -a)` (`e` in x and in y, `a` in
/// yaw), the same four for every candidate, each settled on the live pile; the candidate
/// passes when its object ends inside the box after all four. Of the best
/// [`RELEASE_CHECK_WINDOW`] candidates by return, those that pass are live-checked in order
/// (at most [`LIVE_CHECKS`]) and the first whose live rollout succeeds is chosen; when none
/// is, the one with the most releases inside (ties to the better return). It aims at an object
/// released a few millimetres off its placement ending over a wall. On by default
/// ([`DEFAULT_RELEASE_CHECK`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleaseCheck {
    /// The offset in x and in y (m) of each corner.
    pub offset_m: f32,
    /// The yaw offset (degrees) of each corner.
    pub yaw_deg: f32,
}

impl ReleaseCheck {
    /// The check of a release error of `error_mm` in x and y and `error_deg` in yaw; `None`
    /// when both are 0. The values are the caller's, checked against
    /// [`RobustRollouts::MAX_ERROR_MM`] and [`RobustRollouts::MAX_ERROR_DEG`].
    pub fn assumed(error_mm: f64, error_deg: f64) -> Option<Self> {
        (error_mm > 0.0 || error_deg > 0.0).then_some(Self {
            offset_m: (error_mm * 1e-3) as f32,
            yaw_deg: error_deg as f32,
        })
    }

    /// The [`CHECK_RELEASES`] offsets: x, y (m) and yaw (rad).
    pub fn offsets(&self) -> [[f32; 3]; CHECK_RELEASES] {
        let (e, a) = (self.offset_m, self.yaw_deg.to_radians());
        [[e, e, a], [-e, -e, a], [e, -e, -a], [-e, e, -a]]
    }
}

/// Releases the release check tries per candidate ([`ReleaseCheck::offsets`]).
pub const CHECK_RELEASES: usize = 4;

/// The best candidates by return at most that the release check tries
/// ([`SearchSettings::release_check`]).
pub const RELEASE_CHECK_WINDOW: usize = 6;

/// herbd's release check by default ([`SearchSettings::release_check`]): the corners of 5 mm
/// and 3 deg, field-v1's release error. Under field-v1 it packed more than the search without
/// it on each of four draws of 256 validation episodes (1,024 paired: 13 episodes only with it,
/// 2 only without; +1.07 points, +0.3 to +1.8): `docs/table1.md`, "The release check out of
/// sample" and "The release check on the fresh draw".
pub const DEFAULT_RELEASE_CHECK: ReleaseCheck = ReleaseCheck {
    offset_m: (DEFAULT_RELEASE_ERROR_MM * 1e-3) as f32,
    yaw_deg: DEFAULT_RELEASE_ERROR_DEG as f32,
};

/// The share the support rule was measured with ([`SearchSettings::min_support`]): a candidate
/// above the rim on less than 30 % of its footprint is ranked as a failure. Under field-v1,
/// against the default on four draws of 256 validation episodes (1,024 paired): +0.68 points,
/// -0.7 to +2.0, not separated, so herbd keeps it off (`docs/table1.md`, "The support rule").
pub const SUPPORT_RULE_SHARE: f32 = 0.3;

/// The support rule of a configured share ([`SearchSettings::min_support`]), as herbd's
/// `[decision] min_support`, the CLI and the sweeps give it: 0 is off, a share up to 1 is the
/// rule; anything else (negative, above 1, not a number) is refused, naming the range.
pub fn support_rule(share: f32) -> std::result::Result<Option<f32>, String> {
    if share.is_finite() && (0.0..=1.0).contains(&share) {
        Ok((share > 0.0).then_some(share))
    } else {
        Err(format!("{share} outside 0..=1"))
    }
}

/// The release error (one standard deviation) the search assumes by default, for its release
/// check and its robust rollouts: x and y (mm), field-v1's. herbd's `[decision]
/// release_error_mm` and the evaluation's `search_noise` default to it.
pub const DEFAULT_RELEASE_ERROR_MM: f64 = 5.0;
/// The yaw (degrees) of [`DEFAULT_RELEASE_ERROR_MM`]'s release error.
pub const DEFAULT_RELEASE_ERROR_DEG: f64 = 3.0;

/// Candidates herbd's search rolls out by default, and the evaluation's reproducible budget
/// (one rollout each). Under the field model, with one cell of gap, 16 packed 3.91 points more
/// than 8 over two draws of 256 validation episodes (separated) and 5.70 less of BoxED's 263
/// (not separated); 24 packed less than 16 on both draws: `docs/table1.md`, "How many
/// candidates, and how they are ranked".
pub const DEFAULT_K: usize = 16;

/// The search's default clearance ([`SearchSettings::push_gap`]): one fine cell of 6.25 mm, for
/// a gripper that does not release exactly (`docs/table1.md`, "A clearance for the release
/// error").
pub const DEFAULT_GAP: usize = 1;

impl SearchSettings {
    /// The lattice the search finds its candidates on and its rollouts place with: its
    /// clearances ([`Self::push_gap`], [`Self::wall_gap`]) set.
    pub fn lattice(&self, catalog: &Catalog) -> Lattice {
        let mut l = Lattice::new(catalog);
        l.set_push_gap(self.push_gap);
        l.set_wall_gap(self.wall_gap);
        l
    }
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            budget: Budget::Rollouts(DEFAULT_K),
            horizon: None,
            reward: RewardMode::CompactnessStability { alpha: 0.6 },
            // herbd's default, and the CLI's and the bindings': one default everywhere.
            twin: TwinKind::Job,
            robust: None,
            rigid_pile: true,
            threads: 1,
            push_gap: DEFAULT_GAP,
            wall_gap: 0,
            release_check: Some(DEFAULT_RELEASE_CHECK),
            min_support: None,
            median: false,
        }
    }
}

/// The robust search: each candidate rolled out `samples` times, every object of each rollout
/// released off its placement by `noise`, ranked by the mean return. Sample `i` draws the same
/// offsets for every candidate (seeded by `i` alone), so that candidates are compared under
/// the same releases and a replay draws them again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustRollouts {
    /// The release error assumed.
    pub noise: ReleaseNoise,
    /// Rollouts per candidate (at least 1).
    pub samples: usize,
}

impl RobustRollouts {
    /// Rollouts per candidate at most (herbd's `[decision] samples`, `--search-samples`).
    pub const MAX_SAMPLES: usize = 64;
    /// The largest release error in x and y (mm) a configuration may assume.
    pub const MAX_ERROR_MM: f64 = 50.0;
    /// The largest yaw error (degrees) a configuration may assume.
    pub const MAX_ERROR_DEG: f64 = 45.0;

    /// The robust search of `samples` rollouts a candidate under a release error of
    /// `error_mm` (sd of x and of y) and `error_deg` (sd of the yaw); `None` with 0 samples.
    /// The values are the caller's, checked against the limits above.
    pub fn assumed(samples: usize, error_mm: f64, error_deg: f64) -> Option<Self> {
        (samples > 0).then(|| Self {
            noise: ReleaseNoise {
                sigma_m: (error_mm * 1e-3) as f32,
                sigma_deg: error_deg as f32,
                ..ReleaseNoise::default()
            },
            samples,
        })
    }
}

/// With a rigid pile, the best candidates at most rolled out again on the live pile
/// ([`SearchReport::live_checked`]; not in the heightmap twin, whose pile is rigid).
pub const LIVE_CHECKS: usize = 3;

/// Seeds sample `i`'s release offsets (with `i`).
const ROBUST_SEED: u64 = 0x726f_6275_7374;

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

/// How the job's twin compared with the decision's heightmap ([`TwinKind::Job`]).
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

/// The job's twin between decisions ([`TwinKind::Job`]).
#[derive(Debug, Clone)]
struct JobTwin {
    /// The objects released so far, fitted.
    world: PackingWorld,
    /// The remaining objects at the last decision: the next decision continues the job when
    /// its remaining objects are these without the first (that one was released).
    remaining: Vec<TypeIdx>,
    /// The release pose decided last.
    release: Option<(TypeIdx, Pose)>,
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

    /// Brings the job's twin up to `heightmap`; whether it agrees with it (then the rollouts
    /// run in it). The decision continues the job when `remaining` is the last decision's
    /// without its first object: that object was released where it was decided, and is
    /// replayed there, moved by the offset that best explains `heightmap`, or left out when the
    /// box without it explains `heightmap` better (it was skipped after a missed grasp). The
    /// same remaining objects again (a pick tried again) add nothing; anything else starts a
    /// new job from an empty box.
    fn follow_job(&mut self, heightmap: &Heightmap, remaining: &[TypeIdx]) -> Result<bool> {
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

/// The support rule ([`SearchSettings::min_support`]) on `ranked` (candidate index into
/// `candidates`, return; best first): the return of each candidate standing above the rim on
/// less than `min_support` of its footprint lowered by 1, then sorted again (ties to the
/// prior's order). Returns how many were lowered.
fn demote_unsupported(
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
fn roll_out(
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
fn release_check(
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

/// Writes into `out` the twin's heightmap where it is within [`JOB_CELL_OFF_M`] of the camera's,
/// and the camera's elsewhere. In a world that is its own model the two are equal, and so is
/// `out`. All three on one grid (the twin's is the camera's grid).
fn fuse(twin: &Heightmap, camera: &Heightmap, out: &mut Heightmap) {
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
