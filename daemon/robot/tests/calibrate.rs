//! Cell calibration by touch: a synthetic box at a known pose recovered from noisy corners
//! (4 and 3), bad corner sets rejected with the reason, the `[cell]` lines parsed back, and
//! the touched tip through IK and FK.

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_robot::calibrate::{CalibrationError, box_from_corners, cell_toml, tip_in_base};
use herb_robot::cell::CellConfig;
use herb_robot::kinematics::{Arm, IkOptions, LEFT_TOP_DOWN_NOMINAL};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ORIGIN: [f64; 3] = [0.6, 0.3, -0.25];
const YAW: f64 = 0.1;

fn dims() -> (f64, f64) {
    (2.0 * BOX_HALF_X as f64, 2.0 * BOX_HALF_Y as f64)
}

/// The four inner floor corners in touch order, each moved by up to `noise` (m) per axis.
fn corners(origin: [f64; 3], yaw: f64, noise: f64, seed: u64) -> Vec<[f64; 3]> {
    let (l, w) = dims();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (s, c) = yaw.sin_cos();
    [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
        .iter()
        .map(|[sx, sy]| {
            let (x, y) = (0.5 * l * sx, 0.5 * w * sy);
            let mut n = || {
                if noise > 0.0 {
                    rng.random_range(-noise..=noise)
                } else {
                    0.0
                }
            };
            [
                origin[0] + c * x - s * y + n(),
                origin[1] + s * x + c * y + n(),
                origin[2] + n(),
            ]
        })
        .collect()
}

fn assert_pose(fit: &herb_robot::calibrate::BoxFit, origin: [f64; 3], yaw: f64, yaw_tol: f64) {
    for k in 0..3 {
        assert!(
            (fit.box_origin[k] - origin[k]).abs() < 0.005,
            "origin {:?} vs {origin:?}",
            fit.box_origin
        );
    }
    assert!(
        (fit.box_yaw - yaw).abs() < yaw_tol,
        "yaw {} vs {yaw}",
        fit.box_yaw
    );
}

#[test]
fn four_exact_corners_give_the_pose_exactly() {
    let (l, w) = dims();
    let fit = box_from_corners(&corners(ORIGIN, YAW, 0.0, 0), l, w).unwrap();
    assert_pose(&fit, ORIGIN, YAW, 1e-12);
    for (a, b) in fit.box_origin.iter().zip(ORIGIN) {
        assert!((a - b).abs() < 1e-12);
    }
    assert!((fit.long_side_m - l).abs() < 1e-12);
    assert!((fit.short_side_m - w).abs() < 1e-12);
    assert!(fit.max_corner_deviation_m() < 1e-12);
    assert_eq!(fit.corner_deviations_m.len(), 4);
}

#[test]
fn four_noisy_corners_give_the_pose_within_5_mm_and_0_01_rad() {
    let (l, w) = dims();
    for seed in 0..50 {
        let fit = box_from_corners(&corners(ORIGIN, YAW, 0.002, seed), l, w).unwrap();
        assert_pose(&fit, ORIGIN, YAW, 0.01);
        assert!((fit.long_side_m - l).abs() < 0.006);
        assert!((fit.short_side_m - w).abs() < 0.006);
        assert!(fit.max_corner_deviation_m() < 0.01);
    }
}

#[test]
fn three_noisy_corners_are_enough() {
    let (l, w) = dims();
    for seed in 0..50 {
        let c = corners(ORIGIN, YAW, 0.002, seed);
        let fit = box_from_corners(&c[..3], l, w).unwrap();
        // The yaw comes from side 1-2 alone: up to 2 * sqrt(2) * 2 mm / 0.346 m = 0.016 rad.
        assert_pose(&fit, ORIGIN, YAW, 0.017);
        assert_eq!(fit.corner_deviations_m.len(), 3);
    }
}

#[test]
fn any_yaw_is_recovered_including_across_pi() {
    let (l, w) = dims();
    for yaw in [-3.1, -1.6, -0.4, 0.0, 1.2, 2.9, std::f64::consts::PI - 1e-3] {
        let fit = box_from_corners(&corners(ORIGIN, yaw, 0.0, 0), l, w).unwrap();
        assert_pose(&fit, ORIGIN, yaw, 1e-9);
    }
}

#[test]
fn fewer_than_three_or_more_than_four_corners_are_rejected() {
    let (l, w) = dims();
    let c = corners(ORIGIN, YAW, 0.0, 0);
    assert_eq!(
        box_from_corners(&c[..2], l, w),
        Err(CalibrationError::CornerCount { got: 2 })
    );
    assert_eq!(
        box_from_corners(&[], l, w),
        Err(CalibrationError::CornerCount { got: 0 })
    );
    let mut five = c.clone();
    five.push(c[0]);
    assert_eq!(
        box_from_corners(&five, l, w),
        Err(CalibrationError::CornerCount { got: 5 })
    );
}

#[test]
fn a_wrong_side_length_is_named() {
    let (l, w) = dims();
    let c = corners(ORIGIN, YAW, 0.0, 0);
    // A box 5 cm longer than expected: the first long side is reported.
    match box_from_corners(&c, l - 0.05, w) {
        Err(CalibrationError::Side {
            side,
            measured_m,
            expected_m,
        }) => {
            assert_eq!(side, "long side 1-2");
            assert!((measured_m - l).abs() < 1e-9);
            assert!((expected_m - (l - 0.05)).abs() < 1e-12);
        }
        r => panic!("{r:?}"),
    }
    // Corner 4 touched 3 cm off along -x: the short side 1-4 is still right, long side 4-3
    // is not.
    let mut c4 = c.clone();
    c4[3][0] -= 0.03 * YAW.cos();
    c4[3][1] -= 0.03 * YAW.sin();
    match box_from_corners(&c4, l, w) {
        Err(e @ CalibrationError::Side { side, .. }) => {
            assert_eq!(side, "long side 4-3");
            assert!(e.to_string().contains("long side 4-3"), "{e}");
        }
        r => panic!("{r:?}"),
    }
    // The short side of a three-corner set.
    match box_from_corners(&c[..3], l, w + 0.03) {
        Err(CalibrationError::Side { side, .. }) => assert_eq!(side, "short side 2-3"),
        r => panic!("{r:?}"),
    }
}

#[test]
fn non_finite_values_are_rejected() {
    let (l, w) = dims();
    let mut c = corners(ORIGIN, YAW, 0.0, 0);
    c[2][1] = f64::NAN;
    assert_eq!(
        box_from_corners(&c, l, w),
        Err(CalibrationError::NotFinite {
            what: "corner 3".into()
        })
    );
    let c = corners(ORIGIN, YAW, 0.0, 0);
    assert!(matches!(
        box_from_corners(&c, f64::NAN, w),
        Err(CalibrationError::NotFinite { .. })
    ));
    assert!(matches!(
        box_from_corners(&c, l, f64::INFINITY),
        Err(CalibrationError::NotFinite { .. })
    ));
}

#[test]
fn corners_at_different_heights_are_rejected() {
    let (l, w) = dims();
    let mut c = corners(ORIGIN, YAW, 0.0, 0);
    c[1][2] += 0.03;
    match box_from_corners(&c, l, w) {
        Err(CalibrationError::Height { spread_m, .. }) => {
            assert!((spread_m - 0.03).abs() < 1e-9)
        }
        r => panic!("{r:?}"),
    }
}

#[test]
fn corners_touched_clockwise_are_rejected() {
    let (l, w) = dims();
    let c = corners(ORIGIN, YAW, 0.0, 0);
    // 4, 3, 2, 1 goes round the other way, with the same side lengths.
    let rev = vec![c[3], c[2], c[1], c[0]];
    assert_eq!(
        box_from_corners(&rev, l, w),
        Err(CalibrationError::Clockwise)
    );
}

#[test]
fn a_skewed_corner_set_is_rejected() {
    let (l, w) = dims();
    let c = corners(ORIGIN, 0.0, 0.0, 0);
    // Corner 3 slid 4.5 cm along +x: side 2-3 only 4 mm long, but no right angle.
    let mut s = c[..3].to_vec();
    s[2][0] += 0.045;
    match box_from_corners(&s, l, w) {
        Err(CalibrationError::NotRectangular {
            corner,
            deviation_m,
        }) => {
            assert_eq!(corner, 3);
            assert!((deviation_m - 0.03).abs() < 1e-3, "{deviation_m}");
        }
        r => panic!("{r:?}"),
    }
}

#[derive(serde::Deserialize)]
struct Config {
    cell: CellConfig,
}

#[test]
fn cell_toml_parses_back_into_the_cell_table() {
    let (l, w) = dims();
    let fit = box_from_corners(&corners(ORIGIN, YAW, 0.002, 7), l, w).unwrap();
    let pick = [0.45, 0.65, -0.2512];
    let text = cell_toml(&fit, Some(pick));
    assert!(text.starts_with("# touched 4 corners"), "{text}");
    assert!(
        text.contains("pick_origin = [0.4500, 0.6500, -0.2512]"),
        "{text}"
    );
    let c: Config = toml::from_str(&format!("[cell]\n{text}grasp_depth = 0.02\n")).unwrap();
    c.cell.validate().unwrap();
    for k in 0..3 {
        assert!((c.cell.box_origin[k] - fit.box_origin[k]).abs() <= 5e-5);
    }
    assert!((c.cell.box_yaw - fit.box_yaw).abs() <= 5e-5);
    assert_eq!(c.cell.pick_origin, pick);

    let without = cell_toml(&fit, None);
    assert!(!without.contains("pick_origin"));
    let c: Config = toml::from_str(&format!("[cell]\n{without}")).unwrap();
    assert_eq!(c.cell.pick_origin, CellConfig::default().pick_origin);
}

#[test]
fn the_touched_tip_round_trips_through_ik_and_fk() {
    let arm = Arm::baxter_left();
    let opts = IkOptions::default();
    // A top-down touch of a box corner in front of the robot.
    let target = (0.65, 0.3, -0.2);
    let q = arm
        .ik_top_down(target, 0.3, &LEFT_TOP_DOWN_NOMINAL, &opts)
        .unwrap();
    let p = tip_in_base(&arm, &q, 0.0);
    let t = arm.fk(&q).translation.vector;
    assert_eq!(p, [t.x, t.y, t.z]);
    assert!((p[0] - target.0).abs() < 2e-4);
    assert!((p[1] - target.1).abs() < 2e-4);
    assert!((p[2] - target.2).abs() < 2e-4);
    // With the gripper pointing down, a tip 2 cm beyond the endpoint is 2 cm below it.
    let tip = tip_in_base(&arm, &q, 0.02);
    assert!((tip[0] - p[0]).abs() < 1e-4 && (tip[1] - p[1]).abs() < 1e-4);
    assert!((tip[2] - (p[2] - 0.02)).abs() < 1e-4);
}
