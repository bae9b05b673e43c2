//! Placement policies behind one trait: what the decision core knows in, a placement
//! ([`PlanarPose`]: x, y and yaw in the box frame) out; z comes from the heightmap (the
//! [`crate::Decider`]'s one release pose).
//!
//! A policy sees a [`DecisionInput`]: the observation tensor in the shared layout
//! (`herb_core::ObsLayout`), the heightmap it was built from (checked once, by the
//! `Decider`), the next object and those after it. A network that answers a normalised action
//! (the observation contract, [`crate::OnnxPolicy`]) decodes it once, itself; a method that
//! chooses a placement (BLBF, the candidate contract, the search of `herb-search`) returns it
//! as it is. Decisions are checked before they leave: a placement that is not finite or lies
//! outside the box is a [`DecideError::Rejected`] naming the policy, never passed on.

use crate::error::{DecideError, Result};
use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y, SUCCESS_TOP_Z};
use herb_core::zestimate::{ZScratch, bottom_footprint, estimate_z_rotated, rest_height};
use herb_core::{Catalog, GridSpec, Heightmap, ObjectShape, ObsLayout, TypeIdx};
use parry3d::math::{Mat3, Pose, Rotation, Vector};

/// What a policy decides from.
#[derive(Debug, Clone, Copy)]
pub struct DecisionInput<'a> {
    /// The observation, `ObsLayout::LEN` values in the shared layout.
    pub observation: &'a [f32],
    /// The box heightmap the observation was built from (m).
    pub heightmap: &'a Heightmap,
    /// The next object's type.
    pub object: TypeIdx,
    /// Its shape (canonical frame).
    pub shape: &'a ObjectShape,
    /// Its index in the packing sequence.
    pub step: usize,
    /// The catalog (shapes of every object type).
    pub catalog: &'a Catalog,
    /// The objects of the job still to place, this one first, in order.
    pub remaining: &'a [TypeIdx],
}

impl DecisionInput<'_> {
    /// The objects of the job still to place after this one, in order.
    pub fn after(&self) -> &[TypeIdx] {
        self.remaining.get(1..).unwrap_or(&[])
    }
}

/// Where a policy puts an object: the canonical origin's x and y in the box frame B (m) and its
/// yaw about B z (rad). The release height is not the policy's: the [`crate::Decider`] adds it
/// (the z estimate on the heightmap plus the clearance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarPose {
    /// B x (m).
    pub x: f32,
    /// B y (m).
    pub y: f32,
    /// Yaw about B z (rad).
    pub theta: f32,
}

impl From<herb_core::lattice::Placement> for PlanarPose {
    fn from(p: herb_core::lattice::Placement) -> Self {
        Self {
            x: p.x,
            y: p.y,
            theta: p.theta(),
        }
    }
}

/// A placement policy.
pub trait Policy {
    /// Short name for tables and logs.
    fn name(&self) -> &str;
    /// Starts an episode (seeds stochastic policies; replays reset their cursor).
    fn begin_episode(&mut self, seed: u64);
    /// Where `input.object` goes. [`DecideError::NoFeasiblePlacement`] when nothing fits.
    fn decide(&mut self, input: &DecisionInput) -> Result<PlanarPose>;
    /// Whether [`DecisionInput::observation`] is read. Callers may skip building it (and pass
    /// an empty slice) for policies that return false.
    fn needs_observation(&self) -> bool {
        true
    }
    /// A fresh copy of this policy for another episode loop, sharing what was loaded (an
    /// optimised network) but with its own inference session and buffers, so it decides as a
    /// policy loaded from the same file would; `None` for the policies that are cheap to make.
    /// An evaluation loads a model file once per process through this.
    fn fork(&self) -> Option<Box<dyn Policy + Send>> {
        None
    }
}

/// Checks an observation before a network sees it: its length and values in `[0, 1]` (the
/// heightmap under it was checked once, by the `Decider`).
pub fn check_input(policy: &str, input: &DecisionInput) -> Result<()> {
    let reject = |reason: String| DecideError::Rejected {
        policy: policy.to_owned(),
        reason,
    };
    if input.observation.len() != ObsLayout::LEN {
        return Err(reject(format!(
            "observation has {} values, expected {}",
            input.observation.len(),
            ObsLayout::LEN
        )));
    }
    match input
        .observation
        .iter()
        .position(|v| !(0.0..=1.0).contains(v))
    {
        Some(i) => Err(reject(format!(
            "observation value {} at index {i} outside [0, 1]",
            input.observation[i]
        ))),
        None => Ok(()),
    }
}

/// Checks an action before it leaves a policy: finite and within `[-1, 1]`.
pub fn check_action(policy: &str, a: [f32; 3]) -> Result<[f32; 3]> {
    if a.iter().all(|v| v.is_finite() && v.abs() <= 1.0) {
        Ok(a)
    } else {
        Err(DecideError::Rejected {
            policy: policy.to_owned(),
            reason: format!("action {a:?} is not finite and within [-1, 1]"),
        })
    }
}

