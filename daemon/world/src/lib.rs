//! # herb-world: HERB's packing world
//!
//! The BoxED box in rapier3d, placement, settling and the paper's metrics and rewards
//! ([`RewardMode`]); rollouts of the lattice BLBF rule after a candidate placement
//! ([`rollout`]); the twins of a box built from its heightmap ([`PackingWorld::twin`]); a
//! gripper's release error ([`ReleaseNoise`]). herbd links it only through the search
//! (`herb-search`), the loopback simulates the cell with it, and the evaluation and training
//! (`herb-sim`) run in it. Frames and units: SI, right-handed, z up, the box frame B of
//! `herb_core::frames`.
//!
//! # Metrics (per placement, after the world settles)
//!
//! - **inside**: every vertex of every placed object's hull lies within the success volume,
//!   the box interior `|x| <= BOX_HALF_X`, `|y| <= BOX_HALF_Y`, `z >= 0`, extended upwards to
//!   `SUCCESS_TOP_Z` (rim + 13 cm), all widened by `inside_tolerance_m` for contact
//!   penetration. An earlier object knocked out fails the placement too.
//! - **tilt**: angle between B z and the placed object's axis that pointed up when it was
//!   released: how far it tipped from the intended orientation (a turn about z is not tilt).
//!   For the upright placements of the policies this is the angle of the canonical +z from
//!   vertical; for an orientation laid on its side (PackIt SO(3)) or tilted (the humans'
//!   recorded orientations), the tipping from that orientation.
//! - **S** (stability): 1 if tilt <= `stability_tilt_deg` (10 degrees), else 0.
//! - **C** (compactness, after Huang et al. 2023): `C = sum of the hull volumes of the placed
//!   objects / volume of the minimal box encapsulating them`, where that box is the
//!   axis-aligned bounding box, in B, of all placed objects' hull vertices at their settled
//!   poses (B's axes are the container's, so this is the tightest container-aligned box).

use herb_core::catalog::{SharedCatalog, TypeIdx};
use herb_core::error::{Result, SimError};
use herb_core::frames::{
    BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS, SUCCESS_TOP_Z, tilt_from,
};
use herb_core::heightmap::{GridSpec, Heightmap};
use herb_core::zestimate::{ZScratch, estimate_z_rotated, release_pose_on};
use rapier3d::math::{Pose, Rotation, Vector};
use rapier3d::prelude::*;

mod config;
mod errors;
mod pile;
mod reward;
pub mod rollout;
pub use config::WorldConfig;
pub use errors::{
    Camera, CameraNoise, ObjectErrors, ObjectVariation, ReleaseNoise, offset_pose, offset_release,
    standard_normal,
};
pub use reward::RewardMode;
pub use rollout::{CandidateOutcome, RolloutFailure};

pub use herb_core::frames::INSIDE_TOLERANCE_M;

/// What one placement did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacementOutcome {
    /// Every placed object is inside the success volume.
    pub inside: bool,
    /// Index (placement order) of the first object found outside, if any.
    pub first_outside: Option<usize>,
    /// Which bound that object crosses most and by how much (m), e.g. `("floor", 0.004)`.
    pub violation: Option<(&'static str, f32)>,
    /// Tilt of the placed object after settling from its release orientation (rad; module
    /// docs).
    pub tilt_rad: f32,
    /// S: tilt within the stability threshold.
    pub stable: bool,
    /// C over all placed objects after settling.
    pub compactness: f32,
    /// z of the object's canonical origin at release (m): estimate plus clearance.
    pub z: f32,
    /// Physics steps taken to settle.
    pub settle_steps: u32,
    /// True if every body fell asleep before the time cap (or the early exit).
    pub settled: bool,
}

/// Where one placed object ended, as the success check sees it ([`PackingWorld::report`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectReport {
    /// Its type.
    pub ty: TypeIdx,
    /// Position of its canonical origin in B (m).
    pub origin: [f32; 3],
    /// Heading of its canonical x axis about z (rad).
    pub yaw: f32,
    /// Its orientation in B, a unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
    /// Lowest corner of its vertices' bounds in B (m).
    pub lo: [f32; 3],
    /// Highest corner of its vertices' bounds in B (m).
    pub hi: [f32; 3],
    /// `None` when inside the success volume; else the bound it crosses most and by how much
    /// (m), as [`SuccessVolume::violation`].
    pub violation: Option<(&'static str, f32)>,
}

