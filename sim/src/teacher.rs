//! The lookahead teacher: one step of policy improvement over the lattice BLBF rule.
//!
//! For the next object, the teacher takes the first `k` candidates of the placement lattice
//! ([`Lattice::candidates`], candidate 0 being the lattice BLBF choice), and for each one
//! simulates, on a clone of the world ([`PackingWorld`] is `Clone` and a clone steps
//! bit-identically), that placement followed by the lattice BLBF rule for every remaining
//! object of the sequence, to the episode's end. It keeps the candidate with the highest
//! return (sum of the rewards of the simulated placements, [`RewardMode::reward`], a failed
//! placement or an object without a feasible placement scoring -1 and ending the rollout);
//! ties go to the earlier candidate.
//!
//! Because candidate 0's rollout is exactly what the lattice BLBF rule would do from the same
//! state, and the physics is deterministic, the teacher's episode return is never below the
//! lattice BLBF rule's on the same sequence. It knows the objects still to come, which a policy
//! that only sees the next object does not; its value as prior data is the simulated outcome
//! of every candidate ([`CandidateOutcome`]).

use crate::catalog::TypeIdx;
use crate::env::{PackingEnv, RewardMode};
use crate::error::Result;
use crate::heightmap::Heightmap;
use crate::lattice::{Lattice, Placement};
use crate::reserve::Reserve;
use crate::world::PackingWorld;
pub use crate::world::rollout::{CandidateOutcome, RolloutFailure, rollout, rollout_until};
use rapier3d::math::Vector;

/// The lookahead teacher (see the module docs). Holds its lattices and outcome buffer.
#[derive(Debug, Clone)]
pub struct Lookahead {
    k: usize,
    horizon: usize,
    reward: RewardMode,
    lattice: Lattice,
    rollout: Lattice,
    outcomes: Vec<CandidateOutcome>,
}

impl Lookahead {
    /// A teacher simulating the first `k` (at least 1) candidates, scoring with `reward`.
    pub fn new(catalog: &crate::Catalog, k: usize, reward: RewardMode) -> Self {
        Self {
            k: k.max(1),
            horizon: usize::MAX,
            reward,
            lattice: Lattice::new(catalog),
            rollout: Lattice::new(catalog),
            outcomes: Vec::with_capacity(k.max(1)),
        }
    }

    /// The same teacher with rollouts that stop after `horizon` (at least 1) objects, the
    /// candidate's included: a cheaper teacher whose returns cover only the next `horizon`
    /// placements (a rollout that reaches the horizon counts as a success). `usize::MAX`, the
    /// default, simulates to the episode's end.
    pub fn with_horizon(mut self, horizon: usize) -> Self {
        self.horizon = horizon.max(1);
        self
    }

    /// Candidates simulated per decision.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Objects simulated per rollout at most, the candidate's included.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The teacher's placement for `remaining[0]` in `world`, or `None` when the lattice holds
    /// no feasible placement (or `remaining` is empty). [`Lookahead::outcomes`] then holds the
    /// simulated outcome of every candidate tried, in candidate order.
    pub fn decide(
        &mut self,
        world: &PackingWorld,
        remaining: &[TypeIdx],
    ) -> Result<Option<Placement>> {
        self.outcomes.clear();
        let Some(&next) = remaining.first() else {
            return Ok(None);
        };
        self.lattice
            .compute(world.heightmap(), world.catalog(), next);
        let n = self.lattice.candidates().len().min(self.k);
        for c in 0..n {
            let first = self.lattice.candidates()[c];
            let end = remaining.len().min(self.horizon);
            let o = rollout(
                &mut self.rollout,
                self.reward,
                world,
                &remaining[..end],
                first,
            )?;
            self.outcomes.push(o);
        }
        let best =
            self.outcomes
                .iter()
                .enumerate()
                .fold(None::<(usize, f32)>, |b, (i, o)| match b {
                    Some((_, r)) if r >= o.ret => b,
                    _ => Some((i, o.ret)),
                });
        Ok(best.map(|(i, _)| self.outcomes[i].placement))
    }

