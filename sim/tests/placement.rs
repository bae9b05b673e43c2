//! Placement physics: resting heights, stacking, walls, tipping.

mod common;

use herb_sim::catalog::Primitive;
use herb_sim::frames::BOX_HALF_X;
use herb_sim::{SharedCatalog, TypeIdx};
use rapier3d::math::Rotation;

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
        // Resting contact, not penetration: within 1 mm of the floor board.
        assert!(
            lowest.abs() < 0.001,
            "{label} {id}: lowest point at {lowest} m, not on the floor"
        );
        // Round objects (fruit, balls) may roll onto another side; everything else must stand
        // in its canonical resting orientation at its canonical height.
        // Scanned bases are not flat (the YCB scans' bottoms bulge, the bread is low-poly): a
        // mesh hull may settle a few degrees off its fitted up axis, well within S's 10 degrees.
        let max_tilt = if label == "mesh" { 6.0 } else { 0.5 };
        let rolls = spec.primitive == Primitive::Ellipsoid;
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

/// A hull in the world: its vertices and outward face normals.
struct WorldHull {
    verts: Vec<rapier3d::math::Vector>,
    normals: Vec<rapier3d::math::Vector>,
    edges: Vec<rapier3d::math::Vector>,
    lo: rapier3d::math::Vector,
    hi: rapier3d::math::Vector,
}

fn world_hull(w: &herb_sim::PackingWorld, p: &herb_sim::world::PlacedObject) -> WorldHull {
    let pose = w.pose_of(p);
    let shape = w.catalog().shape(p.ty);
    let verts: Vec<_> = shape
        .vertices
        .iter()
        .map(|&v| pose.transform_point(v))
        .collect();
    let normals = shape
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| verts[i as usize]);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .filter(|n| n.length_squared() > 0.5)
        .collect();
    let mut pairs: Vec<(u32, u32)> = shape
        .triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let edges = pairs
        .iter()
        .map(|&(a, b)| (verts[b as usize] - verts[a as usize]).normalize_or_zero())
        .collect();
    let lo = verts.iter().fold(verts[0], |a, &v| a.min(v));
    let hi = verts.iter().fold(verts[0], |a, &v| a.max(v));
    WorldHull {
        verts,
        normals,
        edges,
        lo,
        hi,
    }
}

/// Overlap of two hulls' projections on axis `n` (negative: separated along it).
fn projected_overlap(a: &WorldHull, b: &WorldHull, n: rapier3d::math::Vector) -> f32 {
    let span = |h: &WorldHull| {
        h.verts.iter().fold((f32::MAX, f32::MIN), |(lo, hi), v| {
            let d = v.dot(n);
            (lo.min(d), hi.max(d))
        })
    };
    let ((alo, ahi), (blo, bhi)) = (span(a), span(b));
    ahi.min(bhi) - alo.max(blo)
}

/// Penetration depth of two convex hulls by the separating axis theorem: 0 if separated, else
/// the smallest overlap of their projections over both hulls' face normals and, where those
/// leave more than 2 mm, the cross products of their edges (which makes it exact). parry's
/// `query::contact` is not used as the oracle: on these polyhedra its EPA now and then
/// reports 10 cm for a 0.1 mm contact.
fn sat_overlap(a: &WorldHull, b: &WorldHull) -> f32 {
    if a.lo.cmpgt(b.hi).any() || b.lo.cmpgt(a.hi).any() {
        return 0.0;
    }
    let mut depth = f32::MAX;
    for &n in a.normals.iter().chain(&b.normals) {
        depth = depth.min(projected_overlap(a, b, n));
        if depth <= 0.0 {
            return 0.0;
        }
    }
    if depth > 0.002 {
        for &ea in &a.edges {
            for &eb in &b.edges {
                let n = ea.cross(eb);
                if n.length_squared() < 1e-8 {
                    continue;
                }
                depth = depth.min(projected_overlap(a, b, n.normalize()));
                if depth <= 0.0 {
                    return 0.0;
                }
            }
        }
    }
    depth
}

/// Deepest overlap (m) among the placed objects' hulls and between any hull and the floor.
fn deepest_overlap(w: &herb_sim::PackingWorld) -> (f32, String) {
    let hulls: Vec<WorldHull> = w.placed().iter().map(|p| world_hull(w, p)).collect();
    let mut worst = (0.0f32, String::from("none"));
    for (i, a) in hulls.iter().enumerate() {
        if -a.lo.z > worst.0 {
            worst = (-a.lo.z, format!("object {} into the floor", i + 1));
        }
        for (j, b) in hulls.iter().enumerate().skip(i + 1) {
            let d = sat_overlap(a, b);
            if d > worst.0 {
                worst = (d, format!("objects {} and {}", i + 1, j + 1));
            }
        }
    }
    worst
}

