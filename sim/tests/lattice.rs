//! The placement lattice, its candidates and the lookahead teacher.

mod common;

use herb_sim::env::{PackingEnv, RewardMode};
use herb_sim::eval::NO_FEASIBLE_PLACEMENT;
use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y, SUCCESS_TOP_Z};
use herb_sim::lattice::{BELOW_LIMIT, FEASIBLE, INSIDE, Lattice, NUM_YAWS, WALL_TOL_M, YAWS};
use herb_sim::teacher::{GeoLookahead, LatticeRule, Lookahead, raise_bounding_box, rollout};
use herb_sim::zestimate::{ZScratch, estimate_z};
use herb_sim::{Heightmap, PackingWorld, SharedCatalog, TypeIdx, WorldConfig};
use rapier3d::math::Rotation;

const IDS: [&str; 9] = [
    "003", "005", "013", "007", "011", "004", "057", "003", "005",
];

/// A world with the first `n` objects of `IDS` placed at fixed, scattered positions.
fn pile(c: &SharedCatalog, n: usize) -> PackingWorld {
    common::pile(c, &IDS[..n])
}

#[test]
fn on_the_empty_floor_every_inside_node_rests_on_the_floor_and_blbf_takes_the_corner() {
    let c = common::primitives();
    let w = common::world(&c);
    let ty = c.by_id("004").unwrap();
    let shape = c.shape(ty);
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, ty);
    let spec = *l.spec();
    assert_eq!((spec.nx, spec.ny), (28, 19));
    let lowest = shape.aabb_min.z;
    let mut inside = 0;
    for (k, &yaw) in YAWS.iter().enumerate() {
        let (lo, hi) = shape.rotated_bounds(Rotation::from_rotation_z(yaw));
        for row in 0..spec.ny {
            for col in 0..spec.nx {
                let i = l.index(k, col, row);
                let (x, y) = spec.cell_centre(col, row);
                let expect_inside = x + lo.x >= -BOX_HALF_X - WALL_TOL_M
                    && x + hi.x <= BOX_HALF_X + WALL_TOL_M
                    && y + lo.y >= -BOX_HALF_Y - WALL_TOL_M
                    && y + hi.y <= BOX_HALF_Y + WALL_TOL_M;
                assert_eq!(
                    l.flags()[i] & INSIDE != 0,
                    expect_inside,
                    "node {k} {col} {row}"
                );
                if expect_inside {
                    inside += 1;
                    // Resting on the floor: the lowest point at z = 0, fully supported.
                    assert!(
                        (l.rest_z()[i] + lowest).abs() < 1e-5,
                        "rest {}",
                        l.rest_z()[i]
                    );
                    assert_eq!(l.support()[i], 1.0);
                    assert_eq!(l.flags()[i], FEASIBLE);
                }
            }
        }
    }
    assert!(inside > 100, "only {inside} inside nodes");
    assert_eq!(l.feasible_count(), inside);
    let cands = l.candidates().to_vec();
    assert!(cands.len() >= 8, "{} candidates", cands.len());
    // Candidate 0: the deep-bottom-left-back corner, flush within one refinement cell.
    let b = l.blbf().unwrap();
    assert_eq!(b, cands[0]);
    let (lo, _) = shape.rotated_bounds(Rotation::from_rotation_z(b.theta()));
    assert!(
        b.x + lo.x - -BOX_HALF_X < 0.00625 + 1e-4,
        "x gap {}",
        b.x + lo.x + BOX_HALF_X
    );
    assert!(
        b.y + lo.y - -BOX_HALF_Y < 0.00625 + 1e-4,
        "y gap {}",
        b.y + lo.y + BOX_HALF_Y
    );
    // The candidates are distinct, feasible, and in the BLBF order.
    for (i, a) in cands.iter().enumerate() {
        assert!(a.top <= herb_sim::lattice::HEIGHT_LIMIT_M);
        for o in &cands[i + 1..] {
            assert!(a.blbf_cmp(o).is_le());
            assert!((a.x, a.y, a.yaw, a.tight) != (o.x, o.y, o.yaw, o.tight));
        }
    }
    // They reach all four corners.
    for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        assert!(
            cands.iter().any(|p| p.x * sx > 0.08 && p.y * sy > 0.04),
            "no candidate near corner ({sx}, {sy})"
        );
    }
}

