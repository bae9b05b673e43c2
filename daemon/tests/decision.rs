//! The decision worker's core (`DecisionCore`, what herbd's decision thread and the replay run)
//! on bad and edge inputs: a budget of zero, a method that panics, heightmaps that are not the
//! box's or not finite, and a search replayed from the count of rollouts its budget allowed.

use herb_core::observation::ObsLayout;
use herb_core::paths::MeshSource;
use herb_core::{Catalog, GridSpec, Heightmap, TypeIdx};
use herb_daemon::config::{Config, DecisionMethod};
use herb_daemon::decision::DecisionCore;
use herb_daemon::plan::{DecisionRequest, NOT_A_SEARCH};
use herb_decide::{DecisionInput, PlanarPose, Policy};
use herb_ipc::{Fault, HeightmapFrame, MAX_JOB_OBJECTS};
use std::path::Path;
use std::sync::Arc;

fn catalog() -> Arc<Catalog> {
    Arc::new(Catalog::builtin(&MeshSource::None("fixture".into())).unwrap())
}

fn config(method: DecisionMethod, budget_s: f64) -> Config {
    let mut cfg = Config::default();
    cfg.models.sequence = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/sequence.json");
    cfg.decision.method = method;
    cfg.decision.budget_s = budget_s;
    cfg.decision.k = 3;
    cfg
}

/// The box's heightmap with a block of `h` m in one corner, as the camera publishes it.
fn frame(h: f32) -> Box<HeightmapFrame> {
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let mut f = Box::new(HeightmapFrame {
        header: herb_ipc::Header::at(1, 2),
        nx: spec.nx as u32,
        ny: spec.ny as u32,
        cell_m: ObsLayout::CELL_M,
        objects: 0,
        data: [0.0; herb_ipc::HEIGHTMAP_MAX_CELLS],
    });
    for row in 0..spec.ny / 2 {
        for col in 0..spec.nx / 3 {
            f.data[row * spec.nx + col] = h;
        }
    }
    f
}

/// Object `objects[0]` of a job of `objects`.
fn request(objects: &[u16]) -> DecisionRequest {
    let mut order = [0u16; MAX_JOB_OBJECTS];
    order[..objects.len()].copy_from_slice(objects);
    DecisionRequest {
        job_id: 3,
        index: 0,
        order,
        count: objects.len() as u32,
        after_stamp_ns: 0,
    }
}

#[test]
fn a_search_with_no_budget_takes_the_priors_first_and_says_so() {
    let c = catalog();
    let mut core = DecisionCore::new(&config(DecisionMethod::Search, 0.0), c.clone()).unwrap();
    let f = frame(0.04);
    let d = core.decide(&request(&[5, 9, 11]), &f, None);
    assert_eq!(d.allowed, 0, "no rollout finished");
    let pose = d.outcome.expect("a placement");
    // The prior: lattice BLBF's first candidate on this heightmap.
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let hm = Heightmap::from_data(spec, f.cells().to_vec()).unwrap();
    // The search's own lattice, with its clearances.
    let mut lattice = core.search_settings().unwrap().lattice(&c);
    lattice.compute(&hm, &c, TypeIdx(5));
    let first = lattice.candidates()[0];
    assert!((pose[0] - first.x).abs() < 1e-5 && (pose[1] - first.y).abs() < 1e-5);
    let report = core.search_report().unwrap();
    assert!(report.finished.is_empty() && report.chosen == Some(0));
}

#[test]
fn a_search_replays_from_the_count_its_budget_allowed() {
    let c = catalog();
    let mut live = DecisionCore::new(&config(DecisionMethod::Search, 0.5), c.clone()).unwrap();
    let f = frame(0.04);
    let req = request(&[5, 9, 11, 2]);
    let d = live.decide(&req, &f, None);
    assert!(d.allowed != NOT_A_SEARCH && d.allowed > 0, "{d:?}");
    // Another core (a replay) given what the budget allowed makes the same decision.
    let mut replay = DecisionCore::new(&config(DecisionMethod::Search, 0.5), c).unwrap();
    let again = replay.decide(&req, &f, Some(d.allowed));
    assert_eq!(again.digest(), d.digest(), "{d:?} vs {again:?}");
}

