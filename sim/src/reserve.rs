//! Room left for the objects still to come: for each candidate placement of the next object,
//! how low a few of the later objects could still go once it is placed.
//!
//! Most failures of the BLBF rule in a human-like order are capacity failures: a large object
//! comes late and nothing is left where it fits. This module measures, per candidate, what
//! the candidate costs the objects after it, cheaply enough to run inside a decision.
//!
//! # Model
//!
//! - **Reserved objects** (at most [`RESERVE_SLOTS`]): slot 0 is the object right after the
//!   next one; the other slots are the largest of the later objects by footprint area (the
//!   canonical extents x times y), largest first. Missing slots (short jobs) read as "fits,
//!   no cost".
//! - Each reserved object is taken as its upright bounding box (canonical extents), in two
//!   yaws (0 and 90 degrees), on the lattice's pooled heightmap ([`crate::lattice`]): at a
//!   window of `ceil(extent / cell)` cells fully inside the walls its bottom rests on the
//!   window's highest cell and its top is that plus its height. Its **best top** is the lowest
//!   over all windows and both yaws. This is coarser than the lattice (a box, not the hull;
//!   max-pooled cells), so it errs towards "does not fit".
//! - A candidate placement raises every cell its footprint's bounding box overlaps to the
//!   candidate's top. A window overlapping that rectangle then rests at
//!   `max(window, candidate top)`, the others are unchanged, so the best top after the
//!   candidate is found by scanning the windows in ascending order (sorted once per decision)
//!   for the first one not overlapping and the first one overlapping: a handful of steps per
//!   candidate.
//!
//! Allocation happens in [`Reserve::new`] only.

use crate::catalog::{Catalog, TypeIdx};
use crate::heightmap::{GridSpec, Heightmap};
use crate::lattice::{HEIGHT_LIMIT_M, LATTICE_CELL_M, Lattice, Placement};
use rapier3d::math::Vector;

/// Number of later objects whose room is measured.
pub const RESERVE_SLOTS: usize = 3;

/// One reserved object in one yaw: its windows over the pooled heightmap, lowest first.
#[derive(Debug, Clone, Default)]
struct Windows {
    /// Window size in cells (columns, rows).
    size: (usize, usize),
    /// `(resting bottom, first column, first row)` of every window inside the walls, sorted
    /// by bottom.
    sorted: Vec<(f32, u16, u16)>,
}

/// The reserved objects of one decision and their windows (see the module docs).
#[derive(Debug, Clone)]
pub struct Reserve {
    count: usize,
    objects: [TypeIdx; RESERVE_SLOTS],
    height: [f32; RESERVE_SLOTS],
    windows: [[Windows; 2]; RESERVE_SLOTS],
    before: [f32; RESERVE_SLOTS],
    rowmax: Vec<f32>,
}

/// A rectangle of lattice cells, inclusive: columns `c0..=c1`, rows `r0..=r1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellRect {
    /// First column.
    pub c0: usize,
    /// Last column.
    pub c1: usize,
    /// First row.
    pub r0: usize,
    /// Last row.
    pub r1: usize,
}

impl Default for Reserve {
    fn default() -> Self {
        Self::new()
    }
}

impl Reserve {
    /// Buffers for the lattice grid.
    pub fn new() -> Self {
        let n = GridSpec::for_box(LATTICE_CELL_M)
            .expect("lattice cell within GridSpec range")
            .len();
        let windows = || Windows {
            size: (0, 0),
            sorted: Vec::with_capacity(n),
        };
        Self {
            count: 0,
            objects: [TypeIdx(0); RESERVE_SLOTS],
            height: [0.0; RESERVE_SLOTS],
            windows: std::array::from_fn(|_| [windows(), windows()]),
            before: [f32::INFINITY; RESERVE_SLOTS],
            rowmax: vec![0.0; n],
        }
    }

    /// Chooses the reserved objects among `after` (the objects after the next one, in order)
    /// and measures their windows over `pooled`, the heightmap pooled to the lattice grid
    /// ([`Lattice::pooled`] after [`Lattice::compute`]).
    pub fn prepare(&mut self, pooled: &Heightmap, catalog: &Catalog, after: &[TypeIdx]) {
        self.count = 0;
        if let Some(&first) = after.first() {
            self.objects[0] = first;
            self.count = 1;
            // The largest later objects by footprint area, largest first (earliest of equals).
            let area = |t: TypeIdx| {
                let e = catalog.shape(t).extents();
                e.x * e.y
            };
            let mut taken = [usize::MAX; RESERVE_SLOTS];
            while self.count < RESERVE_SLOTS {
                let mut best: Option<(f32, usize)> = None;
                for (i, &t) in after.iter().enumerate().skip(1) {
                    if taken.contains(&i) {
                        continue;
                    }
                    let a = area(t);
                    if best.is_none_or(|(ba, _)| a > ba) {
                        best = Some((a, i));
                    }
                }
                let Some((_, i)) = best else { break };
                taken[self.count] = i;
                self.objects[self.count] = after[i];
                self.count += 1;
            }
        }
        for j in 0..self.count {
            let shape = catalog.shape(self.objects[j]);
            let e = shape.extents();
            self.height[j] = e.z;
            let cell = pooled.spec().cell;
            let cells = |v: f32| (v / cell - 1e-3).ceil().max(1.0) as usize;
            let (w, h) = (cells(e.x), cells(e.y));
            let mut best = f32::INFINITY;
            for (o, size) in [(w, h), (h, w)].into_iter().enumerate() {
                let mut win = std::mem::take(&mut self.windows[j][o]);
                self.measure(pooled, size, &mut win);
                if let Some(&(b, _, _)) = win.sorted.first() {
                    best = best.min(b + e.z);
                }
                self.windows[j][o] = win;
            }
            self.before[j] = best;
        }
    }

