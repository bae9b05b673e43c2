//! Packing-world benchmarks: placements per second on one core (z estimate,
//! release, settle, inside and compactness scan, heightmap render), heightmap render time, and
//! memory per world.
//!
//! The search's rollout worlds are timed side by side: the exact clone and the heightmap twin.
//!
//! `cargo bench -p herb-sim --bench world`. Besides criterion's mean, every timed call is
//! recorded in a histogram and p50/p99 are printed. Uses the BoxED meshes when present (mesh
//! hulls), and the primitives in any case; the scenes are the humans' planar placements of the
//! first sessions (or, without the data, a fixed pseudo-random sequence).

use criterion::{Criterion, criterion_group, criterion_main};
use hdrhistogram::Histogram;
use herb_sim::boxed::{Episode, load_session};
use herb_sim::paths::{self, MeshSource};
use herb_sim::{Catalog, PackingWorld, SharedCatalog, TypeIdx, WorldConfig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Arc;
use std::sync::atomic::{AtomicIsize, Ordering};
use std::time::{Duration, Instant};

/// Counts live heap bytes, to measure memory per world.
struct Counting;
static LIVE: AtomicIsize = AtomicIsize::new(0);

// SAFETY: forwards to the system allocator and only counts sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        LIVE.fetch_add(l.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        LIVE.fetch_sub(l.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        LIVE.fetch_add(new as isize - l.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(p, l, new) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Episodes whose second halves the rollout benches replay on their first halves (and whose
/// outcomes the A/B compares): enough that one chaotic settle does not decide a ratio.
const BENCH_EPISODES: usize = 20;

/// A placement to replay: type and planar pose.
type Step = (TypeIdx, f32, f32, f32);

struct Setup {
    label: &'static str,
    catalog: SharedCatalog,
    episodes: Vec<Vec<Step>>,
}

fn setups() -> Vec<Setup> {
    let root = paths::boxed_root(None).filter(|r| r.join("sessions").is_dir());
    let mut out = Vec::new();
    let sources = [
        (
            "mesh",
            root.as_ref().map(|r| MeshSource::Folder(r.join("meshes"))),
        ),
        ("primitive", Some(MeshSource::None("bench".into()))),
    ];
    for (label, src) in sources {
        let Some(src) = src else {
            eprintln!("no BoxED data: the mesh-hull benchmarks are skipped");
            continue;
        };
        let catalog = Arc::new(Catalog::builtin(&src).expect("built-in catalog"));
        let episodes = match &root {
            Some(r) => paths_episodes(r, &catalog),
            None => synthetic_episodes(&catalog),
        };
        out.push(Setup {
            label,
            catalog,
            episodes,
        });
    }
    out
}

fn paths_episodes(root: &std::path::Path, c: &Catalog) -> Vec<Vec<Step>> {
    let names = herb_sim::boxed::list_sessions(root).expect("sessions");
    names
        .iter()
        .take(20)
        .map(|n| {
            let ep: Episode = load_session(root, n, c).expect("session").episode(c);
            ep.objects
                .iter()
                .zip(&ep.human)
                .map(|(&t, h)| (t, h.x, h.y, h.theta))
                .collect()
        })
        .collect()
}

fn synthetic_episodes(c: &Catalog) -> Vec<Vec<Step>> {
    let types: Vec<TypeIdx> = c.types().collect();
    (0..20u32)
        .map(|e| {
            (0..16u32)
                .map(|i| {
                    let k = (e * 31 + i * 17) as usize;
                    let f = |m: u32| ((k as u32 * m) % 1000) as f32 / 1000.0 - 0.5;
                    (
                        types[k % types.len()],
                        0.25 * f(7),
                        0.16 * f(13),
                        6.0 * f(3),
                    )
                })
                .collect()
        })
        .collect()
}

fn hist() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("histogram bounds")
}

fn report(what: &str, h: &Histogram<u64>) {
    if h.is_empty() {
        return; // filtered out by criterion's name filter
    }
    eprintln!(
        "{what}: n {} p50 {:.3} ms p99 {:.3} ms max {:.3} ms mean {:.3} ms",
        h.len(),
        h.value_at_quantile(0.5) as f64 / 1e6,
        h.value_at_quantile(0.99) as f64 / 1e6,
        h.max() as f64 / 1e6,
        h.mean() / 1e6
    );
}

