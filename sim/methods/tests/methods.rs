//! The method registry: every registered method runs one BoxED episode through the one episode
//! loop (`herb_sim::eval::run_episode`), built by the one factory (`Method::placer`).

use herb_decide::{Order, PolicySpec, SequenceModel};
use herb_methods::{Method, MethodSettings};
use herb_sim::eval::{self, EpisodeResult};
use herb_sim::paths::{self, MeshSource};
use herb_sim::{Catalog, PackingEnv, RewardMode, SharedCatalog, WorldConfig};
use std::path::Path;
use std::sync::Arc;

fn models() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// One episode of `m` on session p28_s2 (7 objects), in the method's default order.
fn run(
    m: Method,
    catalog: &SharedCatalog,
    ep: &herb_sim::boxed::Episode,
    settings: &MethodSettings,
) -> EpisodeResult {
    let seq = SequenceModel::load(&models().join("sequence.json"), catalog).unwrap();
    let mut env =
        PackingEnv::new(catalog.clone(), WorldConfig::default(), RewardMode::Simple).expect("env");
    if m == Method::HumanRecorded {
        let cfg = env.world().config().clone();
        return eval::recorded_episode(catalog, ep, cfg.inside_tolerance_m, cfg.stability_tilt_deg)
            .unwrap();
    }
    let order = match m.order(None) {
        Some(o) => o.order(catalog, Some(&seq), &ep.objects, 0).unwrap(),
        None => ep.objects.clone(),
    };
    let mut placer = m
        .placer(catalog, settings)
        .unwrap_or_else(|e| panic!("{m}: {e}"));
    eval::run_episode(&mut env, ep, &order, placer.as_mut(), 0)
        .unwrap_or_else(|e| panic!("{m}: {e}"))
}

#[test]
fn every_registered_method_packs_one_episode_through_the_one_loop() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    // Primitive shapes keep the test fast; the replays still read the humans' placements.
    let catalog: SharedCatalog =
        Arc::new(Catalog::builtin(&MeshSource::None("test".into())).unwrap());
    let ep = herb_sim::boxed::load_session(&root, "p28_s2", &catalog)
        .unwrap()
        .episode(&catalog);
    let settings = MethodSettings {
        policy: Some(PolicySpec::Onnx(models().join("policy-cs06.onnx"))),
        bc_models: models(),
        lookahead_k: 2,
        lookahead_horizon: Some(1),
        ..MethodSettings::default()
    };
    for m in Method::ALL {
        let r = run(m, &catalog, &ep, &settings);
        assert_eq!(r.objects, ep.objects.len(), "{m}");
        assert!(r.placements >= 1, "{m}: {r:?}");
        assert!(r.packed <= r.placements, "{m}");
        // The deciding methods time every decision; the replays and the recorded poses do not.
        let timed = m.replay().is_none();
        assert_eq!(
            r.decision_ns.len(),
            if timed { r.placements } else { 0 },
            "{m}"
        );
    }
}

#[test]
fn a_method_that_cannot_be_built_is_a_clear_error() {
    let catalog: SharedCatalog =
        Arc::new(Catalog::builtin(&MeshSource::None("test".into())).unwrap());
    let none = MethodSettings::default();
    let e = Method::Herb
        .placer(&catalog, &none)
        .err()
        .expect("no policy");
    assert!(e.to_string().contains("herb: needs a policy"), "{e}");
    let e = Method::HumanRecorded
        .placer(&catalog, &none)
        .err()
        .expect("not a placer");
    assert!(
        e.to_string().contains("not a placement in the world"),
        "{e}"
    );
    let missing = MethodSettings {
        bc_models: "no/such/dir".into(),
        ..MethodSettings::default()
    };
    let e = Method::BcMse
        .placer(&catalog, &missing)
        .err()
        .expect("no models");
    assert!(e.to_string().contains("bc-mse-heldout-even.onnx"), "{e}");
    // The order a method defaults to is named in the registry, one place.
    assert_eq!(Method::Blbf.order(None), Some(Order::Largest));
}

/// A policy file is loaded once per process and catalog: later placers fork it
/// (`Policy::fork`), and a forked policy packs an episode exactly as one loaded from the file.
#[test]
fn a_model_file_is_loaded_once_and_its_forks_decide_as_it_does() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    let catalog: SharedCatalog =
        Arc::new(Catalog::builtin(&MeshSource::None("fork test".into())).unwrap());
    let ep = herb_sim::boxed::load_session(&root, "p28_s2", &catalog)
        .unwrap()
        .episode(&catalog);
    let settings = MethodSettings {
        policy: Some(PolicySpec::Onnx(models().join("policy-cs06.onnx"))),
        ..MethodSettings::default()
    };
    let first = run(Method::Herb, &catalog, &ep, &settings);
    assert_eq!(
        herb_methods::policy_file_reads(&catalog),
        1,
        "the first placer reads the file"
    );
    let second = run(Method::Herb, &catalog, &ep, &settings);
    let third = run(Method::Herb, &catalog, &ep, &settings);
    assert_eq!(
        herb_methods::policy_file_reads(&catalog),
        1,
        "later placers fork"
    );
    // A policy loaded straight from the file, outside the cache.
    let direct = {
        let seq = SequenceModel::load(&models().join("sequence.json"), &catalog).unwrap();
        let order = Order::HERB
            .order(&catalog, Some(&seq), &ep.objects, 0)
            .unwrap();
        let p = herb_decide::load_policy(settings.policy.as_ref().unwrap(), &catalog).unwrap();
        let mut placer = herb_methods::DeciderPlacer(herb_decide::Decider::new(
            p,
            catalog.clone(),
            settings.world.clearance_m,
        ));
        let mut env =
            PackingEnv::new(catalog.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
        eval::run_episode(&mut env, &ep, &order, &mut placer, 0).unwrap()
    };
    let same = |a: &EpisodeResult, b: &EpisodeResult| {
        (
            a.packed,
            a.placements,
            &a.compactness_per_step,
            a.physics_steps,
        ) == (
            b.packed,
            b.placements,
            &b.compactness_per_step,
            b.physics_steps,
        )
    };
    assert!(
        same(&first, &second) && same(&first, &third),
        "{first:?} {second:?}"
    );
    assert!(same(&first, &direct), "{first:?} {direct:?}");
}
