//! The ROS 1 side: one thread running a single-threaded tokio runtime with roslibrust's native
//! client. It subscribes to the robot's joint states, assembly state and gripper state, sends
//! herbd's latest fresh command at the configured rate, drives the gripper, watches the master,
//! and exchanges only small values with the iceoryx2 loop through [`Shared`].

use crate::bridge::{Grip, GripperDriver, HerbdCommand, JointMap, command_to_send, robot_blocker};
use crate::config::{BaxterConfig, Mode};
use herb_adapter::guard::{GuardSettings, JumpGuard, REFUSAL_HOLD_NS, Refusal};
use herb_ipc::{ArmBlocker, DOF, GripperAction, monotonic_ns};
use herb_ros1::baxter_core_msgs::{AssemblyState, EndEffectorState, JointCommand};
use herb_ros1::node::{
    MasterView, Next, RegisterError, announce_again, connect, master_view, next, topic_of,
};
use herb_ros1::sensor_msgs::JointState as RosJointState;
use herb_ros1::std_msgs::{Bool, Float64};
use roslibrust::ros1::{MasterClient, NodeError, RosMasterError};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// An assembly state older than this blocks motion: the robot stopped reporting.
pub const ROBOT_STATE_MAX_AGE_NS: u64 = 1_000_000_000;
/// How often `--enable` asks the robot to enable until it first reports enabled.
const ENABLE_PERIOD_NS: u64 = 500_000_000;
/// Messages a subscription holds for this side: 320 ms of the robot's 100 Hz states (older
/// ones are skipped and counted as lagged).
const SUBSCRIBER_QUEUE: usize = 32;

/// A joint state from the robot, mapped to herbd's order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// Receipt time (CLOCK_MONOTONIC ns): the stamp herbd sees.
    pub stamp_ns: u64,
    /// Angles (rad).
    pub position: [f64; DOF],
    /// Speeds (rad/s).
    pub velocity: [f64; DOF],
}

/// Counters of what came from ROS.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RosCounters {
    /// Joint states received.
    pub joint_states: u64,
    /// Joint states refused (names, lengths, non-finite values, undecodable).
    pub joint_states_rejected: u64,
    /// Messages the subscriptions dropped because this side fell behind.
    pub lagged: u64,
    /// Joint commands sent to the robot.
    pub commands_sent: u64,
    /// Gripper commands sent (calibration, moves and resends).
    pub gripper_commands_sent: u64,
    /// Times the master stopped answering.
    pub master_lost: u64,
    /// Times the node registered again with a master that had forgotten it (restarted).
    pub reregistered: u64,
    /// Joint commands the jump guard refused (`herb_adapter::guard`).
    pub commands_refused: u64,
}

pub use herb_adapter::{Latency, latency, latency_json};

/// What the two threads share (a short lock on each side, no allocation).
#[derive(Debug)]
pub struct Shared {
    /// Latest valid joint state and its number (ROS -> loop).
    pub joint: Option<(u64, Measured)>,
    /// Latest gripper state, its number and receipt time (ROS -> loop).
    pub grip: Option<(u64, u64, Grip)>,
    /// Why the robot must not move now, if it must not (ROS -> loop).
    pub blocker: Option<ArmBlocker>,
    /// Latest valid herbd joint command (loop -> ROS).
    pub command: Option<HerbdCommand>,
    /// herbd's latest gripper request (loop -> ROS).
    pub grip_request: Option<GripperAction>,
    /// Counters.
    pub counters: RosCounters,
    /// herbd's command stamp to the ROS publish returning (the wait for the pacing tick
    /// included).
    pub command_latency: Latency,
    /// The largest offset of a sent command's target from the measured position, per joint
    /// (rad): the tracking lag seen, to set the guard's bound from.
    pub max_command_offset_rad: [f64; DOF],
}