/// One placement per iteration, walking through the episodes; a world is reset (untimed) when
/// an episode ends or an object leaves the box.
fn bench_placements(c: &mut Criterion, s: &Setup) {
    let mut world = PackingWorld::new(s.catalog.clone(), WorldConfig::default()).expect("world");
    let mut h = hist();
    let (mut e, mut i) = (0usize, 0usize);
    c.bench_function(&format!("placement/{}", s.label), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                if i >= s.episodes[e].len() {
                    (e, i) = ((e + 1) % s.episodes.len(), 0);
                    world.reset();
                }
                let (t, x, y, th) = s.episodes[e][i];
                let t0 = Instant::now();
                let o = world.place(t, x, y, th).expect("place");
                let dt = t0.elapsed();
                total += dt;
                h.record(dt.as_nanos() as u64).ok();
                i += 1;
                if !o.inside {
                    i = usize::MAX;
                }
            }
            total
        })
    });
    report(&format!("placement/{} (one core)", s.label), &h);
    if h.is_empty() {
        return;
    }
    eprintln!(
        "placement/{}: {:.0} placements/s per core (1 / mean)",
        s.label,
        1e9 / h.mean()
    );
}

/// Heightmap render of full scenes: each episode replayed, then timed renders.
fn bench_heightmap(c: &mut Criterion, s: &Setup) {
    let mut worlds = Vec::new();
    for ep in s.episodes.iter().take(5) {
        let mut w = PackingWorld::new(s.catalog.clone(), WorldConfig::default()).expect("world");
        for &(t, x, y, th) in ep {
            if !w.place(t, x, y, th).expect("place").inside {
                break;
            }
        }
        worlds.push(w);
    }
    let objects: usize = worlds.iter().map(|w| w.placed().len()).sum();
    let mut h = hist();
    let mut k = 0usize;
    let n_worlds = worlds.len();
    let spec = *worlds[0].heightmap().spec();
    c.bench_function(&format!("heightmap/{}", s.label), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let w = &mut worlds[k % n_worlds];
                k += 1;
                let t0 = Instant::now();
                w.render_heightmap();
                let dt = t0.elapsed();
                total += dt;
                h.record(dt.as_nanos() as u64).ok();
            }
            total
        })
    });
    report(
        &format!(
            "heightmap/{} ({} x {} cells, {:.1} objects per scene)",
            s.label,
            spec.nx,
            spec.ny,
            objects as f64 / worlds.len() as f64
        ),
        &h,
    );
}

/// Live heap bytes of a new world and of a world holding a full episode (the catalog, shared
/// between worlds, is excluded).
fn memory(s: &Setup) {
    let before = LIVE.load(Ordering::Relaxed);
    let mut w = PackingWorld::new(s.catalog.clone(), WorldConfig::default()).expect("world");
    let empty = LIVE.load(Ordering::Relaxed) - before;
    let ep = s
        .episodes
        .iter()
        .max_by_key(|e| e.len())
        .expect("an episode");
    let mut n = 0;
    for &(t, x, y, th) in ep {
        w.place(t, x, y, th).expect("place");
        n += 1;
    }
    let full = LIVE.load(Ordering::Relaxed) - before;
    eprintln!(
        "memory/{}: {:.2} MiB per empty world, {:.2} MiB with {n} objects (catalog shared, not counted)",
        s.label,
        empty as f64 / (1 << 20) as f64,
        full as f64 / (1 << 20) as f64
    );
    drop(w);
}

