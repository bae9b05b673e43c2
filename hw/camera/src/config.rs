//! herb-camera's file: the ROS side, the calibrated camera pose, depth limits and the heightmap
//! settings. Every key has a default; unknown keys and out-of-range values are errors naming the
//! key. The IPC prefix comes from herbd's file (`--config`), as for every adapter.

use crate::project::Params;
use herb_process::config_file::{ConfigFile, Invalid, in_range};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::Deserialize;

/// The whole file.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// `[ros]`.
    pub ros: Ros,
    /// `[topics]`.
    pub topics: Topics,
    /// `[pose]`.
    pub pose: Pose,
    /// `[depth]`.
    pub depth: DepthLimits,
    /// `[heightmap]`.
    pub heightmap: HeightmapSettings,
}

/// `[ros]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros {
    /// ROS master URI, `http://host:port`.
    pub master_uri: String,
    /// This node's name.
    pub node_name: String,
    /// The address other ROS nodes (the camera's driver) reach this one at (`ROS_IP`), an
    /// IPv4 address. Empty: the environment's `ROS_HOSTNAME`/`ROS_IP`, else this PC's hostname
    /// (which they must then resolve).
    pub ip: String,
    /// The host name other ROS nodes reach this one at (`ROS_HOSTNAME`); takes precedence over
    /// `ip`, as in ROS. Empty: see `ip`.
    pub hostname: String,
}

/// `[topics]` (the realsense2_camera driver's defaults).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Topics {
    /// `sensor_msgs/Image`, 16UC1 millimetres or 32FC1 metres.
    pub image: String,
    /// `sensor_msgs/CameraInfo`.
    pub camera_info: String,
}

/// `[pose]`: the camera's optical frame (z along the view, x to the image's right, y down) in
/// the box frame B (origin at the inner floor's centre, x along the long side, z up), as
/// `herb-camera calibrate` writes it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Pose {
    /// Position of the optical centre in B (m).
    pub translation: [f64; 3],
    /// Orientation, quaternion `[x, y, z, w]` (normalised on load).
    pub rotation: [f64; 4],
}

/// `[depth]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthLimits {
    /// Readings nearer than this are ignored (m).
    pub min_m: f64,
    /// Readings farther than this are ignored (m).
    pub max_m: f64,
    /// Images whose stamp is older than this when they arrive are refused (s).
    pub max_age_s: f64,
}

/// `[heightmap]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeightmapSettings {
    /// Cell side (m); herbd's decision needs the observation scale, 0.35 / 224 m.
    pub cell_m: f32,
    /// Heights below this are the floor (m).
    pub floor_threshold_m: f32,
    /// Unseen cells take the highest seen cell within this many cells (else the frame's
    /// highest).
    pub fill_radius_cells: usize,
    /// Per-cell median over this many frames (1: none).
    pub median_frames: usize,
}

impl Default for Ros {
    fn default() -> Self {
        Self {
            master_uri: "http://127.0.0.1:11311".into(),
            node_name: "/herb_camera".into(),
            ip: String::new(),
            hostname: String::new(),
        }
    }
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            image: "/camera/depth/image_rect_raw".into(),
            camera_info: "/camera/depth/camera_info".into(),
        }
    }
}

