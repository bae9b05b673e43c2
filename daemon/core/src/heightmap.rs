//! The top-down heightmap of the box interior and the triangle rasteriser that renders it.
//!
//! **Grid.** Square cells of side `cell` metres, `nx` columns along B x and `ny` rows along B y,
//! centred on the box (so the grid may overhang the inner walls by less than one cell; every
//! cell centre is inside). Storage is row-major, **row 0 at +y** (image top when viewed from
//! above with x to the right), column 0 at -x. A cell's value is the height (m, B z) of the
//! highest surface at the cell centre; the empty floor is 0. Outside the grid the box is
//! treated as its walls: [`OUTSIDE_HEIGHT`].
//!
//! **Rendering** rasterises the upward-facing triangles of every hull into a max z-buffer,
//! sampling at cell centres, instead of casting one ray per cell; tests check it against ray
//! casting.

use crate::error::{Result, SimError};
use crate::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT};
use parry3d::math::Vector;

/// Height reported for points outside the grid (the walls' top, m).
pub const OUTSIDE_HEIGHT: f32 = BOX_HEIGHT;
/// Highest value a valid heightmap may hold (m): well above anything that fits the success volume.
pub const MAX_VALID_HEIGHT: f32 = 1.0;
/// Lowest and highest valid heightmap value (m) ([`Heightmap::validate`]); the IPC frame's
/// copy (`herb_ipc::HEIGHT_RANGE_M`) is tied to it by a test.
pub const HEIGHT_RANGE_M: (f32, f32) = (-0.05, MAX_VALID_HEIGHT);

/// A depth camera adapter's default floor threshold (m): a seen cell lower than this is the
/// floor, 0 ([`finish_camera_cells`]).
pub const CAMERA_FLOOR_THRESHOLD_M: f32 = 0.003;
/// A depth camera adapter's default fill radius (cells): an unseen cell takes the highest seen
/// cell within this many cells ([`finish_camera_cells`]).
pub const CAMERA_FILL_RADIUS_CELLS: usize = 6;

/// How many unseen cells [`finish_camera_cells`] filled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CameraFill {
    /// Cells filled from a seen neighbour within the radius.
    pub near: u32,
    /// Cells filled with the frame's highest seen cell (nothing seen near them).
    pub far: u32,
}

/// What a depth camera's heightmap does to its cells once its points are binned: the one
/// implementation of the camera contract, run by the camera adapter and by the evaluation's
/// field camera. A seen cell lower than `floor_threshold` becomes the floor (0), the others are
/// clamped to `max_height`. An unseen cell (`seen[i]` false: occluded, or without a valid depth)
/// is filled **conservatively**, never as a hole: with the highest seen cell within
/// `fill_radius` cells (a square window), else with the highest seen cell of the frame (0 when
/// none was seen). `scratch` is a buffer of the grid's size. Allocates nothing.
pub fn finish_camera_cells(
    spec: &GridSpec,
    cells: &mut [f32],
    seen: &[bool],
    (floor_threshold, max_height, fill_radius): (f32, f32, usize),
    scratch: &mut [f32],
) -> CameraFill {
    let mut highest = 0.0f32;
    for (o, &s) in cells.iter_mut().zip(seen) {
        if s {
            *o = if *o < floor_threshold {
                0.0
            } else {
                o.min(max_height)
            };
            highest = highest.max(*o);
        }
    }
    scratch.copy_from_slice(cells);
    let r = fill_radius as isize;
    let mut fill = CameraFill::default();
    for row in 0..spec.ny {
        for col in 0..spec.nx {
            let i = row * spec.nx + col;
            if seen[i] {
                continue;
            }
            let mut best = f32::NEG_INFINITY;
            for dr in -r..=r {
                let rr = row as isize + dr;
                if rr < 0 || rr as usize >= spec.ny {
                    continue;
                }
                for dc in -r..=r {
                    let cc = col as isize + dc;
                    if cc < 0 || cc as usize >= spec.nx {
                        continue;
                    }
                    let j = rr as usize * spec.nx + cc as usize;
                    if seen[j] {
                        best = best.max(scratch[j]);
                    }
                }
            }
            if best.is_finite() {
                cells[i] = best;
                fill.near += 1;
            } else {
                cells[i] = highest;
                fill.far += 1;
            }
        }
    }
    fill
}

