//! The episode API: rewards, determinism, bad input.

mod common;

use herb_sim::env::{PackingEnv, RewardMode};
use herb_sim::world::PlacementOutcome;
use herb_sim::{ObsLayout, SimError, WorldConfig};

fn outcome(inside: bool, stable: bool, c: f32) -> PlacementOutcome {
    PlacementOutcome {
        inside,
        first_outside: None,
        violation: None,
        tilt_rad: 0.0,
        stable,
        compactness: c,
        z: 0.0,
        settle_steps: 0,
        settled: true,
    }
}

#[test]
fn reward_formulas_match_the_paper() {
    let cs06 = RewardMode::cs(0.6).unwrap();
    assert_eq!(RewardMode::Simple.reward(&outcome(true, false, 0.4)), 1.0);
    assert_eq!(RewardMode::Simple.reward(&outcome(false, true, 0.4)), -1.0);
    assert_eq!(
        RewardMode::Compactness.reward(&outcome(true, true, 0.4)),
        0.4
    );
    assert_eq!(
        RewardMode::Compactness.reward(&outcome(false, true, 0.4)),
        -1.0
    );
    assert!((cs06.reward(&outcome(true, true, 0.5)) - (0.6 * 0.5 + 0.4)).abs() < 1e-6);
    assert!((cs06.reward(&outcome(true, false, 0.5)) - 0.3).abs() < 1e-6);
    assert_eq!(cs06.reward(&outcome(false, true, 0.5)), -1.0);
    assert_eq!(
        RewardMode::parse("cs0.9").unwrap(),
        RewardMode::CompactnessStability { alpha: 0.9 }
    );
    assert_eq!(RewardMode::parse("C").unwrap(), RewardMode::Compactness);
    assert!(RewardMode::parse("cs1.5").is_err());
    assert!(RewardMode::parse("stability").is_err());
}

fn run(seed: u64) -> (Vec<u32>, Vec<f32>) {
    let c = common::primitives();
    let mut env = PackingEnv::new(c, WorldConfig::default(), RewardMode::cs(0.6).unwrap()).unwrap();
    env.reset_ids(&["003", "005", "013", "007", "011", "004", "057"], seed)
        .unwrap();
    let mut rewards = Vec::new();
    loop {
        let a = env.sample_action();
        let a = [a[0] * 0.5, a[1] * 0.5, a[2]];
        let r = env.step(a).unwrap();
        rewards.push(r.reward);
        if r.terminated {
            break;
        }
    }
    (env.world().state_bits(), rewards)
}

#[test]
fn same_inputs_and_seed_give_bit_identical_worlds() {
    let (a, ra) = run(7);
    let (b, rb) = run(7);
    assert!(a.len() > 100);
    assert_eq!(a, b, "world state bits differ between identical runs");
    assert_eq!(
        ra.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
        rb.iter().map(|r| r.to_bits()).collect::<Vec<_>>()
    );
    // A different seed gives different actions, so a different world.
    let (c, _) = run(8);
    assert_ne!(a, c);
}

