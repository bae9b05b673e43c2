//! Decision latency, on one core, timed exactly as herbd times it: one
//! `herb_decide::Decider::decide` call (heightmap check and copy, observation when the policy
//! reads one, policy inference, action check, z estimate; `daemon/decide/src/decider.rs`), for
//! each ONNX network in `$HERB_BENCH_MODELS` (default `target/onnx-bench`, written by
//! `python3 training/make_fixtures.py --bench target/onnx-bench`; candidate-contract policies
//! include the placement lattice and features in their decision), after the shipped policies
//! (`models/policy-cs06.onnx`, `models/policy-cs09.onnx`), plus the BLBF baseline.
//!
//! `cargo bench -p herb-decide --bench decision`. Every timed decision is recorded in a
//! histogram; p50/p99 are printed with the network's FLOPs (2 x FMA, tract's cost model) and
//! file size. The sized networks have fixed random weights: latency does not depend on the
//! values.

use criterion::{Criterion, criterion_group, criterion_main};
use hdrhistogram::Histogram;
use herb_core::{Catalog, SharedCatalog, TypeIdx};
use herb_decide::policy::{DecisionInput, PlanarPose, Policy};
use herb_decide::{Blbf, CandidatePolicy, Decider, OnnxPolicy};
use herb_world::{PackingWorld, WorldConfig};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A mid-episode scene (a fixed set of placements) and the next object.
fn scene(c: &SharedCatalog) -> (PackingWorld, TypeIdx) {
    let mut w = PackingWorld::new(c.clone(), WorldConfig::default()).expect("world");
    for (id, x, y, th) in [
        ("003", -0.08, 0.05, 0.3),
        ("004", 0.1, -0.05, 0.0),
        ("005", 0.05, 0.06, 1.0),
        ("007", -0.1, -0.06, 0.5),
        ("013", 0.0, 0.0, 0.0),
    ] {
        w.place(c.by_id(id).expect("id"), x, y, th).expect("place");
    }
    (w, c.by_id("006").expect("id"))
}

/// Checks its observation like a network and returns the centre: the cost of everything but
/// the network (heightmap check and copy, observation build, input checks, z estimate).
struct NullPolicy;

impl Policy for NullPolicy {
    fn name(&self) -> &str {
        "null"
    }
    fn begin_episode(&mut self, _seed: u64) {}
    fn decide(&mut self, input: &DecisionInput) -> herb_decide::Result<PlanarPose> {
        herb_decide::policy::check_input("null", input)?;
        Ok(PlanarPose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        })
    }
}

fn report(name: &str, h: &Histogram<u64>, extra: &str) {
    eprintln!(
        "decision/{name}: n {} p50 {:.3} ms p99 {:.3} ms max {:.3} ms mean {:.3} ms{extra}",
        h.len(),
        h.value_at_quantile(0.5) as f64 / 1e6,
        h.value_at_quantile(0.99) as f64 / 1e6,
        h.max() as f64 / 1e6,
        h.mean() / 1e6
    );
}

fn bench_policy(
    c: &mut Criterion,
    name: &str,
    policy: Box<dyn Policy>,
    catalog: &SharedCatalog,
    extra: &str,
) {
    let (world, next) = scene(catalog);
    // The job's remaining objects, the next first (the rest read by candidate policies'
    // context features).
    let remaining: Vec<TypeIdx> = std::iter::once(next)
        .chain(
            ["003", "005", "004", "011"]
                .iter()
                .map(|id| catalog.by_id(id).expect("id")),
        )
        .collect();
    let mut decider = Decider::new(policy, catalog.clone(), world.config().clearance_m);
    let mut h = Histogram::<u64>::new_with_bounds(1, 10_000_000_000, 3).expect("histogram");
    c.bench_function(&format!("decision/{name}"), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                // One decision on a heightmap of its own (herb_decide::decider): herbd's timed
                // decision plus the heightmap's check and copy, which herbd does on receipt.
                let t0 = Instant::now();
                let d = decider
                    .decide_on(world.heightmap().into(), &remaining, 5)
                    .expect("decision");
                let dt = t0.elapsed();
                std::hint::black_box(d);
                total += dt;
                h.record(dt.as_nanos() as u64).ok();
            }
            total
        })
    });
    report(name, &h, extra);
}

fn benches(c: &mut Criterion) {
    let root = herb_core::paths::boxed_root(None);
    let meshes = herb_core::paths::mesh_source(None, root.as_deref());
    let catalog: SharedCatalog = Arc::new(Catalog::builtin(&meshes).expect("catalog"));
    let dir = std::env::var_os("HERB_BENCH_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/onnx-bench")
        });
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "onnx"))
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    if files.is_empty() {
        eprintln!(
            "no ONNX networks in {}: run `python3 training/make_fixtures.py --bench {}` (pip install onnx numpy)",
            dir.display(),
            dir.display()
        );
    }
    // The shipped policies (`models/policy-*.onnx`) always, then the sized networks.
    let models = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let shipped = herb_decide::Shipped::ALL.map(|s| models.join(s.file_name()));
    for f in shipped.into_iter().chain(files) {
        let name = f
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("model")
            .to_owned();
        // Either contract: the observation one (OnnxPolicy) or the candidate one.
        let p = match herb_decide::load_policy(&herb_decide::PolicySpec::Onnx(f.clone()), &catalog)
        {
            Ok(p) => p,
            Err(e) => {
                eprintln!("skipping {}: {e}", f.display());
                continue;
            }
        };
        let fma = OnnxPolicy::load(&f)
            .map(|o| o.fma())
            .or_else(|_| CandidatePolicy::load(&f, &catalog).map(|c| c.fma()))
            .unwrap_or(-1);
        let bytes = std::fs::metadata(&f).map(|m| m.len()).unwrap_or(0);
        let extra = format!(
            "; {:.1} MFLOP, {:.2} MB ONNX",
            2.0 * fma as f64 / 1e6,
            bytes as f64 / 1e6
        );
        bench_policy(c, &name, p, &catalog, &extra);
    }
    bench_policy(
        c,
        "blbf",
        Box::new(Blbf::new()),
        &catalog,
        "; PackIt SO(2) heuristic",
    );
    bench_policy(
        c,
        "null",
        Box::new(NullPolicy),
        &catalog,
        "; no network: heightmap check and copy, observation, input checks, z estimate",
    );
}

criterion_group! {
    name = decision;
    config = Criterion::default().sample_size(30).measurement_time(Duration::from_secs(6));
    targets = benches
}
criterion_main!(decision);
