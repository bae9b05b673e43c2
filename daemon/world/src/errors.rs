//! The errors of a real cell that the evaluation's environment adds to the ideal world (the
//! field model): the gripper's release error ([`ReleaseNoise`]), the camera's depth noise and
//! dropouts ([`Camera`], [`CameraNoise`]) and the objects that are not their catalog hulls
//! ([`ObjectErrors`], [`ObjectVariation`]). The world's own calls and the search's twins never
//! add them. Each is drawn from a seeded generator, and a zero error draws nothing.

use herb_core::heightmap::{
    CAMERA_FILL_RADIUS_CELLS, CAMERA_FLOOR_THRESHOLD_M, CameraFill, Heightmap, MAX_VALID_HEIGHT,
    finish_camera_cells,
};
use rapier3d::math::{Pose, Rotation};

/// `pose` moved by `dx`, `dy` (m) in B and turned by `dyaw` (rad) about B z: a release off
/// the pose it was decided at (the evaluation's release noise, the job twin's fit).
pub fn offset_pose(mut pose: Pose, dx: f32, dy: f32, dyaw: f32) -> Pose {
    pose.translation.x += dx;
    pose.translation.y += dy;
    pose.rotation = Rotation::from_rotation_z(dyaw) * pose.rotation;
    pose
}

/// One draw of a standard normal variable from `rng` (Box-Muller, two uniform draws): the one
/// normal draw of the world's noises.
pub fn standard_normal(rng: &mut impl rand::Rng) -> f32 {
    let (u1, u2): (f32, f32) = (rng.random(), rng.random());
    (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// A gripper's release error: each release off its decided pose by normal noise of these
/// standard deviations in x and y and in yaw (the evaluation's release noise, the robust
/// search's rollouts).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ReleaseNoise {
    /// Standard deviation in x and in y (m).
    pub sigma_m: f32,
    /// Standard deviation in yaw (degrees).
    pub sigma_deg: f32,
    /// Standard deviation in height (m).
    pub sigma_height_m: f32,
    /// The lowest height offset (m, <= 0): a release never lower than touching.
    pub lowest_m: f32,
}

impl ReleaseNoise {
    /// No noise: nothing is drawn.
    pub fn is_zero(&self) -> bool {
        self.sigma_m == 0.0 && self.sigma_deg == 0.0 && self.sigma_height_m == 0.0
    }

    /// One release's offset from `rng`: x, y (m), yaw (rad) and height (m). x, y and yaw are
    /// drawn in that order unless their noise is 0, the height last and only when its noise is
    /// set, so that without a height noise every draw is as it was without one.
    pub fn draw(&self, rng: &mut impl rand::Rng) -> [f32; 4] {
        let (mut dx, mut dy, mut dyaw, mut dz) = (0.0, 0.0, 0.0, 0.0);
        if self.sigma_m != 0.0 || self.sigma_deg != 0.0 {
            dx = self.sigma_m * standard_normal(rng);
            dy = self.sigma_m * standard_normal(rng);
            dyaw = self.sigma_deg.to_radians() * standard_normal(rng);
        }
        if self.sigma_height_m > 0.0 {
            dz = (self.sigma_height_m * standard_normal(rng)).max(self.lowest_m);
        }
        [dx, dy, dyaw, dz]
    }

    /// `pose` moved by one offset drawn from `rng` ([`offset_release`]).
    pub fn apply(&self, pose: Pose, rng: &mut impl rand::Rng) -> Pose {
        offset_release(pose, self.draw(rng))
    }
}

/// `pose` moved by a release offset `[dx, dy, dyaw, dz]` (m, rad, m; [`offset_pose`], then up by
/// `dz`).
pub fn offset_release(pose: Pose, [dx, dy, dyaw, dz]: [f32; 4]) -> Pose {
    let mut p = offset_pose(pose, dx, dy, dyaw);
    p.translation.z += dz;
    p
}

/// A depth camera's errors in the heightmap it gives (the field model's camera): normal depth
/// noise on every seen cell, and cells it does not see (dropouts), anywhere and more often at
/// step edges, where a real depth camera loses its readings. Unseen cells are filled as a camera
/// adapter fills them ([`finish_camera_cells`], with the adapter's default floor threshold and
/// fill radius). Read as the field model file's `[camera]` section.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraNoise {
    /// Standard deviation of a seen cell's depth error (m).
    pub depth_sd_m: f32,
    /// The share of cells not seen, anywhere.
    pub dropout: f32,
    /// The share of cells at a step edge not seen (a 4-neighbour more than [`EDGE_STEP_M`]
    /// higher or lower); the larger of this and `dropout` applies there.
    pub edge_dropout: f32,
}