/// One object in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedObject {
    /// Its type.
    pub ty: TypeIdx,
    /// Its rigid body.
    pub body: RigidBodyHandle,
    /// Its true size against the catalog's hull: 1, or the field model's size error
    /// ([`ObjectVariation::scale`]).
    pub scale: f32,
}

/// The pile of a twin ([`PackingWorld::twin`]): what a heightmap says of the objects already in
/// the box, which the twin cannot move.
#[derive(Debug, Clone)]
struct Pile {
    /// The heightmap the twin was built from: the floor of every render.
    heightmap: Heightmap,
    /// The volume under the heightmap (m^3): what the pile adds to C's numerator.
    volume: f32,
    /// The bounds of the occupied cells (none when the box is empty).
    bounds: Option<(Vector, Vector)>,
}

use pile::PILE_FLOOR_M;

/// The packing world. Deterministic: the same calls give bit-identical states.
pub struct PackingWorld {
    cfg: WorldConfig,
    catalog: SharedCatalog,
    phys: PhysicsWorld,
    placed: Vec<PlacedObject>,
    heightmap: Heightmap,
    verts: Vec<Vector>,
    zscratch: ZScratch,
    pile: Option<Pile>,
}

impl std::fmt::Debug for PackingWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PackingWorld")
            .field("cfg", &self.cfg)
            .field("placed", &self.placed)
            .finish()
    }
}

/// A clone steps exactly as the original: given the same calls, both reach bit-identical
/// states (tested). rapier's `PhysicsWorld` is not `Clone`, but everything in it that carries
/// state between steps is (bodies, colliders, joints, islands, broad and narrow phase with
/// their contact manifolds and warm-start impulses); the pipelines hold per-step workspaces
/// only and start fresh. The lookahead teacher and the search clone a world per candidate
/// placement to simulate what would follow it.
impl Clone for PackingWorld {
    fn clone(&self) -> Self {
        let p = &self.phys;
        let phys = PhysicsWorld {
            gravity: p.gravity,
            integration_parameters: p.integration_parameters,
            physics_pipeline: PhysicsPipeline::new(),
            collision_pipeline: CollisionPipeline::new(),
            islands: p.islands.clone(),
            broad_phase: p.broad_phase.clone(),
            narrow_phase: p.narrow_phase.clone(),
            bodies: p.bodies.clone(),
            colliders: p.colliders.clone(),
            impulse_joints: p.impulse_joints.clone(),
            multibody_joints: p.multibody_joints.clone(),
            soft_bodies: p.soft_bodies.clone(),
            ccd_solver: p.ccd_solver.clone(),
        };
        Self {
            cfg: self.cfg.clone(),
            catalog: self.catalog.clone(),
            phys,
            placed: self.placed.clone(),
            heightmap: self.heightmap.clone(),
            verts: Vec::with_capacity(self.verts.capacity()),
            zscratch: self.zscratch.clone(),
            pile: self.pile.clone(),
        }
    }
}

impl PackingWorld {
    /// An empty box.
    pub fn new(catalog: SharedCatalog, cfg: WorldConfig) -> Result<Self> {
        cfg.validate()?;
        let spec = GridSpec::for_box(cfg.heightmap_cell_m)?;
        let zscratch = ZScratch::for_catalog(&catalog, cfg.heightmap_cell_m);
        let max_verts = catalog
            .types()
            .map(|t| catalog.shape(t).vertices.len())
            .max()
            .unwrap_or(0);
        let mut w = Self {
            phys: Self::empty_physics(&cfg),
            cfg,
            catalog,
            placed: Vec::with_capacity(32),
            heightmap: Heightmap::new(spec),
            verts: Vec::with_capacity(max_verts),
            zscratch,
            pile: None,
        };
        w.render_heightmap();
        Ok(w)
    }