#[test]
fn reset_after_an_episode_is_bit_identical_to_a_fresh_world() {
    let c = common::primitives();
    let mut env = PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
    env.reset_ids(&["003", "005"], 1).unwrap();
    env.step([0.3, 0.2, 0.1]).unwrap();
    env.reset_ids(&["004", "013"], 2).unwrap();
    env.step([-0.2, 0.1, 0.4]).unwrap();
    let reused = env.world().state_bits();
    let mut fresh = PackingEnv::new(c, WorldConfig::default(), RewardMode::Simple).unwrap();
    fresh.reset_ids(&["004", "013"], 2).unwrap();
    fresh.step([-0.2, 0.1, 0.4]).unwrap();
    assert_eq!(reused, fresh.world().state_bits());
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let c = common::primitives();
    let mut env = PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
    assert!(matches!(env.reset(&[], 0), Err(SimError::EmptySequence)));
    let e = env.reset_ids(&["003", "999"], 0).unwrap_err();
    assert!(e.to_string().contains("999"), "{e}");
    assert!(
        matches!(env.step([0.0; 3]), Err(SimError::EpisodeOver { .. })),
        "step before reset"
    );
    env.reset_ids(&["003", "004"], 0).unwrap();
    for bad in [
        [f32::NAN, 0.0, 0.0],
        [0.0, f32::INFINITY, 0.0],
        [0.0, 0.0, f32::NEG_INFINITY],
    ] {
        assert!(matches!(env.step(bad), Err(SimError::InvalidAction(_))));
    }
    // The rejected actions changed nothing: the episode goes on with the first object.
    assert!(env.world().placed().is_empty());
    let r = env.step([5.0, -5.0, 0.0]).unwrap(); // clamped to the corner
    assert_eq!(r.info.placement.0, herb_sim::frames::BOX_HALF_X);
    assert_eq!(r.observation.len(), ObsLayout::LEN);
    assert!(
        r.observation
            .iter()
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    );
    // Bad configs name the field.
    let e = PackingEnv::new(
        c.clone(),
        WorldConfig {
            dt: f32::NAN,
            ..Default::default()
        },
        RewardMode::Simple,
    )
    .unwrap_err();
    assert!(e.to_string().contains("'dt'"), "{e}");
    // World settings by name (`herb-sim eval --world-set`): each bad one named, and the
    // configuration left as it was.
    let mut cfg = WorldConfig::default();
    cfg.set_all("solver_iterations=4, dt=0.025").unwrap();
    assert_eq!((cfg.solver_iterations, cfg.dt), (4, 0.025));
    cfg.set_all(
        "rest_speed_mps=0.01,contact_recycle_m=0.001,out_past_walls=true,out_check_steps=1",
    )
    .unwrap();
    assert_eq!(
        (
            cfg.rest_speed_mps,
            cfg.contact_recycle_m,
            cfg.out_past_walls,
            cfg.out_check_steps
        ),
        (0.01, 0.001, true, 1)
    );
    for (bad, says) in [
        ("solver_iterations=0", "solver_iterations"),
        ("out_past_walls=maybe", "true or false"),
        ("out_check_steps=0", "out_check_steps"),
        ("rest_speed_mps=-1", "rest_speed_mps"),
        ("contact_recycle_m=1", "contact_recycle_m"),
        ("dt=fast", "not a number"),
        ("length_unit_m=2", "length_unit_m"),
        ("gravity=1", "unknown world setting"),
        ("dt", "KEY=VALUE"),
    ] {
        let e = cfg.set_all(bad).unwrap_err().to_string();
        assert!(e.contains(says), "{bad}: {e}");
    }
    assert_eq!((cfg.solver_iterations, cfg.dt), (4, 0.025));
    assert_eq!((cfg.out_past_walls, cfg.out_check_steps), (true, 1));
    assert!(RewardMode::cs(-0.1).is_err());
    // A bad catalog names what is wrong.
    let e = herb_sim::Catalog::from_toml(
        "format = 1\n[[object]]\nid = \"1\"\n",
        "test",
        &herb_sim::paths::MeshSource::None("t".into()),
    )
    .unwrap_err();
    assert!(e.to_string().contains("test"), "{e}");
    let e = herb_sim::Catalog::from_toml(
        "format = 2\nobject = []",
        "test",
        &herb_sim::paths::MeshSource::None("t".into()),
    )
    .unwrap_err();
    assert!(e.to_string().contains("format 2"), "{e}");
}

