//! The one decision path (`Decider`): the same placement the world releases at, carried as the
//! policy chose it, and bad heightmaps refused with a reason, before any policy runs.

use herb_decide::{Blbf, DecideError, Decider, HeightmapView};
use herb_sim::paths::MeshSource;
use herb_sim::{Catalog, ObsLayout, PackingWorld, SharedCatalog, WorldConfig};
use std::sync::Arc;

fn catalog() -> SharedCatalog {
    Arc::new(Catalog::builtin(&MeshSource::None("test".into())).expect("catalog"))
}

/// A few objects already in the box.
fn pile(c: &SharedCatalog) -> PackingWorld {
    let mut w = PackingWorld::new(c.clone(), WorldConfig::default()).expect("world");
    for (id, x, y, th) in [("003", -0.08, 0.05, 0.3), ("004", 0.1, -0.05, 0.0)] {
        w.place(c.by_id(id).unwrap(), x, y, th).expect("place");
    }
    w
}

#[test]
fn the_decided_pose_is_the_one_the_world_releases_at() {
    let c = catalog();
    let mut w = pile(&c);
    let clearance = w.config().clearance_m;
    let mut d = Decider::new(Box::new(Blbf::new()), c.clone(), clearance);
    for id in ["005", "006", "007", "013"] {
        let t = c.by_id(id).unwrap();
        let got = d
            .decide_on(w.heightmap().into(), &[t], 2)
            .expect("decision");
        let [x, y, _] = got.position;
        let want = w.release_pose(t, x, y, got.rotation());
        assert_eq!(got.pose(), want, "{id}");
        // The placement as BLBF chose it, not decoded from an action.
        let shape = c.shape(t);
        let (bx, by, btheta, _) = Blbf::new().best(w.heightmap(), shape).expect("fits");
        let p = got.placement;
        assert_eq!((p.x, p.y, p.theta), (bx, by, btheta), "{id}");
        assert_eq!((x, y, got.theta), (bx, by, btheta), "{id}");
    }
}

#[test]
fn bad_heightmaps_are_refused_with_the_reason() {
    let c = catalog();
    let w = pile(&c);
    let mut d = Decider::new(Box::new(Blbf::new()), c.clone(), 0.005);
    let t = c.by_id("005").unwrap();
    let good: HeightmapView = w.heightmap().into();
    let mut cells = good.cells.to_vec();
    let refused = |d: &mut Decider<Blbf>, v: HeightmapView| match d.decide_on(v, &[t], 0) {
        Err(DecideError::Rejected { reason, .. }) => reason,
        other => panic!("expected a refusal, got {other:?}"),
    };

    cells[7] = f32::NAN;
    let r = refused(
        &mut d,
        HeightmapView {
            cells: &cells,
            ..good
        },
    );
    assert!(r.contains("NaN"), "{r}");
    cells[7] = 2.0;
    let r = refused(
        &mut d,
        HeightmapView {
            cells: &cells,
            ..good
        },
    );
    assert!(r.contains("within"), "{r}");

    let r = refused(
        &mut d,
        HeightmapView {
            nx: good.nx + 1,
            ..good
        },
    );
    assert!(r.contains("the box needs"), "{r}");
    let r = refused(
        &mut d,
        HeightmapView {
            cells: &cells[1..],
            ..good
        },
    );
    assert!(r.contains("values for a"), "{r}");
    let r = refused(
        &mut d,
        HeightmapView {
            cell_m: 0.0,
            ..good
        },
    );
    assert!(r.contains("heightmap"), "{r}");

    // A good frame after the bad ones decides as before.
    assert_eq!(good.cell_m, ObsLayout::CELL_M);
    let first = d.decide_on(good, &[t], 0).expect("decision after refusals");

    // A bad frame after a good one is refused and leaves the good one to decide on.
    cells[7] = f32::NAN;
    let bad = HeightmapView {
        cells: &cells,
        ..good
    };
    assert!(d.observe(bad).is_err());
    assert_eq!(d.decide(&[t], 0).expect("on the good frame"), first);
    // Nothing to place, or nothing observed yet: refused.
    assert!(matches!(
        d.decide(&[], 0),
        Err(DecideError::Rejected { .. })
    ));
    let mut fresh = Decider::new(Box::new(Blbf::new()), c.clone(), 0.005);
    assert!(matches!(
        fresh.decide(&[t], 0),
        Err(DecideError::Rejected { .. })
    ));
}
