//! The adapter's decisions, free of ports and sockets so they are tested directly: joint states
//! mapped by name, the robot's state gate, the command pacing rule and the gripper driver.

use crate::config::{ArmSettings, GripperSettings};
use herb_ipc::{ArmBlocker, DOF, GripperAction};
use herb_ros1::baxter_core_msgs::{AssemblyState, EndEffectorCommand, EndEffectorState};
use herb_ros1::sensor_msgs::JointState as RosJointState;

/// Why a ROS joint state was not passed on.
#[derive(Debug, Clone, PartialEq)]
pub enum JointReject {
    /// `name`, `position` and `velocity` differ in length (velocity may be empty only if
    /// the robot reports none, which Baxter never does: refused).
    Lengths {
        /// Names.
        names: usize,
        /// Positions.
        positions: usize,
        /// Velocities.
        velocities: usize,
    },
    /// One of the arm's joints is not in the message.
    Missing(String),
    /// A joint is named twice.
    Repeated(String),
    /// A position or velocity of the arm is NaN or infinite.
    NotFinite(String),
}

impl std::fmt::Display for JointReject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Lengths {
                names,
                positions,
                velocities,
            } => write!(
                f,
                "{names} names, {positions} positions, {velocities} velocities"
            ),
            Self::Missing(j) => write!(f, "joint {j} missing"),
            Self::Repeated(j) => write!(f, "joint {j} named twice"),
            Self::NotFinite(j) => write!(f, "joint {j}: position or velocity not finite"),
        }
    }
}

/// Maps a robot-wide `sensor_msgs/JointState` (any order, other joints too) to the arm's
/// joints in herbd's order.
#[derive(Debug, Clone)]
pub struct JointMap {
    names: [String; DOF],
}

impl JointMap {
    /// For the configured joint names (herbd's order).
    pub fn new(arm: &ArmSettings) -> Self {
        Self {
            names: arm.joints.clone(),
        }
    }

    /// The arm's joint names, herbd's order.
    pub fn names(&self) -> &[String; DOF] {
        &self.names
    }

    /// Positions and velocities of the arm's joints, or why the message is refused.
    pub fn map(&self, m: &RosJointState) -> Result<([f64; DOF], [f64; DOF]), JointReject> {
        if m.name.len() != m.position.len() || m.name.len() != m.velocity.len() {
            return Err(JointReject::Lengths {
                names: m.name.len(),
                positions: m.position.len(),
                velocities: m.velocity.len(),
            });
        }
        let (mut q, mut qd) = ([0.0; DOF], [0.0; DOF]);
        for (k, want) in self.names.iter().enumerate() {
            let mut found = None;
            for (i, n) in m.name.iter().enumerate() {
                if n == want {
                    if found.is_some() {
                        return Err(JointReject::Repeated(want.clone()));
                    }
                    found = Some(i);
                }
            }
            let i = found.ok_or_else(|| JointReject::Missing(want.clone()))?;
            let (p, v) = (m.position[i], m.velocity[i]);
            if !(p.is_finite() && v.is_finite()) {
                return Err(JointReject::NotFinite(want.clone()));
            }
            q[k] = p;
            qd[k] = v;
        }
        Ok((q, qd))
    }
}

/// Whether the robot may move, from its `AssemblyState`: enabled, not stopped, no error. None
/// received counts as a silent robot.
pub fn robot_blocker(s: Option<&AssemblyState>) -> Option<ArmBlocker> {
    match s {
        None => Some(ArmBlocker::RobotSilent),
        Some(s) if s.stopped => Some(ArmBlocker::EStop),
        Some(s) if s.error => Some(ArmBlocker::RobotError),
        Some(s) if !s.enabled => Some(ArmBlocker::Disabled),
        Some(_) => None,
    }
}

/// The latest valid command herbd sent: its stamp (CLOCK_MONOTONIC ns) and joint angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HerbdCommand {
    /// herbd's stamp.
    pub stamp_ns: u64,
    /// Joint angles, herbd's order (rad).
    pub position: [f64; DOF],
}

/// The pacing rule: at each tick of the command rate, send the latest herbd command if it is
/// fresh, as is (never extrapolated); otherwise send nothing, so the robot holds after its
/// command timeout. (The jump guard, `herb_adapter::guard`, then checks it against the
/// measured position.)
pub fn command_to_send(
    latest: Option<HerbdCommand>,
    now_ns: u64,
    max_age_ns: u64,
) -> Option<HerbdCommand> {
    let c = latest?;
    (now_ns.saturating_sub(c.stamp_ns) <= max_age_ns).then_some(c)
}

/// What the gripper reports to herbd.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Grip {
    /// Closed (position below `closed_below`).
    pub closed: bool,
    /// Holding an object (`gripping`).
    pub holding: bool,
}

