//! Mesh loading (OBJ through `tobj`) and hull reduction.

use crate::catalog::sphere_directions;
use crate::error::{Result, SimError};
use rapier3d::math::Vector;
use std::path::Path;

/// Number of sampling directions used to reduce a hull (plus the 26 axis and diagonal ones).
pub const SUPPORT_DIRECTIONS: usize = 160;

/// All vertex positions of an OBJ file (every object and group), in file units.
pub fn load_obj_vertices(path: &Path) -> Result<Vec<Vector>> {
    let err = |message: String| SimError::Mesh {
        path: path.to_owned(),
        message,
    };
    if !path.is_file() {
        return Err(err("file not found".into()));
    }
    let opts = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj(path, &opts).map_err(|e| err(format!("does not parse: {e}")))?;
    let mut out = Vec::new();
    for m in &models {
        for p in m.mesh.positions.chunks_exact(3) {
            let v = Vector::new(p[0], p[1], p[2]);
            if !v.is_finite() {
                return Err(err(format!("non-finite vertex {v:?}")));
            }
            out.push(v);
        }
    }
    if out.len() < 4 {
        return Err(err(format!(
            "{} vertices; a solid needs at least 4",
            out.len()
        )));
    }
    Ok(out)
}

/// The support points of `points` in a fixed set of directions: the vertices of an inner
/// approximation of the convex hull with at most `SUPPORT_DIRECTIONS + 26` vertices. Keeps the
/// axis-aligned extremes exactly (so extents are preserved) and is deterministic.
pub fn support_points(points: &[Vector]) -> Vec<Vector> {
    let mut dirs = sphere_directions(SUPPORT_DIRECTIONS);
    for i in -1i32..=1 {
        for j in -1i32..=1 {
            for k in -1i32..=1 {
                if (i, j, k) != (0, 0, 0) {
                    dirs.push(Vector::new(i as f32, j as f32, k as f32).normalize());
                }
            }
        }
    }
    let mut idx: Vec<usize> = dirs
        .iter()
        .map(|d| {
            let mut best = 0;
            let mut best_v = f32::MIN;
            for (i, p) in points.iter().enumerate() {
                let v = p.dot(*d);
                if v > best_v {
                    best_v = v;
                    best = i;
                }
            }
            best
        })
        .collect();
    idx.sort_unstable();
    idx.dedup();
    idx.into_iter().map(|i| points[i]).collect()
}