/// The geometry of a heightmap grid over the box interior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// Columns (along B x).
    pub nx: usize,
    /// Rows (along B y).
    pub ny: usize,
    /// Cell side (m).
    pub cell: f32,
}

impl GridSpec {
    /// The grid over the box interior with cells of `cell` metres (0.5 mm to 2 cm).
    pub fn for_box(cell: f32) -> Result<Self> {
        if !(0.0005..=0.02).contains(&cell) {
            return Err(SimError::Config(format!(
                "heightmap cell {cell} m outside 0.0005..=0.02"
            )));
        }
        // Round down to the count whose centres stay inside the walls, at least 1.
        let n = |half: f32| ((2.0 * half / cell).ceil() as usize).max(1);
        let (mut nx, mut ny) = (n(BOX_HALF_X), n(BOX_HALF_Y));
        if (nx as f32 - 1.0) * 0.5 * cell > BOX_HALF_X {
            nx -= 1;
        }
        if (ny as f32 - 1.0) * 0.5 * cell > BOX_HALF_Y {
            ny -= 1;
        }
        Ok(Self { nx, ny, cell })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// True for a grid without cells (never for [`GridSpec::for_box`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// B x of the grid's left edge (m).
    pub fn x_min(&self) -> f32 {
        -0.5 * self.nx as f32 * self.cell
    }

    /// B y of the grid's top edge (row 0 side, m).
    pub fn y_max(&self) -> f32 {
        0.5 * self.ny as f32 * self.cell
    }

    /// B (x, y) of the centre of cell (col, row).
    pub fn cell_centre(&self, col: usize, row: usize) -> (f32, f32) {
        (
            self.x_min() + (col as f32 + 0.5) * self.cell,
            self.y_max() - (row as f32 + 0.5) * self.cell,
        )
    }

    /// Continuous pixel coordinates (u along columns, v along rows) of B (x, y); cell
    /// (col, row) spans `[col, col+1) x [row, row+1)`.
    pub fn to_pixel(&self, x: f32, y: f32) -> (f32, f32) {
        (
            (x - self.x_min()) / self.cell,
            (self.y_max() - y) / self.cell,
        )
    }
}

/// A heightmap of the box interior (see the module docs for the layout).
#[derive(Debug, Clone, PartialEq)]
pub struct Heightmap {
    spec: GridSpec,
    data: Vec<f32>,
}

/// The one check of a heightmap's cells for `spec` (a camera frame before it is copied, or a
/// [`Heightmap`]): `spec.len()` values, each finite and within [`HEIGHT_RANGE_M`]; the error
/// names the first bad cell.
pub fn check_cells(spec: &GridSpec, data: &[f32]) -> Result<()> {
    if data.len() != spec.len() {
        return Err(SimError::Heightmap(format!(
            "{} values for a {} x {} grid",
            data.len(),
            spec.nx,
            spec.ny
        )));
    }
    if let Some((i, v)) = data
        .iter()
        .enumerate()
        .find(|(_, v)| !(v.is_finite() && (HEIGHT_RANGE_M.0..=HEIGHT_RANGE_M.1).contains(*v)))
    {
        return Err(SimError::Heightmap(format!(
            "cell (col {}, row {}) holds {v}: values must be finite and within {}..={} m",
            i % spec.nx,
            i / spec.nx,
            HEIGHT_RANGE_M.0,
            HEIGHT_RANGE_M.1
        )));
    }
    Ok(())
}

impl Heightmap {
    /// An empty box: every cell at the floor (0).
    pub fn new(spec: GridSpec) -> Self {
        Self {
            spec,
            data: vec![0.0; spec.len()],
        }
    }

    /// Wraps external data (e.g. a camera frame), validating size and values: every value must
    /// be finite and within `[-0.05, MAX_VALID_HEIGHT]` m.
    pub fn from_data(spec: GridSpec, data: Vec<f32>) -> Result<Self> {
        let hm = Self { spec, data };
        hm.validate()?;
        Ok(hm)
    }

    /// Checks the size and every value; the error names the first bad cell.
    pub fn validate(&self) -> Result<()> {
        check_cells(&self.spec, &self.data)
    }