    /// A twin of a box seen only as `pile`, a heightmap (a camera's, or any world's): the box's
    /// walls and floor, and the pile as one static heightfield collider through the cells'
    /// centres, which objects placed in the twin land on and settle against but cannot move.
    /// Its heightmap starts as `pile`; C counts the volume under the pile (the objects' own
    /// volume and the voids hidden under them: the twin's C is above the real one) and its
    /// occupied cells' bounds beside the twin's own objects; the success volume checks the twin's own
    /// objects. What the search rolls out in: built from what herbd has in a real cell, never
    /// from a simulator's state. `pile` must be valid and on the world's grid.
    pub fn twin(catalog: SharedCatalog, cfg: WorldConfig, pile: &Heightmap) -> Result<Self> {
        let mut w = Self::new(catalog, cfg)?;
        pile.validate()?;
        let spec = *w.heightmap.spec();
        if *pile.spec() != spec {
            return Err(SimError::Heightmap(format!(
                "twin: a {} x {} heightmap of {} m cells for a world of {} x {} cells of {} m",
                pile.spec().nx,
                pile.spec().ny,
                pile.spec().cell,
                spec.nx,
                spec.ny,
                spec.cell
            )));
        }
        let (nx, ny, cell) = (spec.nx, spec.ny, spec.cell);
        let mut volume = 0.0f32;
        let mut bounds: Option<(Vector, Vector)> = None;
        for row in 0..ny {
            for col in 0..nx {
                let h = pile.data()[row * nx + col];
                volume += h.max(0.0) * cell * cell;
                if h > PILE_FLOOR_M {
                    let (x, y) = spec.cell_centre(col, row);
                    let lo = Vector::new(x - 0.5 * cell, y - 0.5 * cell, 0.0);
                    let hi = Vector::new(x + 0.5 * cell, y + 0.5 * cell, h);
                    bounds = Some(match bounds {
                        Some((l, u)) => (l.min(lo), u.max(hi)),
                        None => (lo, hi),
                    });
                }
            }
        }
        // The collider: the pile max-pooled to cells of about `pile_cell_m` (never
        // below the heightmap: objects land on it, not in it), then static convex pieces or
        // row runs of cuboids from the floor up (`pile::pile_colliders`).
        let f = ((w.cfg.pile_cell_m / cell).round() as usize).max(1);
        let (px, py) = (nx.div_ceil(f), ny.div_ceil(f));
        let mut pooled = vec![0.0f32; px * py];
        for (i, top) in pooled.iter_mut().enumerate() {
            let (bi, bj) = (i / px, i % px);
            for row in bi * f..((bi + 1) * f).min(ny) {
                for col in bj * f..((bj + 1) * f).min(nx) {
                    *top = top.max(pile.data()[row * nx + col]);
                }
            }
        }
        let grid = pile::PileGrid {
            h: &pooled,
            nx: px,
            ny: py,
            xs: (0..=px)
                .map(|c| spec.x_min() + ((c * f).min(nx)) as f32 * cell)
                .collect(),
            ys: (0..=py)
                .map(|r| spec.y_max() - ((r * f).min(ny)) as f32 * cell)
                .collect(),
        };
        let body = w.phys.insert_body(RigidBodyBuilder::fixed());
        for c in pile::pile_colliders(&grid, w.cfg.pile_fit_m, w.cfg.pile_step_m) {
            // A fixed body's colliders need no mass: given, it is not computed from each
            // piece's mesh.
            let c = c
                .friction(w.cfg.friction)
                .restitution(0.0)
                .mass_properties(MassProperties::default());
            w.phys.insert_collider(c, Some(body));
        }
        w.pile = Some(Pile {
            heightmap: pile.clone(),
            volume,
            bounds,
        });
        w.render_heightmap();
        Ok(w)
    }

