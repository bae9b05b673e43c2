//! The packing world's settings ([`WorldConfig`]): physics, settling, the success volume's
//! tolerance and the evaluation's errors (release, camera, objects), with their defaults, setting by name and
//! checks.

use crate::{CameraNoise, INSIDE_TOLERANCE_M, ObjectErrors, ReleaseNoise};
use herb_core::error::{Result, SimError};
use herb_core::observation::ObsLayout;

/// Settings of the packing world. Defaults are the values used for training and evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldConfig {
    /// Heightmap cell side (m); default: the observation scale, 0.35/224 m.
    pub heightmap_cell_m: f32,
    /// Gap added above the estimated resting height before release (m).
    pub clearance_m: f32,
    /// Physics time step (s).
    pub dt: f32,
    /// Longest simulated settling time per placement (s).
    pub settle_cap_s: f32,
    /// A body sleeps after this long below the motion threshold (s).
    pub time_until_sleep_s: f32,
    /// Sleep threshold on a body's farthest-point speed (m/s).
    pub sleep_speed_mps: f32,
    /// A settle also ends once every placed object's farthest point has moved slower than
    /// this for `time_until_sleep_s` (m/s) and every object is inside the success volume,
    /// without waiting for rapier to put each island to sleep (which waits for islands to split
    /// and restarts a whole pile's timer when one body moves). An object slow on a rim goes on
    /// until rapier's sleep or the cap. 0: a settle ends only when rapier has put every body to
    /// sleep.
    pub rest_speed_mps: f32,
    /// Friction coefficient of every surface.
    pub friction: f32,
    /// Widening of the success volume for contact penetration (m).
    pub inside_tolerance_m: f32,
    /// Tilt above which a placement is unstable (degrees).
    pub stability_tilt_deg: f32,
    /// Stop settling early once an object is this far outside the success volume (m).
    pub early_out_m: f32,
    /// Also stop settling once an object's origin is below the rim and past a wall's outer
    /// face, from where it cannot come back in.
    pub out_past_walls: bool,
    /// Steps between two checks for an object out of the box.
    pub out_check_steps: u32,
    /// Fastest speed at which the solver pushes overlapping bodies apart (m/s).
    pub max_corrective_speed_mps: f32,
    /// Solver substeps per physics step (rapier's `num_solver_iterations`).
    pub solver_iterations: u32,
    /// Contacts are computed for pairs closer than this (m; rapier's prediction distance).
    pub prediction_distance_m: f32,
    /// rapier's length unit (m): it scales the margin the broad phase keeps around every
    /// collider (4 cm at 1 m), so smaller values pair fewer objects. Every distance and speed of
    /// this configuration stays in metres whatever it is.
    pub length_unit_m: f32,
    /// A contact pair whose bodies moved relative to each other by less than this since its
    /// last full update keeps its contact points instead of being computed again (m; rapier's
    /// contact recycling). 0: every pair is computed every step.
    pub contact_recycle_m: f32,
    /// Once a placement has settled, every object placed so far becomes fixed: later objects
    /// land and settle on them but cannot move them, so each settle simulates one body against
    /// a rigid pile (the heightmap twin's pile is rigid already). A model's approximation for
    /// the search's rollouts ([`PackingWorld::freeze_settled`](crate::PackingWorld::freeze_settled)),
    /// never the evaluation's world: a real pile can be pushed.
    pub freeze_settled: bool,
    /// The cell of a heightmap twin's pile collider (m): the heightmap max-pooled to about
    /// this (default the placement lattice's own cell, 1.25 cm). Coarser cells make fewer
    /// colliders under an object, and a pile up to a cell wider than it is.
    pub pile_cell_m: f32,
    /// A heightmap twin's pile collider is made of convex pieces, each as large as it can be
    /// while its top stays within this (m) above every cell it covers (never below one): a
    /// flat or tilted top is one piece, so an object resting on it touches one shape, not one
    /// per cell. 0: the collider before pieces, row runs of cuboids of heights rounded up to
    /// `pile_step_m` (kept for the benches' ratios).
    pub pile_fit_m: f32,
    /// With `pile_fit_m` 0 only: the row runs' heights are rounded up to this (m).
    pub pile_step_m: f32,
    /// Release noise of the evaluation: standard deviation (m) of the x and y offsets by which
    /// the evaluation's environment (`herb_sim::PackingEnv`) releases each object off the pose
    /// it was given, as a real gripper does (0: exactly there). The world's own calls ([`PackingWorld::place_pose`]) and the
    /// search's twins never add noise, so with noise the world is no longer their model.
    pub release_noise_m: f32,
    /// Release noise about z: standard deviation of the yaw offset (degrees).
    pub release_noise_deg: f32,
    /// Release noise in height: standard deviation (m) of the release's height off the one
    /// decided, never lower than touching (the decided release is `clearance_m` above the
    /// estimated contact). Drawn after x, y and yaw, and only when not 0, so that without it
    /// every other draw is as before.
    pub release_height_sd_m: f32,
    /// The evaluation's camera: standard deviation (m) of each seen cell's depth error in the
    /// heightmap the methods decide on ([`CameraNoise`]). Like the release noise, applied by
    /// the evaluation's environment only, never by the world or a twin.
    pub camera_depth_sd_m: f32,
    /// The evaluation's camera: the share of cells anywhere that it does not see (dropouts,
    /// filled as a camera adapter fills them).
    pub camera_dropout: f32,
    /// The evaluation's camera: the share of cells at a step edge (a neighbour 1 cm higher or
    /// lower) that it does not see.
    pub camera_edge_dropout: f32,
    /// The evaluation's objects: relative standard deviation of each object's true size
    /// against its catalog hull, per episode ([`ObjectErrors`]).
    pub object_size_sd: f32,
    /// The evaluation's objects: relative standard deviation of each object's true mass.
    pub object_mass_sd: f32,
    /// The evaluation's objects: relative standard deviation of each object's friction.
    pub object_friction_sd: f32,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            heightmap_cell_m: ObsLayout::CELL_M,
            clearance_m: herb_core::frames::RELEASE_CLEARANCE_M,
            dt: 1.0 / 60.0,
            settle_cap_s: 3.0,
            time_until_sleep_s: 0.2,
            sleep_speed_mps: 0.01,
            rest_speed_mps: 0.0,
            friction: 0.6,
            inside_tolerance_m: INSIDE_TOLERANCE_M,
            stability_tilt_deg: 10.0,
            early_out_m: 0.05,
            out_past_walls: false,
            out_check_steps: 8,
            max_corrective_speed_mps: 3.0,
            solver_iterations: 8,
            prediction_distance_m: 0.02,
            length_unit_m: 1.0,
            contact_recycle_m: 0.0,
            freeze_settled: false,
            pile_cell_m: 0.0125,
            pile_fit_m: 0.006,
            pile_step_m: 0.002,
            release_noise_m: 0.0,
            release_noise_deg: 0.0,
            release_height_sd_m: 0.0,
            camera_depth_sd_m: 0.0,
            camera_dropout: 0.0,
            camera_edge_dropout: 0.0,
            object_size_sd: 0.0,
            object_mass_sd: 0.0,
            object_friction_sd: 0.0,
        }
    }
}