    /// The grid.
    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    /// Row-major values (row 0 at +y).
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Mutable values, for renderers.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Resets every cell to the floor.
    pub fn clear(&mut self) {
        self.data.fill(0.0);
    }

    /// Raises every cell to the top of a convex hull whose vertices are in B (`vertices`,
    /// converted in place to grid coordinates: pass a scratch copy): how the world renders
    /// each object.
    pub fn raise_to_hull(&mut self, vertices: &mut [Vector], triangles: &[[u32; 3]]) {
        let spec = self.spec;
        let win = Window {
            col0: 0,
            row0: 0,
            w: spec.nx,
            h: spec.ny,
        };
        raster_hull(
            &spec,
            &mut self.data,
            win,
            vertices,
            triangles,
            DepthTest::Max,
        );
    }

    /// Value of cell (col, row), or [`OUTSIDE_HEIGHT`] outside the grid.
    #[inline]
    pub fn get(&self, col: isize, row: isize) -> f32 {
        if col < 0 || row < 0 || col as usize >= self.spec.nx || row as usize >= self.spec.ny {
            OUTSIDE_HEIGHT
        } else {
            self.data[row as usize * self.spec.nx + col as usize]
        }
    }

    /// Value of the cell containing B (x, y) (nearest-cell sampling).
    pub fn sample(&self, x: f32, y: f32) -> f32 {
        let (u, v) = self.spec.to_pixel(x, y);
        self.get(u.floor() as isize, v.floor() as isize)
    }

    /// Writes into `dst` (a grid over the box, usually coarser) the highest value of the cells
    /// of `self` whose centres fall inside each of its cells (0 where none does). Used by the
    /// BLBF heuristic and the placement lattice.
    pub fn max_pool_into(&self, dst: &mut Heightmap) {
        let (ss, ds) = (self.spec, dst.spec);
        dst.data.fill(0.0);
        let dst_col = |col: usize| {
            let (x, y) = ss.cell_centre(col, 0);
            let u = ds.to_pixel(x, y).0.floor();
            (u >= 0.0 && (u as usize) < ds.nx).then_some(u as usize)
        };
        // Source columns map to destination columns monotonically: each destination column
        // takes a contiguous run of source columns, found once (same arithmetic as the
        // cell-by-cell definition), so each row reduces run by run.
        const MAX_RUNS: usize = 1024;
        let mut runs = [(0usize, 0usize, 0usize); MAX_RUNS];
        let mut n_runs = 0;
        let mut col = 0;
        while col < ss.nx {
            let Some(d) = dst_col(col) else {
                col += 1;
                continue;
            };
            let start = col;
            while col < ss.nx && dst_col(col) == Some(d) {
                col += 1;
            }
            if n_runs == MAX_RUNS {
                // Finer than any grid in use: fall back to cell by cell.
                return self.max_pool_cells(dst);
            }
            runs[n_runs] = (d, start, col);
            n_runs += 1;
        }
        for row in 0..ss.ny {
            let (x, y) = ss.cell_centre(0, row);
            let v = ds.to_pixel(x, y).1.floor();
            if v < 0.0 || v as usize >= ds.ny {
                continue;
            }
            let drow = &mut dst.data[v as usize * ds.nx..(v as usize + 1) * ds.nx];
            let srow = &self.data[row * ss.nx..(row + 1) * ss.nx];
            for &(d, a, b) in &runs[..n_runs] {
                let m = srow[a..b]
                    .iter()
                    .fold(drow[d], |m, &h| if h > m { h } else { m });
                drow[d] = m;
            }
        }
    }

    /// [`Heightmap::max_pool_into`] cell by cell (the definition).
    fn max_pool_cells(&self, dst: &mut Heightmap) {
        let (ss, ds) = (self.spec, dst.spec);
        dst.data.fill(0.0);
        for row in 0..ss.ny {
            for col in 0..ss.nx {
                let (x, y) = ss.cell_centre(col, row);
                let (u, v) = ds.to_pixel(x, y);
                let (c, r) = (u.floor(), v.floor());
                if c >= 0.0 && r >= 0.0 && (c as usize) < ds.nx && (r as usize) < ds.ny {
                    let d = &mut dst.data[r as usize * ds.nx + c as usize];
                    *d = d.max(self.data[row * ss.nx + col]);
                }
            }
        }
    }

