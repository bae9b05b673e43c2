//! The z estimate: the lowest collision-free height of an object over a heightmap.
//!
//! This is the one implementation, used by the simulation's `place`, the evaluation and the
//! daemon. For an object turned by `theta` about z with its canonical origin at B `(x, y)`, it
//! rasterises the object's bottom surface (downward-facing hull triangles, min z-buffer) at the
//! heightmap's cell centres under its footprint and returns the origin height at which that
//! surface clears every cell: `z = max over cells (H(cell) - bottom(cell))`. Cells outside the
//! grid count as the walls' top ([`crate::heightmap::OUTSIDE_HEIGHT`]). No clearance is added.

use crate::catalog::ObjectShape;
use crate::heightmap::{DepthTest, GridSpec, Heightmap, Window, raster_hull};
use parry3d::math::{Pose, Rotation, Vector};

/// Reusable buffers, so repeated estimates do not allocate once warmed up. After
/// [`bottom_footprint`] it holds the object's bottom surface under its footprint.
#[derive(Debug, Default, Clone)]
pub struct ZScratch {
    verts: Vec<Vector>,
    buf: Vec<f32>,
    win: Option<Window>,
    lowest: f32,
    top: f32,
}

impl ZScratch {
    /// Buffers sized for `shape` at the heightmap cell `cell` (m), so later estimates of shapes
    /// no larger do not allocate.
    pub fn with_capacity(max_vertices: usize, max_footprint_m: f32, cell: f32) -> Self {
        let side = (max_footprint_m / cell).ceil() as usize + 3;
        Self {
            verts: Vec::with_capacity(max_vertices),
            buf: Vec::with_capacity(side * side),
            win: None,
            lowest: 0.0,
            top: 0.0,
        }
    }

    /// Buffers sized for every shape of `catalog` at the heightmap cell `cell` (m).
    pub fn for_catalog(catalog: &crate::Catalog, cell: f32) -> Self {
        let max_verts = catalog
            .types()
            .map(|t| catalog.shape(t).vertices.len())
            .max()
            .unwrap_or(0);
        let max_foot = catalog
            .types()
            .map(|t| {
                let e = catalog.shape(t).extents();
                (e.x * e.x + e.y * e.y).sqrt()
            })
            .fold(0.0, f32::max);
        Self::with_capacity(max_verts, max_foot, cell)
    }

    /// Lowest vertex z relative to the origin, of the last footprint (m, <= 0 for a centred
    /// origin).
    pub fn lowest(&self) -> f32 {
        self.lowest
    }