/// Checks a placement before it leaves the decision core: finite, and its origin over the box
/// (`|x| <= BOX_HALF_X`, `|y| <= BOX_HALF_Y`, as a normalised action within `[-1, 1]` is).
pub fn check_placement(policy: &str, p: PlanarPose) -> Result<PlanarPose> {
    let finite = p.x.is_finite() && p.y.is_finite() && p.theta.is_finite();
    if finite && p.x.abs() <= BOX_HALF_X && p.y.abs() <= BOX_HALF_Y {
        Ok(p)
    } else {
        Err(DecideError::Rejected {
            policy: policy.to_owned(),
            reason: format!(
                "placement x {} m, y {} m, yaw {} rad is not finite and over the box",
                p.x, p.y, p.theta
            ),
        })
    }
}

/// The grid cell of the BLBF search, as a multiple of the heightmap cell.
pub const BLBF_CELLS_PER_STEP: usize = 4;

/// The PackIt heuristic restricted to planar rotations (after princeton-vl/PackIt,
/// `packing/packing_heuristic.py`), our stand-in for the paper's "PackIt SO(2)" row.
///
/// The object stays upright (canonical resting orientation) with yaw 0 or 90 degrees. Over a
/// grid of [`BLBF_CELLS_PER_STEP`] heightmap cells (6.25 mm for the observation's 1.5625 mm
/// cells), on a max-pooled copy of the heightmap, every position whose footprint lies inside
/// the walls is scored by its resting height (the shared z estimate) plus the object's height:
/// the position with the lowest resulting top wins, then the smallest x, then the smallest y
/// (deep-bottom-left-back fill), then yaw 0 before 90 degrees. The sequence (largest volume
/// first) is the planner's job (`--sequence largest`). Allocates only on its first decision
/// or when the heightmap grid changes.
#[derive(Debug, Default)]
pub struct Blbf {
    coarse: Option<Heightmap>,
    scratch: ZScratch,
}

impl Blbf {
    /// A BLBF policy.
    pub fn new() -> Self {
        Self::default()
    }

    /// The search grid's cell (m) for a heightmap grid.
    pub fn search_cell(spec: &GridSpec) -> f32 {
        spec.cell * BLBF_CELLS_PER_STEP as f32
    }

    /// The best placement `(x, y, theta)` and its top height, or `None` if no position fits
    /// between the walls.
    pub fn best(&mut self, hm: &Heightmap, shape: &ObjectShape) -> Option<(f32, f32, f32, f32)> {
        const YAWS: [f32; 2] = [0.0, std::f32::consts::FRAC_PI_2];
        let rots = YAWS.map(Rotation::from_rotation_z);
        self.search(hm, shape, &rots)
            .map(|(x, y, i, top)| (x, y, YAWS[i], top))
    }

    /// The search of [`Blbf`] over any `orientations` of the canonical frame: `(x, y, index of
    /// the orientation, top)` of the lowest top, then the smallest x, then the smallest y,
    /// earlier orientations winning ties; `None` if no position fits between the walls.
    pub fn search(
        &mut self,
        hm: &Heightmap,
        shape: &ObjectShape,
        orientations: &[Rotation],
    ) -> Option<(f32, f32, usize, f32)> {
        let cell = Self::search_cell(hm.spec());
        let spec = GridSpec::for_box(cell).ok()?;
        let coarse = match &mut self.coarse {
            Some(c) if *c.spec() == spec => c,
            slot => slot.insert(Heightmap::new(spec)),
        };
        hm.max_pool_into(coarse);
        let mut best: Option<(f32, f32, usize, f32)> = None;
        for (i, &rot) in orientations.iter().enumerate() {
            let (x0, y0) = spec.cell_centre(0, 0);
            bottom_footprint(&spec, shape, x0, y0, rot, &mut self.scratch);
            // Footprint extents around the origin (for the walls).
            let (lo, hi) = shape.rotated_bounds(rot);
            let height = self.scratch.top() - self.scratch.lowest();
            const TOL: f32 = 1e-4;
            for row in 0..spec.ny {
                for col in 0..spec.nx {
                    let (x, y) = spec.cell_centre(col, row);
                    if x + lo.x < -BOX_HALF_X - TOL
                        || x + hi.x > BOX_HALF_X + TOL
                        || y + lo.y < -BOX_HALF_Y - TOL
                        || y + hi.y > BOX_HALF_Y + TOL
                    {
                        continue;
                    }
                    let Some(z) = rest_height(coarse, &self.scratch, col as isize, row as isize)
                    else {
                        continue;
                    };
                    let top = z + self.scratch.lowest() + height;
                    let better = match best {
                        None => true,
                        Some((bx, by, _, btop)) => (top, x, y) < (btop, bx, by),
                    };
                    if better {
                        best = Some((x, y, i, top));
                    }
                }
            }
        }
        best
    }
}