    /// The simulated outcomes of the last decision's candidates.
    pub fn outcomes(&self) -> &[CandidateOutcome] {
        &self.outcomes
    }
}

/// A decision rule over the placement lattice, for evaluation and data collection.
#[derive(Debug, Clone)]
pub enum LatticeRule {
    /// The BLBF rule restricted to the lattice ([`Lattice::blbf`]).
    Blbf(Box<Lattice>),

    /// The lookahead teacher.
    Lookahead(Box<Lookahead>),

    /// The lattice BLBF rule that keeps room for later objects: the first candidate, in BLBF
    /// order, after which the fewest reserved objects stop fitting ([`Reserve::lost`]).
    Reserve(Box<(Lattice, Reserve)>),

    /// The geometric lookahead teacher.
    Geo(Box<GeoLookahead>),
}

impl LatticeRule {
    /// Short name for tables.
    pub fn name(&self) -> String {
        match self {
            Self::Blbf(_) => "lattice-blbf".into(),

            Self::Lookahead(t) => format!("lookahead (teacher, k = {})", t.k()),
            Self::Reserve(_) => "lattice-reserve".into(),
            Self::Geo(t) => format!("geo-lookahead (k = {})", t.k()),
        }
    }

    /// The placement for the environment's next object, `None` when the lattice holds no
    /// feasible placement or the episode is over.
    pub fn decide(&mut self, env: &PackingEnv) -> Result<Option<Placement>> {
        let remaining = env.remaining();
        let Some(&next) = remaining.first() else {
            return Ok(None);
        };
        match self {
            Self::Blbf(l) => {
                l.compute(env.camera(), env.world().catalog(), next);
                Ok(l.blbf())
            }

            Self::Lookahead(t) => t.decide(env.world(), remaining),
            Self::Geo(t) => Ok(t.decide(env.world().catalog(), env.camera(), remaining)),
            Self::Reserve(b) => {
                let (l, r) = &mut **b;
                let catalog = env.world().catalog();
                l.compute(env.camera(), catalog, next);
                r.prepare(l.pooled(), catalog, &remaining[1..]);
                l.candidates();
                let l = &*l;
                let mut best: Option<(usize, Placement)> = None;
                for p in l.computed_candidates() {
                    let lost = r.lost(l, p);
                    if best.is_none_or(|(b, _)| lost < b) {
                        best = Some((lost, *p));
                    }
                }
                Ok(best.map(|(_, p)| p))
            }
        }
    }
}

impl crate::eval::Placer for LatticeRule {
    fn name(&self) -> String {
        LatticeRule::name(self)
    }

    /// The rule's placement, released at the world's release pose (part of the timed
    /// decision).
    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<crate::eval::Decision>, crate::eval::PlaceError> {
        let p = LatticeRule::decide(self, env)?;
        Ok(crate::eval::release_at(env, p))
    }
}

/// What the geometric rollout after one candidate placement achieved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoOutcome {
    /// The candidate placement.
    pub placement: Placement,
    /// Objects of the remaining sequence that found a feasible lattice placement, the
    /// candidate's included.
    pub packed: usize,
    /// The highest cell of the heightmap when the rollout ended (m).
    pub final_top: f32,
}

/// A geometric lookahead teacher: like [`Lookahead`], the first `k` lattice candidates each
/// followed by the lattice BLBF rule for the rest of the sequence, but without physics. Each
/// placed object raises the heightmap cells under its footprint's bounding box to its top
/// (objects never settle, tip or fall), so a rollout costs a few lattice computations, not a
/// physics simulation, and its outcome is a deterministic, piecewise-smooth function of the
/// heightmap. It keeps the candidate whose rollout finds a feasible placement for the most
/// objects, then the lowest final top, then the earlier candidate: with no geometric reason
/// to deviate it places as the lattice BLBF rule.
#[derive(Debug, Clone)]
pub struct GeoLookahead {
    k: usize,
    lattice: Lattice,
    rollout: Lattice,
    scratch: Heightmap,
    outcomes: Vec<GeoOutcome>,
}

