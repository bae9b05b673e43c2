//! The field model: the errors of a real cell that the evaluation's world adds on top of the
//! ideal world, read from one versioned file (`models/field.toml`). No twin and no method is
//! told of them. Each figure is a standard deviation; with every figure 0 the world is the ideal
//! one, bit for bit.
//!
//! Three parts, each its own section of the file: the gripper's release error (x, y, yaw and
//! height), the camera's depth noise and dropouts, and the objects' size, mass and friction
//! against the catalog. Every key is required: a file with a missing, unknown, negative or
//! non-finite figure is refused with the key named.

use crate::error::{Result, SimError};
use crate::world::{CameraNoise, ObjectErrors, WorldConfig};
use std::path::Path;

/// The shipped field model's file, relative to the checkout's root.
pub const SHIPPED: &str = "models/field.toml";

/// A field model (module docs).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldModel {
    /// Its name and version (`field-v1`).
    pub name: String,
    /// The gripper's release error.
    pub release: ReleaseError,
    /// The camera's error in the heightmap the methods see.
    pub camera: CameraNoise,
    /// The objects' error against their catalog entries, per episode.
    pub object: ObjectErrors,
}

/// The release error of the field model: standard deviations of each release off its decided
/// pose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReleaseError {
    /// x and y (m).
    pub xy_sd_m: f32,
    /// Yaw (degrees).
    pub yaw_sd_deg: f32,
    /// Height (m), never lower than touching.
    pub height_sd_m: f32,
}

impl FieldModel {
    /// Reads a field model from TOML `text`; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        let bad = |message: String| SimError::Config(format!("field model {origin}: {message}"));
        let m: FieldModel = toml::from_str(text).map_err(|e| bad(e.message().to_string()))?;
        let (r, c, o) = (m.release, m.camera, m.object);
        // The world's own ranges (`WorldConfig::validate`), named by the file's keys.
        for (key, v, max) in [
            ("release.xy_sd_m", r.xy_sd_m, 0.05),
            ("release.yaw_sd_deg", r.yaw_sd_deg, 45.0),
            ("release.height_sd_m", r.height_sd_m, 0.05),
            ("camera.depth_sd_m", c.depth_sd_m, 0.05),
            ("camera.dropout", c.dropout, 0.5),
            ("camera.edge_dropout", c.edge_dropout, 1.0),
            ("object.size_sd", o.size_sd, 0.1),
            ("object.mass_sd", o.mass_sd, 0.25),
            ("object.friction_sd", o.friction_sd, 0.25),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return Err(bad(format!("{key} = {v}: need a number from 0 to {max}")));
            }
        }
        Ok(m)
    }

    /// Reads a field model file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SimError::Config(format!("field model {}: {e}", path.display())))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// The model a world is named by: `ideal` (none), `field` (the shipped file, [`SHIPPED`],
    /// in the working directory, else in the checkout this was built from) or a file's path.
    pub fn by_name(name: &str) -> Result<Option<Self>> {
        let path = match name {
            "ideal" => return Ok(None),
            "field" => {
                let here = std::path::PathBuf::from(SHIPPED);
                if here.is_file() {
                    here
                } else {
                    Path::new(env!("CARGO_MANIFEST_DIR"))
                        .join("..")
                        .join(SHIPPED)
                }
            }
            file => std::path::PathBuf::from(file),
        };
        Self::load(&path).map(Some)
    }

    /// `cfg` with this model's errors, checked against the world's ranges.
    pub fn apply(&self, cfg: &WorldConfig) -> Result<WorldConfig> {
        let mut c = cfg.clone();
        c.release_noise_m = self.release.xy_sd_m;
        c.release_noise_deg = self.release.yaw_sd_deg;
        c.release_height_sd_m = self.release.height_sd_m;
        c.camera_depth_sd_m = self.camera.depth_sd_m;
        c.camera_dropout = self.camera.dropout;
        c.camera_edge_dropout = self.camera.edge_dropout;
        c.object_size_sd = self.object.size_sd;
        c.object_mass_sd = self.object.mass_sd;
        c.object_friction_sd = self.object.friction_sd;
        c.validate()?;
        Ok(c)
    }
}
