//! Where the search's twin and the world differ, decision by decision (a diagnostic; its
//! figures are in docs/search.md).
//!
//!     cargo run --release -p herb-methods --example twin_fidelity -- [EPISODES] [SEED] [THREADS] [twin|frozen]
//!
//! With `frozen`, the twin is replaced by a clone of the world whose objects are made fixed
//! ([`PackingWorld::freeze_placed`]): the twin's rigid pile with the objects' exact shapes, to
//! tell what the pile's shape costs from what its rigidity costs.
//!
//! The episodes are `training/validate.py`'s (the bindings' sampler: 10 to 25 random catalog
//! objects in HERB's order, one generator per episode seeded from `SEED`, default 777). Each is
//! packed by the search (`herb_sim::search`: k = 8 candidates in lattice BLBF's order, each
//! rolled out to the job's end in the twin, the best return chosen). At every decision the same
//! search also runs in a clone of the episode's world (the exact clone), and each candidate is
//! placed once in both, so that the two can be compared on the same state:
//!
//! - the first placement: how often both call it stable, the mean difference of its tilt;
//! - the rollouts: how often both predict the same success, and where one fails and the other
//!   does not (the step: the candidate, the next object or a later one; the bound crossed);
//! - the choice: how often the twin chooses the exact clone's best, the regret of its choice in
//!   the exact clone's returns, and the share of choices whose exact rollout succeeds, for the
//!   search's rule (the best return) and for "success first, then the prior's order".
//!
//! Reads `models/sequence.json` from the working directory (run it from the repository's root)
//! and the meshes from BoxED when it is found (`HERB_BOXED`, `../shared/boxed`).

