//! `herb-baxter`: bridges herbd's arm services (iceoryx2) and a Baxter's left arm and gripper
//! (ROS 1). See the crate docs. SIGINT/SIGTERM: prints a JSON summary on stdout and exits 0.

use clap::Parser;
use herb_adapter::ArmPorts;
use herb_baxter::bridge::HerbdCommand;
use herb_baxter::config::{BaxterConfig, HerbdView};
use herb_baxter::ros::{self, Shared, lock};
use herb_ipc::bus::Bus;
use herb_ipc::{ArmBlocker, GripperState, Header, JointState, NO_OBJECT, Services, monotonic_ns};
use herb_process::config_file::ConfigFile;
use herb_process::rt::{set_timer_slack, sleep_until};
use herb_ros1::Advertised;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Bridges herbd and a Rethink Baxter (left arm, electric gripper) over ROS 1.
#[derive(Debug, Parser)]
#[command(name = "herb-baxter", version)]
struct Cli {
    /// herbd's configuration file (IPC prefix, joint limits).
    #[arg(long)]
    config: Option<PathBuf>,
    /// This adapter's file (ROS master, rates, modes, topics, gripper).
    #[arg(long)]
    baxter: Option<PathBuf>,
    /// IPC service-name prefix (overrides herbd's file).
    #[arg(long)]
    prefix: Option<String>,
    /// ROS master URI (overrides the adapter's file).
    #[arg(long)]
    master_uri: Option<String>,
    /// Ask the robot to enable (`/robot/set_super_enable`) at start, until it first reports
    /// enabled; a later disable is never undone by the adapter.
    #[arg(long)]
    enable: bool,
    /// Rate of the iceoryx2 side (Hz): how often herbd's commands are taken and the robot's
    /// states passed on.
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// Also write the final summary (JSON) here.
    #[arg(long)]
    report: Option<PathBuf>,
}