impl WorldConfig {
    /// The release noise of [`WorldConfig::release_noise_m`],
    /// [`WorldConfig::release_noise_deg`] and [`WorldConfig::release_height_sd_m`], never lower
    /// than touching.
    pub fn release_noise(&self) -> ReleaseNoise {
        ReleaseNoise {
            sigma_m: self.release_noise_m,
            sigma_deg: self.release_noise_deg,
            sigma_height_m: self.release_height_sd_m,
            lowest_m: -self.clearance_m,
        }
    }

    /// The camera error of [`WorldConfig::camera_depth_sd_m`], [`WorldConfig::camera_dropout`]
    /// and [`WorldConfig::camera_edge_dropout`].
    pub fn camera_noise(&self) -> CameraNoise {
        CameraNoise {
            depth_sd_m: self.camera_depth_sd_m,
            dropout: self.camera_dropout,
            edge_dropout: self.camera_edge_dropout,
        }
    }

    /// The object error of [`WorldConfig::object_size_sd`], [`WorldConfig::object_mass_sd`] and
    /// [`WorldConfig::object_friction_sd`].
    pub fn object_errors(&self) -> ObjectErrors {
        ObjectErrors {
            size_sd: self.object_size_sd,
            mass_sd: self.object_mass_sd,
            friction_sd: self.object_friction_sd,
        }
    }

