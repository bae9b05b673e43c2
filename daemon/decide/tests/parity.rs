//! Parity of tract with PyTorch on exported actors, of both policy contracts: every shipped
//! policy (`models/policy-*.onnx`), the behaviour-cloning models of Table I (`models/bc-*.onnx`)
//! and the export fixtures `models/fixtures/sac-smoke.onnx` (an actor of the observation
//! contract after one minute of CPU training by the first, continuous-action recipe, now in git
//! history) and `models/fixtures/candidates-smoke.onnx` (a candidate policy after a minute of
//! `training/train.py`): tests of the export paths, not policies. Each comes with inputs from
//! the environment and PyTorch's outputs for them (`<name>.parity.bin`, little-endian f32, and
//! `<name>.parity.json`); tract must agree within 1e-4.

use herb_decide::{CandidatePolicy, OnnxPolicy};
use herb_sim::ObsLayout;
use herb_sim::features::{CANDIDATE_LEN, CONTEXT_LEN};
use herb_sim::lattice::MAX_CANDIDATES;
use std::path::{Path, PathBuf};

/// A candidate policy's samples: context, candidates and mask per sample, then its logits.
fn check_candidates(onnx: &Path, meta: &serde_json::Value, data: &[f32]) {
    let logits = meta["logits"].as_array().unwrap();
    let per = CONTEXT_LEN + MAX_CANDIDATES * CANDIDATE_LEN + MAX_CANDIDATES;
    assert_eq!(data.len(), logits.len() * per, "{}", onnx.display());
    assert!(!logits.is_empty());
    let catalog =
        herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::None("test".into())).unwrap();
    let mut p = CandidatePolicy::load(onnx, &catalog).unwrap();
    for (k, want) in logits.iter().enumerate() {
        let x = &data[k * per..(k + 1) * per];
        let (ctx, rest) = x.split_at(CONTEXT_LEN);
        let (cand, mask) = rest.split_at(MAX_CANDIDATES * CANDIDATE_LEN);
        let got = p.logits(ctx, cand, mask).unwrap();
        for (j, w) in want.as_array().unwrap().iter().enumerate() {
            // Only real candidates count (padding is masked to a large negative number).
            if mask[j] > 0.0 {
                let w = w.as_f64().unwrap() as f32;
                assert!(
                    (got[j] - w).abs() <= 1e-4 * w.abs().max(1.0),
                    "{} sample {k} candidate {j}: tract {} vs PyTorch {w}",
                    onnx.display(),
                    got[j]
                );
            }
        }
    }
}

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
    if meta.get("logits").is_some() {
        return check_candidates(onnx, &meta, &obs);
    }
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
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&models)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            (n.starts_with("policy-") || n.starts_with("bc-")) && n.ends_with(".onnx")
        })
        .collect();
    files.push(models.join("fixtures/sac-smoke.onnx"));
    files.push(models.join("fixtures/candidates-smoke.onnx"));
    for f in &files {
        check(f);
    }
    eprintln!("parity checked: {files:?}");
}