    fn empty_physics(cfg: &WorldConfig) -> PhysicsWorld {
        let mut phys = PhysicsWorld::new();
        phys.gravity = Vector::new(0.0, 0.0, -9.81);
        let ip = &mut phys.integration_parameters;
        ip.dt = cfg.dt;
        // rapier's "normalized" values are multiplied by its length unit: given in metres here.
        let unit = cfg.length_unit_m;
        ip.length_unit = unit;
        // 1 mm allowed penetration (default 5 mm is coarse for objects a few cm tall).
        ip.normalized_allowed_linear_error = 0.001 / unit;
        // Speed at which overlaps are resolved (rapier default 3 m/s; lower values let bodies sink).
        ip.normalized_max_corrective_velocity = cfg.max_corrective_speed_mps / unit;
        ip.normalized_prediction_distance = cfg.prediction_distance_m / unit;
        ip.contact_recycling = cfg.contact_recycle_m > 0.0;
        ip.normalized_contact_recycle_distance = cfg.contact_recycle_m / unit;
        ip.num_solver_iterations = cfg.solver_iterations as usize;
        let t = BOX_WALL_THICKNESS;
        let (hx, hy, h) = (BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT);
        let body = phys.insert_body(RigidBodyBuilder::fixed());
        let cuboid = |half: Vector, at: Vector| {
            ColliderBuilder::cuboid(half.x, half.y, half.z)
                .translation(at)
                .friction(cfg.friction)
                .restitution(0.0)
        };
        let parts = [
            // Floor, top face at z = 0, the real 1.57 cm board. (A 10 cm slab was tried against
            // bodies sinking through it; it made some hull-vs-cuboid contacts fail outright.)
            cuboid(
                Vector::new(hx + t, hy + t, 0.5 * t),
                Vector::new(0.0, 0.0, -0.5 * t),
            ),
            // End walls (x) and side walls (y), inner faces on the interior bounds.
            cuboid(
                Vector::new(0.5 * t, hy + t, 0.5 * h),
                Vector::new(hx + 0.5 * t, 0.0, 0.5 * h),
            ),
            cuboid(
                Vector::new(0.5 * t, hy + t, 0.5 * h),
                Vector::new(-hx - 0.5 * t, 0.0, 0.5 * h),
            ),
            cuboid(
                Vector::new(hx + t, 0.5 * t, 0.5 * h),
                Vector::new(0.0, hy + 0.5 * t, 0.5 * h),
            ),
            cuboid(
                Vector::new(hx + t, 0.5 * t, 0.5 * h),
                Vector::new(0.0, -hy - 0.5 * t, 0.5 * h),
            ),
            // The table the box stands on, so objects knocked out come to rest.
            cuboid(
                Vector::new(2.0, 2.0, 0.05),
                Vector::new(0.0, 0.0, -t - 0.05),
            ),
        ];
        for c in parts {
            phys.insert_collider(c, Some(body));
        }
        phys
    }

    /// Removes every object: an empty box again, bit-identical to a new world.
    pub fn reset(&mut self) {
        self.phys = Self::empty_physics(&self.cfg);
        self.pile = None;
        self.placed.clear();
        self.render_heightmap();
    }

    /// The configuration.
    pub fn config(&self) -> &WorldConfig {
        &self.cfg
    }

    /// The catalog.
    pub fn catalog(&self) -> &SharedCatalog {
        &self.catalog
    }

    /// The heightmap after the last settle.
    pub fn heightmap(&self) -> &Heightmap {
        &self.heightmap
    }

    /// Objects placed so far, in order.
    pub fn placed(&self) -> &[PlacedObject] {
        &self.placed
    }

    /// Current pose of a placed object.
    pub fn pose_of(&self, obj: &PlacedObject) -> Pose {
        *self.phys.bodies[obj.body].position()
    }

    /// Lowest collision-free origin height for `ty` at `(x, y, theta)` over the current
    /// heightmap (no clearance). See [`herb_core::zestimate`].
    pub fn estimate_z(&mut self, ty: TypeIdx, x: f32, y: f32, theta: f32) -> f32 {
        self.estimate_z_rotated(ty, x, y, Rotation::from_rotation_z(theta))
    }

    /// As [`PackingWorld::estimate_z`] for any orientation of the canonical frame.
    pub fn estimate_z_rotated(&mut self, ty: TypeIdx, x: f32, y: f32, rot: Rotation) -> f32 {
        estimate_z_rotated(
            &self.heightmap,
            self.catalog.shape(ty),
            x,
            y,
            rot,
            &mut self.zscratch,
        )
    }

