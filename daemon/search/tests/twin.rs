//! The search's twin: a box known only by its heightmap ([`PackingWorld::twin`]), and the
//! search over it ([`herb_search`]).

// The simulation tests' helpers (catalogs, fixture piles), shared by path.
#[path = "../../../sim/tests/common/mod.rs"]
mod common;

use herb_search::{Budget, Search, SearchSettings, TwinKind};
use herb_sim::env::RewardMode;
use herb_sim::lattice::Lattice;
use herb_sim::{Heightmap, PackingWorld, SharedCatalog, WorldConfig};

const IDS: [&str; 6] = ["003", "005", "013", "007", "011", "004"];

/// FIXTURE: a world with six objects at fixed, scattered positions (`common::pile`).
fn exact(c: &SharedCatalog) -> PackingWorld {
    common::pile(c, &IDS)
}

#[test]
fn a_twin_starts_from_the_heightmap_and_objects_land_on_its_pile_as_on_the_real_one() {
    let c = common::primitives();
    let mut real = exact(&c);
    let mut twin = PackingWorld::twin(c.clone(), WorldConfig::default(), real.heightmap()).unwrap();
    assert_eq!(
        twin.heightmap(),
        real.heightmap(),
        "the twin starts from its heightmap"
    );
    assert!(twin.placed().is_empty(), "the pile is not objects");
    // The pile counts in C, by the volume under the heightmap: at least the objects' own
    // volume (it includes the voids the camera cannot see under them).
    let (cr, ct) = (real.compactness(), twin.compactness());
    assert!(cr > 0.0 && ct >= cr, "C real {cr} twin {ct}");
    // The next object, released where the lattice BLBF rule puts it, settles at about the same
    // height in both, and both say whether it ended inside alike.
    let ty = c.by_id("006").unwrap();
    let mut lattice = Lattice::new(&c);
    lattice.compute(real.heightmap(), &c, ty);
    let p = lattice.blbf().expect("a feasible placement");
    real.place(ty, p.x, p.y, p.theta()).unwrap();
    let ot = twin.place(ty, p.x, p.y, p.theta()).unwrap();
    // The twin checks its own objects only: compare the new object's own verdict.
    let new_inside = |w: &mut PackingWorld| w.report().last().unwrap().violation.is_none();
    assert_eq!(new_inside(&mut real), new_inside(&mut twin));
    assert_eq!(ot.inside, new_inside(&mut twin));
    let top = |w: &PackingWorld| w.heightmap().max();
    assert!(
        (top(&real) - top(&twin)).abs() < 0.01,
        "top real {} twin {}",
        top(&real),
        top(&twin)
    );
}

#[test]
fn a_twin_refuses_a_heightmap_of_another_grid_or_with_bad_cells() {
    let c = common::primitives();
    let spec = herb_sim::GridSpec::for_box(0.005).unwrap();
    let other = Heightmap::new(spec);
    let e = PackingWorld::twin(c.clone(), WorldConfig::default(), &other).unwrap_err();
    assert!(e.to_string().contains("twin:"), "{e}");
    let mut bad = exact(&c).heightmap().clone();
    bad.data_mut()[7] = f32::NAN;
    let e = PackingWorld::twin(c, WorldConfig::default(), &bad).unwrap_err();
    assert!(e.to_string().contains("finite"), "{e}");
}

