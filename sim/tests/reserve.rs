//! Room left for later objects ([`herb_sim::reserve`]), checked against a brute-force oracle.

mod common;

use herb_sim::lattice::{HEIGHT_LIMIT_M, Lattice};
use herb_sim::reserve::{CellRect, Reserve};
use herb_sim::{Heightmap, TypeIdx};

/// The oracle: the lowest top of a `extents`-sized box over every window of `hm` (both
/// yaws), with the cells of `raise` lifted to at least `top`.
fn brute_best_top(hm: &Heightmap, e: (f32, f32, f32), raise: Option<(CellRect, f32)>) -> f32 {
    let spec = *hm.spec();
    let mut h = hm.data().to_vec();
    if let Some((r, top)) = raise {
        for row in r.r0..=r.r1 {
            for col in r.c0..=r.c1 {
                let v = &mut h[row * spec.nx + col];
                *v = v.max(top);
            }
        }
    }
    let cells = |v: f32| (v / spec.cell - 1e-3).ceil().max(1.0) as usize;
    let mut best = f32::INFINITY;
    for (w, d) in [(cells(e.0), cells(e.1)), (cells(e.1), cells(e.0))] {
        if w > spec.nx || d > spec.ny {
            continue;
        }
        for r in 0..=spec.ny - d {
            for c in 0..=spec.nx - w {
                let mut m = f32::NEG_INFINITY;
                for rr in r..r + d {
                    for cc in c..c + w {
                        m = m.max(h[rr * spec.nx + cc]);
                    }
                }
                best = best.min(m + e.2);
            }
        }
    }
    best
}

#[test]
fn the_best_top_after_every_candidate_matches_the_brute_force_oracle() {
    let c = common::primitives();
    let w = common::pile(&c, &["003", "005", "013", "007", "011", "004", "057"]);
    let next = c.by_id("004").unwrap();
    let after: Vec<TypeIdx> = ["005", "003", "013", "057", "011"]
        .iter()
        .map(|id| c.by_id(id).unwrap())
        .collect();
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, next);
    let mut r = Reserve::new();
    r.prepare(l.pooled(), &c, &after);
    // Slot 0 is the object right after the next; then the largest by footprint area.
    assert_eq!(r.count(), 3);
    assert_eq!(r.objects()[0], after[0]);
    let area = |t: TypeIdx| {
        let e = c.shape(t).extents();
        e.x * e.y
    };
    let mut rest: Vec<TypeIdx> = after[1..].to_vec();
    rest.sort_by(|a, b| area(*b).total_cmp(&area(*a)));
    assert_eq!(&r.objects()[1..], &rest[..2]);

    let candidates = l.candidates().to_vec();
    assert!(candidates.len() > 4);
    for (j, &t) in r.objects().iter().enumerate() {
        let e = c.shape(t).extents();
        let e = (e.x, e.y, e.z);
        assert_eq!(
            r.before(j),
            brute_best_top(l.pooled(), e, None),
            "slot {j} before"
        );
        for p in &candidates {
            let rect = Reserve::footprint_cells(l.spec(), l.bounds(p.yaw as usize), p);
            assert_eq!(
                r.after(j, rect, p.top),
                brute_best_top(l.pooled(), e, Some((rect, p.top))),
                "slot {j}, candidate {p:?}"
            );
            assert!(r.after(j, rect, p.top) >= r.before(j));
        }
    }
}

#[test]
fn a_candidate_covering_the_floor_to_the_rim_leaves_no_room() {
    let c = common::primitives();
    let w = common::world(&c);
    let next = c.by_id("004").unwrap();
    let after = [c.by_id("005").unwrap()];
    let mut l = Lattice::new(&c);
    l.compute(w.heightmap(), &c, next);
    let mut r = Reserve::new();
    r.prepare(l.pooled(), &c, &after);
    assert_eq!(r.count(), 1);
    assert!(r.before(0) <= HEIGHT_LIMIT_M, "fits on the empty floor");
    let spec = *l.spec();
    let all = CellRect {
        c0: 0,
        c1: spec.nx - 1,
        r0: 0,
        r1: spec.ny - 1,
    };
    assert!(r.after(0, all, HEIGHT_LIMIT_M) > HEIGHT_LIMIT_M);
    // A placement's footprint cells contain its own node.
    let p = l.candidates()[0];
    let rect = Reserve::footprint_cells(l.spec(), l.bounds(p.yaw as usize), &p);
    let (col, row) = (p.node.0 as usize, p.node.1 as usize);
    assert!(
        (rect.c0..=rect.c1).contains(&col) && (rect.r0..=rect.r1).contains(&row),
        "{rect:?} {p:?}"
    );
    // No later objects: nothing reserved.
    r.prepare(l.pooled(), &c, &[]);
    assert_eq!(r.count(), 0);
}

#[test]
fn the_reserve_of_the_box_turned_half_a_turn_is_the_same() {
    let c = common::primitives();
    let l = Lattice::new(&c);
    let spec = *l.spec();
    // An uneven pooled heightmap (a fixture, not a pack) and the same turned half a turn.
    let data: Vec<f32> = (0..spec.len())
        .map(|i| 0.2 * (((i * 7919) % 101) as f32 / 100.0).powi(3))
        .collect();
    let mut turned = data.clone();
    turned.reverse();
    let (a, b) = (
        Heightmap::from_data(spec, data).unwrap(),
        Heightmap::from_data(spec, turned).unwrap(),
    );
    let after: Vec<TypeIdx> = ["005", "013", "003", "057"]
        .iter()
        .map(|id| c.by_id(id).unwrap())
        .collect();
    let (mut ra, mut rb) = (Reserve::new(), Reserve::new());
    ra.prepare(&a, &c, &after);
    rb.prepare(&b, &c, &after);
    assert_eq!(ra.objects(), rb.objects());
    for j in 0..ra.count() {
        assert_eq!(ra.before(j), rb.before(j));
        for (c0, c1, r0, r1) in [
            (0, 5, 0, 3),
            (10, 17, 4, 12),
            (20, 27, 15, 18),
            (3, 3, 9, 9),
        ] {
            let rect = CellRect { c0, c1, r0, r1 };
            let turned_rect = CellRect {
                c0: spec.nx - 1 - c1,
                c1: spec.nx - 1 - c0,
                r0: spec.ny - 1 - r1,
                r1: spec.ny - 1 - r0,
            };
            for top in [0.05, 0.15, 0.3] {
                assert_eq!(
                    ra.after(j, rect, top),
                    rb.after(j, turned_rect, top),
                    "slot {j}"
                );
            }
        }
    }
}
