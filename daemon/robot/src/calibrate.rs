//! Cell calibration by touch: the box pose for the `[cell]` table of herbd's config
//! ([`crate::cell::CellConfig`]), computed from gripper positions an operator touched.
//!
//! The operator moves the gripper (pointing down) until its tip touches each inner floor
//! corner of the box in turn and records the joint angles; [`tip_in_base`] turns each record
//! into a point in Baxter's `base` frame, [`box_from_corners`] fits the box frame B to the
//! points and [`cell_toml`] renders the result as lines to paste under `[cell]`. The pick
//! station's `pick_origin` is the tip touching the centre of its surface, as is.
//!
//! Corner order, in the box frame B (x along the long side, `herb_core::frames`): corner 1 at
//! (-x, -y), corner 2 at (+x, -y) (along the long side from corner 1), corner 3 at (+x, +y),
//! optionally corner 4 at (-x, +y); that is, counter-clockwise seen from above. The box's
//! inner length and width (`2 * BOX_HALF_X`, `2 * BOX_HALF_Y` in `herb_core::frames`) are
//! parameters here: this crate does not depend on the simulator.

use crate::kinematics::{Arm, DOF};
use nalgebra::{Rotation2, Vector2, Vector3};

/// Tolerance of the fit (m): each measured side against the expected dimension, the spread of
/// the corners' heights, and each corner's distance from the fitted rectangle.
pub const TOLERANCE_M: f64 = 0.02;

/// Why touched corners gave no box pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// Not 3 or 4 corners.
    #[error("{got} corners touched; 3 or 4 needed (1: -x-y, 2: +x-y, 3: +x+y, 4: -x+y)")]
    CornerCount {
        /// Corners given.
        got: usize,
    },
    /// A coordinate or a dimension that is not a finite number (or a dimension not positive).
    #[error("{what} is not finite (or not a positive dimension)")]
    NotFinite {
        /// Which value: `corner N` or the dimension's name.
        what: String,
    },
    /// A measured side more than [`TOLERANCE_M`] from the expected dimension.
    #[error(
        "{side}: measured {measured_m:.4} m, expected {expected_m:.4} m (tolerance {TOLERANCE_M} m); wrong corner order or wrong box?"
    )]
    Side {
        /// The side, named by its corners, e.g. `long side 1-2`.
        side: &'static str,
        /// Its measured length (m, horizontal).
        measured_m: f64,
        /// The expected inner dimension (m).
        expected_m: f64,
    },
    /// The corners are not at one height within [`TOLERANCE_M`].
    #[error(
        "corner heights spread over {spread_m:.4} m (lowest {lowest_m:.4}, highest {highest_m:.4}; tolerance {TOLERANCE_M} m)"
    )]
    Height {
        /// Highest minus lowest z (m).
        spread_m: f64,
        /// Lowest corner z (m).
        lowest_m: f64,
        /// Highest corner z (m).
        highest_m: f64,
    },
    /// The corners go round clockwise seen from above: corner 3 is on the wrong side of
    /// the line from corner 1 to corner 2.
    #[error(
        "corners touched clockwise; touch 1: -x-y, 2: +x-y, 3: +x+y, 4: -x+y (counter-clockwise from above)"
    )]
    Clockwise,
    /// A corner farther than [`TOLERANCE_M`] from the fitted rectangle (not a right angle).
    #[error(
        "corner {corner} is {deviation_m:.4} m from the fitted rectangle (tolerance {TOLERANCE_M} m)"
    )]
    NotRectangular {
        /// The corner (1-based).
        corner: usize,
        /// Its distance from its place on the fitted rectangle (m).
        deviation_m: f64,
    },
}

