//! The camera's pose in the box frame, fitted from a depth image of the **empty** box with its
//! whole rim in view (`herb-camera calibrate`):
//!
//! 1. the pixels are deprojected and the dominant plane found (RANSAC, then least squares on
//!    its inliers): the floor or the table, parallel either way; its normal, turned towards the
//!    camera, is the box's z;
//! 2. along that normal the heights cluster on the table, the floor and the rim's top; the rim
//!    is the highest level with a level `BOX_HEIGHT` below it (the floor);
//! 3. the rim's points, in the floor plane, give the long axis (principal direction: B x) and
//!    the centre (the middle of their extent along both axes);
//! 4. B x's sign is the one closest to the image's +u (`x_hint`), so the box's 180-degree
//!    ambiguity is settled by how the camera is mounted.

use crate::project::{Depth, Intrinsics};
use herb_core::frames::BOX_HEIGHT;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// What the fit did not find in the image.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FitError {
    /// Fewer than 1000 pixels with a depth in range.
    #[error("{0} valid depth pixels: too few")]
    TooFewPixels(usize),
    /// No plane through three of the pixels.
    #[error("no plane found")]
    NoPlane,
    /// No level with a populated level `BOX_HEIGHT` below it.
    #[error("no rim found BOX_HEIGHT above a floor: is the empty box's rim in view?")]
    NoRim,
    /// Fewer than 100 points at the rim's level.
    #[error("{0} rim points: too few")]
    TooFewRimPoints(usize),
}

/// Points within this distance of a plane are its inliers (m).
const PLANE_TOL_M: f64 = 0.003;
/// Height bins for the level search (m).
const BIN_M: f64 = 0.002;
/// A rim point is within this of the rim's level (m).
const RIM_TOL_M: f64 = 0.004;

fn points(depth: &Depth<'_>, intr: &Intrinsics, min_m: f64, max_m: f64) -> Vec<Vector3<f64>> {
    let (w, h) = (intr.width as usize, intr.height as usize);
    let mut out = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            if let Some(d) = depth.depth_m(v * w + u)
                && (min_m..=max_m).contains(&d)
            {
                out.push(Vector3::new(
                    (u as f64 - intr.cx) / intr.fx * d,
                    (v as f64 - intr.cy) / intr.fy * d,
                    d,
                ));
            }
        }
    }
    out
}

