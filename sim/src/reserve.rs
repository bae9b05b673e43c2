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
//!   `max(window, candidate top)`, the others are unchanged. The windows overlapping it form a
//!   rectangle of window positions, so the best top after the candidate is the lower of the
//!   lowest window outside that rectangle (prefix and suffix minima per row and over rows)
//!   and the candidate's top raised to the lowest window inside it (range minima per row): a
//!   few steps per row of windows, per candidate.
//!
//! Allocation happens in [`Reserve::new`] only.

use crate::catalog::{Catalog, TypeIdx};
use crate::heightmap::{GridSpec, Heightmap};
use crate::lattice::{HEIGHT_LIMIT_M, LATTICE_CELL_M, Lattice, Placement};
use rapier3d::math::Vector;

/// Number of later objects whose room is measured.
pub const RESERVE_SLOTS: usize = 3;

/// Levels of the per-row range-minimum tables (windows per row at most 2^LEVELS).
const LEVELS: usize = 6;

/// One reserved object in one yaw: the resting bottom of every window inside the walls, with
/// tables that give the lowest bottom outside or inside a rectangle of windows in a few steps
/// per row.
#[derive(Debug, Clone, Default)]
struct Windows {
    /// Window size in cells (columns, rows).
    size: (usize, usize),
    /// Windows per row and rows of windows (0 when the object does not fit in this yaw).
    nwc: usize,
    nwr: usize,
    /// Lowest bottom of all windows.
    lowest: f32,
    /// Lowest bottom of the window rows before / after each row (exclusive; infinite if none).
    above: Vec<f32>,
    below: Vec<f32>,
    /// Per window: lowest bottom of its row's windows left / right of it (exclusive).
    left: Vec<f32>,
    right: Vec<f32>,
    /// Range minima per row: level `l` holds, for window `(c, r)`, the lowest bottom of
    /// windows `c..c + 2^l` of row `r` (level 0: the bottoms themselves).
    sparse: Vec<f32>,
}

impl Windows {
    fn sized(n: usize) -> Self {
        Self {
            above: Vec::with_capacity(n),
            below: Vec::with_capacity(n),
            left: Vec::with_capacity(n),
            right: Vec::with_capacity(n),
            sparse: Vec::with_capacity(LEVELS * n),
            ..Self::default()
        }
    }