#[test]
fn a_mesh_that_does_not_parse_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("herb-bad-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("002_master_chef_can.obj"),
        "v 1 2\nv nonsense\nf 1 2 3\n",
    )
    .unwrap();
    let e = herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::Folder(dir.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("002_master_chef_can.obj"), "{e}");
    // A missing file is named too.
    std::fs::remove_file(dir.join("002_master_chef_can.obj")).unwrap();
    let e = herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::Folder(dir.clone()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("002_master_chef_can.obj") && e.contains("not found"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn observation_channels_hold_box_and_next_object() {
    let c = common::primitives();
    let mut env = PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
    let obs = env.reset_ids(&["003", "007"], 0).unwrap().to_vec();
    let n = ObsLayout::SIZE * ObsLayout::SIZE;
    // Empty box: interior 0, padding 1; object channel shows the cracker box (21.3 cm tall).
    assert_eq!(obs[112 * ObsLayout::SIZE + 112], 0.0);
    assert_eq!(obs[0], ObsLayout::PAD_VALUE);
    let top = obs[n..].iter().copied().fold(0.0, f32::max);
    assert!(
        (top - 0.2146 / ObsLayout::HEIGHT_SCALE_M).abs() < 0.01,
        "{top}"
    );
    let r = env.step([0.0, 0.0, 0.0]).unwrap();
    assert!(!r.terminated);
    // The box channel now shows the cracker box at the centre; the object channel the tuna can.
    assert!(r.observation[112 * ObsLayout::SIZE + 112] > 0.6);
    let top = r.observation[n..].iter().copied().fold(0.0, f32::max);
    assert!(
        (top - 0.0335 / ObsLayout::HEIGHT_SCALE_M).abs() < 0.01,
        "{top}"
    );
    let r = env.step([0.6, 0.5, 0.0]).unwrap();
    assert!(r.terminated && r.info.success, "{:?}", r.info);
    assert!(
        r.observation[n..].iter().all(|&v| v == 0.0),
        "no next object at the end"
    );
}

/// A clone of a world mid-episode, stepped with the same placements as the original, reaches
/// bit-identical states (poses, velocities, heightmap) after every placement, while the
/// original is not disturbed by the clone's existence.
#[test]
fn a_cloned_world_steps_bit_identically_to_the_original() {
    let c = common::primitives();
    let mut w = common::world(&c);
    let ids = [
        "003", "005", "013", "007", "011", "004", "057", "003", "005",
    ];
    let ty = |id: &str| c.by_id(id).unwrap();
    let at = |i: usize| {
        let f = i as f32;
        (0.09 * (f * 1.7).sin(), 0.05 * (f * 2.3).cos(), 0.4 * f)
    };
    for (i, id) in ids[..4].iter().enumerate() {
        let (x, y, t) = at(i);
        w.place(ty(id), x, y, t).unwrap();
    }
    let mut twin = w.clone();
    assert_eq!(w.state_bits(), twin.state_bits());
    for (i, id) in ids.iter().enumerate().skip(4) {
        let (x, y, t) = at(i);
        let a = w.place(ty(id), x, y, t).unwrap();
        let b = twin.place(ty(id), x, y, t).unwrap();
        assert_eq!(a, b, "outcome of placement {i} differs");
        assert_eq!(
            w.state_bits(),
            twin.state_bits(),
            "state after placement {i} differs"
        );
    }
    // The clone is independent: placing in it leaves the original as it was.
    let before = w.state_bits();
    twin.place(ty("004"), 0.0, 0.0, 0.0).unwrap();
    assert_eq!(w.state_bits(), before);
    assert_ne!(twin.state_bits(), before);
}

/// A FIXTURE episode of recorded human poses (primitive shapes): upright at `(x, y, z)`.
fn recorded(ids: &[&str], poses: &[(f32, f32, f32)]) -> herb_sim::boxed::Episode {
    let c = common::primitives();
    herb_sim::boxed::Episode {
        name: "fixture".into(),
        objects: ids.iter().map(|i| c.by_id(i).unwrap()).collect(),
        human: poses
            .iter()
            .map(|&(x, y, z)| herb_sim::boxed::HumanPlacement {
                x,
                y,
                z,
                theta: 0.0,
                tilt_rad: 0.0,
                rotation: rapier3d::math::Rotation::IDENTITY,
            })
            .collect(),
    }
}

#[test]
fn recorded_poses_are_checked_against_the_success_volume_without_physics() {
    use herb_sim::eval::recorded_episode;
    let c = common::primitives();
    let tol = herb_sim::world::INSIDE_TOLERANCE_M;
    // The tuna can (3.4 cm tall, origin at its centre) on the floor, then on a pile.
    let ok = recorded(&["007", "007"], &[(0.0, 0.0, 0.017), (0.1, 0.0, 0.1)]);
    let r = recorded_episode(&c, &ok, tol, 10.0).unwrap();
    assert!(r.success && r.packed == 2 && r.failure.is_none(), "{r:?}");
    assert_eq!(r.compactness_per_step.len(), 2);
    // The second object 2 cm through the +x wall, the third fine: packed counts the objects
    // before the first one outside.
    let hx = herb_sim::frames::BOX_HALF_X;
    let bad = recorded(
        &["007", "007", "007"],
        &[
            (0.0, 0.0, 0.017),
            (hx - 0.043 + 0.02, 0.0, 0.017),
            (0.0, 0.05, 0.017),
        ],
    );
    let r = recorded_episode(&c, &bad, tol, 10.0).unwrap();
    assert!(!r.success);
    assert_eq!(r.packed, 1);
    let f = r.failure.unwrap();
    assert_eq!(f.bound, "+x wall");
    assert!((f.by_m - (0.02 - tol)).abs() < 0.002, "{f:?}");
    // Above the 13 cm margin over the rim.
    let high = recorded(
        &["007"],
        &[(0.0, 0.0, herb_sim::frames::SUCCESS_TOP_Z + 0.01)],
    );
    let r = recorded_episode(&c, &high, tol, 10.0).unwrap();
    assert_eq!(r.failure.unwrap().bound, "top");
    assert_eq!(r.packed, 0);
}

#[test]
fn a_missing_or_non_finite_recorded_pose_is_an_error_naming_it() {
    use herb_sim::eval::recorded_episode;
    let c = common::primitives();
    let mut ep = recorded(&["007", "005"], &[(0.0, 0.0, 0.017), (f32::NAN, 0.0, 0.05)]);
    let e = recorded_episode(&c, &ep, 0.01, 10.0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("fixture") && e.contains("object 2") && e.contains("not finite"),
        "{e}"
    );
    ep.human.pop();
    let e = recorded_episode(&c, &ep, 0.01, 10.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("1 recorded poses for 2 objects"), "{e}");
}

/// Places "003" then "005" at fixed placements with release noise `(mm, deg)`, episode seed
/// `seed`: the world's state bits and where "005" ended (x, y, yaw).
fn noisy_run(mm: f32, deg: f32, seed: u64) -> (Vec<u32>, [f32; 3]) {
    let c = common::primitives();
    let cfg = WorldConfig {
        release_noise_m: mm * 1e-3,
        release_noise_deg: deg,
        ..WorldConfig::default()
    };
    let mut env = PackingEnv::new(c, cfg, RewardMode::Simple).unwrap();
    env.reset_ids(&["003", "005"], seed).unwrap();
    env.step_placement(-0.1, 0.0, 0.0).unwrap();
    env.step_placement(0.1, 0.0, 0.0).unwrap();
    let w = env.world();
    let p = w.pose_of(&w.placed()[1]);
    let yaw = herb_sim::frames::yaw_of(p.rotation);
    (w.state_bits(), [p.translation.x, p.translation.y, yaw])
}

#[test]
fn release_noise_moves_releases_reproducibly_and_none_changes_nothing() {
    // No noise: exactly the placements given (the default world, bit for bit).
    let (quiet, at) = noisy_run(0.0, 0.0, 3);
    assert!((at[0] - 0.1).abs() < 1e-3 && at[1].abs() < 1e-3, "{at:?}");
    // Noise: the same seed gives the same world, another seed another one; the release moved
    // by about its standard deviation (5 mm, 3 deg: within 6 of them).
    let (a, pa) = noisy_run(5.0, 3.0, 3);
    let (b, _) = noisy_run(5.0, 3.0, 3);
    let (c, pc) = noisy_run(5.0, 3.0, 4);
    assert_eq!(a, b, "noise is seeded by the episode");
    assert_ne!(a, quiet, "noise moved the releases");
    assert_ne!(a, c, "another episode seed, other noise");
    for p in [pa, pc] {
        let off = ((p[0] - 0.1).powi(2) + p[1].powi(2)).sqrt();
        assert!(off > 0.0 && off < 0.03, "offset {off} m ({p:?})");
        assert!(
            p[2].abs() < 18f32.to_radians(),
            "yaw {} deg",
            p[2].to_degrees()
        );
    }
    // A bad noise setting names its field.
    let e = PackingEnv::new(
        common::primitives(),
        WorldConfig {
            release_noise_m: -0.001,
            ..WorldConfig::default()
        },
        RewardMode::Simple,
    )
    .unwrap_err();
    assert!(e.to_string().contains("'release_noise_m'"), "{e}");
}

/// Wilson's interval at known values, and its ends inside [0, 1].
#[test]
fn the_success_interval_is_wilsons() {
    use herb_sim::eval::success_interval;
    let (lo, hi) = success_interval(0, 10);
    assert_eq!(lo, 0.0);
    assert!((hi - 0.27753).abs() < 1e-4, "{hi}");
    let (lo, hi) = success_interval(5, 10);
    assert!(
        (lo - 0.23659).abs() < 1e-4 && (hi - 0.76341).abs() < 1e-4,
        "{lo} {hi}"
    );
    let (lo, hi) = success_interval(263, 263);
    assert!(
        hi > 1.0 - 1e-12 && hi <= 1.0 && (lo - 0.98560).abs() < 1e-4,
        "{lo} {hi}"
    );
    assert_eq!(success_interval(0, 0), (0.0, 1.0));
}

/// An episode's result goes through JSON unchanged (a sweep's tasks send it so), and a failure
/// whose bound the world does not name is refused.
#[test]
fn an_episode_result_reads_back_as_written() {
    use herb_sim::eval::{EpisodeResult, Failure};
    let mut r = EpisodeResult::new("p1_s1", 3);
    r.placements = 2;
    r.compactness_per_step = vec![0.25, 0.5];
    r.decision_ns = vec![1_000, 2_000];
    r.failure = Some(Failure {
        bound: "+y wall",
        by_m: 0.012,
        earlier_object: true,
    });
    let text = serde_json::to_string(&r).unwrap();
    let back: EpisodeResult = serde_json::from_str(&text).unwrap();
    assert_eq!(back, r);
    let bad = text.replace("+y wall", "ceiling");
    let err = serde_json::from_str::<EpisodeResult>(&bad).unwrap_err();
    assert!(
        err.to_string()
            .contains("unknown failure bound \"ceiling\""),
        "{err}"
    );
}
