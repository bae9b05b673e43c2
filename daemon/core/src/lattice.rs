//! The placement lattice: every upright placement of the next object on a grid of positions
//! over the box and four yaws, with its resting height and top from the shared z estimate and
//! its feasibility, and the candidate placements derived from it.
//!
//! This is the one implementation of the geometry planes: the training bindings, the
//! evaluation, the teacher ([`crate::teacher`]) and the daemon's policy at run time all call
//! it, and the decision bench times it.
//!
//! # Lattice
//!
//! - **Positions**: the cell centres of the [`LATTICE_CELL_M`] (12.5 mm) grid over the box
//!   interior ([`GridSpec::for_box`]: 28 x 19), with the object's canonical origin there.
//! - **Yaws**: [`YAWS`], 0, 90, 180 and 270 degrees about z, the object upright (canonical
//!   resting orientation). The box's 180-degree turn about z maps yaw `k` at `(x, y)` to yaw
//!   `(k + 2) % 4` at `(-x, -y)` exactly.
//! - **Resting height** (`rest_z`, origin z, no clearance) from the shared z estimate
//!   ([`crate::zestimate`]) over the box heightmap max-pooled to the lattice cell, with the
//!   object's bottom rasterised at the heightmap's resolution and min-pooled to the same
//!   cells ([`crate::zestimate::pool_footprint`]): conservative, never below the estimate at
//!   full resolution at the same position (the lattice's cell edges fall on the observation
//!   grid's). Nodes whose footprint crosses a wall are not estimated (`rest_z` and `top`
//!   infinite).
//! - **Top**: `rest_z` plus the object's highest point above its origin.
//! - **Flags** ([`INSIDE`], [`BELOW_LIMIT`], [`FEASIBLE`]): the footprint lies inside the
//!   walls; the top is at most [`HEIGHT_LIMIT_M`], the success volume's top; both.
//! - **Support**: the share of the footprint's cells whose bottom, at `rest_z`, is within
//!   [`SUPPORT_TOL_M`] of the heightmap below: 1 on a flat floor, small when the object rests
//!   on a ridge.
//!
//! # Candidates
//!
//! A small set of feasible placements ([`Lattice::candidates`], at most [`MAX_CANDIDATES`]):
//! per yaw and per corner of the box, the inside-the-walls lattice node with the lowest top
//! nearest that corner (x or y as the first tie-break), then
//!
//! - **loose**: refined to the best (BLBF order) of the nine [`FINE_CELL_M`] (6.25 mm, the
//!   BLBF grid) positions around the node, with the same conservative pooling at that cell:
//!   the lattice's margin to the neighbours is kept;
//! - **tight**: the loose one slid towards its corner on the 6.25 mm grid while its top, from
//!   the footprint sampled at the cell centres as the BLBF heuristic does, does not rise:
//!   against its neighbours.
//!
//! Each is kept if its top is within the height limit; duplicates are removed and the rest
//! sorted by the BLBF order (lowest top, then smallest x, then smallest y, then yaw), so
//! candidate 0 is the deep-bottom-left-back rule of the BLBF heuristic restricted to the
//! lattice ([`Lattice::blbf`]). No candidate crosses a wall or exceeds the height limit: an
//! empty list means no feasible placement.
//!
//! Allocation happens in [`Lattice::new`] only.

use crate::catalog::{Catalog, ObjectShape, TypeIdx};
use crate::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, SUCCESS_TOP_Z};
use crate::heightmap::{GridSpec, Heightmap};
use crate::zestimate::{ZScratch, bottom_footprint, pool_footprint, rest_height, support_fraction};
use parry3d::math::{Rotation, Vector};
use std::f32::consts::{FRAC_PI_2, PI};