    fn measure(&mut self, pooled: &Heightmap, size: (usize, usize), win: &mut Windows) {
        let spec = *pooled.spec();
        let (nx, ny) = (spec.nx, spec.ny);
        let (w, h) = size;
        win.size = size;
        win.sorted.clear();
        if w > nx || h > ny {
            return;
        }
        let d = pooled.data();
        // Maximum over w columns starting at each column, row by row; then over h rows.
        for r in 0..ny {
            for c in 0..=nx - w {
                let row = &d[r * nx + c..r * nx + c + w];
                self.rowmax[r * nx + c] = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            }
        }
        for r in 0..=ny - h {
            for c in 0..=nx - w {
                let mut m = f32::NEG_INFINITY;
                for rr in r..r + h {
                    m = m.max(self.rowmax[rr * nx + c]);
                }
                win.sorted.push((m, c as u16, r as u16));
            }
        }
        win.sorted
            .sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    }

    /// Number of reserved objects (at most [`RESERVE_SLOTS`]).
    pub fn count(&self) -> usize {
        self.count
    }

    /// The reserved objects, slot order.
    pub fn objects(&self) -> &[TypeIdx] {
        &self.objects[..self.count]
    }

    /// Best top of slot `j` before the next object is placed (infinite when it fits nowhere).
    pub fn before(&self, j: usize) -> f32 {
        self.before[j]
    }

    /// The cells of the lattice grid `spec` that the bounding box `bounds` (around the
    /// origin, as [`Lattice::bounds`] gives it for the placement's yaw) of placement `p`
    /// overlaps.
    pub fn footprint_cells(spec: &GridSpec, bounds: (Vector, Vector), p: &Placement) -> CellRect {
        let (lo, hi) = bounds;
        let eps = 1e-3;
        let (u0, v0) = spec.to_pixel(p.x + lo.x, p.y + hi.y);
        let (u1, v1) = spec.to_pixel(p.x + hi.x, p.y + lo.y);
        let clamp = |v: f32, n: usize| (v.max(0.0) as usize).min(n - 1);
        CellRect {
            c0: clamp((u0 + eps).floor(), spec.nx),
            c1: clamp((u1 - eps).ceil() - 1.0, spec.nx),
            r0: clamp((v0 + eps).floor(), spec.ny),
            r1: clamp((v1 - eps).ceil() - 1.0, spec.ny),
        }
    }

    /// Best top of slot `j` once the cells `rect` are raised to `top` (infinite when it fits
    /// nowhere).
    pub fn after(&self, j: usize, rect: CellRect, top: f32) -> f32 {
        let mut best = f32::INFINITY;
        for win in &self.windows[j] {
            let (w, h) = win.size;
            let mut free: Option<f32> = None;
            let mut covered: Option<f32> = None;
            for &(b, c, r) in &win.sorted {
                let (c, r) = (c as usize, r as usize);
                let overlaps = c <= rect.c1 && c + w > rect.c0 && r <= rect.r1 && r + h > rect.r0;
                if overlaps {
                    covered.get_or_insert(b);
                } else {
                    free.get_or_insert(b);
                }
                if free.is_some() && covered.is_some() {
                    break;
                }
            }
            let lowest = match (free, covered) {
                (Some(f), Some(c)) => f.min(c.max(top)),
                (Some(f), None) => f,
                (None, Some(c)) => c.max(top),
                (None, None) => continue,
            };
            best = best.min(lowest + self.height[j]);
        }
        best
    }

    /// Number of reserved objects that would no longer fit below [`HEIGHT_LIMIT_M`] after
    /// placement `p`, among those that fit before it.
    pub fn lost(&self, lattice: &Lattice, p: &Placement) -> usize {
        let rect = Self::footprint_cells(lattice.spec(), lattice.bounds(p.yaw as usize), p);
        (0..self.count)
            .filter(|&j| {
                self.before[j] <= HEIGHT_LIMIT_M && self.after(j, rect, p.top) > HEIGHT_LIMIT_M
            })
            .count()
    }
}
