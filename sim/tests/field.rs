//! The field model (`models/field.toml`, `herb_sim::field`): read with every key checked, seeded
//! per episode, and with every error 0 the ideal world bit for bit.

use herb_sim::boxed::{self, Episode};
use herb_sim::eval::{self, EpisodeResult, Replay, ReplayPlacer};
use herb_sim::field::FieldModel;
use herb_sim::paths::{self, MeshSource};
use herb_sim::{Catalog, PackingEnv, RewardMode, SharedCatalog, WorldConfig};
use std::path::Path;
use std::sync::Arc;

const ZERO: &str = r#"
name = "field-zero (fixture)"
[release]
xy_sd_m = 0.0
yaw_sd_deg = 0.0
height_sd_m = 0.0
[camera]
depth_sd_m = 0.0
dropout = 0.0
edge_dropout = 0.0
[object]
size_sd = 0.0
mass_sd = 0.0
friction_sd = 0.0
"#;

/// The human replay (every release through the world's noise) of `ep` in `cfg`.
fn replay(catalog: &SharedCatalog, cfg: &WorldConfig, ep: &Episode, seed: u64) -> EpisodeResult {
    let mut env = PackingEnv::new(catalog.clone(), cfg.clone(), RewardMode::Simple).unwrap();
    let mut placer = ReplayPlacer::new(Replay::Human).unwrap();
    eval::run_episode(&mut env, ep, &ep.objects, &mut placer, seed).unwrap()
}

#[test]
fn the_shipped_model_reads_and_a_bad_one_names_its_key() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/field.toml");
    let m = FieldModel::load(&shipped).unwrap();
    assert_eq!(m.name, "field-v1");
    assert!(m.release.xy_sd_m > 0.0 && m.release.yaw_sd_deg > 0.0 && m.release.height_sd_m > 0.0);
    assert!(m.camera.depth_sd_m > 0.0 && m.camera.dropout > 0.0 && m.object.size_sd > 0.0);
    let cfg = m.apply(&WorldConfig::default()).unwrap();
    assert_eq!(cfg.release_noise_m, m.release.xy_sd_m);
    assert_eq!(cfg.release_height_sd_m, m.release.height_sd_m);
    assert_eq!(cfg.camera_edge_dropout, m.camera.edge_dropout);
    assert_eq!(cfg.object_friction_sd, m.object.friction_sd);
    assert_eq!(
        cfg.without_errors(),
        WorldConfig::default(),
        "never told to a twin"
    );
    let err = |text: &str| FieldModel::parse(text, "t.toml").unwrap_err().to_string();
    let e = err(&ZERO.replace("height_sd_m = 0.0", ""));
    assert!(e.contains("t.toml") && e.contains("height_sd_m"), "{e}");
    let e = err(&ZERO.replace("yaw_sd_deg = 0.0", "yaw_sd_deg = -1.0"));
    assert!(e.contains("release.yaw_sd_deg = -1"), "{e}");
    let e = err(&ZERO.replace("dropout = 0.0\nedge", "edge"));
    assert!(e.contains("dropout"), "{e}");
    let e = err(&ZERO.replace("mass_sd = 0.0", "mass_sd = -0.1"));
    assert!(e.contains("object.mass_sd = -0.1"), "{e}");
    let e = err(&ZERO.replace("size_sd = 0.0", "size_sd = nan"));
    assert!(e.contains("object.size_sd"), "{e}");
    let e = err(&format!("{ZERO}\nlens = 1\n"));
    assert!(e.contains("lens"), "{e}");
    let e = FieldModel::load(Path::new("/nonexistent/field.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/field.toml"), "{e}");
}

#[test]
fn with_every_error_zero_it_is_the_ideal_world_and_with_errors_it_is_seeded() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    let catalog: SharedCatalog =
        Arc::new(Catalog::builtin(&MeshSource::None("field test".into())).unwrap());
    let ep = boxed::load_session(&root, "p28_s2", &catalog)
        .unwrap()
        .episode(&catalog);
    let ideal = WorldConfig::default();
    let base = replay(&catalog, &ideal, &ep, 7);
    assert_eq!(base.placements, ep.objects.len(), "{base:?}");
    let zero = FieldModel::parse(ZERO, "zero")
        .unwrap()
        .apply(&ideal)
        .unwrap();
    assert_eq!(
        replay(&catalog, &zero, &ep, 7),
        replay(&catalog, &ideal, &ep, 7)
    );
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/field.toml");
    let field = FieldModel::load(&shipped).unwrap().apply(&ideal).unwrap();
    let a = replay(&catalog, &field, &ep, 7);
    assert_eq!(a, replay(&catalog, &field, &ep, 7), "seeded by the episode");
    assert_ne!(
        a,
        replay(&catalog, &ideal, &ep, 7),
        "the errors move the releases"
    );
    // The height alone: drawn after x, y and yaw, so the other draws are as without it.
    let mut height = ideal.clone();
    height.release_height_sd_m = 0.005;
    assert_ne!(
        replay(&catalog, &height, &ep, 7).compactness_per_step,
        replay(&catalog, &ideal, &ep, 7).compactness_per_step
    );
}

