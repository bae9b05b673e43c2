//! Placement policies: BLBF feasibility and ordering, decisions under adversarial input.

mod common;

use common::decide;
use herb_decide::policy::{Blbf, DecisionInput, check_input};
use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_sim::paths::MeshSource;
use herb_sim::{Catalog, Heightmap, ObsLayout, TypeIdx};
use parry3d::math::Rotation;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn catalog() -> Catalog {
    Catalog::builtin(&MeshSource::None("test".into())).expect("catalog")
}

/// The rotated hull's footprint at (x, y, theta) lies inside the inner walls.
fn inside_walls(c: &Catalog, t: TypeIdx, x: f32, y: f32, theta: f32) -> bool {
    let rot = Rotation::from_rotation_z(theta);
    c.shape(t).vertices.iter().all(|&v| {
        let p = rot * v;
        (x + p.x).abs() <= BOX_HALF_X + 1e-4 && (y + p.y).abs() <= BOX_HALF_Y + 1e-4
    })
}

/// Random heightmaps: flat steps, pillars and noise, up to 1 m (the valid maximum).
fn adversarial(rng: &mut ChaCha8Rng, kind: usize) -> Heightmap {
    let spec = ObsLayout::grid();
    let mut hm = Heightmap::new(spec);
    let d = hm.data_mut();
    match kind % 4 {
        0 => d.iter_mut().for_each(|v| *v = rng.random_range(0.0..=1.0)),
        1 => d.iter_mut().for_each(|v| *v = 1.0),
        2 => {
            for _ in 0..40 {
                let (c0, r0) = (rng.random_range(0..spec.nx), rng.random_range(0..spec.ny));
                let h = rng.random_range(0.0..0.4);
                for r in r0..(r0 + 20).min(spec.ny) {
                    for c in c0..(c0 + 30).min(spec.nx) {
                        d[r * spec.nx + c] = h;
                    }
                }
            }
        }
        _ => {
            let h = rng.random_range(0.0..0.16);
            d.iter_mut().enumerate().for_each(|(i, v)| {
                *v = if i % 7 == 0 { h } else { 0.0 };
            });
        }
    }
    hm
}

#[test]
fn blbf_never_proposes_a_position_overlapping_the_walls() {
    let c = catalog();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut p = Blbf::new();
    let mut n = 0;
    for k in 0..24 {
        let hm = adversarial(&mut rng, k);
        for t in c.types() {
            let a =
                decide(&mut p, &c, &hm, t, &[]).expect("an upright object fits between the walls");
            let (x, y, theta) = (a.x, a.y, a.theta);
            assert!(x.is_finite() && y.is_finite() && theta.is_finite(), "{a:?}");
            assert!(
                inside_walls(&c, t, x, y, theta),
                "{}: ({x}, {y}, {theta}) crosses a wall",
                c.spec(t).id
            );
            n += 1;
        }
    }
    assert_eq!(n, 24 * c.len());
}

#[test]
fn blbf_fills_deep_bottom_left_back_first() {
    let c = catalog();
    let mut p = Blbf::new();
    let sugar = c.by_id("004").unwrap();
    // Empty box: every top is equal, so the smallest x, then the smallest y: the -x, -y corner,
    // against both walls (within one 6.25 mm search step).
    let hm = Heightmap::new(ObsLayout::grid());
    let (x, y, theta, _) = p.best(&hm, c.shape(sugar)).unwrap();
    let rot = Rotation::from_rotation_z(theta);
    let (lx, ly) = c
        .shape(sugar)
        .vertices
        .iter()
        .fold((f32::MAX, f32::MAX), |(a, b), &v| {
            let r = rot * v;
            (a.min(r.x), b.min(r.y))
        });
    let step = Blbf::search_cell(hm.spec());
    assert!(
        (x + lx + BOX_HALF_X).abs() <= step,
        "gap to -x wall {}",
        x + lx + BOX_HALF_X
    );
    assert!(
        (y + ly + BOX_HALF_Y).abs() <= step,
        "gap to -y wall {}",
        y + ly + BOX_HALF_Y
    );
    // A pile at the -x end: the lowest top is now elsewhere, on the floor.
    let mut hm2 = Heightmap::new(ObsLayout::grid());
    let spec = *hm2.spec();
    for r in 0..spec.ny {
        for cidx in 0..spec.nx / 2 {
            hm2.data_mut()[r * spec.nx + cidx] = 0.1;
        }
    }
    let (x2, _, _, top2) = p.best(&hm2, c.shape(sugar)).unwrap();
    assert!(x2 > 0.0, "x {x2}");
    let h = c.shape(sugar).extents().z;
    assert!(
        (top2 - h).abs() < 0.002,
        "rests on the floor: top {top2} vs height {h}"
    );
}

#[test]
fn bad_input_is_rejected_with_a_reason_not_passed_on() {
    let c = catalog();
    let t = c.by_id("004").unwrap();
    // A bad heightmap is refused by its one check, in the decision core, before BLBF runs.
    let shared = std::sync::Arc::new(catalog());
    let mut d = herb_decide::Decider::new(Box::new(Blbf::new()), shared, 0.005);
    let mut hm = Heightmap::new(ObsLayout::grid());
    hm.data_mut()[100] = f32::NAN;
    let e = d.decide_on((&hm).into(), &[t], 0).unwrap_err().to_string();
    assert!(e.contains("decider") && e.contains("NaN"), "{e}");
    hm.data_mut()[100] = 5.0;
    assert!(d.decide_on((&hm).into(), &[t], 0).is_err());
    // The input check names what is wrong.
    let good = Heightmap::new(ObsLayout::grid());
    let mut obs = vec![0.0; ObsLayout::LEN];
    obs[7] = f32::INFINITY;
    let input = DecisionInput {
        observation: &obs,
        heightmap: &good,
        object: t,
        shape: c.shape(t),
        step: 0,
        catalog: &c,
        remaining: &[t],
    };
    let e = check_input("onnx", &input).unwrap_err().to_string();
    assert!(e.contains("index 7"), "{e}");
    let short = vec![0.0; 10];
    let e = check_input(
        "onnx",
        &DecisionInput {
            observation: &short,
            ..input
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("10 values"), "{e}");
}