/// Side of a lattice cell (m).
pub const LATTICE_CELL_M: f32 = 0.0125;
/// Side of the refinement grid's cell (m): the BLBF search grid for the observation heightmap.
pub const FINE_CELL_M: f32 = 0.00625;
/// The yaws of the lattice (rad), index `k` is `k * 90` degrees.
pub const YAWS: [f32; 4] = [0.0, FRAC_PI_2, PI, -FRAC_PI_2];
/// Number of yaws.
pub const NUM_YAWS: usize = YAWS.len();
/// The height limit (m): a feasible placement's estimated top is at most the success volume's
/// top, [`SUCCESS_TOP_Z`] widened by the world's contact tolerance
/// ([`crate::frames::INSIDE_TOLERANCE_M`]): resting as estimated, it would count as inside.
pub const HEIGHT_LIMIT_M: f32 = SUCCESS_TOP_Z + crate::frames::INSIDE_TOLERANCE_M;
/// A footprint cell counts as supported when its bottom is within this of the surface (m).
pub const SUPPORT_TOL_M: f32 = 0.005;
/// Tolerance of the inside-the-walls test (m), as the BLBF heuristic.
pub const WALL_TOL_M: f32 = 1e-4;
/// Most candidates [`Lattice::candidates`] returns.
pub const MAX_CANDIDATES: usize = 64;
/// Cell of the heightmap the lattice expects (the observation's); others work, with the
/// conservative bound then approximate.
const FULL_CELL_M: f32 = crate::observation::ObsLayout::CELL_M;
/// Most refinement-grid steps a tight candidate slides along each axis.
const MAX_PUSH_STEPS: usize = 4;

/// The largest gap [`Lattice::set_push_gap`] is given by herbd's configuration, the CLI and
/// the sweeps (fine cells): as far as a push goes.
pub const MAX_PUSH_GAP: usize = MAX_PUSH_STEPS;

/// Flag: the footprint lies inside the walls.
pub const INSIDE: u8 = 1;
/// Flag: the estimated top is at most [`HEIGHT_LIMIT_M`].
pub const BELOW_LIMIT: u8 = 2;
/// Both flags: the placement is feasible.
pub const FEASIBLE: u8 = INSIDE | BELOW_LIMIT;

/// One upright placement of the next object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// B x of the canonical origin (m).
    pub x: f32,
    /// B y of the canonical origin (m).
    pub y: f32,
    /// Index into [`YAWS`].
    pub yaw: u8,
    /// Origin height at rest, without clearance (m).
    pub rest_z: f32,
    /// Highest point of the object at rest (m).
    pub top: f32,
    /// Supported share of the footprint (0 to 1).
    pub support: f32,
    /// Lattice column and row of the node it was refined from.
    pub node: (u16, u16),
    /// Slid against its neighbours (see [`Lattice::candidates`]), not kept at the lattice's
    /// conservative distance.
    pub tight: bool,
}

impl Placement {
    /// The yaw (rad).
    pub fn theta(&self) -> f32 {
        YAWS[self.yaw as usize]
    }

    /// The BLBF order: lower top first, then smaller x, then smaller y, then lower yaw index.
    pub fn blbf_cmp(&self, o: &Self) -> std::cmp::Ordering {
        (self.top, self.x, self.y, self.yaw)
            .partial_cmp(&(o.top, o.x, o.y, o.yaw))
            .unwrap_or(std::cmp::Ordering::Equal)
    }
}

/// The lattice planes and candidate generator for one object over one heightmap. Reused
/// across decisions: [`Lattice::compute`] overwrites everything.
#[derive(Debug, Clone)]
pub struct Lattice {
    spec: GridSpec,
    fine_spec: GridSpec,
    coarse: Heightmap,
    fine: Heightmap,
    full_fp: ZScratch,
    /// The footprints of the shape of the last [`Lattice::compute`] when it was not cached.
    current: [Footprints; NUM_YAWS],
    /// The footprints of every catalog type over the observation grid, built once.
    cache: Vec<[Footprints; NUM_YAWS]>,
    /// Grid the cache was built for.
    cache_spec: GridSpec,
    /// Which footprints the last [`Lattice::compute`] used: a cached type, or `current`.
    active: Option<usize>,
    rest_z: Vec<f32>,
    top: Vec<f32>,
    support: Vec<f32>,
    /// Scratch for [`Lattice::candidates`]: nodes of one yaw at the lowest top.
    lowest: Vec<u32>,
    /// `support` is up to date with the last [`Lattice::compute`].
    support_ready: bool,
    flags: Vec<u8>,
    candidates: Vec<Placement>,
    /// Fine cells a tight candidate backs off from what stopped its push ([`Lattice::set_push_gap`]).
    push_gap: usize,
    /// Fine cells a candidate standing above the rim keeps from the walls
    /// ([`Lattice::set_wall_gap`]).
    wall_gap: usize,
}