/// Regression test of the sinking defect (bodies sank 1-3 cm into the floor and each other
/// while rapier recycled contact points): replaying the humans' 6-DoF placements of the first
/// 40 sessions, as long as everything is inside the box, the deepest overlap after settling
/// (exact SAT depth over all pairs and the floor) is under 1.5 mm at the median and 4 mm at
/// p90, and over 5 mm in at most 2 % of placements. (Piles are chaotic: a 0.01 mm change in a
/// release height moves these quantiles by a few tenths of a millimetre.)
///
/// KNOWN DEFECT, measured 2026-11-23 over all 263 sessions (3102 placements): p50 1.01,
/// p90 2.63, p99 5.24 mm, 41 placements over 5 mm, worst 33.1 mm (wedged piles, e.g. a tuna can
/// pressed into the edge of a pudding box standing on its side); with contact recycling on,
/// the worst was 31.5 mm in the first 6 sessions alone.
#[test]
fn stacked_human_replays_do_not_interpenetrate() {
    let (Some(c), Some(root)) = (common::meshes(), herb_sim::paths::boxed_root_for_tests()) else {
        return;
    };
    let mut worst = (0.0f32, String::new());
    let mut all = Vec::new();
    let names = herb_sim::boxed::list_sessions(&root).expect("sessions");
    for name in names.iter().take(40) {
        let ep = herb_sim::boxed::load_session(&root, name, &c)
            .expect("session")
            .episode(&c);
        let mut w = common::world(&c);
        for (k, (&ty, h)) in ep.objects.iter().zip(&ep.human).enumerate() {
            let o = w.place_rotated(ty, h.x, h.y, h.rotation).expect("place");
            if !o.inside {
                // Out of the box (some human records are): the episode ends, as in the env.
                break;
            }
            let (d, what) = deepest_overlap(&w);
            all.push(d);
            if d > 0.005 {
                eprintln!(
                    "{name} after placement {}: {what} overlap {:.1} mm",
                    k + 1,
                    d * 1e3
                );
            }
            if d > worst.0 {
                worst = (d, format!("{name} after placement {}: {what}", k + 1));
            }
        }
    }
    all.sort_by(f32::total_cmp);
    let q = |p: f64| all[((all.len() - 1) as f64 * p) as usize];
    let over = all.iter().filter(|&&d| d > 0.005).count();
    let summary = format!(
        "{} placements: overlap p50 {:.2} p90 {:.2} p99 {:.2} mm; {over} over 5 mm; deepest {:.1} mm ({})",
        all.len(),
        q(0.5) * 1e3,
        q(0.9) * 1e3,
        q(0.99) * 1e3,
        worst.0 * 1e3,
        worst.1
    );
    eprintln!("{summary}");
    assert!(all.len() > 300, "{summary}");
    assert!(q(0.5) < 0.0015 && q(0.9) < 0.004, "{summary}");
    assert!(over as f64 <= 0.02 * all.len() as f64, "{summary}");
}

#[test]
fn replays_slide_footprints_just_over_a_wall_back_inside() {
    let c = common::primitives();
    let w = common::world(&c);
    let t = c.by_id("004").unwrap(); // sugar box, 9.2 cm along x when theta = 0
    let half = 0.5 * c.shape(t).extents().x;
    let rot = rapier3d::math::Rotation::IDENTITY;
    // 1 cm into the +x wall: slid back to the clearance.
    let (x, y) = w.slide_inside(t, BOX_HALF_X - half + 0.01, 0.0, rot, 0.015);
    let clear = w.config().clearance_m;
    assert!((x - (BOX_HALF_X - half - clear)).abs() < 1e-5, "x {x}");
    assert_eq!(y, 0.0);
    // 5 cm over: beyond the slide, unchanged.
    let far = BOX_HALF_X - half + 0.05;
    assert_eq!(w.slide_inside(t, far, 0.0, rot, 0.015), (far, 0.0));
    // Inside already: unchanged.
    assert_eq!(w.slide_inside(t, 0.01, -0.02, rot, 0.015), (0.01, -0.02));
}

#[test]
fn a_box_released_on_its_side_is_stable_where_it_was_put() {
    let c = common::primitives();
    let mut w = common::world(&c);
    let cracker = c.by_id("003").unwrap();
    // Laid on its long side, as PackIt SO(3) places it: tilt counts from that orientation.
    let side = Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2);
    let o = w.place_rotated(cracker, 0.0, 0.0, side).unwrap();
    assert!(o.inside);
    assert!(o.stable, "tilt {} deg", o.tilt_rad.to_degrees());
    assert!(o.tilt_rad.to_degrees() < 2.0);
    let up = w.pose_of(&w.placed()[0]).rotation * rapier3d::math::Vector::Z;
    assert!(up.z.abs() < 0.05, "its canonical z lies flat: {up:?}");
}