impl Default for Shared {
    fn default() -> Self {
        Self {
            joint: None,
            grip: None,
            blocker: Some(ArmBlocker::RobotSilent),
            command: None,
            grip_request: None,
            counters: RosCounters::default(),
            command_latency: latency(),
            max_command_offset_rad: [0.0; DOF],
        }
    }
}

/// Locks `shared`, recovering from a poisoned lock (a panic elsewhere leaves plain values).
pub fn lock(shared: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

/// What ends the ROS side (and then the process).
#[derive(Debug, thiserror::Error)]
pub enum RosError {
    /// The tokio runtime could not be built.
    #[error("tokio runtime: {0}")]
    Runtime(#[source] std::io::Error),
    /// Advertising or subscribing to a topic failed.
    #[error("{action} {topic}: {source}")]
    Topic {
        /// `advertise` or `subscribe`.
        action: &'static str,
        /// The topic.
        topic: String,
        /// The node's error.
        source: NodeError,
    },
    /// Publishing on a topic failed.
    #[error("publish {topic}: {source}")]
    Publish {
        /// The topic.
        topic: String,
        /// The publisher's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The node's URI could not be had.
    #[error("node URI: {0}")]
    NodeUri(#[source] NodeError),
    /// No client of the master could be made.
    #[error("master client: {0}")]
    MasterClient(#[source] RosMasterError),
    /// A subscription closed.
    #[error("subscription {0} closed")]
    Closed(String),
    /// Registering again with a restarted master failed.
    #[error(transparent)]
    Register(#[from] RegisterError),
}

/// Runs the ROS side until `stop` is set; an error ends it (the process then exits).
/// `velocity`: herbd's joint speed limits (rad/s), which the jump guard's bound is made from.
pub fn run(
    cfg: BaxterConfig,
    velocity: [f64; DOF],
    enable: bool,
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
) -> Result<(), RosError> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(RosError::Runtime)?;
    rt.block_on(async {
        let mut carry = Carry {
            guard: JumpGuard::new(GuardSettings::from_limits(
                &velocity,
                cfg.arm.command_rate_hz,
                cfg.arm.guard_periods,
                cfg.arm.tracking_lag_s,
            )),
            enabled_seen: false,
            refused_until: 0,
        };
        loop {
            match session(&cfg, enable, &shared, &stop, &mut carry).await? {
                End::Stop => return Ok(()),
                End::Reregister => herb_adapter::log!(
                    "herb-baxter: no robot state since registering again: connecting anew"
                ),
            }
        }
    })
}

/// What outlives one registration.
struct Carry {
    guard: JumpGuard,
    /// The robot reported enabled once: `--enable` never asks again (a later disable is an
    /// operator's, or the e-stop's, and is not undone from here).
    enabled_seen: bool,
    /// Joint state is withheld until then after a command refused for its distance.
    refused_until: u64,
}

/// How a session ended.
enum End {
    /// `stop` was set.
    Stop,
    /// The robot stayed silent after the node announced itself to a restarted master that
    /// already knew the robot: start a new node, which connects to the publishers it lists.
    Reregister,
}

/// After announcing this node again to a master that already listed the robot's publishers,
/// a new node is made if no robot state arrived within this long.
const REANNOUNCE_GRACE_NS: u64 = 2_000_000_000;

fn ros_err(action: &'static str, topic: &str) -> impl FnOnce(NodeError) -> RosError {
    let topic = topic.to_string();
    move |source| RosError::Topic {
        action,
        topic,
        source,
    }
}

fn publish_err<E: std::error::Error + Send + Sync + 'static>(
    topic: &str,
) -> impl FnOnce(E) -> RosError {
    let topic = topic.to_string();
    move |e| RosError::Publish {
        topic,
        source: Box::new(e),
    }
}

/// One registration with the master: advertise, subscribe, then bridge until `stop` is set
/// (`End::Stop`) or the master restarted (`End::Reregister`); an error ends the process.
async fn session(
    cfg: &BaxterConfig,
    enable: bool,
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
    carry: &mut Carry,
) -> Result<End, RosError> {
    let guard = &mut carry.guard;
    let refused_until = &mut carry.refused_until;
    let Some(nh) = connect(
        &cfg.ros.master_uri,
        &cfg.ros.node_name,
        |m| herb_adapter::log!("herb-baxter: {m}"),
        stop,
    )
    .await
    else {
        return Ok(End::Stop);
    };
    let t = &cfg.topics;
    let cmd_pub = nh
        .advertise::<JointCommand>(&t.joint_command, 1, false)
        .await
        .map_err(ros_err("advertise", &t.joint_command))?;
    let grip_pub = nh
        .advertise::<herb_ros1::baxter_core_msgs::EndEffectorCommand>(&t.gripper_command, 8, false)
        .await
        .map_err(ros_err("advertise", &t.gripper_command))?;
    // Latched: the robot (or a driver restarted later) reads them on connection.
    let timeout_pub = nh
        .advertise::<Float64>(&t.command_timeout, 1, true)
        .await
        .map_err(ros_err("advertise", &t.command_timeout))?;
    timeout_pub
        .publish(&Float64 {
            data: cfg.arm.command_timeout_s,
        })
        .await
        .map_err(publish_err(&t.command_timeout))?;
    let ratio_pub = if cfg.arm.mode == Mode::Position {
        let p = nh
            .advertise::<Float64>(&t.speed_ratio, 1, true)
            .await
            .map_err(ros_err("advertise", &t.speed_ratio))?;
        p.publish(&Float64 {
            data: cfg.arm.speed_ratio,
        })
        .await
        .map_err(publish_err(&t.speed_ratio))?;
        Some(p)
    } else {
        None
    };
    let mut enable_pub = if enable && !carry.enabled_seen {
        Some(
            nh.advertise::<Bool>(&t.enable, 1, false)
                .await
                .map_err(ros_err("advertise", &t.enable))?,
        )
    } else {
        None
    };
    let mut joints = nh
        .subscribe::<RosJointState>(&t.joint_states, SUBSCRIBER_QUEUE)
        .await
        .map_err(ros_err("subscribe", &t.joint_states))?;
    let mut robot = nh
        .subscribe::<AssemblyState>(&t.robot_state, SUBSCRIBER_QUEUE)
        .await
        .map_err(ros_err("subscribe", &t.robot_state))?;
    let mut gripper = nh
        .subscribe::<EndEffectorState>(&t.gripper_state, SUBSCRIBER_QUEUE)
        .await
        .map_err(ros_err("subscribe", &t.gripper_state))?;
    let client_uri = nh.get_client_uri().await.map_err(RosError::NodeUri)?;
    let master = MasterClient::new(&cfg.ros.master_uri, client_uri, &cfg.ros.node_name)
        .await
        .map_err(RosError::MasterClient)?;

    // What this node registered, to register it again with a restarted master.
    let subscribed = [
        topic_of::<RosJointState>(&t.joint_states),
        topic_of::<AssemblyState>(&t.robot_state),
        topic_of::<EndEffectorState>(&t.gripper_state),
    ];
    let mut published = vec![
        topic_of::<JointCommand>(&t.joint_command),
        topic_of::<herb_ros1::baxter_core_msgs::EndEffectorCommand>(&t.gripper_command),
        topic_of::<Float64>(&t.command_timeout),
    ];
    if ratio_pub.is_some() {
        published.push(topic_of::<Float64>(&t.speed_ratio));
    }
    if enable_pub.is_some() {
        published.push(topic_of::<Bool>(&t.enable));
    }
    // Set when the node announced itself again to a master that already knew the robot.
    let mut announced_at: Option<u64> = None;
    let map = JointMap::new(&cfg.arm);
    let mut driver = GripperDriver::new(cfg.gripper.clone(), &cfg.ros.node_name);
    let mut command = JointCommand {
        mode: cfg.arm.mode.code(),
        command: vec![0.0; DOF],
        names: map.names().to_vec(),
    };
    let max_age_ns = (cfg.arm.max_command_age_s * 1e9) as u64;
    let period = Duration::from_secs_f64(1.0 / cfg.arm.command_rate_hz);
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let check_period = Duration::from_secs_f64(cfg.ros.master_check_s);
    let mut check = tokio::time::interval(check_period);
    check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);

    let mut assembly: Option<(AssemblyState, u64)> = None;
    let mut master_ok = true;
    let (mut joint_seq, mut grip_seq) = {
        let s = lock(shared);
        (s.joint.map_or(0, |j| j.0), s.grip.map_or(0, |g| g.0))
    };
    let mut last_enable = 0u64;
    let mut last_reject: Option<String> = None;
    let mut blocker_said: Option<Option<ArmBlocker>> = None;
    // Say a refusal when the guard starts refusing, not for every command after it.
    let mut refusing = false;
    // Nothing from before this registration is measured now.
    lock(shared).joint = None;
    guard.set_ready(false, monotonic_ns());
    while !stop.load(Ordering::Relaxed) {
        tokio::select! {
            m = next(&mut joints) => {
                let now = monotonic_ns();
                let mut s = lock(shared);
                match m {
                    Next::Msg(m) => {
                        s.counters.joint_states += 1;
                        match map.map(&m) {
                            Ok((position, velocity)) => {
                                joint_seq += 1;
                                s.joint = Some((joint_seq, Measured { stamp_ns: now, position, velocity }));
                            }
                            Err(e) => {
                                s.counters.joint_states_rejected += 1;
                                let e = e.to_string();
                                if last_reject.as_deref() != Some(e.as_str()) {
                                    herb_adapter::log!("herb-baxter: joint state refused: {e}");
                                    last_reject = Some(e);
                                }
                            }
                        }
                    }
                    Next::Lagged(n) => s.counters.lagged += n,
                    Next::Bad(e) => {
                        s.counters.joint_states += 1;
                        s.counters.joint_states_rejected += 1;
                        herb_adapter::log!("herb-baxter: joint state undecodable: {e}");
                    }
                    Next::Closed => return Err(RosError::Closed(t.joint_states.clone())),
                }
            }
            m = next(&mut robot) => match m {
                Next::Msg(m) => assembly = Some((m, monotonic_ns())),
                Next::Lagged(n) => lock(shared).counters.lagged += n,
                Next::Bad(e) => herb_adapter::log!("herb-baxter: robot state undecodable: {e}"),
                Next::Closed => return Err(RosError::Closed(t.robot_state.clone())),
            },
            m = next(&mut gripper) => match m {
                Next::Msg(m) => {
                    let g = driver.state(&m);
                    grip_seq += 1;
                    lock(shared).grip = Some((grip_seq, monotonic_ns(), g));
                }
                Next::Lagged(n) => lock(shared).counters.lagged += n,
                Next::Bad(e) => herb_adapter::log!("herb-baxter: gripper state undecodable: {e}"),
                Next::Closed => return Err(RosError::Closed(t.gripper_state.clone())),
            },
            _ = check.tick() => {
                let view = master_view(&master, &t.joint_states, &cfg.ros.node_name, check_period).await;
                let ok = view != MasterView::Lost;
                if ok != master_ok {
                    master_ok = ok;
                    if ok {
                        herb_adapter::log!("herb-baxter: ROS master back");
                    } else {
                        lock(shared).counters.master_lost += 1;
                        herb_adapter::log!("herb-baxter: ROS master lost: joint state withheld, nothing commanded");
                    }
                }
                if view == MasterView::Forgotten {
                    herb_adapter::log!("herb-baxter: the ROS master restarted and forgot this node: registering again");
                    let known = announce_again(&master, &subscribed, &published).await?;
                    lock(shared).counters.reregistered += 1;
                    announced_at = known.then(monotonic_ns);
                }
                if let Some(at) = announced_at {
                    let now = monotonic_ns();
                    let heard = assembly.as_ref().is_some_and(|(_, rx)| *rx > at);
                    if heard {
                        announced_at = None;
                    } else if now.saturating_sub(at) > REANNOUNCE_GRACE_NS {
                        let mut s = lock(shared);
                        s.blocker = Some(ArmBlocker::RobotSilent);
                        s.joint = None;
                        drop(s);
                        guard.set_ready(false, now);
                        return Ok(End::Reregister);
                    }
                }
            }
            _ = tick.tick() => {
                let now = monotonic_ns();
                let blocker = if !master_ok {
                    Some(ArmBlocker::MasterLost)
                } else if now < *refused_until {
                    Some(ArmBlocker::CommandRefused)
                } else {
                    match &assembly {
                        Some((_, at)) if now.saturating_sub(*at) > ROBOT_STATE_MAX_AGE_NS => Some(ArmBlocker::RobotSilent),
                        a => robot_blocker(a.as_ref().map(|(a, _)| a)),
                    }
                };
                if Some(blocker) != blocker_said {
                    match blocker {
                        Some(b) => herb_adapter::log!("herb-baxter: {}: joint state withheld, nothing commanded", b.fault().describe()),
                        None => herb_adapter::log!("herb-baxter: robot ready"),
                    }
                    blocker_said = Some(blocker);
                }
                // A command planned before the robot became ready never reaches it.
                guard.set_ready(blocker.is_none(), now);
                let (latest, request, measured) = {
                    let mut s = lock(shared);
                    s.blocker = blocker;
                    (s.command, s.grip_request, s.joint.map(|(_, m)| (m.stamp_ns, m.position)))
                };
                // Enabling is asked for at start only: once the robot reports enabled, a later
                // disable (an operator, the e-stop) is never undone from here.
                if assembly.as_ref().is_some_and(|(a, _)| a.enabled) {
                    enable_pub = None;
                    carry.enabled_seen = true;
                }
                if let Some(p) = &enable_pub
                    && now.saturating_sub(last_enable) >= ENABLE_PERIOD_NS
                {
                    last_enable = now;
                    p.publish(&Bool { data: true }).await.map_err(publish_err(&t.enable))?;
                }
                if blocker.is_some() {
                    continue;
                }
                if let Some(c) = command_to_send(latest, now, max_age_ns) {
                    let verdict = guard.check(c.stamp_ns, &c.position, measured.as_ref().map(|(at, q)| (*at, q)), now);
                    match verdict {
                        Ok(()) => {
                            refusing = false;
                            command.command.copy_from_slice(&c.position);
                            cmd_pub.publish(&command).await.map_err(publish_err(&t.joint_command))?;
                            let mut s = lock(shared);
                            s.counters.commands_sent += 1;
                            s.max_command_offset_rad = guard.max_offset_rad;
                            let _ = s.command_latency.record(monotonic_ns().saturating_sub(c.stamp_ns).max(1));
                        }
                        Err(r) => {
                            if matches!(r, Refusal::TooFar { .. }) {
                                // herbd and the arm disagree: halt herbd (state withheld), which
                                // then resumes from the measured state.
                                *refused_until = now + REFUSAL_HOLD_NS;
                            }
                            lock(shared).counters.commands_refused = guard.refused;
                            if !refusing {
                                herb_adapter::log!("herb-baxter: joint command refused: {r}");
                                refusing = true;
                            }
                        }
                    }
                }
                if let Some(a) = request {
                    driver.request(a);
                }
                if let Some(c) = driver.poll(now) {
                    grip_pub.publish(&c).await.map_err(publish_err(&t.gripper_command))?;
                    lock(shared).counters.gripper_commands_sent += 1;
                }
            }
        }
    }
    drop(ratio_pub);
    Ok(End::Stop)
}