/// A cell is at a step edge when a 4-neighbour differs by more than this (m).
pub const EDGE_STEP_M: f32 = 0.01;

impl CameraNoise {
    /// No error: the camera sees the world's heightmap as it is.
    pub fn is_zero(&self) -> bool {
        self.depth_sd_m == 0.0 && self.dropout == 0.0 && self.edge_dropout == 0.0
    }
}

/// The evaluation's camera: a heightmap seen with [`CameraNoise`], its buffers allocated once.
#[derive(Debug, Clone)]
pub struct Camera {
    view: Heightmap,
    seen: Vec<bool>,
    scratch: Vec<f32>,
    fill: CameraFill,
}

impl Camera {
    /// A camera for heightmaps shaped as `like`.
    pub fn new(like: &Heightmap) -> Self {
        let n = like.data().len();
        Self {
            view: like.clone(),
            seen: vec![true; n],
            scratch: vec![0.0; n],
            fill: CameraFill::default(),
        }
    }

    /// What it saw last.
    pub fn view(&self) -> &Heightmap {
        &self.view
    }

    /// How many cells of the last view were not seen and filled.
    pub fn filled(&self) -> CameraFill {
        self.fill
    }

    /// Sees `truth` with `noise`, drawing from `rng`: for every cell, row by row, one uniform
    /// draw (seen or not) and one normal draw (its depth error), whatever the figures, so that
    /// the draws of a cell do not depend on the others'. Then the camera adapter's floor, clamp
    /// and fill ([`finish_camera_cells`]).
    pub fn see(&mut self, truth: &Heightmap, noise: &CameraNoise, rng: &mut impl rand::Rng) {
        let spec = *truth.spec();
        let t = truth.data();
        let out = self.view.data_mut();
        for row in 0..spec.ny {
            for col in 0..spec.nx {
                let i = row * spec.nx + col;
                let h = t[i];
                let step = |j: usize| (t[j] - h).abs() > EDGE_STEP_M;
                let edge = (col > 0 && step(i - 1))
                    || (col + 1 < spec.nx && step(i + 1))
                    || (row > 0 && step(i - spec.nx))
                    || (row + 1 < spec.ny && step(i + spec.nx));
                let p = if edge {
                    noise.dropout.max(noise.edge_dropout)
                } else {
                    noise.dropout
                };
                let u: f32 = rng.random();
                let n = standard_normal(rng);
                self.seen[i] = u >= p;
                out[i] = h + noise.depth_sd_m * n;
            }
        }
        self.fill = finish_camera_cells(
            &spec,
            out,
            &self.seen,
            (
                CAMERA_FLOOR_THRESHOLD_M,
                MAX_VALID_HEIGHT,
                CAMERA_FILL_RADIUS_CELLS,
            ),
            &mut self.scratch,
        );
    }
}

/// The objects' errors (the field model's objects): each real object differs from its catalog
/// entry by a size, mass and friction drawn per episode, each a normal relative error cut at two
/// standard deviations. Read as the field model file's `[object]` section.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectErrors {
    /// Relative standard deviation of the size (every axis alike).
    pub size_sd: f32,
    /// Relative standard deviation of the mass.
    pub mass_sd: f32,
    /// Relative standard deviation of the friction coefficient.
    pub friction_sd: f32,
}

impl ObjectErrors {
    /// No error: every object is its catalog entry.
    pub fn is_zero(&self) -> bool {
        self.size_sd == 0.0 && self.mass_sd == 0.0 && self.friction_sd == 0.0
    }

    /// One object's variation from `rng`: size, mass and friction, three normal draws in that
    /// order ([`ObjectVariation::NOMINAL`] without drawing when the errors are zero).
    pub fn draw(&self, rng: &mut impl rand::Rng) -> ObjectVariation {
        if self.is_zero() {
            return ObjectVariation::NOMINAL;
        }
        let mut factor = |sd: f32| 1.0 + sd * standard_normal(rng).clamp(-2.0, 2.0);
        ObjectVariation {
            scale: factor(self.size_sd),
            mass: factor(self.mass_sd),
            friction: factor(self.friction_sd),
        }
    }
}

/// How one real object differs from its catalog entry (the field model's object error): its
/// hull scaled about the canonical origin, its mass and its friction scaled. [`Self::NOMINAL`]
/// is the catalog's object, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectVariation {
    /// The hull's scale (every axis).
    pub scale: f32,
    /// The mass's factor.
    pub mass: f32,
    /// The friction coefficient's factor.
    pub friction: f32,
}

impl ObjectVariation {
    /// The catalog's object.
    pub const NOMINAL: Self = Self {
        scale: 1.0,
        mass: 1.0,
        friction: 1.0,
    };
}
