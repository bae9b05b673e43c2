//! A Gymnasium-shaped episode API over the packing world.
//!
//! One step places one object. `reset(sequence, seed)` empties the box and returns the first
//! observation; `step(action)` maps the action (see [`crate::observation`]), places the next
//! object, and returns the observation, the reward, whether the episode ended, and details.
//! The episode ends at the first failed placement (an object outside the success volume) or
//! when every object is placed.
//!
//! Rewards, exactly as the HERB paper (section "Reward"):
//! - `Simple`: +1 if inside, else -1;
//! - `C`: C if inside, else -1;
//! - `CS(alpha)`: `alpha * C + (1 - alpha) * S` if inside, else -1.

use crate::catalog::{SharedCatalog, TypeIdx};
use crate::error::{Result, SimError};
use crate::observation::{ObsLayout, Projections, action_to_placement};
pub use crate::world::RewardMode;
use crate::world::{
    Camera, ObjectVariation, PackingWorld, PlacementOutcome, WorldConfig, offset_release,
};
use herb_core::heightmap::Heightmap;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d::math::{Pose, Rotation};

/// Details of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// The object placed.
    pub object: TypeIdx,
    /// The placement used `(x, y, theta)` after mapping (and clamping) the action.
    pub placement: (f32, f32, f32),
    /// What happened.
    pub outcome: PlacementOutcome,
    /// Objects successfully placed so far in this episode.
    pub packed: usize,
    /// The episode ended with every object placed inside.
    pub success: bool,
}

/// The result of [`PackingEnv::step`].
#[derive(Debug)]
pub struct StepResult<'a> {
    /// Observation after the step (next object in channel 1; none when terminated).
    pub observation: &'a [f32],
    /// Reward of this placement.
    pub reward: f32,
    /// The episode is over (failure or all placed).
    pub terminated: bool,
    /// Details.
    pub info: StepInfo,
}

/// Seeds the release noise's generator (with the episode's seed).
const NOISE_SEED: u64 = 0x6e6f_6973_6521;
/// Seeds the camera error's generator (with the episode's seed).
const CAMERA_SEED: u64 = 0x6361_6d65_7261;
/// Seeds the object error's generator (with the episode's seed).
const OBJECT_SEED: u64 = 0x6f62_6a65_6374;

/// The packing environment.
#[derive(Debug)]
pub struct PackingEnv {
    world: PackingWorld,
    projections: Projections,
    reward: RewardMode,
    sequence: Vec<TypeIdx>,
    next: usize,
    packed: usize,
    running: bool,
    rng: ChaCha8Rng,
    /// Draws the release noise ([`WorldConfig::release_noise_m`]), apart from `rng` so that
    /// noise does not change the random placer's actions.
    noise_rng: ChaCha8Rng,
    /// The camera of a world with a camera error ([`WorldConfig::camera_noise`]); `None`: the
    /// methods see the world's own heightmap.
    camera: Option<Camera>,
    camera_rng: ChaCha8Rng,
    /// Each object's variation in this episode (empty without an object error).
    variations: Vec<ObjectVariation>,
    obs: Vec<f32>,
}

impl PackingEnv {
    /// A new environment (call [`PackingEnv::reset`] before stepping).
    pub fn new(catalog: SharedCatalog, cfg: WorldConfig, reward: RewardMode) -> Result<Self> {
        let projections = Projections::new(&catalog);
        let world = PackingWorld::new(catalog, cfg)?;
        let camera =
            (!world.config().camera_noise().is_zero()).then(|| Camera::new(world.heightmap()));
        Ok(Self {
            world,
            projections,
            reward,
            sequence: Vec::new(),
            next: 0,
            packed: 0,
            running: false,
            rng: ChaCha8Rng::seed_from_u64(0),
            noise_rng: ChaCha8Rng::seed_from_u64(NOISE_SEED),
            camera,
            camera_rng: ChaCha8Rng::seed_from_u64(CAMERA_SEED),
            variations: Vec::new(),
            obs: vec![0.0; ObsLayout::LEN],
        })
    }

