//! The ONNX policy: contract check, numerics against the ONNX reference evaluator, bad files,
//! and decisions that stay finite and in range. The models are FIXTURES with fixed random
//! weights (training/make_fixtures.py), not trained policies.

use herb_decide::policy::{DecisionInput, Policy};
use herb_decide::{DecideError, OnnxPolicy};
use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_sim::paths::MeshSource;
use herb_sim::{Catalog, Heightmap, ObsLayout};
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../models/fixtures")
        .join(name)
}

fn ramp() -> Vec<f32> {
    (0..ObsLayout::LEN)
        .map(|i| (i % 255) as f32 / 255.0)
        .collect()
}

#[test]
fn the_fixture_policy_matches_the_onnx_reference_evaluator() {
    let mut p = OnnxPolicy::load(&fixture("tiny_policy.onnx")).expect("fixture loads");
    let text = std::fs::read_to_string(fixture("tiny_policy_expected.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (name, obs) in [("zeros", vec![0.0; ObsLayout::LEN]), ("ramp", ramp())] {
        let got = p.infer(&obs).unwrap();
        let want: Vec<f32> = expected[name]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w).abs() < 1e-4,
                "{name}: tract {got:?} vs reference {want:?}"
            );
        }
        // The same input twice gives the same output (state reuse).
        assert_eq!(p.infer(&obs).unwrap(), got);
    }
    assert!(p.fma() > 0, "cost model: {} FMA", p.fma());
    assert!(p.file_bytes() > 0);
}

#[test]
fn models_that_break_the_contract_are_refused_naming_what_differs() {
    for (file, needle) in [
        ("bad_input_name.onnx", "input is named \"x\""),
        ("bad_input_shape.onnx", "input shape"),
        ("bad_output_shape.onnx", "output shape"),
    ] {
        let e = OnnxPolicy::load(&fixture(file)).unwrap_err().to_string();
        assert!(e.contains(needle) && e.contains(file), "{file}: {e}");
    }
}

#[test]
fn missing_truncated_and_garbage_files_are_clear_errors() {
    let e = OnnxPolicy::load(std::path::Path::new("/nonexistent/policy.onnx")).unwrap_err();
    assert!(matches!(e, DecideError::Io { .. }), "{e}");
    let dir = std::env::temp_dir().join(format!("herb-onnx-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = std::fs::read(fixture("tiny_policy.onnx")).unwrap();
    for (name, bytes) in [
        ("truncated.onnx", good[..good.len() / 2].to_vec()),
        (
            "garbage.onnx",
            b"this is not a protobuf \xff\xfe\x00\x01".to_vec(),
        ),
        ("empty.onnx", Vec::new()),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let e = OnnxPolicy::load(&path).unwrap_err();
        assert!(
            matches!(e, DecideError::Model { .. }) && e.to_string().contains(name),
            "{name}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn decisions_are_finite_and_in_range_or_rejected() {
    let c = Catalog::builtin(&MeshSource::None("test".into())).unwrap();
    let t = c.by_id("004").unwrap();
    let mut p = OnnxPolicy::load(&fixture("tiny_policy.onnx")).unwrap();
    let hm = Heightmap::new(ObsLayout::grid());
    let mut obs = vec![0.0; ObsLayout::LEN];
    let mut state = 12345u64;
    for k in 0..20 {
        // Adversarial observations: extremes, noise, stripes, all in [0, 1].
        for (i, v) in obs.iter_mut().enumerate() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = match k % 4 {
                0 => 1.0,
                1 => (state >> 40) as f32 / (1u64 << 24) as f32,
                2 => ((i / 224) % 2) as f32,
                _ => 0.0,
            };
        }
        let a = p
            .decide(&DecisionInput {
                observation: &obs,
                heightmap: &hm,
                object: t,
                shape: c.shape(t),
                step: 0,
                catalog: &c,
                remaining: &[t],
            })
            .unwrap();
        // Decoded once from an action within [-1, 1]: over the box, the yaw within [-pi, pi].
        assert!(a.x.abs() <= BOX_HALF_X && a.y.abs() <= BOX_HALF_Y, "{a:?}");
        assert!(a.theta.abs() <= std::f32::consts::PI, "{a:?}");
    }
    obs[3] = f32::NAN;
    let e = p
        .decide(&DecisionInput {
            observation: &obs,
            heightmap: &hm,
            object: t,
            shape: c.shape(t),
            step: 0,
            catalog: &c,
            remaining: &[t],
        })
        .unwrap_err();
    assert!(matches!(e, DecideError::Rejected { .. }), "{e}");
}