#[test]
fn lattice_rest_heights_are_never_below_the_shared_estimate() {
    let c = common::primitives();
    let w = pile(&c, 7);
    let ty = c.by_id("013").unwrap();
    let shape = c.shape(ty);
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, ty);
    let mut scratch = ZScratch::for_catalog(&c, w.heightmap().spec().cell);
    let spec = *l.spec();
    let mut checked = 0;
    for (k, &yaw) in YAWS.iter().enumerate() {
        for row in 0..spec.ny {
            for col in 0..spec.nx {
                let i = l.index(k, col, row);
                if l.flags()[i] & INSIDE == 0 {
                    continue;
                }
                let (x, y) = spec.cell_centre(col, row);
                let fine = estimate_z(w.heightmap(), shape, x, y, yaw, &mut scratch);
                // The max-pooled estimate is conservative up to the footprint's rasterisation
                // at the coarser cell (a few mm at a hull's sloped rim).
                assert!(
                    l.rest_z()[i] >= fine - 0.004,
                    "node {k} {col} {row}: lattice {} below estimate {fine}",
                    l.rest_z()[i]
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 100);
    // Refined loose candidates are conservative too; tight ones use the BLBF heuristic's
    // sampling (footprint at the 6.25 mm cell centres), which is not.
    for p in l.candidates().to_vec().into_iter().filter(|p| !p.tight) {
        let fine = estimate_z(w.heightmap(), shape, p.x, p.y, p.theta(), &mut scratch);
        assert!(
            p.rest_z >= fine - 0.004,
            "candidate {p:?} below estimate {fine}"
        );
        assert!(
            p.rest_z <= fine + 0.02,
            "candidate {p:?} far above estimate {fine}"
        );
    }
}

#[test]
fn the_box_turned_half_a_turn_maps_yaw_k_to_yaw_k_plus_2_at_the_mirrored_node() {
    let c = common::primitives();
    let w = pile(&c, 6);
    let spec = *w.heightmap().spec();
    let mut turned = w.heightmap().data().to_vec();
    turned.reverse();
    let turned = Heightmap::from_data(spec, turned).unwrap();
    let ty = c.by_id("005").unwrap();
    let (mut a, mut b) = (Lattice::new(&c), Lattice::new(&c));
    a.compute(w.heightmap(), &c, ty);
    b.compute(&turned, &c, ty);
    let ls = *a.spec();
    let mut worst = 0.0f32;
    let mut flag_diff = 0;
    for k in 0..NUM_YAWS {
        for row in 0..ls.ny {
            for col in 0..ls.nx {
                let i = a.index(k, col, row);
                let j = b.index((k + 2) % NUM_YAWS, ls.nx - 1 - col, ls.ny - 1 - row);
                worst = worst.max((a.rest_z()[i] - b.rest_z()[j]).abs());
                flag_diff += (a.flags()[i] != b.flags()[j]) as usize;
            }
        }
    }
    assert!(worst < 1e-4, "rest heights differ by up to {worst} m");
    assert_eq!(flag_diff, 0);
}

#[test]
fn a_full_box_has_no_feasible_placement_and_the_episode_ends_with_that_reason() {
    let c = common::primitives();
    let spec = *common::world(&c).heightmap().spec();
    // Everything at the rim + 12 cm: no object's top stays 5 mm below the limit.
    let full = Heightmap::from_data(spec, vec![SUCCESS_TOP_Z - 0.01; spec.len()]).unwrap();
    let mut l = Lattice::new(&c);
    l.compute(&full, &c, c.by_id("003").unwrap());
    assert_eq!(l.feasible_count(), 0);
    assert!(l.flags().iter().all(|f| f & BELOW_LIMIT == 0));
    assert!(l.candidates().is_empty());
    assert_eq!(l.blbf(), None);

    // An object larger than the box has no placement inside the walls either: the lattice
    // episode ends at once, failed, with the reason recorded.
    let (c, big) = with_board();
    let mut env = PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
    let mut rule = LatticeRule::Blbf(Box::new(Lattice::new(&c)));
    let ep = herb_sim::boxed::Episode {
        name: "big".into(),
        objects: vec![big],
        human: vec![],
    };
    let r = herb_sim::eval::run_episode(&mut env, &ep, &[big], &mut rule, 0).unwrap();
    assert!(!r.success);
    assert_eq!(r.placements, 0);
    assert_eq!(r.failure.unwrap().bound, NO_FEASIBLE_PLACEMENT);
}

/// **Fixture**: the built-in catalog (primitives) plus a 50 cm x 50 cm board, wider than the
/// box, and the board's type.
fn with_board() -> (SharedCatalog, TypeIdx) {
    let text = format!(
        "{}\n[[object]]\nid = \"900\"\nname = \"test board\"\ndataset_type = \"900 test board\"\n\
         mass_kg = 1.0\nmass_source = \"test fixture\"\nprimitive = \"cuboid\"\n\
         dims_m = [0.5, 0.5, 0.02]\nmesh_scale = 1.0\nup_mesh = [0.0, 0.0, 1.0]\nyaw_rad = 0.0\n\
         origin_mesh_m = [0.0, 0.0, 0.0]\n",
        herb_sim::catalog::BUILTIN_CATALOG
    );
    let c = herb_sim::Catalog::from_toml(
        &text,
        "test",
        &herb_sim::paths::MeshSource::None("test".into()),
    )
    .unwrap();
    let ty = c.by_id("900").unwrap();
    (std::sync::Arc::new(c), ty)
}

#[test]
fn the_teacher_never_returns_less_than_the_lattice_blbf_rule_and_candidate_0_is_its_rollout() {
    let c = common::primitives();
    let reward = RewardMode::cs(0.6).unwrap();
    let seq: Vec<TypeIdx> = [
        "013", "004", "005", "003", "007", "011", "057", "003", "005", "004",
    ]
    .iter()
    .map(|id| c.by_id(id).unwrap())
    .collect();
    let run = |rule: &mut LatticeRule| {
        let mut env = PackingEnv::new(c.clone(), WorldConfig::default(), reward).unwrap();
        env.reset(&seq, 0).unwrap();
        let mut ret = 0.0;
        while env.next_object().is_some() {
            let Some(p) = rule.decide(&env).unwrap() else {
                ret -= 1.0;
                break;
            };
            let r = env.step_placement(p.x, p.y, p.theta()).unwrap();
            ret += r.reward;
            if r.terminated {
                break;
            }
        }
        ret
    };
    let blbf = run(&mut LatticeRule::Blbf(Box::new(Lattice::new(&c))));
    let teacher = run(&mut LatticeRule::Lookahead(Box::new(Lookahead::new(
        &c, 4, reward,
    ))));
    assert!(teacher >= blbf, "teacher {teacher} < lattice blbf {blbf}");

    // From the empty box, candidate 0's simulated outcome is the lattice BLBF episode.
    let w = common::world(&c);
    let mut t = Lookahead::new(&c, 4, reward);
    let chosen = t.decide(&w, &seq).unwrap().unwrap();
    let outs = t.outcomes().to_vec();
    assert_eq!(outs.len(), 4);
    assert_eq!(outs[0].ret.to_bits(), blbf.to_bits());
    let best = outs.iter().map(|o| o.ret).fold(f32::MIN, f32::max);
    assert!(outs.iter().any(|o| o.placement == chosen && o.ret == best));
    // A rollout run again gives the same bits.
    let mut l = Lattice::new(&c);
    let again = rollout(&mut l, reward, &w, &seq, outs[2].placement).unwrap();
    assert_eq!(again, outs[2]);
}

#[test]
fn cached_footprints_give_the_same_planes_and_candidates_as_rasterising_each_time() {
    let c = common::primitives();
    let w = pile(&c, 7);
    let mut cached = Lattice::new(&c);
    let mut fresh = Lattice::new(&c).without_cache();
    for ty in c.types() {
        cached.compute(w.heightmap(), &c, ty);
        fresh.compute(w.heightmap(), &c, ty);
        let (sa, sb) = (cached.support().to_vec(), fresh.support().to_vec());
        for (a, b) in [
            (cached.rest_z(), fresh.rest_z()),
            (cached.top(), fresh.top()),
            (&sa[..], &sb[..]),
        ] {
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "type {ty:?}"
            );
        }
        assert_eq!(cached.flags(), fresh.flags());
        for k in 0..NUM_YAWS {
            assert_eq!(cached.bounds(k), fresh.bounds(k));
        }
        assert_eq!(cached.candidates(), fresh.candidates(), "type {ty:?}");
    }
}

#[test]
fn raising_a_placement_lifts_exactly_the_cells_under_its_bounding_box() {
    let c = common::primitives();
    let w = common::world(&c);
    let ty = c.by_id("004").unwrap();
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, ty);
    let p = l.blbf().unwrap();
    let (lo, hi) = l.bounds(p.yaw as usize);
    let mut hm = w.heightmap().clone();
    raise_bounding_box(&mut hm, &p, (lo, hi));
    let spec = *hm.spec();
    let mut raised = 0;
    for row in 0..spec.ny {
        for col in 0..spec.nx {
            let (x, y) = spec.cell_centre(col, row);
            let under = x >= p.x + lo.x && x <= p.x + hi.x && y >= p.y + lo.y && y <= p.y + hi.y;
            let h = hm.data()[row * spec.nx + col];
            let before = w.heightmap().data()[row * spec.nx + col];
            if under {
                assert_eq!(h, before.max(p.top), "cell {col} {row}");
                raised += 1;
            } else {
                assert_eq!(h, before, "cell {col} {row}");
            }
        }
    }
    // The footprint's area in cells, within a row and a column of cells.
    let cell = spec.cell;
    let want = ((hi.x - lo.x) / cell) * ((hi.y - lo.y) / cell);
    let slack = (hi.x - lo.x + hi.y - lo.y) / cell + 1.0;
    assert!(
        (raised as f32 - want).abs() <= slack,
        "{raised} cells, about {want}"
    );
}

