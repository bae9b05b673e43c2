//! herbd's decision with the search, timed as herbd times it (one `DecisionCore::decide` call:
//! the heightmap checked and copied, the twin built from it, the rollouts, the z estimate), for
//! a count of rollouts (what tables use) and for herbd's time budget on one thread; then, with
//! every lattice candidate allowed (k = 64, so that the budget and not k ends the decision),
//! herbd's time budget on one thread and on two, in one run: the rollouts finished per
//! decision and their ratio, for the plain search (which may run out of candidates before the
//! budget) and for robust searches of 4 and 16 samples per candidate (16: more work than one
//! thread finishes in the budget on any state).
//!
//! `cargo bench -p herb-daemon --bench search [-- TEXT]` (TEXT: only the cases whose label
//! holds it; BoxED needed: mid-pack heightmaps of the first
//! sessions, their humans' placements after a quarter, half and three quarters of the episode,
//! the object after decided with the rest of the episode to come). Prints p50, p95, p99 and
//! the maximum per budget. A bench binary rather than criterion: a decision takes up to a
//! second, and what matters is the tail over many states, not a mean over repeats of one.

use hdrhistogram::Histogram;
use herb_core::boxed::{list_sessions, load_session};
use herb_core::paths::{self, MeshSource};
use herb_core::{Catalog, SharedCatalog};
use herb_daemon::config::{Config, DecisionMethod};
use herb_daemon::decision::DecisionCore;
use herb_daemon::plan::DecisionRequest;
use herb_ipc::{HeightmapFrame, MAX_JOB_OBJECTS};
use herb_search::{PackingWorld, WorldConfig};
use std::sync::Arc;
use std::time::Instant;

/// One state's decision: rollouts finished, and whether the budget ended it.
type PerState = (usize, bool);

/// Sessions whose states are timed.
const SESSIONS: usize = 12;