#[test]
fn the_search_is_anytime_and_never_worse_than_its_prior_on_its_own_rollouts() {
    let c = common::primitives();
    let world = exact(&c);
    let remaining: Vec<_> = ["006", "010", "003"].map(|i| c.by_id(i).unwrap()).to_vec();
    let settings = |budget| SearchSettings {
        k: 4,
        budget,
        horizon: None,
        reward: RewardMode::cs(0.6).unwrap(),
        twin: TwinKind::Heightmap,
        robust: None,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let mut s = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(Budget::Rollouts(4)),
    );
    let p = s
        .decide(world.heightmap(), &remaining, None)
        .unwrap()
        .unwrap();
    let r = s.report().clone();
    assert_eq!(r.finished.len(), 4.min(r.candidates));
    let chosen = r.chosen.unwrap();
    let best = r
        .finished
        .iter()
        .map(|(_, o)| o.ret)
        .fold(f32::MIN, f32::max);
    let (_, o) = r.finished.iter().find(|(i, _)| *i == chosen).unwrap();
    assert_eq!(o.ret, best, "the best finished return is chosen");
    assert_eq!(o.placement, p);
    // Deterministic with a count of rollouts, on one thread or two: the same outcomes of the
    // same candidates, the same choice.
    let mut again = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(Budget::Rollouts(4)),
    );
    assert_eq!(
        again.decide(world.heightmap(), &remaining, None).unwrap(),
        Some(p)
    );
    let mut two = Search::new(
        c.clone(),
        WorldConfig::default(),
        SearchSettings {
            threads: 2,
            ..settings(Budget::Rollouts(4))
        },
    );
    assert_eq!(
        two.decide(world.heightmap(), &remaining, None).unwrap(),
        Some(p)
    );
    assert_eq!(two.report().finished, r.finished);
    assert_eq!((two.report().chosen, two.report().threads), (r.chosen, 2));
    // On two threads with a deadline, the candidates kept run from the first without a gap,
    // so that a replay's count of rollouts decides alike.
    let mut timed = Search::new(
        c.clone(),
        WorldConfig::default(),
        SearchSettings {
            threads: 2,
            ..settings(Budget::Time(std::time::Duration::from_millis(30)))
        },
    );
    let q = timed.decide(world.heightmap(), &remaining, None).unwrap();
    let kept: Vec<usize> = timed.report().finished.iter().map(|(i, _)| *i).collect();
    assert_eq!(kept, (0..kept.len()).collect::<Vec<_>>());
    let mut replay = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(Budget::Rollouts(kept.len())),
    );
    assert_eq!(
        replay.decide(world.heightmap(), &remaining, None).unwrap(),
        q
    );
    // A budget of zero rollouts returns the prior's first (lattice BLBF's), said so.
    let mut none = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(Budget::Rollouts(0)),
    );
    let first = none.decide(world.heightmap(), &remaining, None).unwrap();
    let mut lattice = Lattice::new(&c);
    lattice.compute(world.heightmap(), &c, remaining[0]);
    assert_eq!(first, lattice.blbf());
    assert!(none.report().finished.is_empty());
    assert_eq!(none.report().chosen, Some(0));
    // A deadline already passed: no rollout finishes, the prior's first again.
    let mut late = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(Budget::Time(Default::default())),
    );
    assert_eq!(
        late.decide(world.heightmap(), &remaining, None).unwrap(),
        lattice.blbf()
    );
    assert!(late.report().finished.is_empty());
}

#[test]
fn a_frozen_world_keeps_its_objects_where_they_are_when_another_settles_among_them() {
    let c = common::primitives();
    let mut w = exact(&c);
    w.freeze_placed();
    let poses = |w: &PackingWorld| -> Vec<_> {
        w.placed()
            .iter()
            .map(|p| *w.physics().bodies[p.body].position())
            .collect()
    };
    assert!(
        w.placed()
            .iter()
            .all(|p| w.physics().bodies[p.body].is_fixed()),
        "every object placed before is fixed"
    );
    let before = poses(&w);
    // The next object released where BLBF puts it settles; the frozen objects do not move.
    let ty = c.by_id("006").unwrap();
    let mut lattice = Lattice::new(&c);
    lattice.compute(w.heightmap(), &c, ty);
    let p = lattice.blbf().expect("a feasible placement");
    let o = w.place(ty, p.x, p.y, p.theta()).unwrap();
    assert!(o.settled, "the new object settles");
    let after = poses(&w);
    assert_eq!(
        before[..],
        after[..before.len()],
        "the frozen objects did not move"
    );
    assert!(w.physics().bodies[w.placed()[before.len()].body].is_dynamic());
}