    /// Highest vertex z relative to the origin, of the last footprint (m).
    pub fn top(&self) -> f32 {
        self.top
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
    bottom_footprint(hm.spec(), shape, x, y, rot, scratch);
    rest_height(hm, scratch, 0, 0).unwrap_or_else(|| hm.sample(x, y) - scratch.lowest)
}

/// Rasterises the bottom surface of `shape` in orientation `rot` with its origin at `(x, y)`
/// on grid `spec` into `scratch` (min z-buffer at the cell centres under the footprint,
/// relative to the origin).
pub fn bottom_footprint(
    spec: &GridSpec,
    shape: &ObjectShape,
    x: f32,
    y: f32,
    rot: Rotation,
    scratch: &mut ZScratch,
) {
    let offset = Vector::new(x, y, 0.0);
    scratch.verts.clear();
    let (mut umin, mut umax, mut vmin, mut vmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let (mut lowest, mut top) = (f32::MAX, f32::MIN);
    for &v in &shape.vertices {
        let w = rot * v + offset;
        let (u, vv) = spec.to_pixel(w.x, w.y);
        umin = umin.min(u);
        umax = umax.max(u);
        vmin = vmin.min(vv);
        vmax = vmax.max(vv);
        lowest = lowest.min(w.z);
        top = top.max(w.z);
        scratch.verts.push(w);
    }
    scratch.lowest = lowest;
    scratch.top = top;
    let col0 = (umin - 0.5).ceil() as isize;
    let row0 = (vmin - 0.5).ceil() as isize;
    let w = ((umax - 0.5).floor() as isize - col0 + 1).max(0) as usize;
    let h = ((vmax - 0.5).floor() as isize - row0 + 1).max(0) as usize;
    if w == 0 || h == 0 {
        // Footprint smaller than a cell between centres: no cell centre under it.
        scratch.win = None;
        return;
    }
    let win = Window { col0, row0, w, h };
    scratch.buf.clear();
    scratch.buf.resize(w * h, f32::INFINITY);
    raster_hull(
        spec,
        &mut scratch.buf,
        win,
        &mut scratch.verts,
        &shape.triangles,
        DepthTest::Min,
    );
    scratch.win = Some(win);
}

/// The origin height at which the footprint last rasterised into `scratch`, moved by `dcol`
/// columns (+x) and `drow` rows (-y), rests on `hm`: `max over cells (H - bottom)`. Equal to
/// the estimate at the moved position when `hm` has the grid the footprint was rasterised on.
/// `None` when no cell centre lies under the footprint.
pub fn rest_height(hm: &Heightmap, scratch: &ZScratch, dcol: isize, drow: isize) -> Option<f32> {
    let win = scratch.win?;
    let mut z = f32::MIN;
    if let Some((c0, r0)) = inside_grid(hm, win, dcol, drow) {
        // Fast path, the window within the grid: cells off the footprint hold +inf, so
        // `ground - bottom` is -inf there and never the maximum.
        let nx = hm.spec().nx;
        for r in 0..win.h {
            let fp = &scratch.buf[r * win.w..(r + 1) * win.w];
            let start = (r0 + r) * nx + c0;
            let ground = &hm.data()[start..start + win.w];
            for (&g, &b) in ground.iter().zip(fp) {
                let d = g - b;
                z = if d > z { d } else { z };
            }
        }
    } else {
        for r in 0..win.h {
            let row = &scratch.buf[r * win.w..(r + 1) * win.w];
            let gr = win.row0 + drow + r as isize;
            for (c, &bottom) in row.iter().enumerate() {
                if bottom.is_finite() {
                    let ground = hm.get(win.col0 + dcol + c as isize, gr);
                    z = z.max(ground - bottom);
                }
            }
        }
    }
    (z != f32::MIN && z.is_finite()).then_some(z)
}

/// The first column and row of `win` moved by `(dcol, drow)`, if the moved window lies
/// entirely within `hm`'s grid.
#[inline]
fn inside_grid(hm: &Heightmap, win: Window, dcol: isize, drow: isize) -> Option<(usize, usize)> {
    let (c0, r0) = (win.col0 + dcol, win.row0 + drow);
    let s = hm.spec();
    (c0 >= 0 && r0 >= 0 && c0 as usize + win.w <= s.nx && r0 as usize + win.h <= s.ny)
        .then_some((c0 as usize, r0 as usize))
}

/// The share of the footprint last rasterised into `scratch`, moved by `dcol` columns and
/// `drow` rows, whose bottom lies within `tol` of `hm` when the origin is at height `z`
/// (usually [`rest_height`]'s): 1 for a flat bottom on a flat surface. 0 when no cell centre
/// lies under the footprint.
pub fn support_fraction(
    hm: &Heightmap,
    scratch: &ZScratch,
    dcol: isize,
    drow: isize,
    z: f32,
    tol: f32,
) -> f32 {
    let Some(win) = scratch.win else {
        return 0.0;
    };
    let (mut cells, mut touching) = (0u32, 0u32);
    if let Some((c0, r0)) = inside_grid(hm, win, dcol, drow) {
        let nx = hm.spec().nx;
        for r in 0..win.h {
            let fp = &scratch.buf[r * win.w..(r + 1) * win.w];
            let start = (r0 + r) * nx + c0;
            let ground = &hm.data()[start..start + win.w];
            for (&g, &b) in ground.iter().zip(fp) {
                // Off the footprint b = +inf: neither a cell nor touching.
                cells += (b < f32::INFINITY) as u32;
                touching += (z + b - g <= tol) as u32;
            }
        }
    } else {
        for r in 0..win.h {
            let row = &scratch.buf[r * win.w..(r + 1) * win.w];
            let gr = win.row0 + drow + r as isize;
            for (c, &bottom) in row.iter().enumerate() {
                if bottom.is_finite() {
                    cells += 1;
                    let ground = hm.get(win.col0 + dcol + c as isize, gr);
                    touching += (z + bottom - ground <= tol) as u32;
                }
            }
        }
    }
    if cells == 0 {
        0.0
    } else {
        touching as f32 / cells as f32
    }
}

/// Min-pools the footprint last rasterised into `src` on grid `src_spec` into `dst` on the
/// grid `dst_spec` (usually coarser): each `dst` cell gets the lowest bottom of the `src`
/// cells whose centres fall inside it. With a heightmap max-pooled the same way
/// ([`Heightmap::max_pool_into`]) and grids whose cell edges align, [`rest_height`] over the
/// pooled pair is never below the estimate at full resolution: every full-resolution cell's
/// `H - bottom` is bounded by its pooled cell's `max H - min bottom`. `shift` moves the source
/// footprint by whole source cells first (the object moved by as many cell sides).
pub fn pool_footprint(
    src_spec: &GridSpec,
    src: &ZScratch,
    shift: (isize, isize),
    dst_spec: &GridSpec,
    dst: &mut ZScratch,
) {
    dst.lowest = src.lowest;
    dst.top = src.top;
    dst.verts.clear();
    let Some(mut win) = src.win else {
        dst.win = None;
        return;
    };
    win.col0 += shift.0;
    win.row0 += shift.1;
    // Destination column of a source column and row of a source row (signed: the window may
    // overhang the grid).
    let dst_col = |col: isize| {
        let x = src_spec.x_min() + (col as f32 + 0.5) * src_spec.cell;
        dst_spec.to_pixel(x, 0.0).0.floor() as isize
    };
    let dst_row = |row: isize| {
        let y = src_spec.y_max() - (row as f32 + 0.5) * src_spec.cell;
        dst_spec.to_pixel(0.0, y).1.floor() as isize
    };
    const MAX: usize = 512;
    let mut cols = [0isize; MAX];
    let direct = win.w <= MAX;
    if direct {
        for (c, d) in cols.iter_mut().enumerate().take(win.w) {
            *d = dst_col(win.col0 + c as isize);
        }
    }
    let (c_lo, r_lo) = (dst_col(win.col0), dst_row(win.row0));
    let (c_hi, r_hi) = (
        dst_col(win.col0 + win.w as isize - 1),
        dst_row(win.row0 + win.h as isize - 1),
    );
    let out = Window {
        col0: c_lo,
        row0: r_lo,
        w: (c_hi - c_lo + 1) as usize,
        h: (r_hi - r_lo + 1) as usize,
    };
    dst.buf.clear();
    dst.buf.resize(out.w * out.h, f32::INFINITY);
    for r in 0..win.h {
        let dr = (dst_row(win.row0 + r as isize) - r_lo) as usize;
        let row = &src.buf[r * win.w..(r + 1) * win.w];
        let drow = &mut dst.buf[dr * out.w..(dr + 1) * out.w];
        for (c, &b) in row.iter().enumerate() {
            if b < f32::INFINITY {
                let dc = if direct {
                    cols[c]
                } else {
                    dst_col(win.col0 + c as isize)
                };
                let d = &mut drow[(dc - c_lo) as usize];
                *d = d.min(b);
            }
        }
    }
    dst.win = Some(out);
}

/// Where an object is released: `shape` at `(x, y, rot)` over `heightmap`, orientation `rot`
/// (normalised), its canonical origin at `(x, y)` and at the estimated resting height
/// ([`estimate_z_rotated`]) plus `clearance_m`. The one release pose: the decision core's
/// (what the arm releases at, herbd's `[models] clearance_m`), the packing world's on its own
/// heightmap, and the search's job twin replaying herbd's releases on the camera's.
pub fn release_pose_on(
    heightmap: &Heightmap,
    shape: &ObjectShape,
    (x, y, rot): (f32, f32, Rotation),
    clearance_m: f32,
    scratch: &mut ZScratch,
) -> Pose {
    let rot = rot.normalize();
    let z = estimate_z_rotated(heightmap, shape, x, y, rot, scratch) + clearance_m;
    Pose::from_parts(Vector::new(x, y, z), rot)
}
