//! The z estimate: the lowest collision-free height of an object over a heightmap.
//!
//! This is the one implementation, used by the simulation's `place`, the evaluation and the
//! daemon. For an object turned by `theta` about z with its canonical origin at B `(x, y)`, it
//! rasterises the object's bottom surface (downward-facing hull triangles, min z-buffer) at the
//! heightmap's cell centres under its footprint and returns the origin height at which that
//! surface clears every cell: `z = max over cells (H(cell) - bottom(cell))`. Cells outside the
//! grid count as the walls' top ([`crate::heightmap::OUTSIDE_HEIGHT`]). No clearance is added.

use crate::catalog::ObjectShape;
use crate::heightmap::{DepthTest, Heightmap, Window, raster_hull};
use rapier3d::math::{Rotation, Vector};

/// Reusable buffers, so repeated estimates do not allocate once warmed up.
#[derive(Debug, Default, Clone)]
pub struct ZScratch {
    verts: Vec<Vector>,
    buf: Vec<f32>,
}

impl ZScratch {
    /// Buffers sized for `shape` at the heightmap cell `cell` (m), so later estimates of shapes
    /// no larger do not allocate.
    pub fn with_capacity(max_vertices: usize, max_footprint_m: f32, cell: f32) -> Self {
        let side = (max_footprint_m / cell).ceil() as usize + 3;
        Self {
            verts: Vec::with_capacity(max_vertices),
            buf: Vec::with_capacity(side * side),
        }
    }
}

/// Origin height (B z, m) at which `shape`, turned by `theta` and centred at `(x, y)`, rests on
/// `hm` without penetrating it. Inputs must be finite (checked by callers at their boundary).
pub fn estimate_z(
    hm: &Heightmap,
    shape: &ObjectShape,
    x: f32,
    y: f32,
    theta: f32,
    scratch: &mut ZScratch,
) -> f32 {
    estimate_z_rotated(hm, shape, x, y, Rotation::from_rotation_z(theta), scratch)
}

/// As [`estimate_z`] for any orientation `rot` of the canonical frame (e.g. a human's tilted
/// placement).
pub fn estimate_z_rotated(
    hm: &Heightmap,
    shape: &ObjectShape,
    x: f32,
    y: f32,
    rot: Rotation,
    scratch: &mut ZScratch,
) -> f32 {
    let spec = *hm.spec();
    let offset = Vector::new(x, y, 0.0);
    scratch.verts.clear();
    let (mut umin, mut umax, mut vmin, mut vmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    for &v in &shape.vertices {
        let w = rot * v + offset;
        let (u, vv) = spec.to_pixel(w.x, w.y);
        umin = umin.min(u);
        umax = umax.max(u);
        vmin = vmin.min(vv);
        vmax = vmax.max(vv);
        scratch.verts.push(w);
    }
    let win = Window {
        col0: (umin - 0.5).ceil() as isize,
        row0: (vmin - 0.5).ceil() as isize,
        w: 0,
        h: 0,
    };
    let w = ((umax - 0.5).floor() as isize - win.col0 + 1).max(0) as usize;
    let h = ((vmax - 0.5).floor() as isize - win.row0 + 1).max(0) as usize;
    let win = Window { w, h, ..win };
    let lowest = scratch.verts.iter().map(|v| v.z).fold(f32::MAX, f32::min);
    if w == 0 || h == 0 {
        // Footprint smaller than a cell between centres: use the cell under the origin.
        return hm.sample(x, y) - lowest;
    }
    scratch.buf.clear();
    scratch.buf.resize(w * h, f32::INFINITY);
    raster_hull(
        &spec,
        &mut scratch.buf,
        win,
        &mut scratch.verts,
        &shape.triangles,
        DepthTest::Min,
    );
    let mut z = f32::MIN;
    for r in 0..h {
        for c in 0..w {
            let bottom = scratch.buf[r * w + c];
            if bottom.is_finite() {
                let ground = hm.get(win.col0 + c as isize, win.row0 + r as isize);
                z = z.max(ground - bottom);
            }
        }
    }
    if z == f32::MIN {
        hm.sample(x, y) - lowest
    } else {
        z
    }
}