    /// `(x, y)` moved by the least amount (at most `max_shift_m` per axis) that brings the
    /// footprint of `ty` in orientation `rot` inside the walls, with the clearance to spare.
    /// Footprints that cross a wall by more, or do not fit between the walls, are returned
    /// unchanged. Used by the human replays: humans push objects against the walls, and our
    /// hulls differ from the real objects by millimetres.
    pub fn slide_inside(
        &self,
        ty: TypeIdx,
        x: f32,
        y: f32,
        rot: Rotation,
        max_shift_m: f32,
    ) -> (f32, f32) {
        if self.check_type(ty).is_err() || !(x.is_finite() && y.is_finite()) {
            return (x, y);
        }
        let (lo, hi) = self.catalog.shape(ty).rotated_bounds(rot);
        let c = self.cfg.clearance_m;
        let axis = |p: f32, lo: f32, hi: f32, half: f32| {
            let (min_p, max_p) = (-half + c - lo, half - c - hi);
            if min_p > max_p {
                return p;
            }
            let q = p.clamp(min_p, max_p);
            if (q - p).abs() <= max_shift_m { q } else { p }
        };
        (
            axis(x, lo.x, hi.x, BOX_HALF_X),
            axis(y, lo.y, hi.y, BOX_HALF_Y),
        )
    }

    /// Places `ty` upright, turned by `theta` about z, with its canonical origin at `(x, y)` and
    /// at the estimated height plus clearance, then settles the world and measures.
    pub fn place(&mut self, ty: TypeIdx, x: f32, y: f32, theta: f32) -> Result<PlacementOutcome> {
        if !theta.is_finite() {
            return Err(SimError::InvalidPlacement { x, y, theta });
        }
        self.place_rotated(ty, x, y, Rotation::from_rotation_z(theta))
    }

    /// As [`PackingWorld::place`] with any orientation of the canonical frame (tilt is then
    /// measured from that orientation, module docs).
    pub fn place_rotated(
        &mut self,
        ty: TypeIdx,
        x: f32,
        y: f32,
        rot: Rotation,
    ) -> Result<PlacementOutcome> {
        let pose = self.checked_release_pose(ty, x, y, rot)?;
        self.place_pose(ty, pose)
    }

    /// [`PackingWorld::release_pose`] after checking the inputs: a catalog type, finite values,
    /// (x, y) within 10 m.
    pub fn checked_release_pose(
        &mut self,
        ty: TypeIdx,
        x: f32,
        y: f32,
        rot: Rotation,
    ) -> Result<Pose> {
        if !(x.is_finite() && y.is_finite() && rot.is_finite()) || x.abs() > 10.0 || y.abs() > 10.0
        {
            return Err(SimError::InvalidPlacement {
                x,
                y,
                theta: herb_core::frames::yaw_of(rot),
            });
        }
        self.check_type(ty)?;
        Ok(self.release_pose(ty, x, y, rot))
    }

    /// The pose at which [`PackingWorld::place_rotated`] releases `ty`: orientation `rot`
    /// (normalised), origin at `(x, y)` and at the estimated height plus clearance. Lets a
    /// caller decide (and time) the release height once and then release with
    /// [`PackingWorld::place_pose`]. `ty` must be a catalog type and the inputs finite.
    pub fn release_pose(&mut self, ty: TypeIdx, x: f32, y: f32, rot: Rotation) -> Pose {
        release_pose_on(
            &self.heightmap,
            self.catalog.shape(ty),
            (x, y, rot),
            self.cfg.clearance_m,
            &mut self.zscratch,
        )
    }

    /// [`PackingWorld::release_pose`] estimated on `seen` instead of the world's own heightmap
    /// (a camera's view of it: where a real cell's controller releases). `seen` must be on the
    /// world's grid, `ty` a catalog type and the inputs finite.
    pub fn release_pose_over(
        &mut self,
        seen: &Heightmap,
        ty: TypeIdx,
        x: f32,
        y: f32,
        rot: Rotation,
    ) -> Pose {
        release_pose_on(
            seen,
            self.catalog.shape(ty),
            (x, y, rot),
            self.cfg.clearance_m,
            &mut self.zscratch,
        )
    }

    /// Releases `ty` at an explicit pose (e.g. the gripper's) and settles. The outcome's `z` is
    /// the pose's z.
    pub fn place_pose(&mut self, ty: TypeIdx, pose: Pose) -> Result<PlacementOutcome> {
        self.place_pose_as(ty, pose, ObjectVariation::NOMINAL)
    }

