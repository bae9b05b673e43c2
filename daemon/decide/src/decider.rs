//! The one decision from a heightmap to a placement, as herbd runs it and as the evaluation, the
//! decision bench and the bindings' expert labels run it.
//!
//! A heightmap is checked once and copied once, when the decider receives it
//! ([`Decider::observe`]: herbd's decision worker does so as each camera frame arrives); every
//! decision on it ([`Decider::decide`]) then trusts it, and so do the policies.
//!
//! **Decision latency** (Table I's latency column, the decision bench) is the duration of one
//! [`Decider::decide_on`] call: checking the heightmap and taking one copy of it, writing the
//! observation when the policy reads one, the policy (with its own lattice or features),
//! checking its placement, and the z estimate of the chosen placement. herbd's `decision_ns` is
//! the same without the check and the copy, which it does as the frame arrives. Waiting for a
//! heightmap and planning the motion are not part of it.

use crate::error::{DecideError, Result};
use crate::policy::{DecisionInput, PlanarPose, Policy, check_placement};
use herb_core::observation::Projections;
use herb_core::zestimate::{ZScratch, release_pose_on};
use herb_core::{GridSpec, Heightmap, ObsLayout, SharedCatalog, TypeIdx};
use parry3d::math::{Pose, Rotation, Vector};

/// A heightmap as it arrives (a camera frame, the simulation's map): row-major cells of a grid
/// over the box interior, heights above the inner floor (m).
#[derive(Debug, Clone, Copy)]
pub struct HeightmapView<'a> {
    /// Columns (along B x).
    pub nx: usize,
    /// Rows (along B y).
    pub ny: usize,
    /// Cell side (m).
    pub cell_m: f32,
    /// `nx * ny` heights, row by row.
    pub cells: &'a [f32],
}

impl<'a> From<&'a Heightmap> for HeightmapView<'a> {
    fn from(hm: &'a Heightmap) -> Self {
        let spec = hm.spec();
        Self {
            nx: spec.nx,
            ny: spec.ny,
            cell_m: spec.cell,
            cells: hm.data(),
        }
    }
}

/// Where an object goes: the policy's placement and the release pose it gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The placement the policy chose (x, y, yaw in B), as it chose it.
    pub placement: PlanarPose,
    /// Release position of the canonical origin in the box frame B (m): x, y, and z from the
    /// heightmap plus the release clearance.
    pub position: [f32; 3],
    /// Yaw about B z (rad).
    pub theta: f32,
}

impl Decision {
    /// The yaw as the rotation the z estimate used (normalised, as the world releases it).
    pub fn rotation(&self) -> Rotation {
        Rotation::from_rotation_z(self.theta).normalize()
    }

    /// The release pose in B.
    pub fn pose(&self) -> Pose {
        let [x, y, z] = self.position;
        Pose::from_parts(Vector::new(x, y, z), self.rotation())
    }

    /// x, y, z, yaw: the placement herbd plans the motion to.
    pub fn xyz_theta(&self) -> [f32; 4] {
        let [x, y, z] = self.position;
        [x, y, z, self.theta]
    }
}

/// Decides placements with one policy: see the module documentation for what a decision
/// covers. Every buffer is allocated at construction or on the first heightmap of a grid.
/// The policy is any [`Policy`], chosen at run time by default (`Decider` is
/// `Decider<dyn Policy>`); a concrete one keeps the decider `Send` and `Sync` where it is.
pub struct Decider<P: Policy + ?Sized = dyn Policy> {
    policy: Box<P>,
    catalog: SharedCatalog,
    projections: Projections,
    obs: Vec<f32>,
    /// The last good heightmap observed (`None` before the first).
    hm: Option<Heightmap>,
    zs: ZScratch,
    clearance_m: f32,
}

impl<P: Policy + ?Sized> std::fmt::Debug for Decider<P> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Decider")
            .field("policy", &self.policy.name())
            .field("clearance_m", &self.clearance_m)
            .finish()
    }
}

impl Decider {
    /// A decider running the policy `spec` names (see [`crate::load_policy`]).
    pub fn load(
        spec: &crate::PolicySpec,
        catalog: SharedCatalog,
        clearance_m: f32,
    ) -> Result<Self> {
        let policy = crate::load_policy(spec, &catalog)?;
        Ok(Self::new(policy, catalog, clearance_m))
    }
}

