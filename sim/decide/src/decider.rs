//! The one decision from a heightmap to a placement, as herbd runs it and as the evaluation, the
//! decision bench and the bindings' expert labels run it.
//!
//! **Decision latency** (herbd's `decision_ns`, Table I's latency column, the decision bench) is
//! the duration of one [`Decider::decide`] call: checking the heightmap and taking one copy of
//! it, writing the observation when the policy reads one, the policy (with its own lattice or
//! features), checking its action, and the z estimate of the chosen placement. Waiting for a
//! heightmap and planning the motion are not part of it.

use crate::error::{DecideError, Result};
use crate::policy::{DecisionInput, Policy, check_action};
use herb_core::observation::{Projections, action_to_placement};
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

/// Where an object goes: the policy's action and the release pose it gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The policy's normalised action (x, y, theta in -1..=1).
    pub action: [f32; 3],
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

    /// The placement of `object` (step `step` of the episode, `after` the objects still to come)
    /// on `heightmap`. A heightmap whose grid is not the box's at its cell size, or with a cell
    /// that is not finite or out of range, is rejected; so is a non-finite or out-of-range
    /// action. [`DecideError::NoFeasiblePlacement`] when the policy finds nothing that fits.
    pub fn decide(
        &mut self,
        heightmap: HeightmapView<'_>,
        object: TypeIdx,
        step: usize,
        after: &[TypeIdx],
    ) -> Result<Decision> {
        let bad = |reason: String| DecideError::Rejected {
            policy: "decider".into(),
            reason,
        };
        let spec =
            GridSpec::for_box(heightmap.cell_m).map_err(|e| bad(format!("heightmap: {e}")))?;
        if (spec.nx, spec.ny) != (heightmap.nx, heightmap.ny) || heightmap.cells.len() != spec.len()
        {
            return Err(bad(format!(
                "heightmap of {} x {} cells ({} values) of {} m; the box needs {} x {}",
                heightmap.nx,
                heightmap.ny,
                heightmap.cells.len(),
                heightmap.cell_m,
                spec.nx,
                spec.ny
            )));
        }
        if self.hm.as_ref().map(|h| *h.spec()) != Some(spec) {
            self.hm = Some(Heightmap::new(spec));
        }
        let hm = self.hm.as_mut().expect("set above");
        // One snapshot (a shared frame must not change under the decision).
        hm.data_mut().copy_from_slice(heightmap.cells);
        hm.validate().map_err(|e| bad(e.to_string()))?;
        let hm = &*hm;
        let observation: &[f32] = if self.policy.needs_observation() {
            ObsLayout::write(hm, Some(self.projections.get(object)), &mut self.obs)?;
            &self.obs
        } else {
            &[]
        };
        let shape = self.catalog.shape(object);
        let action = self
            .policy
            .decide(&DecisionInput {
                observation,
                heightmap: hm,
                object,
                shape,
                step,
                catalog: &self.catalog,
                after,
            })
            .and_then(|a| check_action(self.policy.name(), a))?;
        let (x, y, theta) = action_to_placement(action)?;
        // Normalised once, by the release pose (as before it was moved there).
        let rot = Rotation::from_rotation_z(theta);
        // The one release pose (z estimate plus the clearance), as the search's job twin
        // replays it.
        let z = release_pose_on(hm, shape, (x, y, rot), self.clearance_m, &mut self.zs)
            .translation
            .z;
        Ok(Decision {
            action,
            position: [x, y, z],
            theta,
        })
    }
}