impl GeoLookahead {
    /// A geometric teacher over the first `k` (at least 1) candidates.
    pub fn new(catalog: &crate::Catalog, k: usize) -> Self {
        let spec = crate::heightmap::GridSpec::for_box(crate::ObsLayout::CELL_M)
            .expect("observation cell within GridSpec range");
        Self {
            k: k.max(1),
            lattice: Lattice::new(catalog),
            rollout: Lattice::new(catalog),
            scratch: Heightmap::new(spec),
            outcomes: Vec::with_capacity(k.max(1)),
        }
    }

    /// Candidates tried per decision.
    pub fn k(&self) -> usize {
        self.k
    }

    /// The placement for `remaining[0]` over `hm`, or `None` when the lattice holds no
    /// feasible placement (or `remaining` is empty).
    pub fn decide(
        &mut self,
        catalog: &crate::Catalog,
        hm: &Heightmap,
        remaining: &[TypeIdx],
    ) -> Option<Placement> {
        self.outcomes.clear();
        let &next = remaining.first()?;
        if self.scratch.spec() != hm.spec() {
            self.scratch = hm.clone();
        }
        self.lattice.compute(hm, catalog, next);
        let n = self.lattice.candidates().len().min(self.k);
        for c in 0..n {
            let first = self.lattice.computed_candidates()[c];
            self.scratch.data_mut().copy_from_slice(hm.data());
            raise_bounding_box(
                &mut self.scratch,
                &first,
                self.lattice.bounds(first.yaw as usize),
            );
            let mut packed = 1;
            for &ty in &remaining[1..] {
                self.rollout.compute(&self.scratch, catalog, ty);
                let Some(p) = self.rollout.blbf() else { break };
                raise_bounding_box(&mut self.scratch, &p, self.rollout.bounds(p.yaw as usize));
                packed += 1;
            }
            self.outcomes.push(GeoOutcome {
                placement: first,
                packed,
                final_top: self.scratch.max(),
            });
        }
        let mut best: Option<&GeoOutcome> = None;
        for o in &self.outcomes {
            if best.is_none_or(|b| {
                o.packed > b.packed || (o.packed == b.packed && o.final_top < b.final_top)
            }) {
                best = Some(o);
            }
        }
        best.map(|o| o.placement)
    }

    /// The geometric outcomes of the last decision's candidates.
    pub fn outcomes(&self) -> &[GeoOutcome] {
        &self.outcomes
    }
}

/// Raises the cells of `hm` whose centres lie under the bounding box `bounds` (around the
/// origin) of placement `p` to at least its top.
pub fn raise_bounding_box(hm: &mut Heightmap, p: &Placement, bounds: (Vector, Vector)) {
    let spec = *hm.spec();
    let (lo, hi) = bounds;
    let (u0, v0) = spec.to_pixel(p.x + lo.x, p.y + hi.y);
    let (u1, v1) = spec.to_pixel(p.x + hi.x, p.y + lo.y);
    // Cells whose centre (index + 0.5) lies in [u0, u1] x [v0, v1].
    let first = |a: f32| (a - 0.5).ceil().max(0.0) as usize;
    let last = |b: f32, n: usize| ((b - 0.5).floor().max(-1.0) as isize).min(n as isize - 1);
    let (c0, c1) = (first(u0), last(u1, spec.nx));
    let (r0, r1) = (first(v0), last(v1, spec.ny));
    if c1 < c0 as isize || r1 < r0 as isize {
        return;
    }
    let nx = spec.nx;
    let data = hm.data_mut();
    for r in r0..=r1 as usize {
        for v in &mut data[r * nx + c0..=r * nx + c1 as usize] {
            *v = v.max(p.top);
        }
    }
}