    /// [`PackingWorld::place_pose`] of a real object that differs from its catalog entry by
    /// `v` (the field model's object error; [`ObjectVariation::NOMINAL`]: `place_pose`). Its
    /// factors must be finite and within 0.5 to 2.
    pub fn place_pose_as(
        &mut self,
        ty: TypeIdx,
        pose: Pose,
        v: ObjectVariation,
    ) -> Result<PlacementOutcome> {
        self.check_type(ty)?;
        if !pose.is_finite() {
            return Err(SimError::InvalidPlacement {
                x: pose.translation.x,
                y: pose.translation.y,
                theta: f32::NAN,
            });
        }
        if ![v.scale, v.mass, v.friction]
            .iter()
            .all(|f| f.is_finite() && (0.5..=2.0).contains(f))
        {
            return Err(SimError::Config(format!(
                "object variation {v:?}: each factor must be within 0.5 to 2"
            )));
        }
        let spec = self.catalog.spec(ty);
        let shape = self.catalog.shape(ty);
        let collider = if v == ObjectVariation::NOMINAL {
            // As `ColliderBuilder::mass` computes them, from the catalog's unit-density
            // properties.
            let mut mass = shape.unit_mass;
            mass.set_mass(spec.mass_kg, true);
            ColliderBuilder::new(shape.collider.clone())
                .mass_properties(mass)
                .friction(self.cfg.friction)
        } else {
            let scaled = shape
                .collider
                .as_convex_polyhedron()
                .and_then(|p| p.clone().scaled(Vector::splat(v.scale)))
                .map(SharedShape::new)
                .ok_or_else(|| {
                    SimError::Config(format!("object {}: its hull cannot be scaled", spec.id))
                })?;
            let mut mass = scaled.mass_properties(1.0);
            mass.set_mass(spec.mass_kg * v.mass, true);
            ColliderBuilder::new(scaled)
                .mass_properties(mass)
                .friction(self.cfg.friction * v.friction)
        }
        .restitution(0.0);
        let body = RigidBodyBuilder::dynamic().pose(pose).build();
        let (handle, _) = self.phys.insert(body, collider);
        {
            let act = self.phys.bodies[handle].activation_mut();
            act.normalized_linear_threshold = self.cfg.sleep_speed_mps / self.cfg.length_unit_m;
            act.time_until_sleep = self.cfg.time_until_sleep_s;
        }
        self.placed.push(PlacedObject {
            ty,
            body: handle,
            scale: v.scale,
        });
        let (settle_steps, settled) = self.settle();
        let scan = self.scan(true);
        if self.cfg.freeze_settled {
            self.phys.bodies[handle].set_body_type(RigidBodyType::Fixed, false);
        }
        let rot = *self.phys.bodies[handle].rotation();
        let tilt = tilt_from(pose.rotation, rot);
        Ok(PlacementOutcome {
            inside: scan.first_outside.is_none(),
            first_outside: scan.first_outside,
            violation: scan.violation,
            tilt_rad: tilt,
            stable: tilt <= self.cfg.stability_tilt_deg.to_radians(),
            compactness: scan.compactness,
            z: pose.translation.z,
            settle_steps,
            settled,
        })
    }

    fn check_type(&self, ty: TypeIdx) -> Result<()> {
        if (ty.0 as usize) < self.catalog.len() {
            Ok(())
        } else {
            Err(SimError::UnknownObject(format!("type index {}", ty.0)))
        }
    }

    /// Steps until every placed body sleeps (or, with [`WorldConfig::rest_speed_mps`], has
    /// been that slow for [`WorldConfig::time_until_sleep_s`]), an object is far out, or the
    /// time cap.
    fn settle(&mut self) -> (u32, bool) {
        let max_steps = (self.cfg.settle_cap_s / self.cfg.dt).ceil() as u32;
        let rest = self.cfg.rest_speed_mps;
        let rest_steps = (self.cfg.time_until_sleep_s / self.cfg.dt).ceil().max(1.0) as u32;
        let mut slow_for = 0u32;
        for step in 1..=max_steps {
            self.phys.step();
            if self.placed.iter().all(|p| {
                let b = &self.phys.bodies[p.body];
                b.is_sleeping() || b.is_fixed()
            }) {
                return (step, true);
            }
            if rest > 0.0 {
                slow_for = if self.all_slower_than(rest) {
                    slow_for + 1
                } else {
                    0
                };
                if slow_for >= rest_steps {
                    // Only a pile wholly inside the success volume is taken as at rest: an
                    // object slow on a rim may still go in or out, which rapier's sleep decides.
                    if self.scan(false).first_outside.is_none() {
                        return (step, true);
                    }
                    slow_for = 0;
                }
            }
            if step % self.cfg.out_check_steps == 0 && self.any_far_out() {
                return (step, true);
            }
        }
        (max_steps, false)
    }