#[test]
fn the_geometric_teacher_with_one_candidate_places_as_the_lattice_blbf_rule() {
    let c = common::primitives();
    let w = pile(&c, 5);
    let seq: Vec<TypeIdx> = ["013", "004", "005", "003", "007"]
        .iter()
        .map(|id| c.by_id(id).unwrap())
        .collect();
    let mut one = GeoLookahead::new(&c, 1);
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, seq[0]);
    assert_eq!(one.decide(&c, w.heightmap(), &seq), l.blbf());
    // With more candidates: the choice packs at least as many objects (geometrically) as
    // candidate 0, and every outcome counts the candidate itself.
    let mut eight = GeoLookahead::new(&c, 8);
    let choice = eight.decide(&c, w.heightmap(), &seq).unwrap();
    let outs = eight.outcomes();
    assert!(outs.len() > 1);
    assert!(outs.iter().all(|o| (1..=seq.len()).contains(&o.packed)));
    let chosen = outs.iter().find(|o| o.placement == choice).unwrap();
    assert!(chosen.packed >= outs[0].packed);
    // No objects: no decision.
    assert_eq!(eight.decide(&c, w.heightmap(), &[]), None);
}

#[test]
fn a_teacher_with_a_horizon_simulates_that_many_objects_and_the_rollout_of_that_prefix() {
    let c = common::primitives();
    let reward = RewardMode::cs(0.6).unwrap();
    let seq: Vec<TypeIdx> = ["013", "004", "005", "003", "007", "011"]
        .iter()
        .map(|id| c.by_id(id).unwrap())
        .collect();
    let w = common::world(&c);
    let mut t = Lookahead::new(&c, 3, reward).with_horizon(2);
    assert_eq!(t.horizon(), 2);
    t.decide(&w, &seq).unwrap().unwrap();
    let outs = t.outcomes().to_vec();
    assert_eq!(outs.len(), 3);
    let mut l = Lattice::new(&c);
    for o in &outs {
        assert!(o.packed <= 2, "{o:?}");
        // The same as a rollout of the first two objects.
        assert_eq!(
            *o,
            rollout(&mut l, reward, &w, &seq[..2], o.placement).unwrap()
        );
    }
    // A horizon of 0 is taken as 1: the candidate alone.
    let mut one = Lookahead::new(&c, 2, reward).with_horizon(0);
    assert_eq!(one.horizon(), 1);
    one.decide(&w, &seq).unwrap().unwrap();
    assert!(one.outcomes().iter().all(|o| o.packed <= 1));
}

