//! Why herbd's default search fails under a field model: each failed episode's last decision,
//! beside what the search predicted for it and what the same release would have done without the
//! field's errors (a diagnostic; its figures are in docs/field-variants.md, "Where the search fails
//! under field-v1").
//!
//!     cargo run --release -p herb-methods --example field_failures -- \
//!         [EPISODES] [SEED] [WORLD] [THREADS] [MIN_SUPPORT] [MEDIAN]
//!
//! The episodes are the sweeps' `set = "sample"` ones (`evaluation::sampled_episodes`: seeds
//! `SEED` to `SEED + EPISODES - 1`, default 777, 10 to 25 catalog objects each), in HERB's
//! order, in the evaluation's world `WORLD` (default `field`: `models/field.toml`; a field model
//! file). As in a sweep, the environment's and the order's seed is the episode's index in the
//! set, so a run from a later `SEED` is not a slice of a longer run. Each is decided as Table I's
//! search row decides (herbd's decision path, the default search settings, count budget;
//! `MIN_SUPPORT` turns on the support rule, `--search-min-support`'s share; `MEDIAN` `true` the
//! median-filtered camera, `--search-median`). For
//! each failure it prints one line: the episode, the step, the object and its catalog size, the
//! search's prediction for the chosen candidate (its rollout's success, the live check), the job
//! twin's agreement with the camera, whether the same decided pose released exactly in the true
//! world before the step ends inside ("exact release"), and the failing object's bound and its
//! bounds' top against the rim. Then a tally of those.
//!
//! Reads `models/sequence.json` from the working directory (run it from the repository's root)
//! and the meshes from BoxED when it is found (`HERB_BOXED`, `../shared/boxed`).

use herb_decide::{Decider, Order, SequenceModel};
use herb_methods::evaluation::{self, EvalSettings, SAMPLED_OBJECTS};
use herb_search::Search;
use herb_sim::catalog::{Catalog, SharedCatalog};
use herb_sim::env::{PackingEnv, RewardMode};
use herb_sim::frames::BOX_HEIGHT;
use herb_sim::paths;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

type Error = Box<dyn std::error::Error + Send + Sync>;

/// One episode: its failure's last decision (`None`: packed), and over its decisions how many
/// ran their rollouts in the job's twin, and the sum of the job twin's share of cells off.
struct Probe {
    failure: Option<Failure>,
    decisions: usize,
    job_used: usize,
    off: f64,
}

/// One failed episode's last decision.
struct Failure {
    line: String,
    keys: Vec<String>,
}