use herb_decide::{Order, SequenceModel};
use herb_sim::catalog::{Catalog, SharedCatalog, TypeIdx};
use herb_sim::env::{PackingEnv, RewardMode};
use herb_sim::lattice::{Lattice, Placement};
use herb_sim::paths;
use herb_sim::search::{Budget, Search, SearchSettings, TwinKind};
use herb_sim::teacher::CandidateOutcome;
use herb_sim::world::{PackingWorld, WorldConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Candidates per decision, as herbd's default search.
const K: usize = 8;

/// The search's reward (CS0.6).
const REWARD: RewardMode = RewardMode::CompactnessStability { alpha: 0.6 };

type Error = Box<dyn std::error::Error + Send + Sync>;

/// What the probe counts (summed over threads).
#[derive(Default)]
struct Tally {
    episodes: usize,
    success: usize,
    decisions: usize,
    /// The twin chose the exact clone's best candidate.
    same_choice: usize,
    /// Sum over decisions of the exact return of the exact best minus that of the twin's choice.
    regret: f64,
    /// Decisions whose exact best rollout succeeds; whose twin choice's exact rollout succeeds;
    /// whose "success first, then the prior" choice's exact rollout succeeds.
    exact_best_ok: usize,
    twin_choice_ok: usize,
    success_first_ok: usize,
    /// Rollouts by (twin succeeds, exact succeeds).
    rollouts: [[usize; 2]; 2],
    /// First placements, those both call stable or both unstable, sum of |tilt difference|.
    firsts: usize,
    stable_alike: usize,
    tilt_diff: f64,
    /// Where a rollout failed in one world and not in the other.
    reasons: BTreeMap<String, usize>,
}

impl Tally {
    fn add(&mut self, o: Tally) {
        self.episodes += o.episodes;
        self.success += o.success;
        self.decisions += o.decisions;
        self.same_choice += o.same_choice;
        self.regret += o.regret;
        self.exact_best_ok += o.exact_best_ok;
        self.twin_choice_ok += o.twin_choice_ok;
        self.success_first_ok += o.success_first_ok;
        for (a, b) in self.rollouts.iter_mut().zip(o.rollouts) {
            a[0] += b[0];
            a[1] += b[1];
        }
        self.firsts += o.firsts;
        self.stable_alike += o.stable_alike;
        self.tilt_diff += o.tilt_diff;
        for (k, v) in o.reasons {
            *self.reasons.entry(k).or_default() += v;
        }
    }
}

/// Where and why a rollout failed, in words.
fn failure(o: &CandidateOutcome) -> String {
    let Some(f) = o.failure else {
        return "no failure".into();
    };
    let step = match f.step {
        0 => "candidate",
        1 => "next",
        _ => "later",
    };
    match f.bound {
        None => format!("{step}: no feasible placement"),
        Some(b) if f.by_earlier => format!("{step}: {b}, an object of the pile"),
        Some(b) => format!("{step}: {b}"),
    }
}

/// The index of the greatest key, ties to the first.
fn best<K: PartialOrd>(keys: impl Iterator<Item = K>) -> usize {
    let mut out: Option<(usize, K)> = None;
    for (i, k) in keys.enumerate() {
        if out.as_ref().is_none_or(|(_, b)| k > *b) {
            out = Some((i, k));
        }
    }
    out.map_or(0, |(i, _)| i)
}

/// Packs `episode` with the twin's search, comparing it with the exact clone at each decision.
fn probe(
    catalog: &SharedCatalog,
    episode: &[TypeIdx],
    frozen: bool,
    t: &mut Tally,
) -> Result<(), Error> {
    let cfg = WorldConfig::default();
    let mut env = PackingEnv::new(catalog.clone(), cfg.clone(), REWARD)?;
    env.reset(episode, 0)?;
    let mut lattice = Lattice::new(catalog);
    let settings = |twin| SearchSettings {
        k: K,
        budget: Budget::Rollouts(K),
        horizon: None,
        reward: REWARD,
        twin,
    };
    let kind = if frozen {
        TwinKind::ExactClone
    } else {
        TwinKind::Heightmap
    };
    let mut search_twin = Search::new(catalog.clone(), cfg.clone(), settings(kind));
    let mut search_exact =
        Search::new(catalog.clone(), cfg.clone(), settings(TwinKind::ExactClone));
    let mut success = false;
    while let Some(&next) = env.remaining().first() {
        let remaining = env.remaining().to_vec();
        lattice.compute(env.world().heightmap(), catalog, next);
        let cands: Vec<Placement> = lattice.candidates().iter().take(K).copied().collect();
        if cands.is_empty() {
            break;
        }
        // The twin the search rolls out in, or the frozen clone standing for it.
        let frozen_world = frozen.then(|| {
            let mut w = env.world().clone();
            w.freeze_placed();
            w
        });
        let twin = match &frozen_world {
            Some(w) => w.clone(),
            None => PackingWorld::twin(catalog.clone(), cfg.clone(), env.world().heightmap())?,
        };
        for &c in &cands {
            let (mut a, mut b) = (env.world().clone(), twin.clone());
            let (oa, ob) = (
                a.place(next, c.x, c.y, c.theta())?,
                b.place(next, c.x, c.y, c.theta())?,
            );
            t.firsts += 1;
            t.stable_alike += (oa.stable == ob.stable) as usize;
            t.tilt_diff += (oa.tilt_rad - ob.tilt_rad).abs() as f64;
        }
        // The search itself, in the twin (or the frozen clone) and in the exact clone: every
        // candidate's rollout and the choice are its own.
        let heightmap = env.world().heightmap();
        let p = search_twin
            .decide(heightmap, &remaining, frozen_world.as_ref())?
            .ok_or("the lattice's candidates went missing")?;
        search_exact.decide(heightmap, &remaining, Some(env.world()))?;
        let outcomes = |s: &Search| -> Vec<CandidateOutcome> {
            s.report().finished.iter().map(|(_, o)| *o).collect()
        };
        let (twins, exact) = (outcomes(&search_twin), outcomes(&search_exact));
        for (w, e) in twins.iter().zip(&exact) {
            t.rollouts[w.success as usize][e.success as usize] += 1;
            if w.success != e.success {
                let why = if w.success {
                    format!("the exact clone fails, the twin does not: {}", failure(e))
                } else {
                    format!("the twin fails, the exact clone does not: {}", failure(w))
                };
                *t.reasons.entry(why).or_default() += 1;
            }
        }
        let chosen = search_twin.report().chosen.ok_or("the search chose")?;
        let exact_best = search_exact.report().chosen.ok_or("the search chose")?;
        let success_first = best(
            twins
                .iter()
                .enumerate()
                .map(|(i, o)| (o.success, o.packed, std::cmp::Reverse(i))),
        );
        t.decisions += 1;
        t.same_choice += (chosen == exact_best) as usize;
        t.regret += (exact[exact_best].ret - exact[chosen].ret) as f64;
        t.exact_best_ok += exact[exact_best].success as usize;
        t.twin_choice_ok += exact[chosen].success as usize;
        t.success_first_ok += exact[success_first].success as usize;
        let r = env.step_placement(p.x, p.y, p.theta())?;
        if r.terminated {
            success = r.info.success;
            break;
        }
    }
    t.episodes += 1;
    t.success += success as usize;
    Ok(())
}

fn main() -> Result<(), Error> {
    let arg = |i: usize, default: u64| -> Result<u64, Error> {
        match std::env::args().nth(i) {
            Some(v) => v
                .parse()
                .map_err(|e| format!("argument {i} ({v:?}): {e}").into()),
            None => Ok(default),
        }
    };
    let (n, seed, threads) = (
        arg(1, 16)? as usize,
        arg(2, 777)?,
        arg(3, 2)?.max(1) as usize,
    );
    let frozen = match std::env::args().nth(4).as_deref() {
        None | Some("twin") => false,
        Some("frozen") => true,
        Some(other) => return Err(format!("argument 4 ({other:?}): twin or frozen").into()),
    };
    let root = paths::boxed_root(None);
    let catalog: SharedCatalog = Arc::new(Catalog::builtin(&paths::mesh_source(
        None,
        root.as_deref(),
    ))?);
    let model = SequenceModel::load(Path::new("models/sequence.json"), &catalog)?;
    let order = Order::HERB
        .beam_search()
        .ok_or("HERB's order is a beam search")?;
    let mut root_rng = ChaCha8Rng::seed_from_u64(seed);
    let mut episodes = Vec::with_capacity(n);
    for _ in 0..n {
        let mut rng = ChaCha8Rng::seed_from_u64(root_rng.random());
        let m = rng.random_range(10..=25);
        let objects: Vec<TypeIdx> = (0..m)
            .map(|_| TypeIdx(rng.random_range(0..catalog.len() as u16)))
            .collect();
        episodes.push(order(&model, &objects)?);
    }
    let t0 = std::time::Instant::now();
    let mut t = Tally::default();
    std::thread::scope(|s| -> Result<(), Error> {
        let handles: Vec<_> = (0..threads)
            .map(|i| {
                let (catalog, episodes) = (&catalog, &episodes);
                s.spawn(move || -> Result<Tally, Error> {
                    let mut t = Tally::default();
                    for ep in episodes.iter().skip(i).step_by(threads) {
                        probe(catalog, ep, frozen, &mut t)?;
                    }
                    Ok(t)
                })
            })
            .collect();
        for h in handles {
            t.add(h.join().map_err(|_| "a probe thread panicked")??);
        }
        Ok(())
    })?;
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    let [[ff, ft], [tf, tt]] = t.rollouts;
    println!(
        "{} episodes (seed {seed}), {}, {:.0} s: its search packs {:.2} %",
        t.episodes,
        if frozen {
            "a frozen clone as the twin"
        } else {
            "the twin"
        },
        t0.elapsed().as_secs_f64(),
        pct(t.success, t.episodes)
    );
    println!(
        "first placements: {} compared, stable alike {:.1} %, tilt differs by {:.1} deg on average",
        t.firsts,
        pct(t.stable_alike, t.firsts),
        (t.tilt_diff / t.firsts.max(1) as f64).to_degrees()
    );
    println!(
        "rollouts: {} compared, success predicted alike {:.1} % (both succeed {tt}, both fail {ff}, \
         only the twin fails {ft}, only the exact clone fails {tf})",
        tt + tf + ft + ff,
        pct(tt + ff, tt + tf + ft + ff)
    );
    for (why, count) in &t.reasons {
        println!("  {count:5}  {why}");
    }
    println!(
        "choices: {} decisions, the twin chooses the exact best {:.1} %, mean regret {:.3} (exact \
         return); the exact rollout succeeds for the exact best {:.1} %, the twin's choice {:.1} %, \
         success first then the prior {:.1} %",
        t.decisions,
        pct(t.same_choice, t.decisions),
        t.regret / t.decisions.max(1) as f64,
        pct(t.exact_best_ok, t.decisions),
        pct(t.twin_choice_ok, t.decisions),
        pct(t.success_first_ok, t.decisions)
    );
    Ok(())
}