/// The faster settle rules of `WorldConfig` (off by default) end a settle sooner and keep its
/// outcome: an object at rest is measured where it rests, an object out past a wall is out.
#[test]
fn the_settle_rules_end_sooner_with_the_same_outcome() {
    let c = common::primitives();
    let with = |list: &str| {
        let mut cfg = herb_sim::WorldConfig::default();
        cfg.set_all(list).unwrap();
        herb_sim::PackingWorld::new(c.clone(), cfg).unwrap()
    };
    // At rest: a pile of seven, placed as the fixture places them; slower than 2 cm/s for
    // 0.2 s ends a settle before rapier (1 cm/s for 0.2 s, island by island) puts the pile to
    // sleep. Every object in the box ends within 1 cm of where it ends without the rule.
    let ids = ["003", "005", "013", "007", "011", "004", "057"];
    let (mut a, mut b) = (common::world(&c), with("rest_speed_mps=0.02"));
    let (mut steps_a, mut steps_b) = (0, 0);
    for (i, id) in ids.iter().enumerate() {
        let f = i as f32;
        let (t, x, y, th) = (
            c.by_id(id).unwrap(),
            0.1 * (f * 1.7).sin(),
            0.06 * (f * 2.3).cos(),
            0.4 * f,
        );
        let (oa, ob) = (a.place(t, x, y, th).unwrap(), b.place(t, x, y, th).unwrap());
        assert_eq!((oa.inside, oa.stable), (ob.inside, ob.stable), "{id}");
        steps_a += oa.settle_steps;
        steps_b += ob.settle_steps;
    }
    eprintln!("settle steps: {steps_b} with the rule, {steps_a} without");
    assert!(steps_b < steps_a, "{steps_b} steps against {steps_a}");
    // (The fixture knocks one object out onto the table, where it rolls on: compared in the
    // box only.)
    for (pa, pb) in a.placed().iter().zip(b.placed()) {
        let (pa, pb) = (a.pose_of(pa), b.pose_of(pb));
        if pa.translation.x.abs() > BOX_HALF_X {
            continue;
        }
        assert!(
            (pa.translation - pb.translation).length() < 0.01,
            "{pa:?} against {pb:?}"
        );
    }
    // Out past the end wall, below the rim: it cannot come back in.
    let tall = c.by_id("003").unwrap();
    let x = BOX_HALF_X + 0.03;
    let (mut a, mut b) = (
        common::world(&c),
        with("out_past_walls=true,out_check_steps=1"),
    );
    let (oa, ob) = (
        a.place(tall, x, 0.0, 0.0).unwrap(),
        b.place(tall, x, 0.0, 0.0).unwrap(),
    );
    assert!(!oa.inside && !ob.inside, "{oa:?} {ob:?}");
    assert!(ob.settle_steps < oa.settle_steps, "{ob:?} against {oa:?}");
}

/// The search's rollouts' rigid pile (`freeze_settled`): an object released half over a can
/// settles on it (it comes to rest, tilted), and the can does not move by a bit; every object is
/// fixed after its settle. The world's own default leaves the pile live.
#[test]
fn a_rigid_pile_holds_still_under_an_object_released_on_it() {
    let c = common::primitives();
    let mut w = common::world(&c);
    assert!(!w.config().freeze_settled);
    let tuna = c.by_id("007").unwrap();
    let cracker = c.by_id("004").unwrap();
    assert!(w.place(tuna, 0.0, 0.0, 0.0).unwrap().inside);
    let live = w.clone();
    w.freeze_settled();
    let can = w.pose_of(&w.placed()[0]);
    let o = w.place(cracker, 0.06, 0.0, 0.0).unwrap();
    assert!(o.settled, "{o:?}");
    assert_eq!(w.pose_of(&w.placed()[0]), can, "the rigid can moved");
    for p in w.placed() {
        assert!(w.physics().bodies[p.body].is_fixed());
    }
    // The same release on the live pile leaves the objects dynamic.
    let mut live = live;
    live.place(cracker, 0.06, 0.0, 0.0).unwrap();
    // It rests on the can, tilted (24 degrees), which the live pile's release pushed.
    assert!(o.tilt_rad.to_degrees() > 10.0, "{o:?}");
    assert_ne!(live.pose_of(&live.placed()[0]), can);
    assert!(
        live.placed()
            .iter()
            .all(|p| live.physics().bodies[p.body].is_dynamic())
    );
}