    /// Writes into `dst` each cell's median over its 3 x 3 neighbourhood (clipped at the grid's
    /// edges, where the upper median of the cells inside is taken): a depth camera's per-cell
    /// noise and lone outliers filtered out, a straight step kept where it is. `dst` takes
    /// `self`'s grid (it allocates only when its grid differs). Used by the search to find its
    /// candidates (herb-search's `SearchSettings::median`).
    pub fn median3_into(&self, dst: &mut Heightmap) {
        if dst.spec != self.spec {
            *dst = self.clone();
        }
        let (nx, ny) = (self.spec.nx, self.spec.ny);
        let mut window = [0.0f32; 9];
        for row in 0..ny {
            let rows = row.saturating_sub(1)..(row + 2).min(ny);
            for col in 0..nx {
                let cols = col.saturating_sub(1)..(col + 2).min(nx);
                let mut n = 0;
                for r in rows.clone() {
                    for &h in &self.data[r * nx + cols.start..r * nx + cols.end] {
                        window[n] = h;
                        n += 1;
                    }
                }
                let w = &mut window[..n];
                w.sort_unstable_by(f32::total_cmp);
                dst.data[row * nx + col] = w[n / 2];
            }
        }
    }

    /// Highest value.
    pub fn max(&self) -> f32 {
        self.data.iter().copied().fold(0.0, f32::max)
    }
}

/// Which surface a rasterisation keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthTest {
    /// Keep the highest z (top surfaces, heightmaps); draws upward-facing triangles.
    Max,
    /// Keep the lowest z (bottom surfaces, footprints); draws downward-facing triangles.
    Min,
}

/// A rectangular window of the grid's pixel lattice that a buffer covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First column (may be negative: outside the grid).
    pub col0: isize,
    /// First row.
    pub row0: isize,
    /// Width in cells.
    pub w: usize,
    /// Height in cells.
    pub h: usize,
}

/// Rasterises one triangle given in grid pixel coordinates `(u, v, z)` into `buf` (covering
/// `win`), keeping the highest or lowest z per cell centre. Triangles facing the wrong way for
/// `test` (or vertical) are skipped: for convex hulls they are never the visible surface.
#[inline]
pub fn raster_triangle(buf: &mut [f32], win: Window, p: [Vector; 3], test: DepthTest) {
    // Signed area in (u, v); v points down (-y), so an upward-facing triangle (normal z > 0
    // in B, counter-clockwise seen from above) has negative area here.
    let area = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
    let upward = area < 0.0;
    match test {
        DepthTest::Max if !upward => return,
        DepthTest::Min if upward => return,
        _ => {}
    }
    if area.abs() < 1e-12 {
        return;
    }
    let inv_area = 1.0 / area;
    let umin = p[0].x.min(p[1].x).min(p[2].x);
    let umax = p[0].x.max(p[1].x).max(p[2].x);
    let vmin = p[0].y.min(p[1].y).min(p[2].y);
    let vmax = p[0].y.max(p[1].y).max(p[2].y);
    // Cells whose centre (c + 0.5) lies in [umin, umax].
    let c_lo = ceil_i(umin - 0.5).max(win.col0);
    let c_hi = floor_i(umax - 0.5).min(win.col0 + win.w as isize - 1);
    let r_lo = ceil_i(vmin - 0.5).max(win.row0);
    let r_hi = floor_i(vmax - 0.5).min(win.row0 + win.h as isize - 1);
    if c_lo > c_hi || r_lo > r_hi {
        return;
    }
    // Normalised barycentric weight of vertex k, affine in (u, v): w_k = a_k u + b_k v + c_k,
    // from the edge opposite k. Inside means all w_k >= EPS whatever the winding.
    const EPS: f32 = -1e-6;
    let weight = |a: Vector, b: Vector| {
        // (b.x - a.x) (v - a.y) - (b.y - a.y) (u - a.x), divided by the area.
        let du = -(b.y - a.y) * inv_area;
        let dv = (b.x - a.x) * inv_area;
        let c0 = ((b.y - a.y) * a.x - (b.x - a.x) * a.y) * inv_area;
        (du, dv, c0)
    };
    let w = [weight(p[1], p[2]), weight(p[2], p[0]), weight(p[0], p[1])];
    let inv_du = w.map(|(du, _, _)| if du != 0.0 { 1.0 / du } else { 0.0 });
    // z is affine too: z = dzdu u + dzdv v + z0.
    let dzdu = w[0].0 * p[0].z + w[1].0 * p[1].z + w[2].0 * p[2].z;
    let dzdv = w[0].1 * p[0].z + w[1].1 * p[1].z + w[2].1 * p[2].z;
    let z0 = w[0].2 * p[0].z + w[1].2 * p[1].z + w[2].2 * p[2].z;
    let (u_min_win, u_max_win) = (c_lo as f32 + 0.5, c_hi as f32 + 0.5);
    for r in r_lo..=r_hi {
        let v = r as f32 + 0.5;
        // The row's exact span: intersect the three half-lines a_k u + (b_k v + c_k) >= EPS.
        let (mut lo, mut hi) = (u_min_win, u_max_win);
        for (&(du, dv, c0), &inv_du) in w.iter().zip(&inv_du) {
            let rest = dv * v + c0;
            if du > 0.0 {
                lo = lo.max((EPS - rest) * inv_du);
            } else if du < 0.0 {
                hi = hi.min((EPS - rest) * inv_du);
            } else if rest < EPS {
                hi = f32::MIN;
            }
        }
        if lo > hi {
            continue;
        }
        let c0 = ceil_i(lo - 0.5).max(c_lo);
        let c1 = floor_i(hi - 0.5).min(c_hi);
        if c0 > c1 {
            continue;
        }
        let row_off = (r - win.row0) as usize * win.w;
        let z_row = dzdv * v + z0;
        let cells =
            &mut buf[row_off + (c0 - win.col0) as usize..=row_off + (c1 - win.col0) as usize];
        let u0 = c0 as f32 + 0.5;
        match test {
            DepthTest::Max => {
                for (k, cell) in cells.iter_mut().enumerate() {
                    let z = z_row + dzdu * (u0 + k as f32);
                    *cell = if z > *cell { z } else { *cell };
                }
            }
            DepthTest::Min => {
                for (k, cell) in cells.iter_mut().enumerate() {
                    let z = z_row + dzdu * (u0 + k as f32);
                    *cell = if z < *cell { z } else { *cell };
                }
            }
        }
    }
}