/// Drives Baxter's electric gripper: calibrates it once (`calibrate` sent again only if the
/// gripper is still uncalibrated `calibrate_timeout_s` later: a gripper restarts calibrating on
/// every `calibrate`), then sends a `go` command for each of herbd's open and close requests,
/// resent until the state echoes its sender and sequence.
#[derive(Debug, Clone)]
pub struct GripperDriver {
    settings: GripperSettings,
    sender: String,
    sequence: u32,
    /// The command awaiting acknowledgement, when it was last sent, and the action it serves
    /// (`None` for calibration).
    pending: Option<(EndEffectorCommand, u64, Option<GripperAction>)>,
    /// The action herbd asked for last.
    wanted: Option<GripperAction>,
    /// The action whose command the gripper acknowledged last.
    acked: Option<GripperAction>,
    calibrated: bool,
    /// When `calibrate` was last sent.
    calibrate_sent: Option<u64>,
    /// The gripper's id (from its state).
    id: Option<u32>,
}

impl GripperDriver {
    /// A driver sending as `sender` (the node's name).
    pub fn new(settings: GripperSettings, sender: &str) -> Self {
        Self {
            settings,
            sender: sender.into(),
            sequence: 0,
            pending: None,
            wanted: None,
            acked: None,
            calibrated: false,
            calibrate_sent: None,
            id: None,
        }
    }

    /// herbd asked for `action`.
    pub fn request(&mut self, action: GripperAction) {
        self.wanted = Some(action);
        // A new request supersedes a command for another action not yet acknowledged.
        if self
            .pending
            .as_ref()
            .is_some_and(|(_, _, a)| a.is_some_and(|a| a != action))
        {
            self.pending = None;
        }
    }

    /// A state from the gripper: acknowledgements and calibration; returns what herbd is told.
    pub fn state(&mut self, s: &EndEffectorState) -> Grip {
        self.id = Some(s.id);
        self.calibrated = s.calibrated == 1;
        if let Some((c, _, action)) = &self.pending
            && s.command_sender == c.sender
            && s.command_sequence == c.sequence
        {
            if action.is_some() {
                self.acked = *action;
            }
            self.pending = None;
        }
        Grip {
            closed: f64::from(s.position) < self.settings.closed_below,
            holding: s.gripping == 1,
        }
    }

