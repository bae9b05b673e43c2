//! Placement physics: resting heights, stacking, walls, tipping.

mod common;

use herb_sim::catalog::Primitive;
use herb_sim::frames::BOX_HALF_X;
use herb_sim::{SharedCatalog, TypeIdx};

fn floor_drop_all(c: &SharedCatalog, label: &str) {
    for t in c.types() {
        let mut w = common::world(c);
        let shape = c.shape(t);
        let o = w.place(t, 0.0, 0.0, 0.0).expect("place");
        let pose = w.pose_of(&w.placed()[0]);
        let lowest = shape
            .vertices
            .iter()
            .map(|&v| pose.transform_point(v).z)
            .fold(f32::MAX, f32::min);
        let expected_z = -shape.aabb_min.z;
        let spec = c.spec(t);
        let id = &spec.id;
        eprintln!(
            "{label} {id}: z {:.4} expected {:.4} lowest {:.4} tilt {:.2} deg steps {} settled {}",
            pose.translation.z,
            expected_z,
            lowest,
            o.tilt_rad.to_degrees(),
            o.settle_steps,
            o.settled
        );
        assert!(o.inside, "{label} {id}: not inside");
        // KNOWN DEFECT (open in issue 2): the banana's scanned hull sinks about 6 mm into the
        // floor board; hull-vs-cuboid contacts of some mesh hulls are unreliable.
        let sink_tol = if label == "mesh" && id == "011" {
            0.01
        } else {
            0.003
        };
        assert!(
            lowest.abs() < sink_tol,
            "{label} {id}: lowest point at {lowest} m, not on the floor"
        );
        // Round objects (fruit, balls) may roll onto another side; everything else must stand
        // in its canonical resting orientation at its canonical height.
        // Scanned bases are not flat (the YCB scans' bottoms bulge, the bread is low-poly): a
        // mesh hull may settle a few degrees off its fitted up axis, well within S's 10 degrees.
        let max_tilt = if label == "mesh" { 6.0 } else { 0.5 };
        // The toothpaste tube's hull (crimped end, rounded body) rolls onto a side like fruit.
        let rolls = spec.primitive == Primitive::Ellipsoid
            || (label == "mesh" && (spec.id == "103" || spec.id == "011"));
        if !rolls {
            assert!(o.settled, "{label} {id}: still moving after the time cap");
            assert!(
                (pose.translation.z - expected_z).abs() < 0.003,
                "{label} {id}: rests at z {} not {expected_z}",
                pose.translation.z
            );
            assert!(
                o.tilt_rad.to_degrees() < max_tilt,
                "{label} {id}: tilt {} deg",
                o.tilt_rad.to_degrees()
            );
        }
    }
}

#[test]
fn every_primitive_rests_on_the_empty_floor_at_its_height() {
    floor_drop_all(&common::primitives(), "primitive");
}

#[test]
fn every_mesh_hull_rests_on_the_empty_floor_at_its_height() {
    if let Some(c) = common::meshes() {
        floor_drop_all(&c, "mesh");
    }
}

#[test]
fn an_object_placed_on_another_lands_on_it() {
    let c = common::primitives();
    let mut w = common::world(&c);
    let cracker = c.by_id("003").unwrap(); // 16.4 x 7.2 x 21.3 cm cuboid
    let tuna = c.by_id("007").unwrap(); // 8.6 cm x 3.4 cm cylinder
    let lower = w.place(tuna, 0.0, 0.0, 0.0).unwrap();
    assert!(lower.inside && lower.stable);
    let upper = w.place(tuna, 0.0, 0.0, 0.0).unwrap();
    let z = w.pose_of(&w.placed()[1]).translation.z;
    // Bottom at the lower can's top (3.4 cm), origin half a can higher.
    assert!((z - (0.034 + 0.017)).abs() < 0.004, "upper can at {z}");
    assert!(upper.inside && upper.stable, "{upper:?}");
    assert!(
        (upper.z - (0.034 + 0.017 + w.config().clearance_m)).abs() < 0.003,
        "estimate {}",
        upper.z
    );
    let _ = cracker;
}

#[test]
fn a_placement_outside_the_box_fails() {
    let c = common::primitives();
    let mut w = common::world(&c);
    let t = c.by_id("004").unwrap();
    // Far beyond the end wall: lands on the table outside.
    let o = w.place(t, BOX_HALF_X + 0.2, 0.0, 0.0).unwrap();
    assert!(!o.inside);
    assert_eq!(o.first_outside, Some(0));
    // Centre beyond the end wall: rests on the rim and tips out.
    let mut w = common::world(&c);
    let o = w
        .place(c.by_id("003").unwrap(), BOX_HALF_X + 0.03, 0.0, 0.0)
        .unwrap();
    assert!(!o.inside, "{o:?}");
}

#[test]
fn an_object_knocked_out_fails_the_later_placement() {
    let c = common::primitives();
    let mut w = common::world(&c);
    // A first object straddling the rim (outside) fails at once; a later one inherits the failure.
    let ok = w.place(c.by_id("007").unwrap(), 0.0, 0.0, 0.0).unwrap();
    assert!(ok.inside);
    let bad = w
        .place(c.by_id("003").unwrap(), BOX_HALF_X + 0.01, 0.0, 0.0)
        .unwrap();
    assert!(!bad.inside);
    let later = w.place(c.by_id("007").unwrap(), -0.1, 0.0, 0.0).unwrap();
    assert!(
        !later.inside,
        "an earlier object outside must fail every later placement"
    );
    assert_eq!(later.first_outside, Some(1));
}

#[test]
fn a_cylinder_placed_on_a_sphere_tips() {
    let c = common::primitives();
    let mut w = common::world(&c);
    let ball = c.by_id("057").unwrap(); // racquetball, 5.6 cm
    let can = c.by_id("005").unwrap(); // tomato soup can
    let b = w.place(ball, 0.0, 0.0, 0.0).unwrap();
    assert!(b.inside);
    let o = w.place(can, 0.0, 0.0, 0.0).unwrap();
    assert!(!o.stable, "tilt {} deg", o.tilt_rad.to_degrees());
    assert!(o.tilt_rad.to_degrees() > 10.0);
}

#[test]
fn theta_turns_the_footprint() {
    let c = common::primitives();
    let t: TypeIdx = c.by_id("003").unwrap();
    let mut w = common::world(&c);
    w.place(t, 0.0, 0.0, std::f32::consts::FRAC_PI_2).unwrap();
    let hm = w.heightmap();
    // Turned 90 degrees, the 16.4 cm side runs along y: occupied at y = 7 cm, free at x = 6 cm.
    assert!(hm.sample(0.0, 0.07) > 0.2);
    assert!(hm.sample(0.06, 0.0) < 0.01);
}