fn builtin() -> SharedCatalog {
    Arc::new(Catalog::builtin(&MeshSource::None("field test".into())).unwrap())
}

#[test]
fn the_field_camera_is_seeded_noisy_and_fills_what_it_did_not_see() {
    use herb_sim::world::{Camera, CameraNoise, PackingWorld};
    use rand::SeedableRng;
    let catalog = builtin();
    let mut w = PackingWorld::new(catalog.clone(), WorldConfig::default()).unwrap();
    w.place(herb_sim::TypeIdx(0), -0.05, 0.0, 0.0).unwrap();
    w.place(herb_sim::TypeIdx(3), 0.08, 0.03, 0.5).unwrap();
    let truth = w.heightmap().clone();
    let see = |noise: CameraNoise, seed: u64| {
        let mut c = Camera::new(&truth);
        c.see(
            &truth,
            &noise,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed),
        );
        c
    };
    // Dropouts only: seen cells are the truth (the floor threshold aside), the unseen ones are
    // filled and counted, about the share asked for, and the same seed sees the same.
    let holes = CameraNoise {
        depth_sd_m: 0.0,
        dropout: 0.2,
        edge_dropout: 1.0,
    };
    let c = see(holes, 5);
    assert_eq!(c.view(), see(holes, 5).view(), "seeded");
    assert_ne!(c.view(), see(holes, 6).view());
    let cells = truth.data().len();
    let filled = (c.filled().near + c.filled().far) as usize;
    assert!(
        (0.18..0.3).contains(&(filled as f64 / cells as f64)),
        "{filled} of {cells} filled"
    );
    let changed = truth
        .data()
        .iter()
        .zip(c.view().data())
        .filter(|(t, v)| **t >= 0.003 && t != v)
        .count();
    assert!(
        changed <= filled,
        "only unseen cells change: {changed} > {filled}"
    );
    // Depth noise only: errors of about the standard deviation on the objects' tops.
    let sd = 0.002;
    let noisy = see(
        CameraNoise {
            depth_sd_m: sd,
            dropout: 0.0,
            edge_dropout: 0.0,
        },
        5,
    );
    let errs: Vec<f64> = truth
        .data()
        .iter()
        .zip(noisy.view().data())
        .filter(|(t, _)| **t > 0.02)
        .map(|(t, v)| f64::from(v - t))
        .collect();
    let n = errs.len() as f64;
    let mean = errs.iter().sum::<f64>() / n;
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    assert!(n > 1000.0 && mean.abs() < 2e-4, "{n} cells, mean {mean}");
    assert!((rms / sd as f64 - 1.0).abs() < 0.1, "rms {rms}");
}

#[test]
fn a_true_object_is_its_hull_scaled_and_a_field_episode_decides_through_dropouts() {
    use herb_sim::lattice::Lattice;
    use herb_sim::teacher::LatticeRule;
    use herb_sim::world::{ObjectVariation, PackingWorld};
    use rapier3d::math::{Pose, Rotation, Vector};
    let catalog = builtin();
    let ty = herb_sim::TypeIdx(2);
    let height = |v: ObjectVariation| {
        let mut w = PackingWorld::new(catalog.clone(), WorldConfig::default()).unwrap();
        let pose = Pose::from_parts(Vector::new(0.0, 0.0, 0.1), Rotation::IDENTITY);
        w.place_pose_as(ty, pose, v).unwrap();
        let r = w.report();
        r[0].hi[2] - r[0].lo[2]
    };
    let big = ObjectVariation {
        scale: 1.04,
        mass: 1.2,
        friction: 0.8,
    };
    let ratio = height(big) / height(ObjectVariation::NOMINAL);
    assert!((ratio - 1.04).abs() < 1e-3, "{ratio}");
    let mut w = PackingWorld::new(catalog.clone(), WorldConfig::default()).unwrap();
    let bad = ObjectVariation { scale: 3.0, ..big };
    let e = w.place_pose_as(ty, Pose::IDENTITY, bad).unwrap_err();
    assert!(e.to_string().contains("0.5 to 2"), "{e}");
    // A camera that misses half the box: the lattice rule still decides on the filled view,
    // and the episode runs to its end.
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/field.toml");
    let mut cfg = FieldModel::load(&shipped)
        .unwrap()
        .apply(&WorldConfig::default())
        .unwrap();
    cfg.camera_dropout = 0.5;
    let mut env = PackingEnv::new(catalog.clone(), cfg, RewardMode::Simple).unwrap();
    let seq: Vec<_> = (0..6).map(|i| herb_sim::TypeIdx(i * 3)).collect();
    env.reset(&seq, 11).unwrap();
    let mut rule = LatticeRule::Blbf(Box::new(Lattice::new(&catalog)));
    let mut steps = 0;
    while env.next_object().is_some() {
        let Some(p) = rule.decide(&env).unwrap() else {
            break;
        };
        steps += 1;
        if env.step_placement(p.x, p.y, p.theta()).unwrap().terminated {
            break;
        }
    }
    assert!(
        steps >= 3,
        "decided {steps} placements through the dropouts"
    );
    assert_ne!(
        env.camera(),
        env.world().heightmap(),
        "the methods see the camera"
    );
}
