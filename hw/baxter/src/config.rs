//! What herb-baxter reads: herbd's configuration file (the IPC prefix and the joint limits every
//! command is checked against, so the adapter and herbd agree) and its own file (the ROS
//! master, rates, modes, topic names, gripper settings). Unknown keys are errors, as in herbd.

use herb_process::config_file::{ConfigFile, Invalid, in_range};
use herb_robot::motion::JointLimits;
use serde::Deserialize;

/// The adapter's view of herbd's configuration: the other tables are herbd's and are ignored.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default)]
pub struct HerbdView {
    /// Service-name prefix (`herb_ipc::Services`).
    pub ipc_prefix: String,
    /// Joint limits every command is checked against before it reaches the robot.
    pub limits: JointLimits,
}

impl Default for HerbdView {
    fn default() -> Self {
        Self {
            ipc_prefix: herb_ipc::Services::DEFAULT_PREFIX.into(),
            limits: JointLimits::baxter_left(),
        }
    }
}

impl ConfigFile for HerbdView {
    fn validate(&self) -> Result<(), Invalid> {
        herb_ipc::Services::new(&self.ipc_prefix).map_err(|e| e.to_string())?;
        Ok(self.limits.validate_baxter_left()?)
    }
}

/// How joint commands are sent (`baxter_core_msgs/JointCommand.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// `POSITION_MODE` (1): Baxter's joint position controller, speed set by `speed_ratio`.
    Position,
    /// `RAW_POSITION_MODE` (4): positions straight to the joint controllers, no smoothing;
    /// only for trajectories already limited in speed, acceleration and jerk (herbd's are).
    RawPosition,
}

impl Mode {
    /// The message's mode code.
    pub fn code(self) -> i32 {
        match self {
            Self::Position => herb_ros1::baxter_core_msgs::JointCommand::POSITION_MODE,
            Self::RawPosition => herb_ros1::baxter_core_msgs::JointCommand::RAW_POSITION_MODE,
        }
    }
}

/// herb-baxter's own file.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BaxterConfig {
    /// The ROS side.
    pub ros: Ros,
    /// The arm.
    pub arm: ArmSettings,
    /// The electric gripper.
    pub gripper: GripperSettings,
    /// Topic names (Baxter SDK 1.2 defaults for the left limb).
    pub topics: Topics,
}

/// `[ros]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros {
    /// ROS master URI (`ROS_MASTER_URI`), `http://host:port`.
    pub master_uri: String,
    /// This node's name.
    pub node_name: String,
    /// How often the master is asked whether it is alive and still knows this node (s).
    /// While it is not alive, joint state is withheld from herbd (which halts and reports
    /// `MasterLost`) and nothing is commanded; a master that came back without this node (it
    /// restarted) gets every publisher and subscriber registered again.
    pub master_check_s: f64,
    /// The address other ROS nodes reach this one at (`ROS_IP`): the robot must reach it.
    /// Empty: the environment's `ROS_IP`/`ROS_HOSTNAME`, else this PC's hostname (which the
    /// robot must then resolve).
    pub ip: String,
    /// The host name other ROS nodes reach this one at (`ROS_HOSTNAME`); takes precedence over
    /// `ip`, as in ROS. Empty: see `ip`.
    pub hostname: String,
}

/// `[arm]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArmSettings {
    /// Joint names in herbd's order `s0 .. w2`.
    pub joints: [String; herb_ipc::DOF],
    /// Rate at which the latest fresh herbd command is sent to the robot (Hz, 1 to 800).
    pub command_rate_hz: f64,
    /// A herbd command older than this (by its stamp) is not sent (s): when herbd goes quiet
    /// the adapter stops sending and the robot holds after `command_timeout_s`.
    pub max_command_age_s: f64,
    /// The robot holds its position when no command came for this long (s); latched on the
    /// `joint_command_timeout` topic.
    pub command_timeout_s: f64,
    /// Command mode.
    pub mode: Mode,
    /// Joint position speed ratio for `position` mode (0 to 1, latched on `speed_ratio`).
    pub speed_ratio: f64,
    /// The jump guard (`herb_adapter::guard`): a command's target may be at most
    /// `speed limit x (guard_periods / command_rate_hz + tracking_lag_s)` from the measured
    /// position, per joint; farther, it is refused and counted.
    pub guard_periods: f64,
    /// How long the arm trails its command in normal motion (s), part of the guard's bound.
    /// The adapter's summary reports the largest offset it passed (`max_command_offset_rad`):
    /// measure it on the cell and keep `speed limit x tracking_lag_s` above it.
    pub tracking_lag_s: f64,
}