    /// True if every placed object's farthest point (its hull's bounding radius about the
    /// body's origin) moves slower than `speed` (m/s).
    fn all_slower_than(&self, speed: f32) -> bool {
        self.placed.iter().all(|p| {
            let b = &self.phys.bodies[p.body];
            if b.is_sleeping() {
                return true;
            }
            let s = self.catalog.shape(p.ty);
            let r = s.aabb_min.length().max(s.aabb_max.length()) * p.scale;
            b.linvel().length() + b.angvel().length() * r < speed
        })
    }

    fn any_far_out(&self) -> bool {
        let m = self.cfg.early_out_m;
        let walls = self.cfg.out_past_walls;
        let (ox, oy) = (
            BOX_HALF_X + BOX_WALL_THICKNESS,
            BOX_HALF_Y + BOX_WALL_THICKNESS,
        );
        self.placed.iter().any(|p| {
            let t = self.phys.bodies[p.body].translation();
            t.x.abs() > BOX_HALF_X + m
                || t.y.abs() > BOX_HALF_Y + m
                || t.z < -m
                || (walls && t.z < BOX_HEIGHT && (t.x.abs() > ox || t.y.abs() > oy))
        })
    }

    /// Every placed object, in placement order: where it is and whether it is inside the
    /// success volume (the same check as a placement's outcome).
    pub fn report(&mut self) -> Vec<ObjectReport> {
        let mut out = Vec::with_capacity(self.placed.len());
        self.scan_into(false, Some(&mut out));
        out
    }

    /// One pass over all placed bodies: inside check, compactness, and (optionally) the
    /// heightmap render.
    fn scan(&mut self, render: bool) -> Scan {
        self.scan_into(render, None)
    }

    /// [`Self::scan`], also describing each object into `report` when given.
    fn scan_into(&mut self, render: bool, mut report: Option<&mut Vec<ObjectReport>>) -> Scan {
        let volume_ok = SuccessVolume::new(self.cfg.inside_tolerance_m);
        let mut first_outside = None;
        let mut violation = None;
        let (mut lo, mut hi) = (Vector::splat(f32::MAX), Vector::splat(f32::MIN));
        let mut volume = 0.0f32;
        match &self.pile {
            Some(p) => {
                if render {
                    self.heightmap
                        .data_mut()
                        .copy_from_slice(p.heightmap.data());
                }
                volume = p.volume;
                if let Some((l, u)) = p.bounds {
                    (lo, hi) = (l, u);
                }
            }
            None if render => self.heightmap.clear(),
            None => {}
        }
        for (i, p) in self.placed.iter().enumerate() {
            let pose = *self.phys.bodies[p.body].position();
            let shape = self.catalog.shape(p.ty);
            let scale = p.scale;
            self.verts.clear();
            self.verts.extend(
                shape
                    .vertices
                    .iter()
                    .map(|&v| pose.transform_point(if scale == 1.0 { v } else { v * scale })),
            );
            let (blo, bhi) = bounds_of(&self.verts);
            let crossed = volume_ok.violation(blo, bhi);
            if first_outside.is_none()
                && let Some(v) = crossed
            {
                first_outside = Some(i);
                violation = Some(v);
            }
            if let Some(r) = report.as_deref_mut() {
                let x = pose.rotation * Vector::X;
                r.push(ObjectReport {
                    ty: p.ty,
                    origin: pose.translation.to_array(),
                    yaw: x.y.atan2(x.x),
                    rotation: pose.rotation.to_array(),
                    lo: blo.to_array(),
                    hi: bhi.to_array(),
                    violation: crossed,
                });
            }
            lo = lo.min(blo);
            hi = hi.max(bhi);
            volume += shape.volume * scale * scale * scale;
            if render {
                self.heightmap
                    .raise_to_hull(&mut self.verts, &shape.triangles);
            }
        }
        Scan {
            first_outside,
            violation,
            compactness: compactness_of(volume, lo, hi),
        }
    }

    /// Renders the heightmap of the current state (done after every settle).
    pub fn render_heightmap(&mut self) {
        self.scan(true);
    }