impl Default for Pose {
    fn default() -> Self {
        // 0.6 m above the floor's centre, looking straight down, image right along B x.
        Self {
            translation: [0.0, 0.0, 0.6],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

impl Default for DepthLimits {
    fn default() -> Self {
        Self {
            min_m: 0.2,
            max_m: 1.5,
            max_age_s: 0.5,
        }
    }
}

impl Default for HeightmapSettings {
    fn default() -> Self {
        Self {
            cell_m: herb_core::ObsLayout::CELL_M,
            floor_threshold_m: herb_core::heightmap::CAMERA_FLOOR_THRESHOLD_M,
            fill_radius_cells: herb_core::heightmap::CAMERA_FILL_RADIUS_CELLS,
            median_frames: 1,
        }
    }
}

impl CameraConfig {
    /// The camera pose as an isometry (B from the optical frame).
    pub fn b_from_c(&self) -> Isometry3<f64> {
        let [x, y, z, w] = self.pose.rotation;
        let [tx, ty, tz] = self.pose.translation;
        Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        )
    }

    /// The projection's settings.
    pub fn params(&self) -> Params {
        Params {
            min_depth: self.depth.min_m,
            max_depth: self.depth.max_m,
            floor_threshold: self.heightmap.floor_threshold_m,
            fill_radius: self.heightmap.fill_radius_cells,
            max_height: herb_core::heightmap::HEIGHT_RANGE_M.1,
        }
    }
}

impl ConfigFile for CameraConfig {
    fn validate(&self) -> Result<(), Invalid> {
        herb_ros1::check_master_uri("ros.master_uri", &self.ros.master_uri)
            .map_err(|e| e.to_string())?;
        herb_ros1::check_ip("ros.ip", &self.ros.ip).map_err(|e| e.to_string())?;
        herb_ros1::check_hostname("ros.hostname", &self.ros.hostname).map_err(|e| e.to_string())?;
        for (name, topic) in [
            ("ros.node_name", &self.ros.node_name),
            ("topics.image", &self.topics.image),
            ("topics.camera_info", &self.topics.camera_info),
        ] {
            herb_ros1::check_name(name, topic).map_err(|e| e.to_string())?;
        }
        for (i, t) in self.pose.translation.iter().enumerate() {
            in_range(&format!("pose.translation[{i}]"), *t, -5.0, 5.0)?;
        }
        let q = self.pose.rotation;
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(norm.is_finite() && (0.5..=2.0).contains(&norm)) {
            return Err(format!(
                "pose.rotation = {q:?}: not a quaternion [x, y, z, w] (norm {norm})"
            )
            .into());
        }
        in_range("depth.min_m", self.depth.min_m, 0.01, 10.0)?;
        in_range("depth.max_m", self.depth.max_m, self.depth.min_m, 10.0)?;
        in_range("depth.max_age_s", self.depth.max_age_s, 0.01, 10.0)?;
        let h = &self.heightmap;
        herb_core::heightmap::GridSpec::for_box(h.cell_m)
            .map_err(|e| format!("heightmap.cell_m: {e}"))?;
        in_range(
            "heightmap.floor_threshold_m",
            h.floor_threshold_m.into(),
            0.0,
            0.05,
        )?;
        in_range(
            "heightmap.fill_radius_cells",
            h.fill_radius_cells as f64,
            0.0,
            64.0,
        )?;
        in_range("heightmap.median_frames", h.median_frames as f64, 1.0, 15.0)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_holds_the_defaults() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../systemd/camera.toml");
        let c = CameraConfig::load(std::path::Path::new(path)).unwrap();
        assert_eq!(c, CameraConfig::default());
    }

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        let c = CameraConfig::default();
        c.validate().unwrap();
        // Looking down: the view axis is -z in B.
        let z = c.b_from_c().rotation * nalgebra::Vector3::z();
        assert!((z + nalgebra::Vector3::z()).norm() < 1e-12, "{z}");
        for (text, key) in [
            ("[pose]\nrotation = [0.0, 0.0, 0.0, 0.0]\n", "pose.rotation"),
            ("[depth]\nmin_m = 2.0\nmax_m = 1.0\n", "depth.max_m"),
            ("[heightmap]\ncell_m = 0.5\n", "heightmap.cell_m"),
            (
                "[heightmap]\nmedian_frames = 0\n",
                "heightmap.median_frames",
            ),
            ("[topics]\nimage = \"depth\"\n", "topics.image"),
            ("[pose]\nbogus = 1\n", "bogus"),
            ("[ros]\nip = \"herb-pc\"\n", "ros.ip"),
            ("[ros]\nip = \"10.0.0\"\n", "ros.ip"),
            ("[ros]\nhostname = \"herb pc\"\n", "ros.hostname"),
            ("[ros]\nhostname = \"herb-pc:11311\"\n", "ros.hostname"),
        ] {
            let e = CameraConfig::from_toml(text, "c.toml").unwrap_err();
            assert!(e.to_string().contains(key), "{text}: {e}");
        }
        let c = CameraConfig::from_toml(
            "[ros]\nip = \"10.0.0.5\"\nhostname = \"herb-pc.local\"\n",
            "c.toml",
        )
        .unwrap();
        assert_eq!(
            (c.ros.ip.as_str(), c.ros.hostname.as_str()),
            ("10.0.0.5", "herb-pc.local")
        );
    }
}