    /// Lowest bottom of windows `a..=b` of row `r`.
    #[inline]
    fn range_min(&self, r: usize, a: usize, b: usize) -> f32 {
        let n = self.nwc * self.nwr;
        let len = b - a + 1;
        let l = (usize::BITS - 1 - len.leading_zeros()) as usize;
        let row = l * n + r * self.nwc;
        self.sparse[row + a].min(self.sparse[row + b + 1 - (1 << l)])
    }
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
    /// Scratch: one row of running maxima.
    run: Vec<f32>,
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
        let windows = || Windows::sized(n);
        Self {
            count: 0,
            objects: [TypeIdx(0); RESERVE_SLOTS],
            height: [0.0; RESERVE_SLOTS],
            windows: std::array::from_fn(|_| [windows(), windows()]),
            before: [f32::INFINITY; RESERVE_SLOTS],
            rowmax: vec![0.0; n],
            run: Vec::with_capacity(n),
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
                best = best.min(win.lowest + e.z);
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
        win.nwc = 0;
        win.nwr = 0;
        win.lowest = f32::INFINITY;
        if w > nx || h > ny {
            return;
        }
        let (nwc, nwr) = (nx - w + 1, ny - h + 1);
        assert!(
            nwc <= 1 << LEVELS,
            "lattice rows longer than the range-minimum tables"
        );
        let n = nwc * nwr;
        (win.nwc, win.nwr) = (nwc, nwr);
        let d = pooled.data();
        // Maximum over w columns starting at each column, row by row (maxima over runs of
        // doubling length, then two overlapping runs: exact); then over h rows.
        let run = &mut self.run;
        for r in 0..ny {
            run.clear();
            run.extend_from_slice(&d[r * nx..(r + 1) * nx]);
            let mut len = 1;
            while 2 * len <= w {
                for c in 0..=nx - 2 * len {
                    run[c] = if run[c] > run[c + len] {
                        run[c]
                    } else {
                        run[c + len]
                    };
                }
                len *= 2;
            }
            for c in 0..nwc {
                let (a, b) = (run[c], run[c + w - len]);
                self.rowmax[r * nx + c] = if a > b { a } else { b };
            }
        }
        win.sparse.clear();
        win.sparse.resize(LEVELS * n, f32::INFINITY);
        // The same over h rows, on whole rows at a time (heights are finite: validated).
        let fmax = |a: f32, b: f32| if a > b { a } else { b };
        let mut len = 1;
        while 2 * len <= h {
            for r in 0..=ny - 2 * len {
                for c in 0..nwc {
                    self.rowmax[r * nx + c] =
                        fmax(self.rowmax[r * nx + c], self.rowmax[(r + len) * nx + c]);
                }
            }
            len *= 2;
        }
        for r in 0..nwr {
            for c in 0..nwc {
                win.sparse[r * nwc + c] =
                    fmax(self.rowmax[r * nx + c], self.rowmax[(r + h - len) * nx + c]);
            }
        }
        for l in 1..LEVELS {
            let half = 1 << (l - 1);
            for r in 0..nwr {
                for c in 0..nwc {
                    if c + (1 << l) > nwc {
                        break;
                    }
                    let i = (l - 1) * n + r * nwc + c;
                    win.sparse[l * n + r * nwc + c] = win.sparse[i].min(win.sparse[i + half]);
                }
            }
        }
        win.left.clear();
        win.right.clear();
        win.left.resize(n, f32::INFINITY);
        win.right.resize(n, f32::INFINITY);
        win.above.clear();
        win.below.clear();
        win.above.resize(nwr, f32::INFINITY);
        win.below.resize(nwr, f32::INFINITY);
        for r in 0..nwr {
            let b = &win.sparse[r * nwc..(r + 1) * nwc];
            let mut m = f32::INFINITY;
            for (l, &v) in win.left[r * nwc..(r + 1) * nwc].iter_mut().zip(b) {
                *l = m;
                m = m.min(v);
            }
            let row_min = m;
            let mut m = f32::INFINITY;
            for c in (0..nwc).rev() {
                win.right[r * nwc + c] = m;
                m = m.min(b[c]);
            }
            win.lowest = win.lowest.min(row_min);
            if r + 1 < nwr {
                win.above[r + 1] = win.above[r].min(row_min);
            }
        }
        for r in (0..nwr.saturating_sub(1)).rev() {
            let next_min =
                win.left[(r + 1) * nwc + nwc - 1].min(win.sparse[(r + 1) * nwc + nwc - 1]);
            win.below[r] = win.below[r + 1].min(next_min);
        }
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
            if win.nwc == 0 {
                continue;
            }
            // The windows that overlap the rectangle: a rectangle of window positions.
            let (c_lo, c_hi) = ((rect.c0 + 1).saturating_sub(w), rect.c1.min(win.nwc - 1));
            let (r_lo, r_hi) = ((rect.r0 + 1).saturating_sub(h), rect.r1.min(win.nwr - 1));
            let lowest = if c_lo > c_hi || r_lo > r_hi {
                win.lowest
            } else {
                let mut free = win.above[r_lo].min(win.below[r_hi]);
                let mut covered = f32::INFINITY;
                for r in r_lo..=r_hi {
                    free = free
                        .min(win.left[r * win.nwc + c_lo])
                        .min(win.right[r * win.nwc + c_hi]);
                    covered = covered.min(win.range_min(r, c_lo, c_hi));
                }
                free.min(covered.max(top))
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