impl<P: Policy + ?Sized> Decider<P> {
    /// A decider running `policy`, releasing `clearance_m` above the estimated resting height.
    pub fn new(policy: Box<P>, catalog: SharedCatalog, clearance_m: f32) -> Self {
        Self {
            policy,
            projections: Projections::new(&catalog),
            obs: vec![0.0; ObsLayout::LEN],
            hm: None,
            zs: ZScratch::for_catalog(&catalog, ObsLayout::CELL_M),
            catalog,
            clearance_m,
        }
    }

    /// The policy.
    pub fn policy(&self) -> &P {
        &self.policy
    }

    /// The policy, to change its settings between decisions.
    pub fn policy_mut(&mut self) -> &mut P {
        &mut self.policy
    }

    /// The policy's name.
    pub fn policy_name(&self) -> &str {
        self.policy.name()
    }

    /// Starts an episode (a job): stochastic policies reseed.
    pub fn begin_episode(&mut self, seed: u64) {
        self.policy.begin_episode(seed);
    }

    /// Checks `heightmap` and takes its one copy, on which the next decisions are made. A
    /// heightmap whose grid is not the box's at its cell size, or with a cell that is not finite
    /// or out of range, is rejected, and the decisions stay on the last good one.
    pub fn observe(&mut self, heightmap: HeightmapView<'_>) -> Result<()> {
        let bad = |reason: String| DecideError::Rejected {
            policy: "decider".into(),
            reason,
        };
        let spec =
            GridSpec::for_box(heightmap.cell_m).map_err(|e| bad(format!("heightmap: {e}")))?;
        if (spec.nx, spec.ny) != (heightmap.nx, heightmap.ny) {
            return Err(bad(format!(
                "heightmap of {} x {} cells of {} m; the box needs {} x {}",
                heightmap.nx, heightmap.ny, heightmap.cell_m, spec.nx, spec.ny
            )));
        }
        herb_core::heightmap::check_cells(&spec, heightmap.cells)
            .map_err(|e| bad(e.to_string()))?;
        if self.hm.as_ref().map(|h| *h.spec()) != Some(spec) {
            self.hm = Some(Heightmap::new(spec));
        }
        // One snapshot (a shared frame must not change under the decision).
        let hm = self.hm.as_mut().expect("set above");
        hm.data_mut().copy_from_slice(heightmap.cells);
        Ok(())
    }

    /// [`Decider::observe`] then [`Decider::decide`]: one decision on a heightmap of its own.
    pub fn decide_on(
        &mut self,
        heightmap: HeightmapView<'_>,
        remaining: &[TypeIdx],
        step: usize,
    ) -> Result<Decision> {
        self.observe(heightmap)?;
        self.decide(remaining, step)
    }

    /// The placement of `remaining[0]` (step `step` of the episode, the rest the objects still
    /// to come) on the heightmap last observed. A placement that is not finite or lies outside
    /// the box is rejected; so is a decision without a checked heightmap or without an object.
    /// [`DecideError::NoFeasiblePlacement`] when the policy finds nothing that fits.
    pub fn decide(&mut self, remaining: &[TypeIdx], step: usize) -> Result<Decision> {
        let bad = |reason: &str| DecideError::Rejected {
            policy: "decider".into(),
            reason: reason.into(),
        };
        let &object = remaining.first().ok_or_else(|| bad("no object to place"))?;
        let hm = self
            .hm
            .as_ref()
            .ok_or_else(|| bad("no checked heightmap to decide on"))?;
        let observation: &[f32] = if self.policy.needs_observation() {
            ObsLayout::write(hm, Some(self.projections.get(object)), &mut self.obs)?;
            &self.obs
        } else {
            &[]
        };
        let shape = self.catalog.shape(object);
        let placement = self
            .policy
            .decide(&DecisionInput {
                observation,
                heightmap: hm,
                object,
                shape,
                step,
                catalog: &self.catalog,
                remaining,
            })
            .and_then(|p| check_placement(self.policy.name(), p))?;
        let PlanarPose { x, y, theta } = placement;
        // Yaw within [-pi, pi] as the arm plans it (a network's action reaches both ends); one
        // already there is kept bit for bit, one outside wrapped into (-pi, pi].
        let theta = if (-std::f32::consts::PI..=std::f32::consts::PI).contains(&theta) {
            theta
        } else {
            herb_core::frames::wrap_angle(theta)
        };
        // Normalised once, by the release pose (as before it was moved there).
        let rot = Rotation::from_rotation_z(theta);
        // The one release pose (z estimate plus the clearance), as the search's job twin
        // replays it.
        let z = release_pose_on(hm, shape, (x, y, rot), self.clearance_m, &mut self.zs)
            .translation
            .z;
        Ok(Decision {
            placement,
            position: [x, y, z],
            theta,
        })
    }
}
