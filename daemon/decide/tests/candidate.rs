//! The candidate policy (`herb_decide::candidate`): contract checks at load, decisions that
//! stay inside the walls, "no feasible placement" on a full box, and the policy factory.
//! Uses the export fixture `models/fixtures/candidates-smoke.onnx` (a candidate network after
//! a minute of `training/train.py`; a fixture, not a policy).

mod common;

use common::decide;
use herb_decide::{CandidatePolicy, DecideError, PolicySpec, load_policy};
use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y, SUCCESS_TOP_Z};
use herb_sim::paths::MeshSource;
use herb_sim::{Catalog, Heightmap, ObsLayout, TypeIdx};
use parry3d::math::Rotation;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/fixtures")
}

fn catalog() -> Catalog {
    Catalog::builtin(&MeshSource::None("test".into())).unwrap()
}

#[test]
fn decisions_are_candidates_inside_the_walls() {
    let c = catalog();
    let mut p = CandidatePolicy::load(&fixtures().join("candidates-smoke.onnx"), &c).unwrap();
    assert!(p.fma() > 0);
    let after: Vec<TypeIdx> = ["003", "005", "013"]
        .iter()
        .map(|i| c.by_id(i).unwrap())
        .collect();
    for id in ["004", "003", "013", "057"] {
        let t = c.by_id(id).unwrap();
        for hm in [
            Heightmap::new(ObsLayout::grid()),
            // A step across the box: half of it 8 cm high.
            {
                let mut h = Heightmap::new(ObsLayout::grid());
                let nx = h.spec().nx;
                for (i, v) in h.data_mut().iter_mut().enumerate() {
                    if i % nx < nx / 2 {
                        *v = 0.08;
                    }
                }
                h
            },
        ] {
            let a = decide(&mut p, &c, &hm, t, &after).unwrap();
            let (x, y, theta) = (a.x, a.y, a.theta);
            let (lo, hi) = c.shape(t).rotated_bounds(Rotation::from_rotation_z(theta));
            let tol = 1e-3;
            assert!(
                x + lo.x >= -BOX_HALF_X - tol && x + hi.x <= BOX_HALF_X + tol,
                "{id}: x {x}"
            );
            assert!(
                y + lo.y >= -BOX_HALF_Y - tol && y + hi.y <= BOX_HALF_Y + tol,
                "{id}: y {y}"
            );
        }
    }
}

#[test]
fn a_full_box_is_no_feasible_placement_not_a_nan_or_a_wall() {
    let c = catalog();
    let mut p = load_policy(
        &PolicySpec::Onnx(fixtures().join("candidates-smoke.onnx")),
        &c,
    )
    .unwrap();
    let spec = ObsLayout::grid();
    let full = Heightmap::from_data(spec, vec![SUCCESS_TOP_Z; spec.len()]).unwrap();
    let e = decide(p.as_mut(), &c, &full, c.by_id("003").unwrap(), &[]).unwrap_err();
    assert!(matches!(e, DecideError::NoFeasiblePlacement), "{e}");
    assert_eq!(e.to_string(), "no feasible placement");
}

#[test]
fn models_of_the_other_contract_or_corrupt_files_are_refused_by_name() {
    let c = catalog();
    // An observation-contract model is not a candidate policy, and says why ...
    let e = CandidatePolicy::load(&fixtures().join("tiny_policy.onnx"), &c).unwrap_err();
    assert!(
        e.to_string().contains("inputs") && e.to_string().contains("tiny_policy"),
        "{e}"
    );
    // ... while the factory loads each contract as its own policy.
    let p = load_policy(&PolicySpec::Onnx(fixtures().join("tiny_policy.onnx")), &c).unwrap();
    assert_eq!(p.name(), "onnx");
    let p = load_policy(
        &PolicySpec::Onnx(fixtures().join("candidates-smoke.onnx")),
        &c,
    )
    .unwrap();
    assert_eq!(p.name(), "candidates");
    // A truncated candidate model is an error naming the file, not a panic.
    let bytes = std::fs::read(fixtures().join("candidates-smoke.onnx")).unwrap();
    let path = std::env::temp_dir().join(format!("herb-trunc-{}.onnx", std::process::id()));
    std::fs::write(&path, &bytes[..bytes.len() / 3]).unwrap();
    let e = match load_policy(&PolicySpec::Onnx(path.clone()), &c) {
        Err(e) => e,
        Ok(_) => panic!("a truncated model loaded"),
    };
    assert!(e.to_string().contains("herb-trunc"), "{e}");
    std::fs::remove_file(&path).ok();
    // A wrong input length is an error naming the input.
    let mut p = CandidatePolicy::load(&fixtures().join("candidates-smoke.onnx"), &c).unwrap();
    let e = p.logits(&[0.0; 3], &[], &[]).unwrap_err();
    assert!(e.to_string().contains("context"), "{e}");
}