/// The box pose fitted to touched corners, with its residuals.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxFit {
    /// Origin of the box frame B in `base` (m): the centre of the fitted rectangle, at the
    /// corners' mean height. `CellConfig::box_origin`.
    pub box_origin: [f64; 3],
    /// Yaw of B about `base` z (rad, in `-pi..=pi`): direction of the long side from corner 1
    /// to corner 2 (averaged with corner 4 to corner 3 when 4 corners were touched).
    /// `CellConfig::box_yaw`.
    pub box_yaw: f64,
    /// Measured long side (m, horizontal; mean of sides 1-2 and 4-3 when 4 corners).
    pub long_side_m: f64,
    /// Measured short side (m, horizontal; mean of sides 2-3 and 1-4 when 4 corners).
    pub short_side_m: f64,
    /// Expected long side: the inner length given (m).
    pub inner_length_m: f64,
    /// Expected short side: the inner width given (m).
    pub inner_width_m: f64,
    /// Each corner's distance (3-D, m) from its place on the fitted rectangle (measured
    /// sides, `box_yaw`, `box_origin`), in touch order.
    pub corner_deviations_m: Vec<f64>,
}

impl BoxFit {
    /// The largest of [`Self::corner_deviations_m`] (m).
    pub fn max_corner_deviation_m(&self) -> f64 {
        self.corner_deviations_m.iter().copied().fold(0.0, f64::max)
    }
}

/// Position in `base` (m) of the point the gripper touches with joint angles `q`: the
/// endpoint (the translation of [`Arm::fk`], `left_gripper`) moved `tip_offset_m` along the
/// gripper's approach axis (its z axis, pointing out of the gripper, down when it points
/// down). Use a positive offset when the touching tip (e.g. closed finger tips) lies beyond
/// the endpoint, so below it for a gripper pointing down; 0.0 takes the endpoint itself.
pub fn tip_in_base(arm: &Arm, q: &[f64; DOF], tip_offset_m: f64) -> [f64; 3] {
    let pose = arm.fk(q);
    let p = pose.translation.vector + pose.rotation * Vector3::z() * tip_offset_m;
    [p.x, p.y, p.z]
}

/// Signs of corners 1..4 in B: (-x,-y), (+x,-y), (+x,+y), (-x,+y).
const SIGNS: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