/// `[gripper]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GripperSettings {
    /// Command position for open (0 closed to 100 open).
    pub open_position: f64,
    /// Command position for closed.
    pub closed_position: f64,
    /// Reported closed below this position (percent open).
    pub closed_below: f64,
    /// A command not acknowledged (its sender and sequence echoed in the state) is resent
    /// after this long (s).
    pub resend_s: f64,
    /// `calibrate` is sent once; again only if the gripper still reports uncalibrated this
    /// long after (s). A gripper restarts its calibration on every `calibrate`.
    pub calibrate_timeout_s: f64,
}

/// `[topics]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Topics {
    /// `sensor_msgs/JointState` of every joint.
    pub joint_states: String,
    /// `baxter_core_msgs/JointCommand`.
    pub joint_command: String,
    /// `std_msgs/Float64`, latched.
    pub command_timeout: String,
    /// `std_msgs/Float64`, latched.
    pub speed_ratio: String,
    /// `baxter_core_msgs/AssemblyState`.
    pub robot_state: String,
    /// `std_msgs/Bool` (only with `--enable`).
    pub enable: String,
    /// `baxter_core_msgs/EndEffectorCommand`.
    pub gripper_command: String,
    /// `baxter_core_msgs/EndEffectorState`.
    pub gripper_state: String,
}

impl Default for Ros {
    fn default() -> Self {
        Self {
            master_uri: "http://127.0.0.1:11311".into(),
            node_name: "/herb_baxter".into(),
            master_check_s: 0.25,
            ip: String::new(),
            hostname: String::new(),
        }
    }
}

impl Default for ArmSettings {
    fn default() -> Self {
        Self {
            joints: ["s0", "s1", "e0", "e1", "w0", "w1", "w2"].map(|j| format!("left_{j}")),
            command_rate_hz: 100.0,
            max_command_age_s: 0.05,
            command_timeout_s: 0.2,
            mode: Mode::Position,
            speed_ratio: 1.0,
            guard_periods: 3.0,
            tracking_lag_s: 0.1,
        }
    }
}

impl Default for GripperSettings {
    fn default() -> Self {
        Self {
            open_position: 100.0,
            closed_position: 0.0,
            closed_below: 90.0,
            resend_s: 0.5,
            calibrate_timeout_s: 5.0,
        }
    }
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            joint_states: "/robot/joint_states".into(),
            joint_command: "/robot/limb/left/joint_command".into(),
            command_timeout: "/robot/limb/left/joint_command_timeout".into(),
            speed_ratio: "/robot/limb/left/set_speed_ratio".into(),
            robot_state: "/robot/state".into(),
            enable: "/robot/set_super_enable".into(),
            gripper_command: "/robot/end_effector/left_gripper/command".into(),
            gripper_state: "/robot/end_effector/left_gripper/state".into(),
        }
    }
}