/// One shape's footprints at one yaw: its bottom min-pooled to the lattice and to the
/// refinement grid (conservative), sampled at the refinement grid's cell centres as the BLBF
/// heuristic does (for the tight candidates), and its bounds around the origin. They depend
/// on the shape and the heightmap grid only, not on the heights.
#[derive(Debug, Clone, Default)]
struct Footprints {
    coarse: ZScratch,
    fine: ZScratch,
    tight: ZScratch,
    bounds: (Vector, Vector),
}

impl Footprints {
    fn sized(catalog: &Catalog) -> Self {
        Self {
            coarse: ZScratch::for_catalog(catalog, LATTICE_CELL_M),
            fine: ZScratch::for_catalog(catalog, FINE_CELL_M),
            tight: ZScratch::for_catalog(catalog, FINE_CELL_M),
            bounds: (Vector::ZERO, Vector::ZERO),
        }
    }

    /// Rasterises `shape` at yaw `theta` for heightmaps on the grid `hs` (`full` is scratch
    /// at that grid's resolution).
    fn build(
        &mut self,
        hs: &GridSpec,
        spec: &GridSpec,
        fine_spec: &GridSpec,
        shape: &ObjectShape,
        theta: f32,
        full: &mut ZScratch,
    ) {
        let rot = Rotation::from_rotation_z(theta);
        let (x0, y0) = spec.cell_centre(0, 0);
        bottom_footprint(hs, shape, x0, y0, rot, full);
        pool_footprint(hs, full, (0, 0), spec, &mut self.coarse);
        // The refinement grid's first cell centre, in whole heightmap cells from the
        // lattice's (exact for the observation grid: 2 cells in -x, 0 in y).
        let (fx0, fy0) = fine_spec.cell_centre(0, 0);
        let shift = (
            ((fx0 - x0) / hs.cell).round() as isize,
            ((y0 - fy0) / hs.cell).round() as isize,
        );
        pool_footprint(hs, full, shift, fine_spec, &mut self.fine);
        bottom_footprint(fine_spec, shape, fx0, fy0, rot, &mut self.tight);
        self.bounds = shape.rotated_bounds(rot);
    }
}

impl Lattice {
    /// A lattice with buffers sized for every shape of `catalog`, and the footprints of every
    /// shape of `catalog` over the observation grid ([`crate::ObsLayout`]) built up front.
    pub fn new(catalog: &Catalog) -> Self {
        let spec = GridSpec::for_box(LATTICE_CELL_M).expect("lattice cell within GridSpec range");
        let fine_spec = GridSpec::for_box(FINE_CELL_M).expect("fine cell within GridSpec range");
        let cache_spec = GridSpec::for_box(FULL_CELL_M).expect("observation cell within range");
        let n = NUM_YAWS * spec.len();
        let mut full_fp = ZScratch::for_catalog(catalog, FULL_CELL_M);
        let cache = catalog
            .types()
            .map(|t| {
                std::array::from_fn(|k| {
                    let mut f = Footprints::default();
                    f.build(
                        &cache_spec,
                        &spec,
                        &fine_spec,
                        catalog.shape(t),
                        YAWS[k],
                        &mut full_fp,
                    );
                    f
                })
            })
            .collect();
        Self {
            spec,
            fine_spec,
            coarse: Heightmap::new(spec),
            fine: Heightmap::new(fine_spec),
            full_fp,
            current: std::array::from_fn(|_| Footprints::sized(catalog)),
            cache,
            cache_spec,
            active: None,
            rest_z: vec![0.0; n],
            top: vec![0.0; n],
            support: vec![0.0; n],
            support_ready: false,
            lowest: Vec::with_capacity(spec.len()),
            flags: vec![0; n],
            candidates: Vec::with_capacity(4 * MAX_CANDIDATES),
            push_gap: 0,
            wall_gap: 0,
        }
    }

    /// The same lattice without the footprint cache: every [`Lattice::compute`] rasterises
    /// the object's footprints itself (the path taken on a grid other than the observation
    /// grid). For tests and benchmarks comparing the two paths.
    pub fn without_cache(mut self) -> Self {
        self.cache = Vec::new();
        self.active = None;
        self
    }

    /// The footprints at yaw `k` of the last [`Lattice::compute`].
    #[inline]
    fn fp(&self, k: usize) -> &Footprints {
        match self.active {
            Some(t) => &self.cache[t][k],
            None => &self.current[k],
        }
    }

