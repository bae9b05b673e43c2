//! Where the search's twin and the world differ, decision by decision (a diagnostic; its
//! figures are in docs/search.md).
//!
//!     cargo run --release -p herb-methods --example twin_fidelity -- \
//!         [EPISODES] [SEED] [THREADS] [twin|frozen|job|exact|blbf] [NOISE_MM] [NOISE_DEG] \
//!         [SAMPLES]
//!
//! What packs (and is compared with the exact clone at each decision):
//!
//! - `twin` (default): the search in the heightmap twin, as herbd runs it;
//! - `frozen`: the search in a clone of the world whose objects are made fixed
//!   ([`PackingWorld::freeze_placed`]): the twin's rigid pile with the objects' exact shapes, to
//!   tell what the pile's shape costs from what its rigidity costs;
//! - `job`: the search in the job's own twin (`TwinKind::Job`: its decisions replayed, each
//!   fitted to the heightmap that followed it);
//! - `exact`: the search in the exact clone itself (the bound);
//! - `blbf`: no rollout, the prior's first (lattice BLBF).
//!
//! `NOISE_MM`, `NOISE_DEG` (default 0): the world's release noise
//! (`WorldConfig::release_noise_m`, `release_noise_deg`, as `herb-sim eval --release-noise
//! MM,DEG`): each object released off its decided pose by normal noise of these standard
//! deviations in x and y, and in yaw (seeded by the episode's index: runs reproduce); the twins
//! are not told. Without noise the world is the twins' model exactly, and the job's twin
//! replays it exactly.
//!
//! `SAMPLES` (default 0): the search that packs is the robust one (`RobustRollouts`): each
//! candidate rolled out `SAMPLES` times under the world's release noise, ranked by the mean
//! return. The exact clone's search it is compared with stays plain.
//!
//! The episodes are `training/validate.py`'s (the bindings' sampler: 10 to 25 random catalog
//! objects in HERB's order, one generator per episode seeded from `SEED`, default 777). Each is
//! packed by the search (`herb_search`: k = 8 candidates in lattice BLBF's order, each
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
use herb_search::{Budget, RobustRollouts, Search, SearchSettings, TwinKind};
use herb_sim::catalog::{Catalog, SharedCatalog, TypeIdx};
use herb_sim::env::{PackingEnv, RewardMode};
use herb_sim::lattice::{Lattice, Placement};
use herb_sim::paths;
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
    /// Job mode: decisions, those whose rollouts ran in the job's twin, sums of its mean
    /// |height difference| to the heightmap (m) and of its share of cells off, the fits' total
    /// and longest time (s).
    job_decisions: usize,
    job_used: usize,
    job_diff: f64,
    job_off: f64,
    job_fit: f64,
    job_fit_max: f64,
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
        self.job_decisions += o.job_decisions;
        self.job_used += o.job_used;
        self.job_diff += o.job_diff;
        self.job_off += o.job_off;
        self.job_fit += o.job_fit;
        self.job_fit_max = self.job_fit_max.max(o.job_fit_max);
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

/// What the search rolls out in.
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// The heightmap twin.
    Twin,
    /// A clone of the world with its objects fixed.
    Frozen,
    /// The job's own twin (`TwinKind::Job`).
    Job,
    /// A clone of the world itself (the exact clone) packs.
    Exact,
    /// No rollout: the prior's first (lattice BLBF) packs.
    Blbf,
}