/// Rasterises a convex hull whose vertices are already transformed to B (`vertices`) into
/// `buf` covering `win` of grid `spec`. The vertices are converted to grid pixel coordinates
/// `(u, v, z)` in place (once per vertex, not once per triangle): pass a scratch copy.
pub fn raster_hull(
    spec: &GridSpec,
    buf: &mut [f32],
    win: Window,
    vertices: &mut [Vector],
    triangles: &[[u32; 3]],
    test: DepthTest,
) {
    for w in vertices.iter_mut() {
        let (u, v) = spec.to_pixel(w.x, w.y);
        *w = Vector::new(u, v, w.z);
    }
    for t in triangles {
        let p = [
            vertices[t[0] as usize],
            vertices[t[1] as usize],
            vertices[t[2] as usize],
        ];
        raster_triangle(buf, win, p, test);
    }
}

/// `x.ceil() as isize` without a libm call (finite `x` within the isize range).
#[inline]
fn ceil_i(x: f32) -> isize {
    let i = x as isize;
    if (i as f32) < x { i + 1 } else { i }
}

/// `x.floor() as isize` without a libm call (finite `x` within the isize range).
#[inline]
fn floor_i(x: f32) -> isize {
    let i = x as isize;
    if (i as f32) > x { i - 1 } else { i }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 x 3 median on a heightmap with a straight step and one outlier: only the outlier
    /// changes (a step's cells have more of their side in every window, the box's corners
    /// too).
    #[test]
    fn the_median_filter_takes_out_a_lone_outlier_and_keeps_a_step() {
        let spec = GridSpec::for_box(0.00625).unwrap();
        let mut h = Heightmap::new(spec);
        // A step of 5 cm along a column, and one cell 3 cm up on the low side (an outlier).
        for row in 0..spec.ny {
            for col in 0..spec.nx {
                h.data_mut()[row * spec.nx + col] = if col >= spec.nx / 2 { 0.05 } else { 0.0 };
            }
        }
        let (orow, ocol) = (spec.ny / 2, spec.nx / 4);
        h.data_mut()[orow * spec.nx + ocol] = 0.03;
        let mut m = Heightmap::new(GridSpec::for_box(0.0125).unwrap());
        h.median3_into(&mut m);
        assert_eq!(m.spec(), h.spec(), "the output takes the input's grid");
        let mut expected = h.clone();
        expected.data_mut()[orow * spec.nx + ocol] = 0.0;
        assert_eq!(
            m.data(),
            expected.data(),
            "the outlier goes, the step and the corners stay"
        );
    }

    /// The run-by-run pooling equals the cell-by-cell definition, bit for bit, for the grids
    /// the lattice and BLBF use, on a rough heightmap.
    #[test]
    fn max_pooling_by_runs_equals_the_definition() {
        let spec = GridSpec::for_box(crate::observation::ObsLayout::CELL_M).unwrap();
        let mut hm = Heightmap::new(spec);
        for (i, v) in hm.data_mut().iter_mut().enumerate() {
            *v = ((i * 7919) % 1000) as f32 * 2.9e-4 - 0.01;
        }
        for cell in [0.00625, 0.0125, 0.01, 0.0031] {
            let ds = GridSpec::for_box(cell).unwrap();
            let (mut a, mut b) = (Heightmap::new(ds), Heightmap::new(ds));
            hm.max_pool_into(&mut a);
            hm.max_pool_cells(&mut b);
            let bits = |h: &Heightmap| h.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b), "cell {cell}");
        }
    }

    #[test]
    fn grid_centres_stay_inside_the_walls() {
        for cell in [0.0015625, 0.002, 0.005, 0.0123] {
            let g = GridSpec::for_box(cell).unwrap();
            let (x0, y0) = g.cell_centre(0, 0);
            let (x1, y1) = g.cell_centre(g.nx - 1, g.ny - 1);
            assert!(x0 >= -BOX_HALF_X && x1 <= BOX_HALF_X, "{cell}: {x0} {x1}");
            assert!(y0 <= BOX_HALF_Y && y1 >= -BOX_HALF_Y, "{cell}: {y0} {y1}");
            assert!(g.nx as f32 * cell >= 2.0 * BOX_HALF_X - cell);
        }
        assert!(GridSpec::for_box(0.0).is_err());
        assert!(GridSpec::for_box(f32::NAN).is_err());
    }

    #[test]
    fn from_data_rejects_bad_values() {
        let g = GridSpec::for_box(0.01).unwrap();
        assert!(Heightmap::from_data(g, vec![0.0; g.len() - 1]).is_err());
        let mut d = vec![0.05; g.len()];
        d[7] = f32::NAN;
        let e = Heightmap::from_data(g, d.clone()).unwrap_err().to_string();
        assert!(e.contains("col 7"), "{e}");
        d[7] = 3.0;
        assert!(Heightmap::from_data(g, d).is_err());
    }

    #[test]
    fn triangle_max_covers_centres() {
        let g = GridSpec::for_box(0.01).unwrap();
        let mut hm = Heightmap::new(g);
        let win = Window {
            col0: 0,
            row0: 0,
            w: g.nx,
            h: g.ny,
        };
        // A horizontal square 4 cm x 4 cm at z = 0.1, as two upward (CCW from above) triangles.
        let v = [
            Vector::new(-0.02, -0.02, 0.1),
            Vector::new(0.02, -0.02, 0.1),
            Vector::new(0.02, 0.02, 0.1),
            Vector::new(-0.02, 0.02, 0.1),
        ];
        raster_hull(
            &g,
            hm.data_mut(),
            win,
            &mut v.clone(),
            &[[0, 1, 2], [0, 2, 3]],
            DepthTest::Max,
        );
        let covered = hm.data().iter().filter(|&&z| z > 0.05).count();
        assert!((12..=25).contains(&covered), "{covered}");
        assert!((hm.sample(0.0, 0.0) - 0.1).abs() < 1e-6);
        // Reversed winding faces down: not drawn by Max.
        let mut hm2 = Heightmap::new(g);
        raster_hull(
            &g,
            hm2.data_mut(),
            win,
            &mut v.clone(),
            &[[0, 2, 1]],
            DepthTest::Max,
        );
        assert_eq!(hm2.max(), 0.0);
    }
}