fn run(cli: Cli) -> Result<serde_json::Value, String> {
    let mut herbd = HerbdView::load_or_default(cli.config.as_deref()).map_err(|e| e.to_string())?;
    if let Some(p) = &cli.prefix {
        herbd.ipc_prefix = p.clone();
    }
    herbd.validate().map_err(|e| e.to_string())?;
    let mut cfg =
        BaxterConfig::load_or_default(cli.baxter.as_deref()).map_err(|e| e.to_string())?;
    if let Some(u) = &cli.master_uri {
        cfg.ros.master_uri = u.clone();
    }
    cfg.validate().map_err(|e| e.to_string())?;
    if !(cli.rate_hz.is_finite() && (10.0..=10_000.0).contains(&cli.rate_hz)) {
        return Err(format!("--rate-hz {} outside 10..=10000", cli.rate_hz));
    }
    // The address the robot reaches this node at: the file's keys, else ROS_HOSTNAME/ROS_IP.
    // SAFETY: no other thread runs yet (the bus, the ROS thread and the signal handler start
    // below), so nothing reads the environment concurrently.
    let advertised =
        unsafe { Advertised::set(&cfg.ros.ip, &cfg.ros.hostname) }.map_err(|e| e.to_string())?;
    let services = Services::new(&herbd.ipc_prefix).map_err(|e| e.to_string())?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let s = stop.clone();
        ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)).map_err(|e| e.to_string())?;
    }
    let bus = Bus::open("herb-baxter", &services).map_err(|e| e.to_string())?;
    let mut arm = ArmPorts::open(&bus).map_err(|e| e.to_string())?;
    let shared = Arc::new(Mutex::new(Shared::default()));
    let ros_thread = {
        let (cfg, shared, stop) = (cfg.clone(), shared.clone(), stop.clone());
        let enable = cli.enable;
        let velocity = herbd.limits.velocity;
        std::thread::Builder::new()
            .name("herb-baxter-ros".into())
            .spawn(move || {
                let r = ros::run(cfg, velocity, enable, shared, stop.clone());
                // The ROS side ending ends the process: herbd sees the states stop.
                stop.store(true, Ordering::Relaxed);
                r
            })
            .map_err(|e| e.to_string())?
    };
    herb_adapter::log!(
        "herb-baxter: prefix {:?}, master {}, reached at {advertised}, commands at {} Hz ({:?} mode)",
        herbd.ipc_prefix,
        cfg.ros.master_uri,
        cfg.arm.command_rate_hz,
        cfg.arm.mode
    );
    let (lower, upper) = (herbd.limits.lower, herbd.limits.upper);
    let arm_range = herb_robot::motion::baxter_left_arm_range();
    let period = (1e9 / cli.rate_hz) as u64;
    set_timer_slack();
    let mut next = monotonic_ns() + period;
    let (mut joint_seen, mut grip_seen, mut seq) = (0u64, 0u64, 0u64);
    let (mut withheld, mut max_excess) = (0u64, 0.0f64);
    // A joint state's ROS receipt to its publication to herbd.
    let mut state_latency = ros::latency();
    while !stop.load(Ordering::Relaxed) {
        sleep_until(next, 0);
        next += period;
        let now = monotonic_ns();
        if now > next {
            next = now + period;
        }
        let mut latest = None;
        // herbd's limits, widened to an arm that sagged past them while disabled (herbd brings
        // it back in from where it is, toward the limit), never past the arm's own.
        let measured = lock(&shared).joint.map(|(_, m)| m.position);
        let (lo, hi) = herb_adapter::command_range(
            (&lower, &upper),
            measured.as_ref(),
            (&arm_range.0, &arm_range.1),
        );
        arm.drain_joint_commands(&lo, &hi, |c, valid| {
            for i in 0..herb_ipc::DOF {
                let p = c.position[i];
                if p.is_finite() {
                    max_excess = max_excess.max((lower[i] - p).max(p - upper[i]).max(0.0));
                }
            }
            if valid {
                latest = Some(HerbdCommand {
                    stamp_ns: c.header.stamp_ns,
                    position: c.position,
                });
            }
        });
        let mut request = None;
        // The catalog is herbd's business: a real gripper ignores the object type, so any
        // type is accepted here.
        arm.drain_gripper_commands(usize::MAX, |_, a| request = Some(a));
        let (joint, grip, blocker, refused) = {
            let mut s = lock(&shared);
            if latest.is_some() {
                s.command = latest;
            }
            if request.is_some() {
                s.grip_request = request;
            }
            (s.joint, s.grip, s.blocker, s.counters.commands_refused)
        };
        arm.report_arm_status(blocker.unwrap_or(ArmBlocker::None), refused, now);
        if let Some((n, m)) = joint
            && n != joint_seen
        {
            joint_seen = n;
            if blocker.is_none() {
                seq += 1;
                arm.publish_joint_state(JointState {
                    header: Header::at(seq, m.stamp_ns),
                    position: m.position,
                    velocity: m.velocity,
                });
                let _ = state_latency.record(monotonic_ns().saturating_sub(m.stamp_ns).max(1));
            } else {
                withheld += 1;
            }
        }
        if let Some((n, at, g)) = grip
            && n != grip_seen
        {
            grip_seen = n;
            arm.publish_gripper_state(GripperState {
                header: Header::at(n, at),
                closed: g.closed as u32,
                holding: g.holding as u32,
                object_type: NO_OBJECT,
                reserved: 0,
            });
        }
    }
    let ros_result = match ros_thread.join() {
        Ok(r) => r.map_err(|e| e.to_string()),
        Err(_) => Err("the ROS thread panicked".to_string()),
    };
    let (c, command_latency, offsets) = {
        let s = lock(&shared);
        (
            s.counters,
            ros::latency_json(&s.command_latency),
            s.max_command_offset_rad,
        )
    };
    let summary = serde_json::json!({ "baxter_final": {
        "commands": arm.joint.received,
        "commands_rejected": arm.joint.rejected,
        "gripper_commands_rejected": arm.gripper.rejected,
        "max_limit_excess_rad": max_excess,
        "joint_states_withheld": withheld,
        "max_command_offset_rad": offsets,
        "ros": c,
        "joint_state_to_herbd_ms": ros::latency_json(&state_latency),
        "command_to_ros_ms": command_latency,
        "ros_error": ros_result.as_ref().err(),
    }});
    herb_adapter::summary_or_error(summary, ros_result)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let report = cli.report.clone();
    herb_adapter::finish("herb-baxter", run(cli), report.as_deref())
}