fn main() -> Result<(), Error> {
    let arg = |i: usize| std::env::args().nth(i);
    let n: usize = arg(1).map_or(Ok(64), |v| v.parse())?;
    let seed: u64 = arg(2).map_or(Ok(777), |v| v.parse())?;
    let world = arg(3).unwrap_or_else(|| "field".into());
    let threads: usize = arg(4).map_or(Ok(2), |v| v.parse())?;
    let defaults = EvalSettings::default();
    let settings = EvalSettings {
        world,
        search_min_support: arg(5).map_or(Ok(defaults.search_min_support), |v| v.parse())?,
        search_median: arg(6).map_or(Ok(defaults.search_median), |v| v.parse())?,
        ..defaults
    };
    settings.validate()?;
    let cfg = settings.world()?;
    let ms = settings.method_settings(&cfg)?;
    let root = paths::boxed_root(None);
    let catalog: SharedCatalog = Arc::new(Catalog::builtin(&paths::mesh_source(
        None,
        root.as_deref(),
    ))?);
    let model = SequenceModel::load(Path::new("models/sequence.json"), &catalog)?;
    let episodes = evaluation::sampled_episodes(catalog.len(), seed, n, SAMPLED_OBJECTS);
    let next = AtomicUsize::new(0);
    let run = |i: usize| -> Result<Probe, Error> {
        let mut probe = Probe {
            failure: None,
            decisions: 0,
            job_used: 0,
            off: 0.0,
        };
        let (name, objects) = (&episodes[i].name, &episodes[i].objects);
        // The sweep's episode i: the environment's and the order's seed is its index.
        let order = Order::HERB.order(&catalog, Some(&model), objects, i as u64)?;
        let mut env = PackingEnv::new(catalog.clone(), cfg.clone(), RewardMode::Simple)?;
        env.reset(&order, i as u64)?;
        let search = Search::new(catalog.clone(), cfg.clone(), ms.search);
        let mut decider = Decider::new(Box::new(search), catalog.clone(), cfg.clearance_m);
        decider.begin_episode(i as u64);
        while let Some(object) = env.next_object() {
            let step = env.step_index();
            let before = env.world().clone();
            let d = match decider.decide_on(env.camera().into(), env.remaining(), step) {
                Ok(d) => d,
                Err(herb_decide::DecideError::NoFeasiblePlacement) => {
                    let r = decider.policy().report();
                    let job = r.job.map_or("-".into(), |j| {
                        format!("used {} off {:.1} %", j.used, 100.0 * j.off)
                    });
                    probe.failure = Some(Failure {
                        line: format!(
                            "{name} step {}/{} {}: no feasible placement (job twin {job})",
                            step + 1,
                            order.len(),
                            catalog.spec(object).id
                        ),
                        keys: vec!["no feasible placement".into()],
                    });
                    return Ok(probe);
                }
                Err(e) => return Err(e.into()),
            };
            let r = decider.policy().report().clone();
            probe.decisions += 1;
            if let Some(j) = r.job {
                probe.job_used += j.used as usize;
                probe.off += f64::from(j.off);
            }
            let pose = d.pose();
            let chosen = r
                .chosen
                .and_then(|c| r.finished.iter().find(|(i, _)| *i == c).map(|(_, o)| *o));
            let exact = before.clone().place_pose(object, pose)?;
            let result = env.step_pose(pose)?;
            let (terminated, success) = (result.terminated, result.info.success);
            if !terminated || success {
                continue;
            }
            let mut world = env.world().clone();
            let report = world.report();
            let Some((k, o)) = report
                .iter()
                .enumerate()
                .find(|(_, o)| o.violation.is_some())
            else {
                return Ok(probe);
            };
            let (bound, by) = o.violation.unwrap_or(("-", 0.0));
            let placed = k + 1 == report.len();
            let shape = catalog.shape(object);
            let size = shape.aabb_max - shape.aabb_min;
            let predicted = chosen.map_or("none finished".into(), |o| {
                format!("rollout {}", if o.success { "ok" } else { "fails" })
            });
            let job = r.job.map_or("-".into(), |j| {
                format!("used {} off {:.1} %", j.used, 100.0 * j.off)
            });
            let top = chosen.map_or(f32::NAN, |o| o.placement.top);
            let line = format!(
                "{name} step {}/{} {} ({:.0} x {:.0} x {:.0} mm): {bound} by {:.1} mm ({}), \
                 top {:+.0} mm over the rim (decided {:+.0}), {predicted}, live {}/{}, job twin \
                 {job}, exact release {}",
                step + 1,
                order.len(),
                catalog.spec(object).id,
                1e3 * size.x,
                1e3 * size.y,
                1e3 * size.z,
                1e3 * by,
                if placed { "placed" } else { "earlier" },
                1e3 * (o.hi[2] - BOX_HEIGHT),
                1e3 * (top - BOX_HEIGHT),
                r.live_checked - r.live_rejected,
                r.live_checked,
                if exact.inside { "inside" } else { "outside" },
            );
            let mut keys = vec![
                format!("{} object", if placed { "placed" } else { "earlier" }),
                format!(
                    "exact release {}",
                    if exact.inside { "inside" } else { "outside" }
                ),
                format!(
                    "{predicted}, exact release {}",
                    if exact.inside { "inside" } else { "outside" }
                ),
                format!(
                    "decided top {} the rim",
                    if top > BOX_HEIGHT { "above" } else { "below" }
                ),
            ];
            if !placed {
                keys.push(format!("earlier object, bound {bound}"));
            }
            probe.failure = Some(Failure { line, keys });
            return Ok(probe);
        }
        Ok(probe)
    };
    let results: Vec<Result<Probe, Error>> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..threads.max(1))
            .map(|_| {
                sc.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            return out;
                        }
                        out.push((i, run(i)));
                    }
                })
            })
            .collect();
        let mut all: Vec<_> = handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect();
        all.sort_by_key(|(i, _)| *i);
        all.into_iter().map(|(_, r)| r).collect()
    });
    let mut tally: BTreeMap<String, usize> = BTreeMap::new();
    let mut failed = 0;
    let (mut decisions, mut used, mut off) = (0, 0, 0.0);
    for r in results {
        let p = r?;
        decisions += p.decisions;
        used += p.job_used;
        off += p.off;
        if let Some(f) = p.failure {
            failed += 1;
            println!("{}", f.line);
            for k in f.keys {
                *tally.entry(k).or_default() += 1;
            }
        }
    }
    println!(
        "{decisions} decisions: rollouts in the job's twin {:.1} %, its cells off by more than \
         10 mm {:.1} % on average",
        100.0 * used as f64 / decisions.max(1) as f64,
        100.0 * off / decisions.max(1) as f64
    );
    println!("{failed} of {n} episodes failed (seed {seed}):");
    for (k, v) in tally {
        println!("  {v:4}  {k}");
    }
    Ok(())
}