/// Packs `ids` in an environment with release noise `(mm, deg)`, deciding with the search in
/// its `twin` (3 candidates, 3 rollouts): each decision's placement and report.
fn pack_with(
    c: &SharedCatalog,
    ids: &[&str],
    twin: TwinKind,
    noise: (f32, f32),
) -> Vec<(herb_sim::lattice::Placement, herb_search::SearchReport)> {
    let cfg = WorldConfig {
        release_noise_m: noise.0 * 1e-3,
        release_noise_deg: noise.1,
        ..WorldConfig::default()
    };
    let mut env = herb_sim::PackingEnv::new(c.clone(), cfg, RewardMode::Simple).unwrap();
    env.reset_ids(ids, 1).unwrap();
    let settings = SearchSettings {
        k: 3,
        budget: Budget::Rollouts(3),
        horizon: Some(3),
        reward: RewardMode::cs(0.6).unwrap(),
        twin,
        robust: None,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
    let mut out = Vec::new();
    while env.next_object().is_some() {
        let exact = (twin == TwinKind::ExactClone).then(|| env.world());
        let Some(p) = s
            .decide(env.world().heightmap(), env.remaining(), exact)
            .unwrap()
        else {
            break;
        };
        out.push((p, s.report().clone()));
        let d = herb_sim::eval::release_at(&mut env, Some(p)).unwrap();
        if herb_sim::eval::apply(&mut env, d).unwrap().terminated {
            break;
        }
    }
    out
}

#[test]
fn the_jobs_twin_replays_its_decisions_and_falls_back_where_the_heightmap_disagrees() {
    let c = common::primitives();
    let ids = ["003", "005", "013", "007", "011", "004"];
    // Without release noise the world is the job twin's model: it replays the world exactly
    // (no cell differs) and the search decides as in the exact clone.
    let job = pack_with(&c, &ids, TwinKind::Job, (0.0, 0.0));
    let clone = pack_with(&c, &ids, TwinKind::ExactClone, (0.0, 0.0));
    assert!(job.len() >= 4, "{} decisions", job.len());
    for (i, ((pj, rj), (pe, _))) in job.iter().zip(&clone).enumerate() {
        let a = rj.job.expect("the job's twin compared");
        assert_eq!(a.objects, i, "one object replayed a decision");
        assert!(a.used && a.mean_diff_m == 0.0 && a.off == 0.0, "{i}: {a:?}");
        assert_eq!(pj, pe, "{i}: the exact clone's choice");
    }
    // With noise it is fitted, not exact, and still used while it agrees.
    let noisy = pack_with(&c, &ids, TwinKind::Job, (5.0, 3.0));
    let last = noisy.last().unwrap().1.job.unwrap();
    assert!(last.objects > 0 && last.mean_diff_m > 0.0, "{last:?}");
    // A box it did not fill (a restart, a box filled by hand): the heightmap disagrees, so the
    // rollouts run in the heightmap twin, and the decision is the heightmap twin's.
    let world = exact(&c);
    let remaining: Vec<_> = ["006", "010"].map(|i| c.by_id(i).unwrap()).to_vec();
    let settings = |twin| SearchSettings {
        k: 3,
        budget: Budget::Rollouts(3),
        horizon: None,
        reward: RewardMode::cs(0.6).unwrap(),
        twin,
        robust: None,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let mut s = Search::new(c.clone(), WorldConfig::default(), settings(TwinKind::Job));
    let p = s.decide(world.heightmap(), &remaining, None).unwrap();
    let a = s.report().job.unwrap();
    assert!(!a.used && a.objects == 0 && a.off > 0.0, "{a:?}");
    assert!(s.job_twin().is_none());
    let mut h = Search::new(
        c.clone(),
        WorldConfig::default(),
        settings(TwinKind::Heightmap),
    );
    assert_eq!(p, h.decide(world.heightmap(), &remaining, None).unwrap());
    // Names.
    for (name, kind) in TwinKind::ALL {
        assert_eq!(TwinKind::parse(name).unwrap(), kind);
        assert_eq!(kind.name(), name);
    }
    assert_eq!(TwinKind::parse("twin").unwrap(), TwinKind::Heightmap);
    let e = TwinKind::parse("clone").unwrap_err().to_string();
    assert!(e.contains("heightmap, exact or job"), "{e}");
}

#[test]
fn the_jobs_twin_leaves_out_an_object_never_released_and_forgets_a_finished_job() {
    let c = common::primitives();
    let ids: Vec<_> = ["003", "005", "013"].map(|i| c.by_id(i).unwrap()).to_vec();
    let settings = SearchSettings {
        k: 2,
        budget: Budget::Rollouts(2),
        horizon: Some(2),
        reward: RewardMode::cs(0.6).unwrap(),
        twin: TwinKind::Job,
        robust: None,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let empty = PackingWorld::new(c.clone(), WorldConfig::default()).unwrap();
    let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
    let first = s.decide(empty.heightmap(), &ids, None).unwrap().unwrap();
    // The first object was skipped (a missed grasp): the box is still empty when the job goes
    // on with the second. The twin leaves it out and still agrees with the camera.
    s.decide(empty.heightmap(), &ids[1..], None).unwrap();
    let a = s.report().job.unwrap();
    assert!(a.objects == 0 && a.used && a.off == 0.0, "{a:?}");
    // Released this time: the next decision replays it.
    let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
    s.decide(empty.heightmap(), &ids, None).unwrap();
    let mut world = empty.clone();
    world
        .place(ids[0], first.x, first.y, first.theta())
        .unwrap();
    let mut replayed = s.clone();
    replayed.decide(world.heightmap(), &ids[1..], None).unwrap();
    let a = replayed.report().job.unwrap();
    assert!(a.objects == 1 && a.used, "{a:?}");
    // A new job whose objects happen to be the last job's remaining ones starts from an empty
    // box: the object in the box is not one of its decisions.
    s.new_job();
    s.decide(world.heightmap(), &ids[1..], None).unwrap();
    let a = s.report().job.unwrap();
    assert!(a.objects == 0 && a.off > 0.0, "{a:?}");
}

#[test]
fn the_robust_search_ranks_by_noisy_rollouts_that_a_replay_draws_again() {
    use herb_search::RobustRollouts;
    use herb_sim::world::ReleaseNoise;
    let c = common::primitives();
    let world = exact(&c);
    let remaining: Vec<_> = ["006", "010", "003"].map(|i| c.by_id(i).unwrap()).to_vec();
    let run = |robust: Option<RobustRollouts>| {
        let settings = SearchSettings {
            k: 3,
            budget: Budget::Rollouts(3),
            horizon: None,
            reward: RewardMode::cs(0.6).unwrap(),
            twin: TwinKind::Heightmap,
            robust,
            rigid_pile: true,
            threads: 1,
            push_gap: 0,
            wall_gap: 0,
            release_check: None,
            min_support: None,
            median: false,
        };
        let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
        let p = s.decide(world.heightmap(), &remaining, None).unwrap();
        (p, s.report().clone())
    };
    let search = |noise| run(Some(RobustRollouts { noise, samples: 3 }));
    let plain = run(None);
    // No noise: the plain search.
    let (p, r) = search(ReleaseNoise::default());
    assert_eq!((p, &r.finished), (plain.0, &plain.1.finished));
    // With noise: other returns (the releases moved), the same ones when run again.
    let noise = ReleaseNoise {
        sigma_m: 0.005,
        sigma_deg: 3.0,
        ..ReleaseNoise::default()
    };
    let (p, r) = search(noise);
    assert_eq!(r.finished.len(), 3, "{r:?}");
    let rets = |r: &herb_search::SearchReport| -> Vec<f32> {
        r.finished.iter().map(|(_, o)| o.ret).collect()
    };
    assert_ne!(rets(&r), rets(&plain.1), "the noisy rollouts moved");
    let (again, r2) = search(noise);
    assert_eq!((p, rets(&r)), (again, rets(&r2)), "drawn again alike");
}

#[test]
fn the_candidates_come_from_the_jobs_twin_where_the_camera_agrees_and_from_the_camera_elsewhere() {
    let c = common::primitives();
    let ids: Vec<_> = ["003", "005", "013", "007"]
        .map(|i| c.by_id(i).unwrap())
        .to_vec();
    let settings = SearchSettings {
        k: 3,
        budget: Budget::Rollouts(3),
        horizon: Some(2),
        reward: RewardMode::cs(0.6).unwrap(),
        twin: TwinKind::Job,
        robust: None,
        rigid_pile: true,
        threads: 1,
        push_gap: 0,
        wall_gap: 0,
        release_check: None,
        min_support: None,
        median: false,
    };
    let mut world = PackingWorld::new(c.clone(), WorldConfig::default()).unwrap();
    let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
    let first = s.decide(world.heightmap(), &ids, None).unwrap().unwrap();
    world
        .place(ids[0], first.x, first.y, first.theta())
        .unwrap();
    let decide = |seen: &Heightmap| {
        let mut s = s.clone();
        let p = s.decide(seen, &ids[1..], None).unwrap().unwrap();
        (p, s.report().job.unwrap())
    };
    let (clean, a) = decide(world.heightmap());
    assert!(a.used && a.off == 0.0, "{a:?}");
    // A camera's noise (up to 3 mm, a fixed pattern) on every cell: the twin agrees, so the
    // candidates and the decision are the clean heightmap's.
    let mut noisy = world.heightmap().clone();
    for (i, v) in noisy.data_mut().iter_mut().enumerate() {
        *v += 0.003 * (((i * 7919) % 13) as f32 / 6.0 - 1.0);
    }
    let (p, a) = decide(&noisy);
    assert!(a.used && a.mean_diff_m > 0.0, "{a:?}");
    assert_eq!(
        p, clean,
        "camera noise within 1 cm does not move the decision"
    );
    // Something the twin does not know (5 cm high) where the clean decision would go: the
    // camera's cells count there, and the decision goes elsewhere.
    let mut foreign = world.heightmap().clone();
    let spec = *foreign.spec();
    for row in 0..spec.ny {
        for col in 0..spec.nx {
            let (x, y) = spec.cell_centre(col, row);
            if (x - clean.x).abs() < 0.03 && (y - clean.y).abs() < 0.03 {
                foreign.data_mut()[row * spec.nx + col] += 0.05;
            }
        }
    }
    let (p, a) = decide(&foreign);
    assert!(a.used && a.off > 0.0, "{a:?}");
    assert_ne!(p, clean, "the unknown object is seen");
}

/// A world of `ids` placed in turn by lattice BLBF, every one inside.
fn packed(c: &SharedCatalog, ids: &[&str]) -> PackingWorld {
    let mut w = common::world(c);
    let mut lattice = Lattice::new(c);
    for id in ids {
        let ty = c.by_id(id).unwrap();
        lattice.compute(w.heightmap(), c, ty);
        let p = lattice.blbf().expect("a feasible placement");
        assert!(
            w.place(ty, p.x, p.y, p.theta()).unwrap().inside,
            "{id} inside"
        );
    }
    w
}

#[test]
fn the_release_check_passes_over_a_candidate_that_a_release_off_its_placement_leaves_outside() {
    use herb_search::ReleaseCheck;
    let c = common::primitives();
    let world = packed(&c, &["003", "005", "013", "007", "011", "004", "010"]);
    let remaining: Vec<_> = ["006"].map(|i| c.by_id(i).unwrap()).to_vec();
    let run = |check: Option<ReleaseCheck>| {
        let settings = SearchSettings {
            k: 6,
            budget: Budget::Rollouts(6),
            horizon: None,
            reward: RewardMode::cs(0.6).unwrap(),
            twin: TwinKind::ExactClone,
            robust: None,
            rigid_pile: true,
            threads: 1,
            push_gap: 0,
            wall_gap: 0,
            release_check: check,
            min_support: None,
            median: false,
        };
        let mut s = Search::new(c.clone(), WorldConfig::default(), settings);
        let p = s
            .decide(world.heightmap(), &remaining, Some(&world))
            .unwrap();
        (p.unwrap(), s.report().clone())
    };
    let plain = run(None);
    assert_eq!(ReleaseCheck::assumed(0.0, 0.0), None, "no error, no check");
    let check = ReleaseCheck::assumed(5.0, 3.0).unwrap();
    // Each of the four releases of `p` off its placement, on a clone of the world: inside?
    let releases = |p: herb_sim::lattice::Placement| -> Vec<bool> {
        let rot = rapier3d::math::Rotation::from_rotation_z(p.theta());
        check
            .offsets()
            .iter()
            .map(|&[dx, dy, dyaw]| {
                let mut w = world.clone();
                let pose = w.checked_release_pose(remaining[0], p.x, p.y, rot).unwrap();
                let pose = herb_sim::world::offset_pose(pose, dx, dy, dyaw);
                w.place_pose(remaining[0], pose).unwrap().inside
            })
            .collect()
    };
    let (p, r) = run(Some(check));
    // FIXTURE-specific: on this pile one of the plain choice's four releases ends outside
    // (a release 5 mm / 3 deg off lands it over a wall), and the check passes it over for a
    // candidate whose four stay inside.
    assert!(
        releases(plain.0).contains(&false),
        "{:?}",
        releases(plain.0)
    );
    assert_ne!(p, plain.0, "passed over");
    assert!(
        r.release_rejected >= 1 && r.release_checked > r.release_rejected,
        "{r:?}"
    );
    assert_eq!(releases(p), vec![true; 4]);
    let again = run(Some(check));
    assert_eq!(
        (again.0, again.1.chosen, again.1.release_rejected),
        (p, r.chosen, r.release_rejected),
        "a replay checks alike"
    );
}

#[test]
fn the_median_filter_keeps_a_camera_outlier_from_moving_the_candidates() {
    let c = common::primitives();
    let clean = PackingWorld::new(c.clone(), WorldConfig::default())
        .unwrap()
        .heightmap()
        .clone();
    let remaining = [c.by_id("005").unwrap()];
    let decide = |hm: &Heightmap, median: bool| {
        let settings = SearchSettings {
            k: 1,
            budget: Budget::Rollouts(1),
            twin: TwinKind::Heightmap,
            median,
            ..SearchSettings::default()
        };
        Search::new(c.clone(), WorldConfig::default(), settings)
            .decide(hm, &remaining, None)
            .unwrap()
            .expect("an empty box has room")
    };
    // The empty box's first choice, and the same box seen with one cell 4 mm high under it
    // (a depth camera's outlier).
    let p = decide(&clean, false);
    let mut seen = clean.clone();
    let spec = *seen.spec();
    let (u, v) = spec.to_pixel(p.x, p.y);
    seen.data_mut()[v as usize * spec.nx + u as usize] = 0.004;
    assert_ne!(
        decide(&seen, false),
        p,
        "the outlier moves the unfiltered choice"
    );
    assert_eq!(decide(&seen, true), p, "the filtered choice stays");
    assert_eq!(
        decide(&clean, true),
        p,
        "an exact empty box is its own median"
    );
}
