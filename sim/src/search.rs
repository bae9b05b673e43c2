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

use crate::catalog::{SharedCatalog, TypeIdx};
use crate::env::{PackingEnv, RewardMode};
use crate::error::Result;
use crate::heightmap::Heightmap;
use crate::lattice::{Lattice, Placement};
use crate::teacher::{CandidateOutcome, rollout_until};
use crate::world::{PackingWorld, WorldConfig};
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
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            k: 8,
            budget: Budget::Rollouts(8),
            horizon: None,
            reward: RewardMode::CompactnessStability { alpha: 0.6 },
            twin: TwinKind::Heightmap,
        }
    }
}

/// What one decision's search did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SearchReport {
    /// Feasible candidates the lattice offered.
    pub candidates: usize,
    /// Each finished rollout, in the prior's order (candidate index in the lattice's list
    /// and its outcome).
    pub finished: Vec<(usize, CandidateOutcome)>,
    /// Rollouts started but cut by the deadline.
    pub cut: usize,
    /// The chosen candidate's index in the lattice's list.
    pub chosen: Option<usize>,
    /// Wall time of the decision.
    pub elapsed: Duration,
}

/// The search (see the module docs): its lattices and the last decision's report.
#[derive(Debug, Clone)]
pub struct Search {
    settings: SearchSettings,
    catalog: SharedCatalog,
    cfg: WorldConfig,
    lattice: Lattice,
    rollout: Lattice,
    report: SearchReport,
}

impl Search {
    /// A search over `catalog`'s objects, its twins built with the world configuration `cfg`.
    pub fn new(catalog: SharedCatalog, cfg: WorldConfig, settings: SearchSettings) -> Self {
        Self {
            lattice: Lattice::new(&catalog),
            rollout: Lattice::new(&catalog),
            settings,
            catalog,
            cfg,
            report: SearchReport::default(),
        }
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
        self.lattice.compute(heightmap, &self.catalog, next);
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
        if k > 0 {
            let twin;
            let world = match (self.settings.twin, exact) {
                (TwinKind::ExactClone, Some(w)) => w,
                _ => {
                    twin = PackingWorld::twin(self.catalog.clone(), self.cfg.clone(), heightmap)?;
                    &twin
                }
            };
            let end = remaining
                .len()
                .min(self.settings.horizon.unwrap_or(usize::MAX).max(1));
            for c in 0..k {
                if deadline.is_some_and(|d| Instant::now() >= d) {
                    break;
                }
                let first = self.lattice.candidates()[c];
                match rollout_until(
                    &mut self.rollout,
                    self.settings.reward,
                    world,
                    &remaining[..end],
                    first,
                    deadline,
                )? {
                    Some(o) => self.report.finished.push((c, o)),
                    None => self.report.cut += 1,
                }
            }
        }
        // The best finished return, ties to the prior's order; else the prior's first.
        let best = self
            .report
            .finished
            .iter()
            .fold(None::<(usize, f32)>, |b, &(c, ref o)| match b {
                Some((_, r)) if r >= o.ret => b,
                _ => Some((c, o.ret)),
            })
            .map_or(0, |(c, _)| c);
        self.report.chosen = Some(best);
        self.report.elapsed = t0.elapsed();
        Ok(Some(self.lattice.candidates()[best]))
    }
}

impl crate::eval::Placer for Search {
    fn name(&self) -> String {
        let budget = match self.settings.budget {
            Budget::Rollouts(r) => format!("{r} rollouts"),
            Budget::Time(d) => format!("{:.2} s", d.as_secs_f64()),
        };
        let twin = match self.settings.twin {
            TwinKind::Heightmap => "twin",
            TwinKind::ExactClone => "exact clone",
        };
        format!("search ({budget}, {twin})")
    }

    /// The search over the environment's heightmap and remaining objects, released at the
    /// world's release pose (part of the timed decision). The evaluation's world is passed for
    /// [`TwinKind::ExactClone`] only.
    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<crate::eval::Decision>, crate::eval::PlaceError> {
        let exact = (self.settings.twin == TwinKind::ExactClone).then(|| env.world());
        let p = Search::decide(self, env.world().heightmap(), env.remaining(), exact)?;
        Ok(crate::eval::release_at(env, p))
    }
}
