//! The default cell is reachable: every placement over the box interior (heights from the
//! floor to the rim, any yaw) and every grasp of every catalog object plans to joint targets
//! within the configured limits, and the planned poses are where the object should go.

use herb_core::Catalog;
use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT};
use herb_core::paths::MeshSource;
use herb_robot::cell::{CellConfig, plan_waypoints};
use herb_robot::kinematics::{Arm, IkOptions, LEFT_TOP_DOWN_NOMINAL};
use herb_robot::motion::JointLimits;
use nalgebra::{Point3, Vector3};

fn arm(l: &JointLimits) -> Arm {
    Arm::baxter_left().with_limits(&l.lower, &l.upper)
}

#[test]
fn every_placement_over_the_box_is_reachable() {
    let cell = CellConfig::default();
    let limits = JointLimits::baxter_left();
    let arm = arm(&limits);
    let opts = IkOptions::default();
    let catalog = Catalog::builtin(&MeshSource::None("test".into())).unwrap();
    let mut n = 0;
    for t in catalog.types() {
        let h = catalog.shape(t).extents().z as f64;
        for ix in -2..=2 {
            for iy in -2..=2 {
                for iz in 0..=2 {
                    for iyaw in -2..=2 {
                        let x = ix as f64 / 2.0 * (BOX_HALF_X as f64 - 0.03);
                        let y = iy as f64 / 2.0 * (BOX_HALF_Y as f64 - 0.03);
                        let z = 0.5 * h + iz as f64 / 2.0 * (BOX_HEIGHT as f64 - 0.5 * h).max(0.0);
                        let yaw = iyaw as f64 * std::f64::consts::FRAC_PI_2;
                        let w = plan_waypoints(
                            &cell,
                            &arm,
                            &opts,
                            h,
                            [x, y, z, yaw],
                            &LEFT_TOP_DOWN_NOMINAL,
                            herb_core::frames::SUCCESS_TOP_Z as f64,
                        )
                        .unwrap_or_else(|e| {
                            panic!(
                                "{} at ({x:.3}, {y:.3}, {z:.3}, {yaw:.2}): {e}",
                                catalog.spec(t).id
                            )
                        });
                        for q in [w.pre_grasp, w.grasp, w.pre_place, w.place] {
                            assert!(limits.contains(&q));
                        }
                        // The release pose: gripper endpoint above the object's origin.
                        let p = arm.fk(&w.place);
                        let want = cell.box_pose() * Point3::new(x, y, z + 0.5 * h - cell.depth(h));
                        assert!((p.translation.vector - want.coords).norm() < 1e-3);
                        assert!((p.rotation * Vector3::z()).z < -0.9999, "points down");
                        n += 1;
                    }
                }
            }
        }
    }
    assert_eq!(n, catalog.len() * 375);
}