    /// The lattice grid (positions are its cell centres).
    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    /// The heightmap max-pooled to the lattice cell, from the last [`Lattice::compute`].
    pub fn pooled(&self) -> &Heightmap {
        &self.coarse
    }

    /// The footprint's bounds `(min, max)` around the origin at yaw `k`, from the last
    /// [`Lattice::compute`].
    pub fn bounds(&self, k: usize) -> (Vector, Vector) {
        self.fp(k).bounds
    }

    /// Index of yaw `k`, column `col`, row `row` in the planes.
    #[inline]
    pub fn index(&self, k: usize, col: usize, row: usize) -> usize {
        (k * self.spec.ny + row) * self.spec.nx + col
    }

    /// Resting heights `[yaw][row][col]` (m, origin z, no clearance).
    pub fn rest_z(&self) -> &[f32] {
        &self.rest_z
    }

    /// Tops `[yaw][row][col]` (m).
    pub fn top(&self) -> &[f32] {
        &self.top
    }

    /// Supported footprint shares `[yaw][row][col]`, at feasible nodes (0 elsewhere). The
    /// decision does not need this plane (candidates carry their own support), so it is
    /// computed here, on the first call after [`Lattice::compute`].
    pub fn support(&mut self) -> &[f32] {
        if !self.support_ready {
            let spec = self.spec;
            for k in 0..NUM_YAWS {
                let fp = match self.active {
                    Some(t) => &self.cache[t][k].coarse,
                    None => &self.current[k].coarse,
                };
                for row in 0..spec.ny {
                    for col in 0..spec.nx {
                        let i = (k * spec.ny + row) * spec.nx + col;
                        self.support[i] = if self.flags[i] == FEASIBLE {
                            let (dc, dr) = (col as isize, row as isize);
                            support_fraction(
                                &self.coarse,
                                fp,
                                dc,
                                dr,
                                self.rest_z[i],
                                SUPPORT_TOL_M,
                            )
                        } else {
                            0.0
                        };
                    }
                }
            }
            self.support_ready = true;
        }
        &self.support
    }

    /// A clearance for a gripper that does not release exactly: each tight candidate, once
    /// pushed against what stops it (a neighbour or a wall), backs off by up to `fine_cells`
    /// cells of [`FINE_CELL_M`] along each axis it was pushed, as far as it stays at its
    /// height, so that an object released a few millimetres off lands beside its neighbour
    /// rather than on its edge. 0 (the default, and every rule of Table I): tight against it.
    /// Takes effect at the next [`Lattice::compute`].
    pub fn set_push_gap(&mut self, fine_cells: usize) {
        self.push_gap = fine_cells;
        self.candidates.clear();
    }

    /// A clearance from the walls for objects that stand above the box's rim, where a wall no
    /// longer holds an object released a few millimetres off, nor one that tilts: each
    /// candidate (loose or tight) whose estimated top is above [`BOX_HEIGHT`] and whose
    /// footprint is within `fine_cells` cells of [`FINE_CELL_M`] of a wall moves away from that
    /// wall, a cell at a time up to that distance, as far as its top does not rise (less where
    /// there is no room). Below the rim the wall itself holds the object: no clearance. 0 (the
    /// default, and every rule of Table I): none. Takes effect at the next
    /// [`Lattice::compute`].
    pub fn set_wall_gap(&mut self, fine_cells: usize) {
        self.wall_gap = fine_cells;
        self.candidates.clear();
    }

    /// Flags `[yaw][row][col]` ([`INSIDE`], [`BELOW_LIMIT`]).
    pub fn flags(&self) -> &[u8] {
        &self.flags
    }

    /// Number of feasible placements on the lattice.
    pub fn feasible_count(&self) -> usize {
        self.flags.iter().filter(|&&f| f == FEASIBLE).count()
    }