/// A policy that panics (a fixture standing for a broken method).
struct Panics;

impl Policy for Panics {
    fn name(&self) -> &str {
        "panics (fixture)"
    }
    fn begin_episode(&mut self, _seed: u64) {}
    fn decide(&mut self, _input: &DecisionInput) -> herb_decide::Result<PlanarPose> {
        panic!("a broken decision method")
    }
    fn needs_observation(&self) -> bool {
        false
    }
}

#[test]
fn a_method_that_panics_answers_a_decision_fault_and_the_worker_goes_on() {
    let cfg = config(DecisionMethod::Policy, 1.0);
    let mut core = DecisionCore::with_policy(&cfg, catalog(), Box::new(Panics));
    let req = request(&[5]);
    core.observe(&frame(0.0)).expect("a good frame");
    for _ in 0..2 {
        let d = core.decide_guarded(&req, None);
        assert_eq!(d.outcome, Err(Fault::Decision));
        assert_eq!((d.job_id, d.index), (3, 0));
    }
}

#[test]
fn heightmaps_not_of_the_box_or_not_finite_are_refused_by_both_methods() {
    let c = catalog();
    for method in [DecisionMethod::Policy, DecisionMethod::Search] {
        let mut core = DecisionCore::new(&config(method, 0.1), c.clone()).unwrap();
        let mut nan = frame(0.02);
        nan.data[7] = f32::NAN;
        let mut high = frame(0.02);
        high.data[9] = 5.0;
        let mut grid = frame(0.02);
        grid.nx = 100;
        for (what, f) in [("NaN", nan), ("out of range", high), ("another grid", grid)] {
            let d = core.decide(&request(&[5, 6]), &f, None);
            assert_eq!(d.outcome, Err(Fault::Decision), "{method:?}, {what}");
        }
        // A good frame afterwards is decided as usual.
        let d = core.decide(&request(&[5, 6]), &frame(0.02), None);
        assert!(d.outcome.is_ok(), "{method:?}: {d:?}");
    }
}

#[test]
fn a_job_with_no_object_left_has_no_placement() {
    let mut core = DecisionCore::new(&config(DecisionMethod::Search, 0.1), catalog()).unwrap();
    let mut req = request(&[5]);
    req.index = 1;
    let d = core.decide(&req, &frame(0.0), None);
    assert_eq!(d.outcome, Err(Fault::NoFeasiblePlacement));
}

#[test]
fn a_job_whose_rest_cannot_fit_the_twin_still_gets_a_feasible_placement() {
    // Twenty cracker boxes (about 1.3 l each) after the first: the box holds a few. The
    // rollouts end in failures, the search still ranks them and places the first object.
    let c = catalog();
    let mut core = DecisionCore::new(&config(DecisionMethod::Search, 5.0), c.clone()).unwrap();
    let cracker = c.by_id("003").unwrap().0;
    let job = vec![cracker; 21];
    let d = core.decide(&request(&job), &frame(0.0), Some(3));
    assert_eq!(d.allowed, 3);
    let pose = d.outcome.expect("a placement");
    assert!(pose.iter().all(|v| v.is_finite()));
    let report = core.search_report().unwrap();
    assert!(
        report.finished.iter().all(|(_, o)| !o.success),
        "no rollout fits them all"
    );
}