/// The search's rollout worlds, side by side in one run: the second half of each episode placed
/// on its first half, in a clone of the world that packed the first half (the exact clone, the
/// lookahead teacher's) and in the twin built from that world's heightmap alone
/// ([`PackingWorld::twin`]). A clone or twin is made (untimed) for each pass; each placement
/// (z estimate, release, settle, checks) is timed.
///
/// With `HERB_WORLD_B=KEY=VALUE,...` (settings of [`WorldConfig::set`]) the same is timed again
/// under those settings, in the same run, and the ratio of the rates printed, with how far the
/// outcomes agree ([`agreement`]): every speed-up is a ratio measured in one run.
///
/// `HERB_WORLD_A=KEY=VALUE,...` changes the first run's settings (default: today's defaults), so
/// a default that changed can still be compared with the settings it replaced.
fn bench_rollout_worlds(c: &mut Criterion, s: &Setup) {
    let settings = |var: &str| {
        let list = std::env::var(var).ok()?;
        let mut cfg = WorldConfig::default();
        if let Err(e) = cfg.set_all(&list) {
            panic!("{var}: world settings KEY=VALUE,...: {e}");
        }
        Some((cfg, list))
    };
    let (cfg_a, list_a) = settings("HERB_WORLD_A").unwrap_or_default();
    let a = bench_rollout_worlds_with(c, s, "", &cfg_a);
    let Some((cfg, list)) = settings("HERB_WORLD_B") else {
        return;
    };
    let b = bench_rollout_worlds_with(c, s, "-b", &cfg);
    for (kind, (ra, rb)) in ["exact", "twin"].iter().zip(a.iter().zip(&b)) {
        eprintln!(
            "rollout-{kind}/{}: settings B ({list}) place {:.2} x as many objects per second as A ({})",
            s.label,
            rb / ra,
            if list_a.is_empty() {
                "defaults"
            } else {
                &list_a
            }
        );
    }
    agreement(s, &cfg_a, &cfg, &list);
}

/// How far the outcomes under `cfg` agree with those under `cfg_a`, for the first
/// [`BENCH_EPISODES`] episodes: in the world itself (each episode from an empty box), and in
/// the heightmap twin (the second half of each episode in a twin of the world that packed its
/// first half under today's defaults). Each placed object's inside and stable flags are
/// compared while both runs go on, and the compactness after each.
fn agreement(s: &Setup, cfg_a: &WorldConfig, cfg: &WorldConfig, list: &str) {
    let run = |cfg: &WorldConfig, twin: bool| -> Vec<Vec<(bool, bool, f32)>> {
        s.episodes
            .iter()
            .take(BENCH_EPISODES)
            .map(|ep| {
                let (mut w, rest) = if twin {
                    let half = ep.len() / 2;
                    let mut w = PackingWorld::new(s.catalog.clone(), WorldConfig::default())
                        .expect("world");
                    for &(t, x, y, th) in &ep[..half] {
                        w.place(t, x, y, th).expect("place");
                    }
                    let t = PackingWorld::twin(s.catalog.clone(), cfg.clone(), w.heightmap())
                        .expect("twin");
                    (t, &ep[half..])
                } else {
                    let w = PackingWorld::new(s.catalog.clone(), cfg.clone()).expect("world");
                    (w, &ep[..])
                };
                let mut out = Vec::new();
                for &(t, x, y, th) in rest {
                    let o = w.place(t, x, y, th).expect("place");
                    out.push((o.inside, o.stable, o.compactness));
                    if !o.inside {
                        break;
                    }
                }
                out
            })
            .collect()
    };
    for (kind, twin) in [("world", false), ("twin", true)] {
        let (a, b) = (run(cfg_a, twin), run(cfg, twin));
        let (mut same, mut n, mut dc, mut ended_same) = (0, 0, 0.0f64, 0);
        for (ea, eb) in a.iter().zip(&b) {
            ended_same +=
                (ea.len() == eb.len() && ea.last().map(|o| o.0) == eb.last().map(|o| o.0)) as usize;
            for (oa, ob) in ea.iter().zip(eb) {
                n += 1;
                same += (oa.0 == ob.0 && oa.1 == ob.1) as usize;
                dc += (oa.2 - ob.2).abs() as f64;
            }
        }
        eprintln!(
            "agreement-{kind}/{} ({list}): {same} of {n} placements with the same inside and stable flags, mean |dC| {:.4}; {ended_same} of {} episodes ended alike",
            s.label,
            dc / n.max(1) as f64,
            a.len()
        );
    }
}