    /// Starts an episode with `sequence` (packing order). `seed` seeds the environment's random
    /// generator ([`PackingEnv::sample_action`]); the physics itself is deterministic.
    pub fn reset(&mut self, sequence: &[TypeIdx], seed: u64) -> Result<&[f32]> {
        if sequence.is_empty() {
            return Err(SimError::EmptySequence);
        }
        if let Some(bad) = sequence
            .iter()
            .find(|t| t.0 as usize >= self.world.catalog().len())
        {
            return Err(SimError::UnknownObject(format!("type index {}", bad.0)));
        }
        self.world.reset();
        self.sequence.clear();
        self.sequence.extend_from_slice(sequence);
        self.next = 0;
        self.packed = 0;
        self.running = true;
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        self.noise_rng = ChaCha8Rng::seed_from_u64(seed ^ NOISE_SEED);
        self.camera_rng = ChaCha8Rng::seed_from_u64(seed ^ CAMERA_SEED);
        let objects = self.world.config().object_errors();
        self.variations.clear();
        if !objects.is_zero() {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ OBJECT_SEED);
            self.variations
                .extend(sequence.iter().map(|_| objects.draw(&mut rng)));
        }
        self.look();
        self.write_obs()?;
        Ok(&self.obs)
    }

    /// Starts an episode from catalog ids (`["003", "004"]`); unknown ids are an error.
    pub fn reset_ids(&mut self, ids: &[&str], seed: u64) -> Result<&[f32]> {
        let seq = ids
            .iter()
            .map(|id| self.world.catalog().by_id(id))
            .collect::<Result<Vec<_>>>()?;
        self.reset(&seq, seed)
    }

    /// Places the next object with `action` in `[-1, 1]^3`. A non-finite action is rejected
    /// with an error and changes nothing.
    pub fn step(&mut self, action: [f32; 3]) -> Result<StepResult<'_>> {
        let (x, y, theta) = action_to_placement(action)?;
        self.step_placement(x, y, theta)
    }

    /// Places the next object at an explicit placement `(x, y, theta)` in B (m, rad), bypassing
    /// the action mapping (used to replay human placements). Non-finite values are rejected.
    pub fn step_placement(&mut self, x: f32, y: f32, theta: f32) -> Result<StepResult<'_>> {
        if !theta.is_finite() {
            return Err(SimError::InvalidPlacement { x, y, theta });
        }
        self.step_rotated(x, y, Rotation::from_rotation_z(theta))
    }

    /// Places the next object at `(x, y)` with any orientation `rot` of its canonical frame
    /// (used to replay the humans' full, possibly tilted, placements), released at its height
    /// estimated on the heightmap the methods see ([`PackingEnv::release_pose`]). With the
    /// field model's errors, as [`PackingEnv::step_pose`] releases.
    pub fn step_rotated(&mut self, x: f32, y: f32, rot: Rotation) -> Result<StepResult<'_>> {
        let yaw = crate::frames::yaw_of(rot);
        if !self.has_field_errors() {
            let offset = self.draw_noise();
            return self.step_with(
                |w, object, _| match offset {
                    None => w.place_rotated(object, x, y, rot),
                    Some(offset) => {
                        let pose = w.checked_release_pose(object, x, y, rot)?;
                        w.place_pose(object, offset_release(pose, offset))
                    }
                },
                (x, y, yaw),
            );
        }
        let object = self.next_object().ok_or(SimError::EpisodeOver {
            placed: self.packed,
        })?;
        let pose = self.checked_release_pose(object, x, y, rot)?;
        self.step_pose(pose)
    }

    /// Releases the next object at an explicit pose of its canonical frame (z included, no
    /// estimate): the humans' recorded poses, or a gripper's. With release noise, at that pose
    /// moved by the noise; with the field model's camera or object error, never lower than
    /// touching the true pile with the true object ([`PackingEnv::release_of`]).
    pub fn step_pose(&mut self, pose: Pose) -> Result<StepResult<'_>> {
        // The step reports the pose given; the world gets it moved by the noise.
        let (t, yaw) = (pose.translation, crate::frames::yaw_of(pose.rotation));
        let offset = self.draw_noise();
        if !self.has_field_errors() {
            let released = offset.map_or(pose, |o| offset_release(pose, o));
            return self.step_with(
                |w, object, _| w.place_pose(object, released),
                (t.x, t.y, yaw),
            );
        }
        self.step_with(
            |w, object, v| {
                let released = Self::release_of(w, object, pose, offset, v);
                w.place_pose_as(object, released, v)
            },
            (t.x, t.y, yaw),
        )
    }

    /// Where a real cell releases `object` decided at `pose`: moved by the release offset, then
    /// raised to touching the true pile (the world's own heightmap, the gripper stops on
    /// contact) when lower, and by what the true object's larger size adds below its catalog
    /// hull (its lowest point scaled about the canonical origin).
    fn release_of(
        w: &mut PackingWorld,
        object: TypeIdx,
        pose: Pose,
        offset: Option<[f32; 4]>,
        v: ObjectVariation,
    ) -> Pose {
        let mut released = offset.map_or(pose, |o| offset_release(pose, o));
        let t = released.translation;
        let touching = w
            .release_pose(object, t.x, t.y, released.rotation)
            .translation
            .z
            - w.config().clearance_m;
        let below = (-w.catalog().shape(object).aabb_min.z).max(0.0);
        let grown = (v.scale - 1.0).max(0.0) * below;
        released.translation.z = released.translation.z.max(touching) + grown;
        released
    }

    /// Whether this world has a camera or object error (the field model beyond the release).
    fn has_field_errors(&self) -> bool {
        self.camera.is_some() || !self.variations.is_empty()
    }

    /// The pose at which a controller releases `object` decided at `(x, y)` with orientation
    /// `rot`: its height estimated on the heightmap the methods see ([`PackingEnv::camera`])
    /// plus the world's clearance. `object` must be a catalog type and the inputs finite, as
    /// [`PackingWorld::release_pose`] requires (the steps check them first).
    pub fn release_pose(&mut self, object: TypeIdx, x: f32, y: f32, rot: Rotation) -> Pose {
        match &self.camera {
            Some(c) => self.world.release_pose_over(c.view(), object, x, y, rot),
            None => self.world.release_pose(object, x, y, rot),
        }
    }

    fn checked_release_pose(
        &mut self,
        object: TypeIdx,
        x: f32,
        y: f32,
        rot: Rotation,
    ) -> Result<Pose> {
        self.world.checked_release_pose(object, x, y, rot)?;
        Ok(self.release_pose(object, x, y, rot))
    }

    /// The heightmap the methods see: the world's own, or with a camera error
    /// ([`WorldConfig::camera_noise`]) the camera's view of it after the last placement.
    pub fn camera(&self) -> &Heightmap {
        match &self.camera {
            Some(c) => c.view(),
            None => self.world.heightmap(),
        }
    }

    /// The camera looks at the world again (after a reset or a placement).
    fn look(&mut self) {
        if let Some(c) = &mut self.camera {
            let noise = self.world.config().camera_noise();
            c.see(self.world.heightmap(), &noise, &mut self.camera_rng);
        }
    }

    /// The next release's offset (x, y, yaw, height) by the world's release noise
    /// ([`crate::world::ReleaseNoise::draw`]), `None` without noise (nothing drawn).
    fn draw_noise(&mut self) -> Option<[f32; 4]> {
        let n = self.world.config().release_noise();
        (!n.is_zero()).then(|| n.draw(&mut self.noise_rng))
    }

    fn step_with(
        &mut self,
        place: impl FnOnce(&mut PackingWorld, TypeIdx, ObjectVariation) -> Result<PlacementOutcome>,
        (x, y, theta): (f32, f32, f32),
    ) -> Result<StepResult<'_>> {
        if !self.running {
            return Err(SimError::EpisodeOver {
                placed: self.packed,
            });
        }
        let object = self.sequence[self.next];
        let variation = self
            .variations
            .get(self.next)
            .copied()
            .unwrap_or(ObjectVariation::NOMINAL);
        let outcome = place(&mut self.world, object, variation)?;
        self.look();
        self.next += 1;
        if outcome.inside {
            self.packed += 1;
        }
        let success = outcome.inside && self.next == self.sequence.len();
        let terminated = !outcome.inside || success;
        self.running = !terminated;
        self.write_obs()?;
        Ok(StepResult {
            observation: &self.obs,
            reward: self.reward.reward(&outcome),
            terminated,
            info: StepInfo {
                object,
                placement: (x, y, theta),
                outcome,
                packed: self.packed,
                success,
            },
        })
    }

    fn write_obs(&mut self) -> Result<()> {
        let next = if self.running {
            Some(self.projections.get(self.sequence[self.next]))
        } else {
            None
        };
        let seen = match &self.camera {
            Some(c) => c.view(),
            None => self.world.heightmap(),
        };
        ObsLayout::write(seen, next, &mut self.obs)
    }

    /// A uniform random action from the environment's seeded generator.
    pub fn sample_action(&mut self) -> [f32; 3] {
        [0; 3].map(|_| self.rng.random_range(-1.0f32..=1.0))
    }

    /// The next object to place, if the episode runs.
    pub fn next_object(&self) -> Option<TypeIdx> {
        self.running.then(|| self.sequence[self.next])
    }

    /// The index in the sequence of the next object to place (the number of placements made
    /// in this episode).
    pub fn step_index(&self) -> usize {
        self.next
    }

    /// The objects still to place, the next one first (empty once the episode is over).
    pub fn remaining(&self) -> &[TypeIdx] {
        if self.running {
            &self.sequence[self.next..]
        } else {
            &[]
        }
    }

    /// The underlying world.
    pub fn world(&self) -> &PackingWorld {
        &self.world
    }

    /// The underlying world, mutable (for tools and custom placements).
    pub fn world_mut(&mut self) -> &mut PackingWorld {
        &mut self.world
    }

    /// The reward mode.
    pub fn reward_mode(&self) -> RewardMode {
        self.reward
    }

    /// The current observation.
    pub fn observation(&self) -> &[f32] {
        &self.obs
    }
}

/// The objects of an episode of the training distribution (the HERB paper's): a count drawn
/// uniformly from `count`, then each object's type uniformly from the catalog's `catalog_len`
/// types, in the order drawn. The training environments (the bindings' `VecEnv`) and the
/// sampled episode sets of a sweep draw through this.
pub fn sample_objects(
    rng: &mut impl rand::Rng,
    catalog_len: usize,
    count: std::ops::RangeInclusive<usize>,
) -> Vec<crate::TypeIdx> {
    let n = rng.random_range(count);
    (0..n)
        .map(|_| crate::TypeIdx(rng.random_range(0..catalog_len as u16)))
        .collect()
}