/// Packs `episode` with the twin's search, comparing it with the exact clone at each decision.
fn probe(
    catalog: &SharedCatalog,
    episode: &[TypeIdx],
    mode: Mode,
    noisy: &WorldConfig,
    robust: Option<RobustRollouts>,
    seed: u64,
    t: &mut Tally,
) -> Result<(), Error> {
    let cfg = WorldConfig::default();
    let mut env = PackingEnv::new(catalog.clone(), noisy.clone(), REWARD)?;
    env.reset(episode, seed)?;
    let mut lattice = Lattice::new(catalog);
    let settings = |twin, robust| SearchSettings {
        k: K,
        budget: Budget::Rollouts(K),
        horizon: None,
        reward: REWARD,
        twin,
        robust,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let kind = match mode {
        Mode::Twin | Mode::Blbf => TwinKind::Heightmap,
        Mode::Job => TwinKind::Job,
        Mode::Frozen | Mode::Exact => TwinKind::ExactClone,
    };
    let mut search_twin = Search::new(catalog.clone(), cfg.clone(), settings(kind, robust));
    if mode == Mode::Blbf {
        search_twin.set_budget(Budget::Rollouts(0));
    }
    let mut search_exact = Search::new(
        catalog.clone(),
        cfg.clone(),
        settings(TwinKind::ExactClone, None),
    );
    let mut success = false;
    while let Some(&next) = env.remaining().first() {
        let remaining = env.remaining().to_vec();
        lattice.compute(env.world().heightmap(), catalog, next);
        let cands: Vec<Placement> = lattice.candidates().iter().take(K).copied().collect();
        if cands.is_empty() {
            break;
        }
        // The search itself, in its twin (or the clone standing for it) and in the exact
        // clone: every candidate's rollout and the choice are its own.
        let given = match mode {
            Mode::Frozen => {
                let mut w = env.world().clone();
                w.freeze_placed();
                Some(w)
            }
            Mode::Exact => Some(env.world().clone()),
            Mode::Twin | Mode::Blbf | Mode::Job => None,
        };
        let heightmap = env.world().heightmap();
        let p = search_twin
            .decide(heightmap, &remaining, given.as_ref())?
            .ok_or("the lattice's candidates went missing")?;
        search_exact.decide(heightmap, &remaining, Some(env.world()))?;
        if let Some(j) = search_twin.report().job {
            t.job_decisions += 1;
            t.job_used += j.used as usize;
            t.job_diff += j.mean_diff_m as f64;
            t.job_off += j.off as f64;
            t.job_fit += j.fit.as_secs_f64();
            t.job_fit_max = t.job_fit_max.max(j.fit.as_secs_f64());
        }
        // The world the search rolled out in, each candidate placed once there and in the
        // world.
        let twin = match (&given, search_twin.job_twin()) {
            (Some(w), _) | (None, Some(w)) => w.clone(),
            _ => PackingWorld::twin(catalog.clone(), cfg.clone(), heightmap)?,
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
        // Released at the world's release pose, plus the world's release noise.
        let rot = rapier3d::math::Rotation::from_rotation_z(p.theta());
        let decided = env.world_mut().release_pose(next, p.x, p.y, rot);
        let r = env.step_pose(decided)?;
        let (terminated, ok) = (r.terminated, r.info.success);
        if terminated {
            success = ok;
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
    let mode = match std::env::args().nth(4).as_deref() {
        None | Some("twin") => Mode::Twin,
        Some("frozen") => Mode::Frozen,
        Some("job") => Mode::Job,
        Some("exact") => Mode::Exact,
        Some("blbf") => Mode::Blbf,
        Some(other) => {
            return Err(format!("argument 4 ({other:?}): twin, frozen, job, exact or blbf").into());
        }
    };
    let noisy = WorldConfig {
        release_noise_m: arg(5, 0)? as f32 * 1e-3,
        release_noise_deg: arg(6, 0)? as f32,
        ..WorldConfig::default()
    };
    noisy.validate()?;
    let samples = arg(7, 0)? as usize;
    let robust = (samples > 0).then_some(RobustRollouts {
        noise: noisy.release_noise(),
        samples,
    });
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
                let (catalog, episodes, noisy) = (&catalog, &episodes, &noisy);
                s.spawn(move || -> Result<Tally, Error> {
                    let mut t = Tally::default();
                    for (e, ep) in episodes.iter().enumerate().skip(i).step_by(threads) {
                        probe(catalog, ep, mode, noisy, robust, e as u64, &mut t)?;
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
        "{} episodes (seed {seed}), {}{}, release noise {} mm / {} deg, {:.0} s: packs {:.2} %",
        t.episodes,
        match mode {
            Mode::Twin => "the search in the heightmap twin",
            Mode::Frozen => "the search in a frozen clone",
            Mode::Job => "the search in the job's twin",
            Mode::Exact => "the search in the exact clone",
            Mode::Blbf => "BLBF (no rollout)",
        },
        match robust {
            Some(r) => format!(", robust ({} noisy rollouts a candidate)", r.samples),
            None => String::new(),
        },
        1e3 * noisy.release_noise_m,
        noisy.release_noise_deg,
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
    if mode == Mode::Job {
        let n = t.job_decisions.max(1) as f64;
        println!(
            "the job's twin against the heightmap at each decision: mean |height difference| \
             {:.2} mm, cells off by more than 10 mm {:.2} %; rollouts ran in it in {:.1} % of {} \
             decisions (else in the heightmap twin); its fit took {:.1} ms a decision on \
             average, {:.1} ms at most",
            1e3 * t.job_diff / n,
            100.0 * t.job_off / n,
            pct(t.job_used, t.job_decisions),
            t.job_decisions,
            1e3 * t.job_fit / n,
            1e3 * t.job_fit_max
        );
    }
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