    /// Compactness C of the current state.
    pub fn compactness(&mut self) -> f32 {
        self.scan(false).compactness
    }

    /// Raw bits of every placed body's pose and velocities plus the heightmap, for bit-exact
    /// determinism checks.
    pub fn state_bits(&self) -> Vec<u32> {
        let mut out = Vec::new();
        for p in &self.placed {
            let b = &self.phys.bodies[p.body];
            let pose = b.position();
            out.extend(pose.translation.to_array().map(f32::to_bits));
            out.extend(pose.rotation.to_array().map(f32::to_bits));
            out.extend(b.linvel().to_array().map(f32::to_bits));
            out.extend(b.angvel().to_array().map(f32::to_bits));
        }
        out.extend(self.heightmap.data().iter().map(|v| v.to_bits()));
        out
    }

    /// Makes every object placed so far fixed: later objects land on them and settle against
    /// them but cannot move them. A diagnostic of the search's twin: a clone frozen so has the
    /// twin's rigid pile with the objects' exact shapes (`examples/twin_fidelity.rs` in
    /// herb-methods).
    pub fn freeze_placed(&mut self) {
        for p in &self.placed {
            self.phys.bodies[p.body].set_body_type(RigidBodyType::Fixed, false);
        }
    }

    /// From now on a rigid pile ([`WorldConfig::freeze_settled`]): every object placed so far
    /// becomes fixed, and so does each later one once it has settled. What the search's
    /// rollouts run in: one body simulated per settle.
    pub fn freeze_settled(&mut self) {
        self.cfg.freeze_settled = true;
        self.freeze_placed();
    }

    /// The collider set and body set, for queries in tests and tools (ray casting).
    pub fn physics(&self) -> &PhysicsWorld {
        &self.phys
    }
}

/// The success volume (module docs): the box interior extended upwards to `SUCCESS_TOP_Z`,
/// widened by a tolerance. The one check of "inside" for the world's placements and for the
/// humans' recorded poses (the evaluation, `herb_sim::eval`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SuccessVolume {
    lo: Vector,
    hi: Vector,
}

impl SuccessVolume {
    /// The names of the volume's bounds, as [`SuccessVolume::violation`] reports them.
    pub const BOUNDS: [&'static str; 6] =
        ["-x wall", "+x wall", "-y wall", "+y wall", "floor", "top"];

    /// The volume widened by `tolerance_m` on every side.
    pub fn new(tolerance_m: f32) -> Self {
        let tol = tolerance_m;
        Self {
            lo: Vector::new(-BOX_HALF_X - tol, -BOX_HALF_Y - tol, -tol),
            hi: Vector::new(BOX_HALF_X + tol, BOX_HALF_Y + tol, SUCCESS_TOP_Z + tol),
        }
    }

    /// For an object whose vertices span `lo..hi`: `None` if it is inside, else the bound it
    /// crosses most and by how much (m), e.g. `("floor", 0.004)`.
    pub fn violation(&self, lo: Vector, hi: Vector) -> Option<(&'static str, f32)> {
        if !(lo.cmplt(self.lo).any() || hi.cmpgt(self.hi).any()) {
            return None;
        }
        let over = [
            self.lo.x - lo.x,
            hi.x - self.hi.x,
            self.lo.y - lo.y,
            hi.y - self.hi.y,
            self.lo.z - lo.z,
            hi.z - self.hi.z,
        ];
        Self::BOUNDS
            .into_iter()
            .zip(over)
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// The axis-aligned bounds of `points` (`(MAX, MIN)` for none).
pub fn bounds_of(points: &[Vector]) -> (Vector, Vector) {
    points.iter().fold(
        (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
        |(a, b), &v| (a.min(v), b.max(v)),
    )
}

/// C (module docs) of objects of total hull volume `volume` whose vertices span `lo..hi`; 0
/// when nothing spans a volume.
pub fn compactness_of(volume: f32, lo: Vector, hi: Vector) -> f32 {
    let ext = (hi - lo).max(Vector::ZERO);
    let bbox = ext.x * ext.y * ext.z;
    if volume <= 0.0 || bbox <= 0.0 || !bbox.is_finite() {
        0.0
    } else {
        (volume / bbox).min(1.0)
    }
}

struct Scan {
    first_outside: Option<usize>,
    violation: Option<(&'static str, f32)>,
    compactness: f32,
}