    /// The command to send now, if any: calibration first, then the wanted action once; a
    /// pending one again every `resend_s`.
    pub fn poll(&mut self, now_ns: u64) -> Option<EndEffectorCommand> {
        let id = self.id?; // no state yet: the gripper's id is unknown
        let resend_ns = (self.settings.resend_s * 1e9) as u64;
        if let Some((c, sent, _)) = &mut self.pending {
            if now_ns.saturating_sub(*sent) < resend_ns {
                return None;
            }
            *sent = now_ns;
            return Some(c.clone());
        }
        let (command, args, action) = if !self.calibrated {
            let timeout_ns = (self.settings.calibrate_timeout_s * 1e9) as u64;
            if self
                .calibrate_sent
                .is_some_and(|t| now_ns.saturating_sub(t) < timeout_ns)
            {
                return None; // calibrating
            }
            self.calibrate_sent = Some(now_ns);
            (EndEffectorCommand::CMD_CALIBRATE, String::new(), None)
        } else {
            let action = self.wanted.filter(|&w| Some(w) != self.acked)?;
            let position = match action {
                GripperAction::Open => self.settings.open_position,
                GripperAction::Close => self.settings.closed_position,
            };
            (
                EndEffectorCommand::CMD_GO,
                format!("{{\"position\": {position:.1}}}"),
                Some(action),
            )
        };
        self.sequence = self.sequence.wrapping_add(1);
        let c = EndEffectorCommand {
            id,
            command: command.into(),
            args,
            sender: self.sender.clone(),
            sequence: self.sequence,
        };
        // A `go` is resent until acknowledged; `calibrate` only after its timeout (above).
        if action.is_some() {
            self.pending = Some((c.clone(), now_ns, action));
        }
        Some(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm() -> ArmSettings {
        ArmSettings::default()
    }

    fn ros_state(names: &[&str], p: &[f64], v: &[f64]) -> RosJointState {
        RosJointState {
            name: names.iter().map(|s| s.to_string()).collect(),
            position: p.to_vec(),
            velocity: v.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn joint_states_are_mapped_by_name_in_any_order_and_bad_ones_refused_with_a_reason() {
        let map = JointMap::new(&arm());
        // Shuffled, with the head and the right arm among them.
        let names = [
            "head_pan", "left_w2", "right_s0", "left_s0", "left_e1", "left_s1", "left_w0",
            "left_e0", "left_w1",
        ];
        let p = [9.0, 0.7, 9.0, 0.1, 0.4, 0.2, 0.5, 0.3, 0.6];
        let v = [9.0, 7.0, 9.0, 1.0, 4.0, 2.0, 5.0, 3.0, 6.0];
        let (q, qd) = map.map(&ros_state(&names, &p, &v)).unwrap();
        assert_eq!(q, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]);
        assert_eq!(qd, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);

        let mut nan = p;
        nan[3] = f64::NAN;
        assert_eq!(
            map.map(&ros_state(&names, &nan, &v)),
            Err(JointReject::NotFinite("left_s0".into()))
        );
        assert_eq!(
            map.map(&ros_state(&names[..8], &p[..8], &v[..8])),
            Err(JointReject::Missing("left_w1".into()))
        );
        assert!(matches!(
            map.map(&ros_state(&names, &p, &v[..3])),
            Err(JointReject::Lengths { velocities: 3, .. })
        ));
        let mut twice = names;
        twice[0] = "left_w2";
        assert_eq!(
            map.map(&ros_state(&twice, &p, &v)),
            Err(JointReject::Repeated("left_w2".into()))
        );
        let wrong = ["a", "b", "c", "d", "e", "f", "g"];
        assert_eq!(
            map.map(&ros_state(&wrong, &p[..7], &v[..7])),
            Err(JointReject::Missing("left_s0".into()))
        );
    }

    #[test]
    fn the_robot_may_move_only_enabled_unstopped_and_without_error() {
        let ok = AssemblyState {
            enabled: true,
            ready: true,
            ..Default::default()
        };
        assert_eq!(robot_blocker(Some(&ok)), None);
        assert!(robot_blocker(None).is_some());
        for bad in [
            AssemblyState {
                enabled: false,
                ..ok.clone()
            },
            AssemblyState {
                stopped: true,
                ..ok.clone()
            },
            AssemblyState {
                error: true,
                ..ok.clone()
            },
        ] {
            assert!(robot_blocker(Some(&bad)).is_some(), "{bad:?}");
        }
    }

    #[test]
    fn only_a_fresh_command_is_sent_and_never_extrapolated() {
        let c = HerbdCommand {
            stamp_ns: 1_000_000_000,
            position: [0.5; DOF],
        };
        assert_eq!(command_to_send(None, 2, 10), None);
        assert_eq!(command_to_send(Some(c), 1_040_000_000, 50_000_000), Some(c));
        assert_eq!(command_to_send(Some(c), 1_050_000_001, 50_000_000), None);
    }

    fn gstate(
        position: f32,
        gripping: u8,
        calibrated: u8,
        ack: Option<&EndEffectorCommand>,
    ) -> EndEffectorState {
        EndEffectorState {
            id: 65664,
            calibrated,
            position,
            gripping,
            command_sender: ack.map_or(String::new(), |c| c.sender.clone()),
            command_sequence: ack.map_or(0, |c| c.sequence),
            ..Default::default()
        }
    }

    #[test]
    fn the_gripper_is_calibrated_once_then_driven_and_resent_until_acknowledged() {
        let mut d = GripperDriver::new(GripperSettings::default(), "/herb_baxter");
        d.request(GripperAction::Close);
        assert_eq!(d.poll(0), None, "no state: the gripper's id is unknown");
        d.state(&gstate(100.0, 0, 0, None));
        let cal = d.poll(1).unwrap();
        assert_eq!((cal.command.as_str(), cal.id), ("calibrate", 65664));
        // Acknowledged at once, calibrating for a while: one calibrate, however many states
        // come meanwhile (a gripper restarts its calibration on each).
        for k in 1..400u64 {
            d.state(&gstate(100.0, 0, 0, Some(&cal)));
            assert_eq!(d.poll(1 + k * 10_000_000), None, "calibrate sent once");
        }
        // Still uncalibrated after the timeout (5 s): sent again.
        let again = d.poll(5_000_000_001).unwrap();
        assert_eq!(again.command, "calibrate");
        assert!(again.sequence > cal.sequence);
        d.state(&gstate(100.0, 0, 1, Some(&again)));
        let go = d.poll(5_100_000_000).unwrap();
        assert_eq!(go.command, "go");
        assert_eq!(go.args, "{\"position\": 0.0}");
        assert!(go.sequence > cal.sequence);
        // Acknowledged and closed on an object: reported closed and holding, nothing more sent.
        let g = d.state(&gstate(42.0, 1, 1, Some(&go)));
        assert_eq!(
            g,
            Grip {
                closed: true,
                holding: true
            }
        );
        assert_eq!(d.poll(6_000_000_000), None);
        // Open: one new command, acknowledged; reported open once the fingers passed 90.
        d.request(GripperAction::Open);
        let open = d.poll(6_100_000_000).unwrap();
        assert_eq!(open.args, "{\"position\": 100.0}");
        let g = d.state(&gstate(60.0, 0, 1, Some(&open)));
        assert!(g.closed && !g.holding);
        let g = d.state(&gstate(99.0, 0, 1, Some(&open)));
        assert!(!g.closed);
        assert_eq!(d.poll(7_000_000_000), None);
        // A `go` not acknowledged is resent after `resend_s`.
        d.request(GripperAction::Close);
        let close = d.poll(7_100_000_000).unwrap();
        assert_eq!(d.poll(7_200_000_000), None);
        assert_eq!(d.poll(7_700_000_000), Some(close));
    }
}
