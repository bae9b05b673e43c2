//! The candidate policy's inputs: a context vector for the decision and a feature row per
//! lattice candidate. The one implementation, used by the training bindings, the evaluation,
//! the daemon's policy and the decision bench; the ONNX I/O contract of a candidate policy is
//! written against it ([`CandidateLayout`]).
//!
//! # Context (`CONTEXT_LEN` values)
//!
//! - `[0, 532)`: the box heightmap max-pooled to the lattice cell (28 x 19, row 0 at +y,
//!   column 0 at -x), height / [`HEIGHT_SCALE_M`];
//! - then the next object: its canonical extents x, y, z / [`SIZE_SCALE_M`], its hull volume
//!   / the box volume;
//! - then the objects after it (the rest of the job, known to herbd): count /
//!   [`COUNT_SCALE`], total hull volume / box volume, total footprint area (extents x * y) /
//!   box floor area, largest extent / [`SIZE_SCALE_M`];
//! - then the free volume under the rim (sum over cells of `max(0, rim - h)` times the cell
//!   area) / box volume, and the highest cell / [`HEIGHT_SCALE_M`].
//!
//! # Candidate row (`CANDIDATE_LEN` values), for each of up to [`MAX_CANDIDATES`]
//!
//! x / `BOX_HALF_X`, y / `BOX_HALF_Y`, the yaw one-hot (4), rest z, top, top minus the highest
//! cell (each / `HEIGHT_SCALE_M`), support, tight flag, the four wall gaps of the footprint
//! (-x, +x, -y, +y; / [`GAP_SCALE_M`], clamped to 1), and a 5 x 5 patch of the pooled heightmap centred on the candidate's lattice node,
//! each cell's height minus the object's bottom at rest, / [`GAP_SCALE_M`], clamped to
//! `[-1, 1]` (cells outside the box count as the walls' top). Rows past the candidate count are
//! zero and masked.
//!
//! # Symmetry
//!
//! Turning the box half a turn about z maps a state to an equivalent one: x and y change sign,
//! yaw `k` becomes `k + 2`, the -x/+x and -y/+y wall gaps swap, and the context heightmap and
//! each patch are turned half a turn (their values reversed). [`half_turn_context`] and
//! [`half_turn_candidates`] apply it: an exact augmentation for training.

use crate::catalog::{Catalog, TypeIdx};
use crate::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT};
use crate::heightmap::Heightmap;
use crate::lattice::{Lattice, MAX_CANDIDATES, NUM_YAWS, Placement};
use parry3d::math::Rotation;

/// Heights are divided by this (m): the observation's height scale.
pub const HEIGHT_SCALE_M: f32 = crate::observation::ObsLayout::HEIGHT_SCALE_M;
/// Object sizes are divided by this (m).
pub const SIZE_SCALE_M: f32 = 0.3;
/// Gaps (walls, neighbours) are divided by this (m).
pub const GAP_SCALE_M: f32 = 0.1;
/// Object counts are divided by this.
pub const COUNT_SCALE: f32 = 25.0;
/// Side of the heightmap patch of a candidate row (lattice cells).
pub const PATCH: usize = 5;
/// Lattice columns and rows (the 12.5 mm grid over the box).
pub const GRID: (usize, usize) = (28, 19);
/// Values of the context vector.
pub const CONTEXT_LEN: usize = GRID.0 * GRID.1 + 4 + 4 + 2;
/// Values of a candidate row.
pub const CANDIDATE_LEN: usize = 2 + NUM_YAWS + 3 + 2 + 4 + PATCH * PATCH;

/// Names and shapes of a candidate policy's ONNX inputs and output.
#[derive(Debug, Clone, Copy)]
pub struct CandidateLayout;

impl CandidateLayout {
    /// Input: the context, `[1, CONTEXT_LEN]`.
    pub const CONTEXT_NAME: &'static str = "context";
    /// Input: the candidate rows, `[1, MAX_CANDIDATES, CANDIDATE_LEN]`.
    pub const CANDIDATES_NAME: &'static str = "candidates";
    /// Input: 1 for a real candidate, 0 for padding, `[1, MAX_CANDIDATES]`.
    pub const MASK_NAME: &'static str = "mask";
    /// Output: a score per candidate, `[1, MAX_CANDIDATES]`; the policy takes the highest
    /// among real candidates (padding is masked inside the model, and again by the caller).
    pub const OUTPUT_NAME: &'static str = "logits";
}

/// The inputs of one decision, reused across decisions.
#[derive(Debug, Clone)]
pub struct DecisionFeatures {
    /// The context vector.
    pub context: Vec<f32>,
    /// `MAX_CANDIDATES` rows of `CANDIDATE_LEN`.
    pub candidates: Vec<f32>,
    /// 1 for real candidates.
    pub mask: Vec<f32>,
    /// The candidate placements, row order.
    pub placements: Vec<Placement>,
}

impl Default for DecisionFeatures {
    fn default() -> Self {
        Self {
            context: vec![0.0; CONTEXT_LEN],
            candidates: vec![0.0; MAX_CANDIDATES * CANDIDATE_LEN],
            mask: vec![0.0; MAX_CANDIDATES],
            placements: Vec::with_capacity(MAX_CANDIDATES),
        }
    }
}