fn main() {
    let Some(root) = paths::boxed_root(None).filter(|r| r.join("sessions").is_dir()) else {
        eprintln!("no BoxED data: nothing to time (set HERB_BOXED)");
        return;
    };
    let catalog: SharedCatalog =
        Arc::new(Catalog::builtin(&MeshSource::Folder(root.join("meshes"))).expect("catalog"));
    // The states: (heightmap frame, the rest of the episode from the object to place).
    let mut states = Vec::new();
    for name in list_sessions(&root)
        .expect("sessions")
        .iter()
        .take(SESSIONS)
    {
        let ep = load_session(&root, name, &catalog)
            .expect("session")
            .episode(&catalog);
        let n = ep.objects.len();
        for cut in [n / 4, n / 2, 3 * n / 4] {
            let mut w = PackingWorld::new(catalog.clone(), WorldConfig::default()).expect("world");
            let mut inside = true;
            for (t, h) in ep.objects[..cut].iter().zip(&ep.human) {
                inside &= w.place(*t, h.x, h.y, h.theta).expect("place").inside;
            }
            if !inside || cut + 1 >= n {
                continue;
            }
            let spec = *w.heightmap().spec();
            let mut f: Box<HeightmapFrame> = Box::new(HeightmapFrame {
                header: herb_ipc::Header::at(1, 1),
                nx: spec.nx as u32,
                ny: spec.ny as u32,
                cell_m: spec.cell,
                objects: cut as u32,
                data: [0.0; herb_ipc::HEIGHTMAP_MAX_CELLS],
            });
            f.data[..spec.len()].copy_from_slice(w.heightmap().data());
            let rest: Vec<u16> = ep.objects[cut..].iter().map(|t| t.0).collect();
            states.push((f, rest));
        }
    }
    let mut cfg = Config::default();
    cfg.models.sequence =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/sequence.json");
    cfg.decision.method = DecisionMethod::Search;
    eprintln!(
        "{} states from {SESSIONS} sessions (objects still to place: {}..{})",
        states.len(),
        states.iter().map(|s| s.1.len()).min().unwrap_or(0),
        states.iter().map(|s| s.1.len()).max().unwrap_or(0)
    );
    // The k = 64 cases' per-state results (rollouts finished, ended by the budget), one run per
    // thread count, by robust samples (0: plain).
    let mut per_thread: Vec<(usize, Vec<Vec<PerState>>)> = Vec::new();
    for (label, budget_s, allowed, k, threads, samples) in [
        ("8 rollouts of 8 candidates", 30.0, Some(8), 8, 1, 0),
        ("herbd's default budget, 1.0 s", 1.0, None, 8, 1, 0),
        ("16 rollouts of 16 candidates", 30.0, Some(16), 16, 1, 0),
        ("16 rollouts of 16 candidates", 30.0, Some(16), 16, 2, 0),
        ("1.0 s, k = 64", 1.0, None, 64, 1, 0),
        ("1.0 s, k = 64", 1.0, None, 64, 2, 0),
        ("robust, 4 samples, 1.0 s, k = 8", 1.0, None, 8, 1, 4),
        ("robust, 4 samples, 1.0 s, k = 64", 1.0, None, 64, 1, 4),
        ("robust, 4 samples, 1.0 s, k = 64", 1.0, None, 64, 2, 4),
        // Work that one thread cannot finish in the budget on any state: what two threads add
        // where there is work for them.
        ("robust, 16 samples, 1.0 s, k = 64", 1.0, None, 64, 1, 16),
        ("robust, 16 samples, 1.0 s, k = 64", 1.0, None, 64, 2, 16),
    ] {
        // `cargo bench -p herb-daemon --bench search -- TEXT`: only the cases whose label
        // holds TEXT.
        if let Some(only) = std::env::args().skip(1).find(|a| !a.starts_with('-'))
            && !label.contains(&only)
        {
            continue;
        }
        cfg.decision.budget_s = budget_s;
        cfg.decision.timeout_s = budget_s + 10.0;
        cfg.decision.k = k;
        cfg.decision.threads = threads;
        cfg.decision.samples = samples;
        let mut core = DecisionCore::new(&cfg, catalog.clone()).expect("decision core");
        let mut h = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).expect("histogram");
        let (mut rollouts, mut feasible, mut bound, mut cut) = (0u64, 0u64, 0u64, 0u64);
        // Per state: rollouts finished, and whether the budget ended the decision.
        let mut each = Vec::new();
        for (f, rest) in &states {
            let mut order = [0u16; MAX_JOB_OBJECTS];
            order[..rest.len()].copy_from_slice(rest);
            let req = DecisionRequest {
                job_id: 1,
                index: 0,
                order,
                count: rest.len() as u32,
                after_stamp_ns: 0,
            };
            let t0 = Instant::now();
            let d = core.decide(&req, f, allowed);
            h.record(t0.elapsed().as_nanos() as u64).ok();
            assert!(d.outcome.is_ok(), "{d:?}");
            rollouts += d.allowed as u64;
            if let Some(r) = core.search_report() {
                feasible += r.candidates.min(k) as u64;
                cut += r.cut as u64;
                // The budget, not the candidates, ended it.
                let ended = r.finished.len() < r.candidates.min(k);
                bound += ended as u64;
                each.push((r.finished.len(), ended));
            }
        }
        let ms = |q: f64| h.value_at_quantile(q) as f64 / 1e6;
        let per = rollouts as f64 / h.len().max(1) as f64;
        println!(
            "search, {label}, {threads} thread{}: n {} p50 {:.0} ms p95 {:.0} ms p99 {:.0} ms max {:.0} ms mean {:.0} ms; {per:.1} rollouts finished per decision of {:.1} candidates ({bound} decisions ended by the budget; {cut} rollouts cut or not counted)",
            if threads == 1 { "" } else { "s" },
            h.len(),
            ms(0.5),
            ms(0.95),
            ms(0.99),
            h.max() as f64 / 1e6,
            h.mean() / 1e6,
            feasible as f64 / h.len().max(1) as f64,
        );
        if k == 64 {
            match per_thread.iter_mut().find(|p| p.0 == samples) {
                Some(p) => p.1.push(each),
                None => per_thread.push((samples, vec![each])),
            }
        }
    }
    for (samples, runs) in &per_thread {
        let [one, two] = &runs[..] else { continue };
        let sum = |v: &[PerState]| v.iter().map(|e| e.0).sum::<usize>() as f64;
        // Where the budget ended the decision on both thread counts: what it bought, not
        // what the candidates allowed.
        let both: Vec<_> = one.iter().zip(two).filter(|(a, b)| a.1 && b.1).collect();
        let (a, b): (Vec<_>, Vec<_>) = both.iter().map(|(a, b)| (**a, **b)).unzip();
        println!(
            "search, 1.0 s, k = 64, {samples} samples: two threads finish {:.3} x the rollouts of one over every decision, {:.3} x over the {} the budget ended on both",
            sum(two) / sum(one).max(f64::MIN_POSITIVE),
            sum(&b) / sum(&a).max(f64::MIN_POSITIVE),
            both.len()
        );
    }
}