/// The search's clearance (`Lattice::set_push_gap`): on an empty floor every tight candidate is
/// pushed into a corner; with a gap of one fine cell each backs off from both walls by one cell
/// at the same height, and with no gap the candidates are as before.
#[test]
fn a_push_gap_backs_each_tight_candidate_off_its_walls_by_one_fine_cell() {
    use herb_sim::lattice::FINE_CELL_M;
    let c = common::primitives();
    let w = common::world(&c);
    let ty = c.by_id("004").unwrap();
    let tight = |gap| {
        let mut l = Lattice::new(&c);
        l.set_push_gap(gap);
        l.compute(w.heightmap(), &c, ty);
        let mut t: Vec<_> = l.candidates().iter().filter(|p| p.tight).copied().collect();
        t.sort_by_key(|p| (p.yaw, p.node));
        t
    };
    let (none, one) = (tight(0), tight(1));
    assert!(!none.is_empty());
    assert_eq!(none.len(), one.len());
    for (a, b) in none.iter().zip(&one) {
        assert_eq!((a.yaw, a.node), (b.yaw, b.node));
        assert!((a.rest_z - b.rest_z).abs() < 1e-6, "{a:?} {b:?}");
        // One cell nearer the box's centre along each axis.
        assert!(
            ((a.x.abs() - b.x.abs()) - FINE_CELL_M).abs() < 1e-5,
            "{a:?} {b:?}"
        );
        assert!(
            ((a.y.abs() - b.y.abs()) - FINE_CELL_M).abs() < 1e-5,
            "{a:?} {b:?}"
        );
    }
}

