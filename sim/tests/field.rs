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
    assert_eq!(m.name, "field-v0");
    assert!(m.release.xy_sd_m > 0.0 && m.release.yaw_sd_deg > 0.0 && m.release.height_sd_m > 0.0);
    let cfg = m.apply(&WorldConfig::default()).unwrap();
    assert_eq!(cfg.release_noise_m, m.release.xy_sd_m);
    assert_eq!(cfg.release_height_sd_m, m.release.height_sd_m);
    let err = |text: &str| FieldModel::parse(text, "t.toml").unwrap_err().to_string();
    let e = err(&ZERO.replace("height_sd_m = 0.0", ""));
    assert!(e.contains("t.toml") && e.contains("height_sd_m"), "{e}");
    let e = err(&ZERO.replace("yaw_sd_deg = 0.0", "yaw_sd_deg = -1.0"));
    assert!(e.contains("release.yaw_sd_deg = -1"), "{e}");
    let e = err(&format!("{ZERO}\n[camera]\ndepth_sd_m = 0.002\n"));
    assert!(e.contains("camera"), "{e}");
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