/// Fits the box frame B to the inner floor corners touched in order (see the module
/// documentation: 1 at (-x,-y), 2 at (+x,-y), 3 at (+x,+y), optionally 4 at (-x,+y); points in
/// `base`, m), for a box of inner `inner_length` (along x) by `inner_width` (along y).
///
/// The yaw is the direction of the long side 1-2 (averaged with 4-3); the measured sides are
/// the horizontal lengths (averaged over opposite sides with 4 corners); the origin is the
/// centre of the rectangle with those sides and that yaw fitted to the corners by least
/// squares (the corners' centroid with 4), at the corners' mean height.
///
/// Errors: not 3 or 4 corners, a non-finite value, any side more than [`TOLERANCE_M`] from
/// its dimension, corner heights spread by more than [`TOLERANCE_M`], corners touched
/// clockwise, or a corner more than [`TOLERANCE_M`] from the fitted rectangle.
pub fn box_from_corners(
    corners: &[[f64; 3]],
    inner_length: f64,
    inner_width: f64,
) -> Result<BoxFit, CalibrationError> {
    let n = corners.len();
    if !(3..=4).contains(&n) {
        return Err(CalibrationError::CornerCount { got: n });
    }
    for (name, v) in [("inner_length", inner_length), ("inner_width", inner_width)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(CalibrationError::NotFinite { what: name.into() });
        }
    }
    if let Some(i) = corners
        .iter()
        .position(|c| c.iter().any(|v| !v.is_finite()))
    {
        return Err(CalibrationError::NotFinite {
            what: format!("corner {}", i + 1),
        });
    }

    let (lowest, highest) = corners
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c[2]), hi.max(c[2]))
        });
    if highest - lowest > TOLERANCE_M {
        return Err(CalibrationError::Height {
            spread_m: highest - lowest,
            lowest_m: lowest,
            highest_m: highest,
        });
    }

    let xy: Vec<Vector2<f64>> = corners.iter().map(|c| Vector2::new(c[0], c[1])).collect();
    let z = corners.iter().map(|c| c[2]).sum::<f64>() / n as f64;

    // Sides as (name, from, to, expected); long sides point along +x of B, short along +y.
    let mut long = vec![("long side 1-2", 0, 1)];
    let mut short = vec![("short side 2-3", 1, 2)];
    if n == 4 {
        long.push(("long side 4-3", 3, 2));
        short.push(("short side 1-4", 0, 3));
    }
    let check = |sides: &[(&'static str, usize, usize)], expected: f64| {
        let mut sum = 0.0;
        for &(side, a, b) in sides {
            let measured = (xy[b] - xy[a]).norm();
            if (measured - expected).abs() > TOLERANCE_M {
                return Err(CalibrationError::Side {
                    side,
                    measured_m: measured,
                    expected_m: expected,
                });
            }
            sum += measured;
        }
        Ok(sum / sides.len() as f64)
    };
    let long_side = check(&long, inner_length)?;
    let short_side = check(&short, inner_width)?;

    let d12 = xy[1] - xy[0];
    let d23 = xy[2] - xy[1];
    if d12.perp(&d23) <= 0.0 {
        return Err(CalibrationError::Clockwise);
    }

    let dir: Vector2<f64> = long
        .iter()
        .map(|&(_, a, b)| (xy[b] - xy[a]).normalize())
        .sum();
    let yaw = dir.y.atan2(dir.x);
    let rot = Rotation2::new(yaw);

    // Offsets of the corners from the centre, in `base`.
    let half = Vector2::new(0.5 * long_side, 0.5 * short_side);
    let offsets: Vec<Vector2<f64>> = SIGNS[..n]
        .iter()
        .map(|s| rot * Vector2::new(s[0] * half.x, s[1] * half.y))
        .collect();
    let centre = xy
        .iter()
        .zip(&offsets)
        .map(|(p, o)| p - o)
        .sum::<Vector2<f64>>()
        / n as f64;

    let corner_deviations: Vec<f64> = corners
        .iter()
        .zip(&offsets)
        .map(|(c, o)| {
            let fitted = centre + o;
            Vector3::new(c[0] - fitted.x, c[1] - fitted.y, c[2] - z).norm()
        })
        .collect();
    if let Some((i, &d)) = corner_deviations
        .iter()
        .enumerate()
        .find(|&(_, &d)| d > TOLERANCE_M)
    {
        return Err(CalibrationError::NotRectangular {
            corner: i + 1,
            deviation_m: d,
        });
    }

    Ok(BoxFit {
        box_origin: [centre.x, centre.y, z],
        box_yaw: yaw,
        long_side_m: long_side,
        short_side_m: short_side,
        inner_length_m: inner_length,
        inner_width_m: inner_width,
        corner_deviations_m: corner_deviations,
    })
}

/// Keys of the `[cell]` table from a fit: a comment line with the residuals, then
/// `box_origin`, `box_yaw` and, when given, `pick_origin` (`base`, m and rad, 4 decimals), one
/// per line, each line ending in a newline. No table header: the lines go under `[cell]`,
/// replacing the keys there.
pub fn cell_toml(fit: &BoxFit, pick: Option<[f64; 3]>) -> String {
    let v = |p: [f64; 3]| format!("[{:.4}, {:.4}, {:.4}]", p[0], p[1], p[2]);
    let mut s = format!(
        "# touched {} corners: long side {:.4} m (expected {:.4}, {:+.4}), short side {:.4} m (expected {:.4}, {:+.4}), max corner deviation {:.4} m\n",
        fit.corner_deviations_m.len(),
        fit.long_side_m,
        fit.inner_length_m,
        fit.long_side_m - fit.inner_length_m,
        fit.short_side_m,
        fit.inner_width_m,
        fit.short_side_m - fit.inner_width_m,
        fit.max_corner_deviation_m(),
    );
    s += &format!("box_origin = {}\n", v(fit.box_origin));
    s += &format!("box_yaw = {:.4}\n", fit.box_yaw);
    if let Some(p) = pick {
        s += &format!("pick_origin = {}\n", v(p));
    }
    s
}
