//! The search's settings: its budget, twins, candidates and checks, and their defaults
//! (herbd's, the CLI's and the bindings': one default everywhere).

use herb_core::catalog::Catalog;
use herb_core::error::{Result, SimError};
use herb_core::lattice::Lattice;
use herb_world::{ReleaseNoise, RewardMode};
use std::time::Duration;

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
    /// A twin built from the heightmap only ([`PackingWorld::twin`](crate::PackingWorld::twin)): what works on a real
    /// camera's heightmap.
    Heightmap,
    /// A clone of the evaluation's own world (the lookahead teacher's): the twin's fidelity
    /// bound, for measurements only.
    ExactClone,
    /// The job's own twin: the objects this search decided in the job, replayed as their hulls
    /// at the release poses it decided, each moved by the small offset whose settle looks most
    /// like the heightmap that followed its release ([`JOB_FIT_XY_M`](crate::JOB_FIT_XY_M), [`JOB_FIT_YAW_DEG`](crate::JOB_FIT_YAW_DEG)).
    /// Used while it agrees with the latest heightmap ([`JOB_MAX_OFF`](crate::JOB_MAX_OFF)); where it does not (a
    /// restart, an object skipped or knocked, a box emptied by hand), the heightmap twin.
    /// Built from what herbd has in a real cell: its own decisions and the camera. The fit runs
    /// at every decision whatever the budget, so that the twin follows the job: one settle of
    /// the object when its decided pose already explains the heightmap
    /// ([`JOB_FIT_GOOD_M`](crate::JOB_FIT_GOOD_M)), else a climb over the offsets, a few settles each step (75 at
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
    /// The rollouts' pile is rigid ([`PackingWorld::freeze_settled`](crate::PackingWorld::freeze_settled)): each object of a
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
    /// rim ([`BOX_HEIGHT`](herb_core::frames::BOX_HEIGHT)) and whose footprint rests on less than this share of its cells
    /// ([`Placement::support`](herb_core::lattice::Placement::support)) is one a release a few millimetres off can slide or tip off
    /// the pile, where no wall holds it: its rollout's return is lowered by 1, as a failed
    /// rollout's is, so that it is chosen only when nothing better finished. Off by default;
    /// [`SUPPORT_RULE_SHARE`] is the share measured.
    pub min_support: Option<f32>,
    /// The camera's heightmap filtered by a 3 x 3 median ([`Heightmap::median3_into`](herb_core::heightmap::Heightmap::median3_into)) before
    /// the candidates are found on it, and before the job twin's heights are fused into it
    /// where they agree: the camera's per-cell depth noise otherwise decides the lattice's ties
    /// between positions of the same top, and lifts every footprint's resting height by its
    /// highest noisy cell. The job twin's agreement and the release heights are still read
    /// from the camera's own heightmap. On by default since 2026-12-02 (herbd's, the CLI's and
    /// the bindings'): under the field model it gained +5.86 points over the search without it
    /// on 512 paired episodes; in the ideal world it packs within one episode of it.
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
/// 2 only without; +1.07 points, +0.3 to +1.8): `docs/field-variants.md`, "The release check out of
/// sample" and "The release check on the fresh draw".
pub const DEFAULT_RELEASE_CHECK: ReleaseCheck = ReleaseCheck {
    offset_m: (DEFAULT_RELEASE_ERROR_MM * 1e-3) as f32,
    yaw_deg: DEFAULT_RELEASE_ERROR_DEG as f32,
};

/// The share the support rule was measured with ([`SearchSettings::min_support`]): a candidate
/// above the rim on less than 30 % of its footprint is ranked as a failure. Under field-v1, against
/// the default on four draws of 256 validation episodes (1,024 paired): +0.68 points, -0.7 to +2.0,
/// not separated, so herbd keeps it off (`docs/field-variants.md`, "The support rule").
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
/// (not separated); 24 packed less than 16 on both draws: `docs/field-variants.md`, "How many
/// candidates, and how they are ranked".
pub const DEFAULT_K: usize = 16;

/// The search's default clearance ([`SearchSettings::push_gap`]): one fine cell of 6.25 mm, for
/// a gripper that does not release exactly (`docs/field-variants.md`, "A clearance for the release
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
            median: true,
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
/// ([`SearchReport::live_checked`](crate::SearchReport::live_checked); not in the heightmap twin, whose pile is rigid).
pub const LIVE_CHECKS: usize = 3;

/// Seeds sample `i`'s release offsets (with `i`).
pub(crate) const ROBUST_SEED: u64 = 0x726f_6275_7374;
