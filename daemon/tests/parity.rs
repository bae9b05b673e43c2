//! Parity of tract with PyTorch on exported SAC actors: every shipped policy
//! (`models/policy-*.onnx`) and the export fixture `models/fixtures/sac-smoke.onnx` (an actor
//! after one minute of CPU training by `models/continuous/train.py`: a test of the export path, not a
//! policy) come with observations from the environment and PyTorch's actions for them
//! (`<name>.parity.bin`, little-endian f32, and `<name>.parity.json`); tract must agree within
//! 1e-4.

use herb_daemon::OnnxPolicy;
use herb_sim::ObsLayout;
use std::path::{Path, PathBuf};

fn check(onnx: &Path) {
    let json = onnx.with_extension("parity.json");
    let bin = onnx.with_extension("parity.bin");
    let meta: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&json).unwrap_or_else(|e| panic!("{}: {e}", json.display())),
    )
    .unwrap();
    let bytes = std::fs::read(&bin).unwrap_or_else(|e| panic!("{}: {e}", bin.display()));
    let obs: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let actions = meta["actions"].as_array().unwrap();
    assert_eq!(
        obs.len(),
        actions.len() * ObsLayout::LEN,
        "{}",
        bin.display()
    );
    assert!(!actions.is_empty());
    let mut p = OnnxPolicy::load(onnx).unwrap();
    for (k, want) in actions.iter().enumerate() {
        let got = p
            .infer(&obs[k * ObsLayout::LEN..(k + 1) * ObsLayout::LEN])
            .unwrap();
        for j in 0..3 {
            let w = want[j].as_f64().unwrap() as f32;
            assert!(
                (got[j] - w).abs() <= 1e-4,
                "{} sample {k}: tract {got:?} vs PyTorch {want:?}",
                onnx.display()
            );
        }
    }
}

#[test]
fn tract_matches_pytorch_on_exported_actors() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&models)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            n.starts_with("policy-") && n.ends_with(".onnx")
        })
        .collect();
    files.push(models.join("fixtures/sac-smoke.onnx"));
    for f in &files {
        check(f);
    }
    eprintln!("parity checked: {files:?}");
}