/// The search's clearance from the walls above the rim (`Lattice::set_wall_gap`): on an empty
/// floor a tall object (its top above the rim) keeps two fine cells from the walls its tight
/// candidates were pushed against, at the same height; a short one (below the rim, held by the
/// walls) is placed as without the clearance.
#[test]
fn a_wall_gap_keeps_objects_above_the_rim_off_the_walls_and_leaves_the_others() {
    use herb_sim::frames::BOX_HEIGHT;
    use herb_sim::lattice::FINE_CELL_M;
    let c = common::primitives();
    let w = common::world(&c);
    let candidates = |id: &str, gap| {
        let mut l = Lattice::new(&c);
        l.set_wall_gap(gap);
        l.compute(w.heightmap(), &c, c.by_id(id).unwrap());
        let mut t = l.candidates().to_vec();
        t.sort_by_key(|p| (p.yaw, p.node, p.tight));
        t
    };
    // The cracker box stands 21.5 cm, above the 16.4 cm rim.
    let (none, two) = (candidates("003", 0), candidates("003", 2));
    assert!(none.iter().any(|p| p.tight));
    assert_eq!(none.len(), two.len());
    for (a, b) in none.iter().zip(&two) {
        assert!(a.top > BOX_HEIGHT, "{a:?}");
        assert_eq!((a.yaw, a.node, a.tight), (b.yaw, b.node, b.tight));
        assert!((a.rest_z - b.rest_z).abs() < 1e-6, "{a:?} {b:?}");
        assert!(b.x.abs() <= a.x.abs() + 1e-6 && b.y.abs() <= a.y.abs() + 1e-6);
        if a.tight {
            // Against both walls of its corner: two cells nearer the centre along each axis.
            for (da, db) in [(a.x, b.x), (a.y, b.y)] {
                assert!(
                    ((da.abs() - db.abs()) - 2.0 * FINE_CELL_M).abs() < 1e-5,
                    "{a:?} {b:?}"
                );
            }
        }
    }
    // The soup can stands under the rim: the walls hold it, no clearance.
    let (none, two) = (candidates("005", 0), candidates("005", 2));
    assert!(!none.is_empty() && none.iter().all(|p| p.top <= BOX_HEIGHT));
    assert_eq!(none, two);
}