    /// Fills the planes for object type `ty` of `catalog` (the catalog given to
    /// [`Lattice::new`]) over `hm` (any grid covering the box; validated by the caller).
    /// Clears the candidates. On the observation grid the footprints come from the cache
    /// built by [`Lattice::new`]; on another grid they are rasterised here.
    pub fn compute(&mut self, hm: &Heightmap, catalog: &Catalog, ty: TypeIdx) {
        hm.max_pool_into(&mut self.coarse);
        hm.max_pool_into(&mut self.fine);
        self.support_ready = false;
        self.candidates.clear();
        let spec = self.spec;
        let limit = HEIGHT_LIMIT_M;
        let cached = *hm.spec() == self.cache_spec && catalog.len() == self.cache.len();
        self.active = cached.then_some(ty.0 as usize);
        if !cached {
            let shape = catalog.shape(ty);
            for (k, &theta) in YAWS.iter().enumerate() {
                let (spec, fine_spec) = (self.spec, self.fine_spec);
                self.current[k].build(
                    hm.spec(),
                    &spec,
                    &fine_spec,
                    shape,
                    theta,
                    &mut self.full_fp,
                );
            }
        }
        for k in 0..NUM_YAWS {
            let fps = match self.active {
                Some(t) => &self.cache[t][k],
                None => &self.current[k],
            };
            let fp = &fps.coarse;
            let (lo, hi) = fps.bounds;
            for row in 0..spec.ny {
                for col in 0..spec.nx {
                    let i = (k * spec.ny + row) * spec.nx + col;
                    let (x, y) = spec.cell_centre(col, row);
                    let inside = inside_walls(x, y, lo, hi);
                    if !inside {
                        // Across a wall: not estimated.
                        self.rest_z[i] = f32::INFINITY;
                        self.top[i] = f32::INFINITY;
                        self.flags[i] = 0;
                        continue;
                    }
                    let (dc, dr) = (col as isize, row as isize);
                    let z = rest_height(&self.coarse, fp, dc, dr)
                        // No cell centre under the footprint: the estimate's own fallback.
                        .unwrap_or_else(|| self.coarse.sample(x, y) - fp.lowest());
                    let top = z + fp.top();
                    let below = top <= limit;
                    self.rest_z[i] = z;
                    self.top[i] = top;
                    self.flags[i] = INSIDE | if below { BELOW_LIMIT } else { 0 };
                }
            }
        }
    }

    /// The candidate placements (see the module docs), candidate 0 first; empty when no
    /// lattice placement is feasible. Call after [`Lattice::compute`].
    pub fn candidates(&mut self) -> &[Placement] {
        if !self.candidates.is_empty() {
            return &self.candidates;
        }
        let spec = self.spec;
        let limit = HEIGHT_LIMIT_M;
        let mut lowest = std::mem::take(&mut self.lowest);
        for k in 0..NUM_YAWS {
            // The inside-the-walls nodes of the lowest top, in row-major order: every corner's
            // choice below is among them (the top is the first key). Inside the walls suffices
            // here: the coarse top is conservative, the refined top decides the height limit.
            lowest.clear();
            let mut min_top = f32::INFINITY;
            for i in k * spec.len()..(k + 1) * spec.len() {
                if self.flags[i] & INSIDE == 0 {
                    continue;
                }
                let t = self.top[i];
                if t < min_top {
                    min_top = t;
                    lowest.clear();
                }
                if t == min_top {
                    lowest.push((i - k * spec.len()) as u32);
                }
            }
            for (sx, sy) in [(1.0f32, 1.0f32), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                for x_first in [true, false] {
                    // Lowest top, then nearest the corner (-sx, -sy) along the first axis.
                    let mut best: Option<(usize, usize, (f32, f32))> = None;
                    for &j in &lowest {
                        let (col, row) = (j as usize % spec.nx, j as usize / spec.nx);
                        let (x, y) = spec.cell_centre(col, row);
                        let key = if x_first {
                            (sx * x, sy * y)
                        } else {
                            (sy * y, sx * x)
                        };
                        if best.is_none_or(|(_, _, b)| key < b) {
                            best = Some((col, row, key));
                        }
                    }
                    let Some((col, row, _)) = best else { continue };
                    if self
                        .candidates
                        .iter()
                        .any(|c| c.yaw as usize == k && c.node == (col as u16, row as u16))
                    {
                        continue;
                    }
                    let Some(loose) = self.refine(k, col, row) else {
                        continue;
                    };
                    if loose.top <= limit {
                        self.candidates.push(loose);
                    }
                    if let Some(t) = self.push(loose, sx, sy, x_first)
                        && t.top <= limit
                    {
                        self.candidates.push(t);
                    }
                }
            }
        }
        self.lowest = lowest;
        self.candidates.sort_by(Placement::blbf_cmp);
        // Keep one of each position and yaw (sorted, so duplicates are adjacent unless their
        // estimates differ, loose and tight at the same spot: keep both then).
        self.candidates
            .dedup_by(|a, b| a.yaw == b.yaw && a.x == b.x && a.y == b.y && a.tight == b.tight);
        self.candidates.truncate(MAX_CANDIDATES);
        &self.candidates
    }