/// The PackIt heuristic with its rotation search (after princeton-vl/PackIt,
/// `packing/packing_heuristic.py`, `rot_best_pos` then `mov_best`), our "PackIt SO(3)" row.
///
/// The object may be laid in any of the 24 orientations that align its canonical bounding box
/// with the box's axes. They are tried in PackIt's order of preference ([`Self::orientations`]):
/// smallest side up, longest side along the box's long side (x), then the other assignments of
/// sides to axes, each in its four half-turns. The first orientation with a position inside
/// the walls whose top stays under the success volume's top wins, placed where [`Blbf`]'s
/// search puts it in that orientation (lowest top, then deep-bottom-left-back); if none stays
/// under that top, the orientation with the lowest top. Release height from the shared z
/// estimate at full resolution. The decision, as timed in Table I, includes the alignment
/// (sides measured, orientations ranked) and the z estimate.
#[derive(Debug, Default)]
pub struct PackitSo3 {
    blbf: Blbf,
    zs: Option<ZScratch>,
}

impl PackitSo3 {
    /// The heuristic.
    pub fn new() -> Self {
        Self::default()
    }

    /// The 24 axis-aligned orientations of `shape` in PackIt's order of preference: the
    /// canonical sides sorted shortest to longest (s, m, l) are assigned to the box's axes
    /// (z, y, x) as (s, m, l), (s, l, m), (m, s, l), (l, s, m), (m, l, s), (l, m, s), ranked as
    /// PackIt's `cmp_func` ranks them (the shortest side up first, then the middle one along
    /// y); each assignment in its four half-turns (none, about z, about x, about y).
    pub fn orientations(shape: &ObjectShape) -> [Rotation; 24] {
        let e = shape.extents();
        let mut axes = [0usize, 1, 2];
        axes.sort_by(|&a, &b| e[a].total_cmp(&e[b]).then(a.cmp(&b)));
        let [s, m, l] = axes;
        // (object axis along B z, along B y, along B x)
        let classes = [
            (s, m, l),
            (s, l, m),
            (m, s, l),
            (l, s, m),
            (m, l, s),
            (l, m, s),
        ];
        let half_turns = [
            Rotation::IDENTITY,
            Rotation::from_rotation_z(std::f32::consts::PI),
            Rotation::from_rotation_x(std::f32::consts::PI),
            Rotation::from_rotation_y(std::f32::consts::PI),
        ];
        let mut out = [Rotation::IDENTITY; 24];
        for (k, &(up, side, long)) in classes.iter().enumerate() {
            // Columns: where each object axis goes in B.
            let mut cols = [Vector::ZERO; 3];
            cols[long] = Vector::X;
            cols[side] = Vector::Y;
            cols[up] = Vector::Z;
            let mut mat = Mat3::from_cols(cols[0], cols[1], cols[2]);
            if mat.determinant() < 0.0 {
                cols[side] = -Vector::Y;
                mat = Mat3::from_cols(cols[0], cols[1], cols[2]);
            }
            let base = Rotation::from_mat3(&mat).normalize();
            for (j, &h) in half_turns.iter().enumerate() {
                out[4 * k + j] = (h * base).normalize();
            }
        }
        out
    }

    /// The release pose of `shape` on `hm` (canonical origin at the estimated resting height
    /// plus `clearance_m`), or `None` when no orientation fits between the walls.
    pub fn decide(
        &mut self,
        hm: &Heightmap,
        shape: &ObjectShape,
        clearance_m: f32,
    ) -> Option<Pose> {
        let mut fallback: Option<(f32, f32, Rotation, f32)> = None;
        let mut chosen = None;
        for rot in Self::orientations(shape) {
            let Some((x, y, _, top)) = self.blbf.search(hm, shape, &[rot]) else {
                continue;
            };
            if top <= SUCCESS_TOP_Z {
                chosen = Some((x, y, rot));
                break;
            }
            if fallback.is_none_or(|f| top < f.3) {
                fallback = Some((x, y, rot, top));
            }
        }
        let (x, y, rot) = chosen.or(fallback.map(|(x, y, r, _)| (x, y, r)))?;
        let zs = self.zs.get_or_insert_with(|| {
            let e = shape.extents();
            ZScratch::with_capacity(shape.vertices.len(), e.length(), hm.spec().cell)
        });
        let z = estimate_z_rotated(hm, shape, x, y, rot, zs) + clearance_m;
        Some(Pose::from_parts(Vector::new(x, y, z), rot))
    }
}

impl Policy for Blbf {
    fn name(&self) -> &str {
        "blbf"
    }
    fn begin_episode(&mut self, _seed: u64) {}
    fn decide(&mut self, input: &DecisionInput) -> Result<PlanarPose> {
        let (x, y, theta, _) =
            self.best(input.heightmap, input.shape)
                .ok_or_else(|| DecideError::Rejected {
                    policy: "blbf".into(),
                    reason: "the object does not fit between the walls in either yaw".into(),
                })?;
        Ok(PlanarPose { x, y, theta })
    }
}