/// Least-squares plane through `pts`: unit normal and a point on it.
fn fit_plane(pts: &[&Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let n = pts.len() as f64;
    let c = pts.iter().fold(Vector3::zeros(), |a, p| a + **p) / n;
    let mut cov = Matrix3::zeros();
    for p in pts {
        let d = **p - c;
        cov += d * d.transpose();
    }
    let e = cov.symmetric_eigen();
    let k = e.eigenvalues.imin();
    (e.eigenvectors.column(k).normalize(), c)
}

/// The camera's optical frame in the box frame B (see the module docs); `Err` says what was
/// not found.
pub fn fit_pose(
    depth: &Depth<'_>,
    intr: &Intrinsics,
    min_m: f64,
    max_m: f64,
    x_hint: Vector3<f64>,
) -> Result<Isometry3<f64>, FitError> {
    let pts = points(depth, intr, min_m, max_m);
    if pts.len() < 1000 {
        return Err(FitError::TooFewPixels(pts.len()));
    }
    // 1. Dominant plane: RANSAC on a deterministic subsample.
    let sample: Vec<&Vector3<f64>> = pts.iter().step_by((pts.len() / 4000).max(1)).collect();
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rand = |n: usize| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % n as u64) as usize
    };
    let mut best: Option<(usize, Vector3<f64>, Vector3<f64>)> = None;
    for _ in 0..300 {
        let (a, b, c) = (
            sample[rand(sample.len())],
            sample[rand(sample.len())],
            sample[rand(sample.len())],
        );
        let n = (b - a).cross(&(c - a));
        if n.norm() < 1e-9 {
            continue;
        }
        let n = n.normalize();
        let count = sample
            .iter()
            .filter(|p| (**p - a).dot(&n).abs() < PLANE_TOL_M)
            .count();
        if best.as_ref().is_none_or(|(k, _, _)| count > *k) {
            best = Some((count, n, *a));
        }
    }
    let (_, n0, p0) = best.ok_or(FitError::NoPlane)?;
    let inliers: Vec<&Vector3<f64>> = pts
        .iter()
        .filter(|p| (**p - p0).dot(&n0).abs() < PLANE_TOL_M)
        .collect();
    let (mut n, p0) = fit_plane(&inliers);
    // Towards the camera (the origin of the optical frame).
    if n.dot(&(-p0)) < 0.0 {
        n = -n;
    }
    // 2. Levels along n.
    let heights: Vec<f64> = pts.iter().map(|p| (p - p0).dot(&n)).collect();
    let (lo, hi) = heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    let bins = (((hi - lo) / BIN_M) as usize + 1).min(100_000);
    let mut hist = vec![0usize; bins];
    for &h in &heights {
        hist[(((h - lo) / BIN_M) as usize).min(bins - 1)] += 1;
    }
    let level = |i: usize| lo + (i as f64 + 0.5) * BIN_M;
    let min_count = pts.len() / 200;
    let box_bins = (BOX_HEIGHT as f64 / BIN_M).round() as isize;
    // The highest populated level with a populated level BOX_HEIGHT below it.
    let populated = |i: isize| -> usize {
        (i - 1..=i + 1)
            .filter(|&j| j >= 0 && (j as usize) < bins)
            .map(|j| hist[j as usize])
            .sum()
    };
    let rim_bin = (0..bins as isize)
        .rev()
        .find(|&i| populated(i) >= min_count && populated(i - box_bins) >= min_count)
        .ok_or(FitError::NoRim)?;
    let rim_h = level(rim_bin as usize);
    // Refine the rim level: mean height of the points near it.
    let near: Vec<f64> = heights
        .iter()
        .copied()
        .filter(|h| (h - rim_h).abs() < RIM_TOL_M)
        .collect();
    let rim_h = near.iter().sum::<f64>() / near.len() as f64;
    let floor_h = rim_h - BOX_HEIGHT as f64;
    // 3. Rim points in the plane: principal axis and extent.
    let rim: Vec<Vector3<f64>> = pts
        .iter()
        .zip(&heights)
        .filter(|(_, h)| (*h - rim_h).abs() < RIM_TOL_M)
        .map(|(p, h)| p - n * (h - floor_h))
        .collect();
    if rim.len() < 100 {
        return Err(FitError::TooFewRimPoints(rim.len()));
    }
    let c = rim.iter().fold(Vector3::zeros(), |a, p| a + p) / rim.len() as f64;
    let mut cov = Matrix3::zeros();
    for p in &rim {
        let d = p - c;
        cov += d * d.transpose();
    }
    let e = cov.symmetric_eigen();
    let k = e.eigenvalues.imax();
    let mut x = e.eigenvectors.column(k).into_owned();
    x = (x - n * x.dot(&n)).normalize();
    // 4. B x's sign from the hint.
    if x.dot(&x_hint) < 0.0 {
        x = -x;
    }
    let y = n.cross(&x);
    let (mut ax, mut ay) = (
        (f64::INFINITY, f64::NEG_INFINITY),
        (f64::INFINITY, f64::NEG_INFINITY),
    );
    for p in &rim {
        let (u, v) = ((p - c).dot(&x), (p - c).dot(&y));
        ax = (ax.0.min(u), ax.1.max(u));
        ay = (ay.0.min(v), ay.1.max(v));
    }
    let origin = c + x * (0.5 * (ax.0 + ax.1)) + y * (0.5 * (ay.0 + ay.1));
    // B's axes in C are the columns of c_R_b; B from C is its inverse.
    let c_r_b = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, n]));
    let b_r_c = c_r_b.inverse();
    let t = -(b_r_c * Point3::from(origin)).coords;
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&b_r_c),
    ))
}