    /// The candidates from the last [`Lattice::candidates`] call (empty before it).
    pub fn computed_candidates(&self) -> &[Placement] {
        &self.candidates
    }

    /// The BLBF rule restricted to the lattice: candidate 0, or `None` when nothing is
    /// feasible.
    pub fn blbf(&mut self) -> Option<Placement> {
        self.candidates().first().copied()
    }

    /// `from` slid on the refinement grid towards the corner `(-sx, -sy)`, along x then y
    /// (or y then x), by up to [`MAX_PUSH_STEPS`] cells per axis while it stays inside the
    /// walls and its top, from the footprint sampled at the grid's cell centres as the BLBF
    /// heuristic does, does not rise: against its neighbours. A candidate that cannot move is
    /// only re-estimated with that footprint. `None` when `from` is not on the grid.
    fn push(&self, from: Placement, sx: f32, sy: f32, x_first: bool) -> Option<Placement> {
        let fs = self.fine_spec;
        let k = from.yaw as usize;
        let fps = self.fp(k);
        let fp = &fps.tight;
        let (lo, hi) = fps.bounds;
        let (u, v) = fs.to_pixel(from.x, from.y);
        let (mut c, mut r) = (u.floor() as isize, v.floor() as isize);
        let top_at = |c: isize, r: isize| self.rest_at(fp, (lo, hi), c, r);
        let (_, _, z0) = top_at(c, r)?;
        let mut z = z0;
        // +x is +column, +y is -row: towards -sx in x, towards -sy in y.
        let (dc, dr) = (-sx as isize, sy as isize);
        let axes = if x_first {
            [(dc, 0), (0, dr)]
        } else {
            [(0, dr), (dc, 0)]
        };
        for (ac, ar) in axes {
            for _ in 0..MAX_PUSH_STEPS {
                match top_at(c + ac, r + ar) {
                    Some((_, _, zn)) if zn <= z + 1e-4 => {
                        c += ac;
                        r += ar;
                        z = zn;
                    }
                    _ => break,
                }
            }
        }
        // A gap left (`push_gap`): back along each axis pushed, as far as the object stays at
        // its height; less where there is no room (the gap shrinks to what fits).
        for (ac, ar) in axes.into_iter().rev() {
            for _ in 0..self.push_gap {
                match top_at(c - ac, r - ar) {
                    Some((_, _, zn)) if zn <= z + 1e-4 => {
                        c -= ac;
                        r -= ar;
                        z = zn;
                    }
                    _ => break,
                }
            }
        }
        // Clear of the walls above the rim (`wall_gap`).
        let (c, r, _) = self.clear_walls(fp, (lo, hi), c, r, z);
        let (x, y, z) = top_at(c, r)?;
        Some(Placement {
            x,
            y,
            yaw: from.yaw,
            rest_z: z,
            top: z + fp.top(),
            support: support_fraction(&self.fine, fp, c, r, z, SUPPORT_TOL_M),
            node: from.node,
            tight: true,
        })
    }

    /// The best (BLBF order) inside-the-walls position of the fine grid among the nine around
    /// lattice node `(col, row)` at yaw `k`.
    fn refine(&self, k: usize, col: usize, row: usize) -> Option<Placement> {
        let (x, y) = self.spec.cell_centre(col, row);
        let fs = self.fine_spec;
        let (u, v) = fs.to_pixel(x, y);
        let (c0, r0) = (u.floor() as isize, v.floor() as isize);
        let fps = self.fp(k);
        let (lo, hi) = fps.bounds;
        let fp = &fps.fine;
        let mut best: Option<(Placement, isize, isize)> = None;
        for r in r0 - 1..=r0 + 1 {
            for c in c0 - 1..=c0 + 1 {
                let Some((fx, fy, z)) = self.rest_at(fp, (lo, hi), c, r) else {
                    continue;
                };
                let p = Placement {
                    x: fx,
                    y: fy,
                    yaw: k as u8,
                    rest_z: z,
                    top: z + fp.top(),
                    support: 0.0,
                    node: (col as u16, row as u16),
                    tight: false,
                };
                if best.is_none_or(|(b, _, _)| p.blbf_cmp(&b).is_lt()) {
                    best = Some((p, c, r));
                }
            }
        }
        // Clear of the walls above the rim (`wall_gap`), then support (not part of the
        // order) for the winner only.
        best.map(|(p, c, r)| {
            let (c, r, z) = self.clear_walls(fp, (lo, hi), c, r, p.rest_z);
            let (x, y) = fs.cell_centre(c as usize, r as usize);
            Placement {
                x,
                y,
                rest_z: z,
                top: z + fp.top(),
                support: support_fraction(&self.fine, fp, c, r, z, SUPPORT_TOL_M),
                ..p
            }
        })
    }

