//! Placement-lattice benchmark: the cost per decision of the geometry planes
//! (`Lattice::compute`: pooling, footprints, rest height, top, flags and support over 28 x 19
//! positions x 4 yaws) and of the candidates (`Lattice::candidates`: selection, refinement and
//! tight variants), on one core.
//!
//! `cargo bench -p herb-sim --bench lattice`. Every timed call is also recorded in a histogram
//! and p50/p99 are printed. States: the heightmaps reached by replaying the humans' planar
//! placements of the first 20 BoxED sessions with mesh hulls (primitives without the data),
//! each with its next object.

use criterion::{Criterion, criterion_group, criterion_main};
use hdrhistogram::Histogram;
use herb_sim::boxed::load_session;
use herb_sim::lattice::Lattice;
use herb_sim::paths::{self, MeshSource};
use herb_sim::{Catalog, Heightmap, PackingWorld, SharedCatalog, TypeIdx, WorldConfig};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Decision states: a heightmap and the object to place on it.
fn states() -> (SharedCatalog, Vec<(Heightmap, TypeIdx)>) {
    let root = paths::boxed_root(None).filter(|r| r.join("sessions").is_dir());
    let src = match &root {
        Some(r) => MeshSource::Folder(r.join("meshes")),
        None => {
            eprintln!("no BoxED data: primitives and a fixed sequence");
            MeshSource::None("bench".into())
        }
    };
    let catalog: SharedCatalog = Arc::new(Catalog::builtin(&src).expect("built-in catalog"));
    let episodes: Vec<Vec<(TypeIdx, f32, f32, f32)>> = match &root {
        Some(r) => herb_sim::boxed::list_sessions(r)
            .expect("sessions")
            .iter()
            .take(20)
            .map(|n| {
                let ep = load_session(r, n, &catalog)
                    .expect("session")
                    .episode(&catalog);
                ep.objects
                    .iter()
                    .zip(&ep.human)
                    .map(|(&t, h)| (t, h.x, h.y, h.theta))
                    .collect()
            })
            .collect(),
        None => {
            let types: Vec<TypeIdx> = catalog.types().collect();
            (0..10usize)
                .map(|e| {
                    (0..12usize)
                        .map(|i| {
                            let k = e * 31 + i * 17;
                            let f = |m: usize| ((k * m) % 1000) as f32 / 1000.0 - 0.5;
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
    };
    let mut out = Vec::new();
    for ep in &episodes {
        let mut w = PackingWorld::new(catalog.clone(), WorldConfig::default()).expect("world");
        for &(t, x, y, th) in ep {
            out.push((w.heightmap().clone(), t));
            if !w.place(t, x, y, th).expect("place").inside {
                break;
            }
        }
    }
    (catalog, out)
}

fn hist() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("histogram bounds")
}

fn report(what: &str, h: &Histogram<u64>) {
    eprintln!(
        "{what}: n {} p50 {:.3} ms p99 {:.3} ms max {:.3} ms mean {:.3} ms",
        h.len(),
        h.value_at_quantile(0.5) as f64 / 1e6,
        h.value_at_quantile(0.99) as f64 / 1e6,
        h.max() as f64 / 1e6,
        h.mean() / 1e6
    );
}

fn benches(c: &mut Criterion) {
    let (catalog, states) = states();
    // The footprint cache (the run-time path) and rasterising the footprints every decision
    // (the path on other grids), in one run.
    for (label, mut lattice) in [
        ("cached footprints", Lattice::new(&catalog)),
        (
            "footprints rasterised each decision",
            Lattice::new(&catalog).without_cache(),
        ),
    ] {
        let (mut h_planes, mut h_cands, mut h_all) = (hist(), hist(), hist());
        let mut k = 0usize;
        let mut n_cands = 0usize;
        c.bench_function(&format!("lattice/planes+candidates ({label})"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let (hm, t) = &states[k % states.len()];
                    k += 1;
                    let t0 = Instant::now();
                    lattice.compute(hm, &catalog, *t);
                    let t1 = Instant::now();
                    n_cands += lattice.candidates().len();
                    let t2 = Instant::now();
                    total += t2 - t0;
                    h_planes.record((t1 - t0).as_nanos() as u64).ok();
                    h_cands.record((t2 - t1).as_nanos() as u64).ok();
                    h_all.record((t2 - t0).as_nanos() as u64).ok();
                }
                total
            })
        });
        eprintln!(
            "{label}: {} states, {:.1} candidates per decision",
            states.len(),
            n_cands as f64 / h_all.len().max(1) as f64
        );
        report(&format!("lattice planes (compute), {label}"), &h_planes);
        report(&format!("lattice candidates, {label}"), &h_cands);
        report(&format!("lattice planes + candidates, {label}"), &h_all);
    }
}

criterion_group! {
    name = lattice;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(6));
    targets = benches
}
criterion_main!(lattice);