impl DecisionFeatures {
    /// Computes the lattice for `next` over `hm` and fills the inputs; `after` are the objects
    /// to place after `next`. Returns the number of candidates (0: no feasible placement).
    pub fn compute(
        &mut self,
        lattice: &mut Lattice,
        catalog: &Catalog,
        hm: &Heightmap,
        next: TypeIdx,
        after: &[TypeIdx],
    ) -> usize {
        lattice.compute(hm, catalog, next);
        self.placements.clear();
        self.placements.extend_from_slice(lattice.candidates());
        self.fill(lattice, catalog, next, after);
        self.placements.len()
    }

    /// No decision (the episode is over): everything zero, no candidates.
    pub fn clear(&mut self) {
        self.context.fill(0.0);
        self.candidates.fill(0.0);
        self.mask.fill(0.0);
        self.placements.clear();
    }

    fn fill(&mut self, lattice: &Lattice, catalog: &Catalog, next: TypeIdx, after: &[TypeIdx]) {
        let pooled = lattice.pooled();
        let spec = *pooled.spec();
        debug_assert_eq!((spec.nx, spec.ny), GRID);
        let box_vol = 4.0 * BOX_HALF_X * BOX_HALF_Y * BOX_HEIGHT;
        let floor = 4.0 * BOX_HALF_X * BOX_HALF_Y;
        let c = &mut self.context;
        let mut hmax = 0.0f32;
        let mut free = 0.0f32;
        let cell_area = spec.cell * spec.cell;
        for (dst, &h) in c.iter_mut().zip(pooled.data()) {
            *dst = h / HEIGHT_SCALE_M;
            hmax = hmax.max(h);
            free += (BOX_HEIGHT - h).max(0.0) * cell_area;
        }
        let mut i = GRID.0 * GRID.1;
        let shape = catalog.shape(next);
        let e = shape.extents();
        for v in [
            e.x / SIZE_SCALE_M,
            e.y / SIZE_SCALE_M,
            e.z / SIZE_SCALE_M,
            shape.volume / box_vol,
        ] {
            c[i] = v;
            i += 1;
        }
        let (mut vol, mut area, mut largest) = (0.0f32, 0.0f32, 0.0f32);
        for &t in after {
            let s = catalog.shape(t);
            let e = s.extents();
            vol += s.volume;
            area += e.x * e.y;
            largest = largest.max(e.x.max(e.y).max(e.z));
        }
        for v in [
            after.len() as f32 / COUNT_SCALE,
            vol / box_vol,
            area / floor,
            largest / SIZE_SCALE_M,
            free / box_vol,
            hmax / HEIGHT_SCALE_M,
        ] {
            c[i] = v;
            i += 1;
        }
        debug_assert_eq!(i, CONTEXT_LEN);

        self.candidates.fill(0.0);
        self.mask.fill(0.0);
        let lowest = shape.aabb_min.z;
        for (j, p) in self.placements.iter().enumerate() {
            let row = &mut self.candidates[j * CANDIDATE_LEN..(j + 1) * CANDIDATE_LEN];
            self.mask[j] = 1.0;
            row[0] = p.x / BOX_HALF_X;
            row[1] = p.y / BOX_HALF_Y;
            row[2 + p.yaw as usize] = 1.0;
            let mut k = 2 + NUM_YAWS;
            let (lo, hi) = lattice.bounds(p.yaw as usize);
            let gap = |g: f32| (g / GAP_SCALE_M).clamp(0.0, 1.0);
            for v in [
                p.rest_z / HEIGHT_SCALE_M,
                p.top / HEIGHT_SCALE_M,
                (p.top - hmax) / HEIGHT_SCALE_M,
                p.support,
                p.tight as u8 as f32,
                gap(p.x + lo.x + BOX_HALF_X),
                gap(BOX_HALF_X - p.x - hi.x),
                gap(p.y + lo.y + BOX_HALF_Y),
                gap(BOX_HALF_Y - p.y - hi.y),
            ] {
                row[k] = v;
                k += 1;
            }
            let bottom = p.rest_z + lowest;
            let (nc, nr) = (p.node.0 as isize, p.node.1 as isize);
            let half = (PATCH / 2) as isize;
            for dr in -half..=half {
                for dc in -half..=half {
                    let h = pooled.get(nc + dc, nr + dr);
                    row[k] = ((h - bottom) / GAP_SCALE_M).clamp(-1.0, 1.0);
                    k += 1;
                }
            }
            debug_assert_eq!(k, CANDIDATE_LEN);
        }
    }
}

/// Applies the box's half turn about z to context vectors (consecutive runs of
/// [`CONTEXT_LEN`] values) in place (see the module docs).
pub fn half_turn_context(contexts: &mut [f32]) {
    for c in contexts.chunks_exact_mut(CONTEXT_LEN) {
        c[..GRID.0 * GRID.1].reverse();
    }
}

/// Applies the box's half turn about z to candidate rows (consecutive runs of
/// [`CANDIDATE_LEN`] values) in place (see the module docs). Applying it twice restores them.
pub fn half_turn_candidates(rows: &mut [f32]) {
    for row in rows.chunks_exact_mut(CANDIDATE_LEN) {
        row[0] = -row[0];
        row[1] = -row[1];
        row[2..2 + NUM_YAWS].rotate_left(2);
        let g = 2 + NUM_YAWS + 5;
        row.swap(g, g + 1);
        row.swap(g + 2, g + 3);
        row[g + 4..].reverse();
    }
}

/// The yaw rotation of a candidate (for callers releasing it).
pub fn rotation(p: &Placement) -> Rotation {
    Rotation::from_rotation_z(p.theta())
}