    /// This configuration without the evaluation's errors (release, camera, objects): what a
    /// method, the search and its twins are given, which are never told of them.
    pub fn without_errors(&self) -> Self {
        let d = Self::default();
        Self {
            release_noise_m: d.release_noise_m,
            release_noise_deg: d.release_noise_deg,
            release_height_sd_m: d.release_height_sd_m,
            camera_depth_sd_m: d.camera_depth_sd_m,
            camera_dropout: d.camera_dropout,
            camera_edge_dropout: d.camera_edge_dropout,
            object_size_sd: d.object_size_sd,
            object_mass_sd: d.object_mass_sd,
            object_friction_sd: d.object_friction_sd,
            ..self.clone()
        }
    }

    /// The settings [`WorldConfig::set`] knows, by name.
    pub const SETTABLE: [&'static str; 20] = [
        "dt",
        "settle_cap_s",
        "time_until_sleep_s",
        "sleep_speed_mps",
        "rest_speed_mps",
        "friction",
        "max_corrective_speed_mps",
        "solver_iterations",
        "prediction_distance_m",
        "length_unit_m",
        "contact_recycle_m",
        "clearance_m",
        "early_out_m",
        "out_past_walls",
        "out_check_steps",
        "inside_tolerance_m",
        "freeze_settled",
        "pile_cell_m",
        "pile_fit_m",
        "pile_step_m",
    ];

    /// Sets the field `key` (one of [`WorldConfig::SETTABLE`]) from its text, then checks the
    /// whole configuration ([`WorldConfig::validate`]); the error names what was wrong and
    /// leaves the configuration as it was.
    pub fn set(&mut self, key: &str, value: &str) -> Result<()> {
        let mut next = self.clone();
        let bad = || SimError::Config(format!("world setting {key} = {value:?}: not a number"));
        let num = || value.trim().parse::<f32>().map_err(|_| bad());
        let int = || value.trim().parse::<u32>().map_err(|_| bad());
        let flag = || match value.trim() {
            "true" | "1" => Ok(true),
            "false" | "0" => Ok(false),
            _ => Err(SimError::Config(format!(
                "world setting {key} = {value:?}: expected true or false"
            ))),
        };
        match key {
            "dt" => next.dt = num()?,
            "settle_cap_s" => next.settle_cap_s = num()?,
            "time_until_sleep_s" => next.time_until_sleep_s = num()?,
            "sleep_speed_mps" => next.sleep_speed_mps = num()?,
            "rest_speed_mps" => next.rest_speed_mps = num()?,
            "friction" => next.friction = num()?,
            "max_corrective_speed_mps" => next.max_corrective_speed_mps = num()?,
            "solver_iterations" => next.solver_iterations = int()?,
            "prediction_distance_m" => next.prediction_distance_m = num()?,
            "length_unit_m" => next.length_unit_m = num()?,
            "contact_recycle_m" => next.contact_recycle_m = num()?,
            "clearance_m" => next.clearance_m = num()?,
            "early_out_m" => next.early_out_m = num()?,
            "out_past_walls" => next.out_past_walls = flag()?,
            "freeze_settled" => next.freeze_settled = flag()?,
            "pile_cell_m" => next.pile_cell_m = num()?,
            "pile_fit_m" => next.pile_fit_m = num()?,
            "pile_step_m" => next.pile_step_m = num()?,
            "out_check_steps" => next.out_check_steps = int()?,
            "inside_tolerance_m" => next.inside_tolerance_m = num()?,
            _ => {
                return Err(SimError::Config(format!(
                    "unknown world setting {key:?} (expected one of {})",
                    Self::SETTABLE.join(", ")
                )));
            }
        }
        next.validate()?;
        *self = next;
        Ok(())
    }