#[test]
fn the_jobs_twin_follows_the_job_and_falls_back_on_a_box_it_did_not_fill() {
    let c = catalog();
    let mut cfg = config(DecisionMethod::Search, 0.0);
    cfg.decision.twin = herb_daemon::config::DecisionTwin::Job;
    let mut core = DecisionCore::new(&cfg, c.clone()).unwrap();
    // An empty box: the job's twin (no object yet) agrees with it.
    let d = core.decide(&request(&[5, 9, 11]), &frame(0.0), None);
    assert!(d.outcome.is_ok(), "{d:?}");
    let j = core
        .search_report()
        .unwrap()
        .job
        .expect("the job's twin compared");
    assert!(j.used && j.objects == 0, "{j:?}");
    // The next decision of the job, on a box whose half holds a block the job never placed:
    // neither its one object (replayed or left out) explains it, so the rollouts run in the
    // heightmap twin.
    let mut next = request(&[5, 9, 11]);
    next.index = 1;
    let mut half = frame(0.0);
    let n = (half.nx * half.ny) as usize;
    half.data[..n / 2].fill(0.04);
    let d = core.decide(&next, &half, None);
    assert!(d.outcome.is_ok(), "{d:?}");
    let j = core.search_report().unwrap().job.unwrap();
    assert!(j.objects <= 1 && !j.used && j.off > 0.2, "{j:?}");
}

#[test]
fn a_new_job_starts_the_jobs_twin_from_an_empty_box() {
    let c = catalog();
    let mut cfg = config(DecisionMethod::Search, 0.0);
    cfg.decision.twin = herb_daemon::config::DecisionTwin::Job;
    let mut core = DecisionCore::new(&cfg, c.clone()).unwrap();
    let [x, y, _, theta] = core
        .decide(&request(&[5, 9, 11]), &frame(0.0), None)
        .outcome
        .expect("a placement");
    // The camera then sees the object where it was decided.
    let mut world =
        herb_sim::PackingWorld::new(c.clone(), herb_sim::WorldConfig::default()).unwrap();
    world.place(TypeIdx(5), x, y, theta).unwrap();
    let mut seen = frame(0.0);
    seen.data[..world.heightmap().data().len()].copy_from_slice(world.heightmap().data());
    // The same job goes on: its twin replays the object.
    let mut same = core_after_first(&cfg, &c, &[5, 9, 11]);
    let mut next = request(&[5, 9, 11]);
    next.index = 1;
    same.decide(&next, &seen, None);
    let j = same.search_report().unwrap().job.unwrap();
    assert_eq!(j.objects, 1, "{j:?}");
    // Another job whose objects are the last job's remaining ones: not a continuation.
    let mut other = request(&[9, 11]);
    other.job_id = 4;
    core.decide(&other, &seen, None);
    let j = core.search_report().unwrap().job.unwrap();
    assert!(j.objects == 0 && j.off > 0.0, "{j:?}");
}

/// A decision core of `cfg` that has decided the first object of `objects` on an empty box.
fn core_after_first(cfg: &Config, c: &Arc<Catalog>, objects: &[u16]) -> DecisionCore {
    let mut core = DecisionCore::new(cfg, c.clone()).unwrap();
    core.decide(&request(objects), &frame(0.0), None);
    core
}

/// One release pose: the job's twin replays each release where the arm releases it, at the
/// configured clearance. With `[models] clearance_m` changed, the decided z (the arm's) and the
/// twin's replayed release both move by the change, and stay equal.
#[test]
fn the_jobs_twin_replays_the_release_at_the_configured_clearance() {
    let c = catalog();
    let mut zs = Vec::new();
    for clearance in [0.01, 0.03] {
        let mut cfg = config(DecisionMethod::Search, 0.0);
        cfg.decision.twin = herb_daemon::config::DecisionTwin::Job;
        cfg.models.clearance_m = clearance;
        let mut core = DecisionCore::new(&cfg, c.clone()).unwrap();
        let pose = core
            .decide(&request(&[5, 9, 11]), &frame(0.0), None)
            .outcome
            .expect("a placement");
        let replayed = core
            .search_report()
            .unwrap()
            .replayed_release
            .expect("the twin keeps the release");
        assert_eq!(replayed.translation.z, pose[2], "clearance {clearance}");
        assert_eq!(
            (replayed.translation.x, replayed.translation.y),
            (pose[0], pose[1])
        );
        zs.push(pose[2]);
    }
    assert!((zs[1] - zs[0] - 0.02).abs() < 1e-5, "{zs:?}");
}