    /// Where footprint `fp` with bounds `(lo, hi)` rests with its origin at the centre of fine
    /// cell `(c, r)`: `(x, y, z)`, or `None` off the grid, across a wall, or with no cell
    /// centre under the footprint. Shared by the refinement, the push and the clearances.
    fn rest_at(
        &self,
        fp: &ZScratch,
        (lo, hi): (Vector, Vector),
        c: isize,
        r: isize,
    ) -> Option<(f32, f32, f32)> {
        let fs = self.fine_spec;
        if c < 0 || r < 0 || c as usize >= fs.nx || r as usize >= fs.ny {
            return None;
        }
        let (x, y) = fs.cell_centre(c as usize, r as usize);
        if !inside_walls(x, y, lo, hi) {
            return None;
        }
        Some((x, y, rest_height(&self.fine, fp, c, r)?))
    }

    /// Fine cell `(c, r)`, where footprint `fp` with bounds `(lo, hi)` rests at `z`, moved
    /// away from each wall it is within `wall_gap` cells of when its top stands above the rim
    /// ([`Lattice::set_wall_gap`]): a cell at a time, while its rest height does not rise.
    fn clear_walls(
        &self,
        fp: &ZScratch,
        (lo, hi): (Vector, Vector),
        mut c: isize,
        mut r: isize,
        mut z: f32,
    ) -> (isize, isize, f32) {
        if self.wall_gap == 0 || z + fp.top() <= BOX_HEIGHT {
            return (c, r, z);
        }
        let fs = self.fine_spec;
        let m = self.wall_gap as f32 * FINE_CELL_M;
        // The step away from the wall `(c, r)` is near along each axis (0: near neither, or
        // both). +x is +column, +y is -row.
        let away = |c: isize, r: isize| -> (isize, isize) {
            let (x, y) = fs.cell_centre(c as usize, r as usize);
            let dc = match (x + lo.x < -BOX_HALF_X + m, x + hi.x > BOX_HALF_X - m) {
                (true, false) => 1,
                (false, true) => -1,
                _ => 0,
            };
            let dr = match (y + lo.y < -BOX_HALF_Y + m, y + hi.y > BOX_HALF_Y - m) {
                (true, false) => -1,
                (false, true) => 1,
                _ => 0,
            };
            (dc, dr)
        };
        let (dc, dr) = away(c, r);
        for (ac, ar) in [(dc, 0), (0, dr)] {
            if (ac, ar) == (0, 0) {
                continue;
            }
            for _ in 0..self.wall_gap {
                let (nc, nr) = away(c, r);
                if (ac != 0 && nc != ac) || (ar != 0 && nr != ar) {
                    break; // clear of that wall
                }
                match self.rest_at(fp, (lo, hi), c + ac, r + ar) {
                    Some((_, _, zn)) if zn <= z + 1e-4 => (c, r, z) = (c + ac, r + ar, zn),
                    _ => break,
                }
            }
        }
        (c, r, z)
    }
}

/// The footprint with bounds `(lo, hi)` around its origin at `(x, y)` lies inside the walls.
#[inline]
fn inside_walls(x: f32, y: f32, lo: Vector, hi: Vector) -> bool {
    x + lo.x >= -BOX_HALF_X - WALL_TOL_M
        && x + hi.x <= BOX_HALF_X + WALL_TOL_M
        && y + lo.y >= -BOX_HALF_Y - WALL_TOL_M
        && y + hi.y <= BOX_HALF_Y + WALL_TOL_M
}