    /// [`WorldConfig::set`] for each `KEY=VALUE` of `list` (comma-separated), in order.
    pub fn set_all(&mut self, list: &str) -> Result<()> {
        for item in list.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (k, v) = item.split_once('=').ok_or_else(|| {
                SimError::Config(format!("world setting {item:?}: expected KEY=VALUE"))
            })?;
            self.set(k.trim(), v)?;
        }
        Ok(())
    }

    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<()> {
        let check = |name: &str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(SimError::Config(format!(
                    "'{name}' = {v} outside {lo}..={hi}"
                )))
            }
        };
        let count = |name: &str, v: u32, hi: u32| {
            if (1..=hi).contains(&v) {
                Ok(())
            } else {
                Err(SimError::Config(format!("'{name}' = {v} outside 1..={hi}")))
            }
        };
        check("heightmap_cell_m", self.heightmap_cell_m, 0.0005, 0.02)?;
        check("clearance_m", self.clearance_m, 0.0, 0.05)?;
        check("dt", self.dt, 1e-4, 0.05)?;
        check("settle_cap_s", self.settle_cap_s, self.dt, 60.0)?;
        check("time_until_sleep_s", self.time_until_sleep_s, 0.0, 5.0)?;
        check("sleep_speed_mps", self.sleep_speed_mps, 0.0, 1.0)?;
        check("rest_speed_mps", self.rest_speed_mps, 0.0, 1.0)?;
        check("friction", self.friction, 0.0, 2.0)?;
        check("inside_tolerance_m", self.inside_tolerance_m, 0.0, 0.05)?;
        check("stability_tilt_deg", self.stability_tilt_deg, 0.0, 90.0)?;
        check("early_out_m", self.early_out_m, 0.0, 10.0)?;
        count("out_check_steps", self.out_check_steps, 1000)?;
        check(
            "max_corrective_speed_mps",
            self.max_corrective_speed_mps,
            0.01,
            10.0,
        )?;
        count("solver_iterations", self.solver_iterations, 64)?;
        check(
            "prediction_distance_m",
            self.prediction_distance_m,
            1e-4,
            0.1,
        )?;
        check("length_unit_m", self.length_unit_m, 0.01, 1.0)?;
        check("contact_recycle_m", self.contact_recycle_m, 0.0, 0.05)?;
        check("pile_cell_m", self.pile_cell_m, 0.001, 0.05)?;
        check("pile_step_m", self.pile_step_m, 0.0005, 0.02)?;
        check("pile_fit_m", self.pile_fit_m, 0.0, 0.02)?;
        check("release_noise_m", self.release_noise_m, 0.0, 0.05)?;
        check("release_noise_deg", self.release_noise_deg, 0.0, 45.0)?;
        check("release_height_sd_m", self.release_height_sd_m, 0.0, 0.05)?;
        check("camera_depth_sd_m", self.camera_depth_sd_m, 0.0, 0.05)?;
        check("camera_dropout", self.camera_dropout, 0.0, 0.5)?;
        check("camera_edge_dropout", self.camera_edge_dropout, 0.0, 1.0)?;
        check("object_size_sd", self.object_size_sd, 0.0, 0.1)?;
        check("object_mass_sd", self.object_mass_sd, 0.0, 0.25)?;
        check("object_friction_sd", self.object_friction_sd, 0.0, 0.25)?;
        Ok(())
    }
}