/// [`bench_rollout_worlds`] under `cfg` (benches named with `suffix`): the placements per
/// second per core in the exact clone and in the twin.
fn bench_rollout_worlds_with(
    c: &mut Criterion,
    s: &Setup,
    suffix: &str,
    cfg: &WorldConfig,
) -> Vec<f64> {
    // The first halves packed as the evaluation's world packs them (never frozen); a rollout
    // under `freeze_settled` freezes its clone.
    let unfrozen = WorldConfig {
        freeze_settled: false,
        ..cfg.clone()
    };
    let mut starts = Vec::new();
    for ep in s.episodes.iter().take(BENCH_EPISODES) {
        let half = ep.len() / 2;
        let mut w = PackingWorld::new(s.catalog.clone(), unfrozen.clone()).expect("world");
        if ep[..half]
            .iter()
            .all(|&(t, x, y, th)| w.place(t, x, y, th).expect("place").inside)
            && half < ep.len()
        {
            starts.push((w, &ep[half..]));
        }
    }
    let mut rates = Vec::new();
    for kind in ["exact", "twin"] {
        let mut h = hist();
        let mut steps = 0u64;
        let mut step_hist = hist();
        let mut capped = 0u64;
        let mut k = 0usize;
        // The twin's build (not in the placements' rate: herbd's search builds it once per
        // decision).
        let mut build = hist();
        c.bench_function(&format!("rollout-{kind}{suffix}/{}", s.label), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut done = 0;
                while done < iters {
                    let (start, rest) = &starts[k % starts.len()];
                    k += 1;
                    let mut w = match kind {
                        "exact" => {
                            let mut w = start.clone();
                            if cfg.freeze_settled {
                                w.freeze_settled();
                            }
                            w
                        }
                        _ => {
                            let t0 = Instant::now();
                            let w = PackingWorld::twin(
                                s.catalog.clone(),
                                cfg.clone(),
                                start.heightmap(),
                            )
                            .expect("twin");
                            build.record(t0.elapsed().as_nanos() as u64).ok();
                            w
                        }
                    };
                    for &(t, x, y, th) in rest.iter() {
                        if done == iters {
                            break;
                        }
                        let t0 = Instant::now();
                        let o = w.place(t, x, y, th).expect("place");
                        let dt = t0.elapsed();
                        total += dt;
                        done += 1;
                        h.record(dt.as_nanos() as u64).ok();
                        steps += o.settle_steps as u64;
                        step_hist.record(o.settle_steps as u64).ok();
                        capped += !o.settled as u64;
                        if !o.inside {
                            break;
                        }
                    }
                }
                total
            })
        });
        report(
            &format!("rollout-{kind}{suffix}/{} (one core)", s.label),
            &h,
        );
        if h.is_empty() {
            // Filtered out: no rate (the ratios below print NaN).
            rates.push(f64::NAN);
            continue;
        }
        let rate = 1e9 / h.mean();
        eprintln!(
            "rollout-{kind}{suffix}/{}: {rate:.0} placements/s per core, {:.1} settle steps per placement (p50 {}, p90 {}, {:.1} % at the time cap)",
            s.label,
            steps as f64 / h.len().max(1) as f64,
            step_hist.value_at_quantile(0.5),
            step_hist.value_at_quantile(0.9),
            100.0 * capped as f64 / h.len().max(1) as f64
        );
        rates.push(rate);
        if !build.is_empty() {
            report(
                &format!("twin-build{suffix}/{} (once per decision)", s.label),
                &build,
            );
        }
    }
    eprintln!(
        "rollout{suffix}/{}: the twin places {:.2} x as many objects per second as the exact clone",
        s.label,
        rates[1] / rates[0]
    );
    rates
}

fn benches(c: &mut Criterion) {
    for s in setups() {
        memory(&s);
        bench_heightmap(c, &s);
        bench_placements(c, &s);
        bench_rollout_worlds(c, &s);
    }
}

criterion_group! {
    name = world;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(8));
    targets = benches
}
criterion_main!(world);