impl ConfigFile for BaxterConfig {
    fn validate(&self) -> Result<(), Invalid> {
        let r = &self.ros;
        herb_ros1::check_master_uri("ros.master_uri", &r.master_uri).map_err(|e| e.to_string())?;
        herb_ros1::check_name("ros.node_name", &r.node_name).map_err(|e| e.to_string())?;
        in_range("ros.master_check_s", r.master_check_s, 0.01, 10.0)?;
        herb_ros1::check_ip("ros.ip", &r.ip).map_err(|e| e.to_string())?;
        herb_ros1::check_hostname("ros.hostname", &r.hostname).map_err(|e| e.to_string())?;
        let a = &self.arm;
        for (i, j) in a.joints.iter().enumerate() {
            if j.is_empty() || a.joints[..i].contains(j) {
                return Err(format!("arm.joints: {j:?} is empty or repeated").into());
            }
        }
        in_range("arm.command_rate_hz", a.command_rate_hz, 1.0, 800.0)?;
        in_range("arm.max_command_age_s", a.max_command_age_s, 0.001, 1.0)?;
        in_range("arm.command_timeout_s", a.command_timeout_s, 0.01, 5.0)?;
        in_range("arm.speed_ratio", a.speed_ratio, 0.0, 1.0)?;
        in_range("arm.guard_periods", a.guard_periods, 1.0, 20.0)?;
        in_range("arm.tracking_lag_s", a.tracking_lag_s, 0.0, 0.5)?;
        let g = &self.gripper;
        in_range("gripper.open_position", g.open_position, 0.0, 100.0)?;
        in_range("gripper.closed_position", g.closed_position, 0.0, 100.0)?;
        in_range("gripper.closed_below", g.closed_below, 0.0, 100.0)?;
        if !(g.closed_position < g.closed_below && g.closed_below <= g.open_position) {
            return Err(format!(
                "gripper: closed_position {} < closed_below {} <= open_position {} must hold",
                g.closed_position, g.closed_below, g.open_position
            )
            .into());
        }
        in_range("gripper.resend_s", g.resend_s, 0.01, 10.0)?;
        in_range(
            "gripper.calibrate_timeout_s",
            g.calibrate_timeout_s,
            0.5,
            60.0,
        )?;
        let t = &self.topics;
        for (name, topic) in [
            ("topics.joint_states", &t.joint_states),
            ("topics.joint_command", &t.joint_command),
            ("topics.command_timeout", &t.command_timeout),
            ("topics.speed_ratio", &t.speed_ratio),
            ("topics.robot_state", &t.robot_state),
            ("topics.enable", &t.enable),
            ("topics.gripper_command", &t.gripper_command),
            ("topics.gripper_state", &t.gripper_state),
        ] {
            herb_ros1::check_name(name, topic).map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_bad_values_are_named() {
        BaxterConfig::default().validate().unwrap();
        HerbdView::default().validate().unwrap();
        let e = BaxterConfig::from_toml("[arm]\ncommand_rate_hz = 900.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml") && e.contains("arm.command_rate_hz"),
            "{e}"
        );
        let e = BaxterConfig::from_toml("[arm]\nbogus = 1\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
        let e = BaxterConfig::from_toml("[ros]\nmaster_uri = \"localhost\"\n", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("ros.master_uri"), "{e}");
        let e = BaxterConfig::from_toml(
            "[gripper]\nclosed_below = 100.0\nopen_position = 50.0\n",
            "t",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("closed_below"), "{e}");
        let e = BaxterConfig::from_toml("[arm]\nmode = \"torque\"\n", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("torque"), "{e}");
        let c = BaxterConfig::from_toml("[arm]\nmode = \"raw_position\"\n", "t").unwrap();
        assert_eq!(c.arm.mode.code(), 4);
    }

    #[test]
    fn the_shipped_file_holds_the_defaults() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../systemd/baxter.toml");
        let c = BaxterConfig::load(std::path::Path::new(path)).unwrap();
        assert_eq!(c, BaxterConfig::default());
    }

    #[test]
    fn herbd_s_shipped_file_reads_as_the_adapter_s_view() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../systemd/herbd.toml");
        let v = HerbdView::load(std::path::Path::new(path)).unwrap();
        let (a, b) = (v.limits, JointLimits::baxter_left());
        // The file writes the defaults in decimal: equal to the last few ulps.
        for (x, y) in [
            (a.lower, b.lower),
            (a.upper, b.upper),
            (a.velocity, b.velocity),
        ] {
            for i in 0..herb_ipc::DOF {
                assert!(
                    (x[i] - y[i]).abs() < 1e-9,
                    "joint {i}: {} vs {}",
                    x[i],
                    y[i]
                );
            }
        }
        assert_eq!(v.ipc_prefix, "herb");
    }
}
