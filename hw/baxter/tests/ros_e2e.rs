//! herb-baxter end to end against real ROS 1 peers: a real `rosmaster` on a free port, a rospy
//! fake Baxter (`fake_baxter.py`, a test fixture speaking the Baxter SDK topics), herb-baxter,
//! herbd and herbctl, each a process, each test under its own IPC prefix and master port.
//!
//! The heightmaps come from a **fixture camera** in the test process: the empty box's
//! heightmap published every 100 ms on the camera service (the depth-camera adapter is not
//! part of these tests), so every object is decided on an empty box.
//!
//! Needs Debian's ROS 1 packages (`python3-rospy python3-rosmaster python3-genpy ...`, see the
//! README); `.ci/run` installs them. Without them the tests say so and pass, except under
//! `CI=true`, where they fail.

use herb_robot::kinematics::LEFT_TOP_DOWN_NOMINAL;
use herb_testkit::ros::{Camera, PYTHON, RosWorld, ros_available};
use herb_testkit::{
    Follow, Proc, config, exe, fast_limits, last_json, lines, repo, spawn, spawn_env, tmp,
};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// The fake Baxter in `ros`: a joint state in `corrupt_every` corrupted (0: none); `extra`
/// arguments.
fn fake_baxter(ros: &RosWorld, report: &Path, corrupt_every: u32, extra: &[&str]) -> Proc {
    let l = fast_limits();
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    let script = repo().join("hw/baxter/tests/fake_baxter.py");
    // `--x=v` form: the values may start with '-'.
    let args = [
        format!("--report={}", report.display()),
        format!("--start={}", list(&LEFT_TOP_DOWN_NOMINAL)),
        format!("--lower={}", list(&l.lower)),
        format!("--upper={}", list(&l.upper)),
        format!("--vmax={}", list(&l.velocity)),
        format!("--corrupt-every={corrupt_every}"),
    ];
    let args: Vec<String> = args
        .into_iter()
        .chain(extra.iter().map(|a| a.to_string()))
        .collect();
    ros.python(&script, &args, "fake_baxter", Duration::from_millis(1500))
}

/// herb-baxter in `ros` on herbd's configuration `cfg`, with `extra` arguments.
fn adapter(ros: &RosWorld, cfg: &Path, tag: &str, extra: &[&str]) -> Proc {
    let uri = ros.uri();
    let base = ["--config", cfg.to_str().unwrap(), "--master-uri", &uri];
    spawn_env(
        Path::new(env!("CARGO_BIN_EXE_herb-baxter")),
        &[&base[..], extra].concat(),
        &ros.env(),
        &ros.dir.join(format!("herb-baxter-{tag}.log")),
    )
}

/// The rospy modules of the vendored baxter_core_msgs, generated without catkin.
fn generate_python_messages(dir: &Path) -> PathBuf {
    let root = dir.join("py");
    let out = root.join("baxter_core_msgs/msg");
    std::fs::create_dir_all(&out).unwrap();
    let msgs = repo().join("hw/ros1/msgs");
    let src = msgs.join("baxter_core_msgs/msg");
    let files: Vec<PathBuf> = [
        "JointCommand",
        "AssemblyState",
        "EndEffectorCommand",
        "EndEffectorState",
    ]
    .iter()
    .map(|m| src.join(format!("{m}.msg")))
    .collect();
    let include = |p: &str| format!("{p}:{}", msgs.join(p).join("msg").display());
    let genpy = "/usr/lib/genpy/genmsg_py.py";
    let st = Command::new(PYTHON)
        .args([genpy, "-p", "baxter_core_msgs", "-o", out.to_str().unwrap()])
        .args([
            "-I",
            &include("baxter_core_msgs"),
            "-I",
            &include("std_msgs"),
        ])
        .args(["-I", &include("sensor_msgs")])
        .args(&files)
        .status()
        .expect("genmsg_py runs");
    assert!(st.success(), "genmsg_py.py failed");
    let st = Command::new(PYTHON)
        .args([genpy, "--initpy", "-o", out.to_str().unwrap()])
        .status()
        .expect("genmsg_py runs");
    assert!(st.success(), "genmsg_py.py --initpy failed");
    std::fs::write(root.join("baxter_core_msgs/__init__.py"), "").unwrap();
    root
}

fn herbd(cfg: &Path, dir: &Path, extra: &[&str]) -> Proc {
    let cfg = cfg.to_str().unwrap();
    spawn(
        &exe("herbd", "herb-daemon"),
        &[&["--config", cfg], extra].concat(),
        &dir.join("herbd.log"),
    )
}

/// `herbctl` under `prefix` with `args` (a `pack` of objects or a session), JSON summary.
fn pack(prefix: &str, args: &[&str], dir: &Path) -> Proc {
    spawn(
        &exe("herbctl", "herbctl"),
        &[
            &["--prefix", prefix][..],
            args,
            &["--json", "--timeout", "300"],
        ]
        .concat(),
        &dir.join("herbctl.log"),
    )
}

/// The empty box's heightmap (the fake camera's scene: the fake Baxter places nothing).
fn empty_box() -> (herb_sim::GridSpec, Vec<f32>) {
    let spec = herb_sim::GridSpec::for_box(herb_sim::ObsLayout::CELL_M).unwrap();
    (spec, vec![0.0; spec.len()])
}

/// Stops the fake Baxter and reads its report.
fn fake_report(mut fake: Proc, report: &Path) -> serde_json::Value {
    fake.signal(libc::SIGTERM);
    assert!(
        fake.wait_for(Duration::from_secs(10)).success(),
        "fake Baxter exits 0"
    );
    serde_json::from_str(&std::fs::read_to_string(report).expect("fake Baxter's report")).unwrap()
}

/// Stops herb-baxter and reads its summary.
fn adapter_summary(mut a: Proc) -> serde_json::Value {
    let rx = lines(&mut a);
    a.signal(libc::SIGTERM);
    assert!(
        a.wait_for(Duration::from_secs(10)).success(),
        "herb-baxter exits 0"
    );
    last_json(&rx, "baxter_final")
}

/// The shortest BoxED episode packed through ROS, the arm by the fake Baxter and herb-baxter,
/// the heightmaps by the fake camera and herb-camera: every object decided and placed, every
/// joint command sent to the robot within the limits and addressed to the left arm's joints by
/// name, the gripper calibrated once then closed and opened once per object, the command
/// timeout latched; one joint state in 25 is bad (NaN, misspelt name, short array): each is
/// refused and counted by herb-baxter and never reaches herbd.
#[test]
fn packs_through_ros_with_a_fake_baxter() {
    if !ros_available() {
        return;
    }
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = herb_testkit::shortest_session(&root);
    let boxed = root.to_str().unwrap();
    let dir = tmp("ros-pack");
    let prefix = format!("ros{}pack", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir, Some(&generate_python_messages(&dir)));
    let _master = ros.master("1");
    let report = dir.join("fake.json");
    let fake = fake_baxter(&ros, &report, 25, &[]);
    let adapter = adapter(&ros, &cfg, "1", &[]);
    let (spec, truth) = empty_box();
    let camera = Camera::start(&ros, &cfg, &spec, &truth, 0, 0.0);
    let mut hd = herbd(&cfg, &dir, &["--boxed", boxed]);
    // The job is submitted once the robot is ready and a frame is out, so that herbd refuses
    // nothing (a job sent earlier is answered NotReady, which herbd counts).
    herb_testkit::wait_for_log(
        &dir.join("herb-baxter-1.log"),
        "robot ready",
        Duration::from_secs(30),
    );
    herb_testkit::wait_for_log(
        &dir.join("herb-camera.log"),
        "first heightmap published",
        Duration::from_secs(30),
    );
    std::thread::sleep(Duration::from_millis(500));
    let mut ctl = pack(
        &prefix,
        &["--boxed", boxed, "pack", "--session", &session],
        &dir,
    );
    let mut out = Follow::new(&mut ctl);
    out.wait_for(
        &format!("placed: {n} of {n} object"),
        Duration::from_secs(300),
    );
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], n as u64, "{summary}");
    assert_eq!(summary["decisions"], n as u64, "{summary}");
    let faults = summary["faults"].as_array().map_or(0, |f| f.len());
    assert_eq!(faults, 0, "no fault: {summary}");

    let hd_lines = lines(&mut hd);
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let stats = last_json(&hd_lines, "herbd_final");
    let a = adapter_summary(adapter);
    let f = fake_report(fake, &report);
    let mut cam = camera.adapter;
    let cam_rx = lines(&mut cam);
    cam.signal(libc::SIGTERM);
    assert!(cam.wait_for(Duration::from_secs(10)).success());
    let c = last_json(&cam_rx, "camera_final");
    eprintln!(
        "episode {session} ({n} objects)\nherbctl: {summary}\nherbd: {stats}\nherb-baxter: {a}\nfake Baxter: {f}\nherb-camera: {c}"
    );
    assert!(c["counters"]["published"].as_u64().unwrap() > 10, "{c}");
    // No image refused as bad input (those before the first camera info are counted apart);
    // the adapter's log says why if one was.
    let cam_log = std::fs::read_to_string(dir.join("herb-camera.log")).unwrap_or_default();
    assert_eq!(c["counters"]["images_rejected"], 0, "{c}\n{cam_log}");
    assert_eq!(a["commands_rejected"], 0, "{a}");
    assert_eq!(a["max_limit_excess_rad"], 0.0, "{a}");
    assert!(a["ros"]["commands_sent"].as_u64().unwrap() > 100, "{a}");
    assert_eq!(a["ros_error"], serde_json::Value::Null, "{a}");
    assert!(f["commands"].as_u64().unwrap() > 100, "{f}");
    assert_eq!(f["out_of_limits"], 0, "{f}");
    assert_eq!(f["bad_names"], 0, "{f}");
    assert_eq!(f["modes"], serde_json::json!([1]), "position mode: {f}");
    assert_eq!(f["timeouts_latched"], serde_json::json!([0.2]), "{f}");
    assert_eq!(f["calibrations"], 1, "{f}");
    assert_eq!(
        f["grip_events"],
        serde_json::json!(["close", "open"].repeat(n)),
        "{f}"
    );
    // Every corrupted state that reached the adapter refused: at most the states it never
    // received (before it subscribed, skipped while it lagged, after it stopped) were
    // corrupted ones it could not see.
    let corrupted = f["corrupted"].as_u64().unwrap();
    let unseen = f["published"].as_u64().unwrap() - a["ros"]["joint_states"].as_u64().unwrap();
    let refused = a["ros"]["joint_states_rejected"].as_u64().unwrap();
    assert!(corrupted > 10, "{f}");
    assert!(
        refused <= corrupted && refused + unseen >= corrupted,
        "refused {refused} of {corrupted} corrupted, {unseen} unseen: {a}"
    );
    let log = std::fs::read_to_string(dir.join("herb-baxter-1.log")).unwrap();
    for why in ["not finite", "joint left_e0 missing", "velocities"] {
        assert!(log.contains(why), "{why}: {log}");
    }
    assert_eq!(
        summary["rejected_inputs"], 0,
        "nothing bad reached herbd: {summary}"
    );
    assert!(stats["cycles"].as_u64().unwrap() > 1000, "{stats}");
}

/// The robot starts disabled and `--enable` enables it. Disabled mid-motion (its assembly
/// state says so), then e-stopped mid-motion, then its master dies mid-motion: each time
/// herb-baxter withholds joint state and says why, herbd names the fault (`RobotDisabled`,
/// `RobotEStop`, `MasterLost`) and commands nothing; the arm sags meanwhile (0.05 rad/s). Enabled
/// again (a new master on the same port), the job resumes, and the first command the fake
/// Baxter receives after each interruption is within 0.01 rad of where it sagged to. The
/// adapter never enables the robot again, and the gripper is calibrated with one `calibrate`.
#[test]
fn interruptions_halt_say_why_and_resume_without_a_jump() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-faults");
    let prefix = format!("ros{}faults", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir, Some(&generate_python_messages(&dir)));
    let master = ros.master("1");
    let report = dir.join("fake.json");
    // The robot starts disabled and herb-baxter enables it (--enable), once: the disable below
    // must not be undone by the adapter.
    let fake = fake_baxter(&ros, &report, 0, &["--start-disabled", "--calibrate-s=0.5"]);
    let adapter = adapter(&ros, &cfg, "1", &["--enable"]);
    let (spec, truth) = empty_box();
    let _camera = Camera::start(&ros, &cfg, &spec, &truth, 0, 0.0);
    let _hd = herbd(&cfg, &dir, &[]);
    let mut ctl = pack(&prefix, &["pack", "--objects", "003,005,011"], &dir);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/3", Duration::from_secs(60));
    for (signal, fault) in [
        (libc::SIGUSR1, "FAULT RobotDisabled"),
        (libc::SIGUSR2, "FAULT RobotEStop"),
    ] {
        std::thread::sleep(Duration::from_millis(700));
        fake.signal(signal); // disabled, or e-stopped
        out.wait_for(fault, Duration::from_secs(5));
        std::thread::sleep(Duration::from_secs(2)); // sagging
        fake.signal(signal); // enabled again (the e-stop released)
        out.wait_for("resumed", Duration::from_secs(10));
    }
    out.wait_for("object  2/3", Duration::from_secs(120));
    std::thread::sleep(Duration::from_millis(700));
    drop(master);
    out.wait_for("FAULT MasterLost", Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(1));
    let _master2 = ros.master("2");
    out.wait_for("resumed", Duration::from_secs(20));
    out.wait_for("placed: 3 of 3 objects", Duration::from_secs(180));
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 3, "{summary}");
    let a = adapter_summary(adapter);
    let f = fake_report(fake, &report);
    eprintln!("herbctl: {summary}\nherb-baxter: {a}\nfake Baxter: {f}");
    assert_eq!(f["enable_toggles"], 2, "{f}");
    assert_eq!(f["estop_toggles"], 2, "{f}");
    assert!(
        f["enable_requests"].as_u64().unwrap() >= 1,
        "enabled at start: {f}"
    );
    assert_eq!(
        f["enable_requests_after_toggle"], 0,
        "a disabled robot is not re-enabled by the adapter: {f}"
    );
    assert_eq!(f["out_of_limits"], 0, "{f}");
    assert_eq!(f["calibrate_commands"], 1, "calibrate sent once: {f}");
    // The first command after the start, after the disable, after the e-stop and after the
    // master loss (a pause in the commands: herbd halted), at least; each at the arm.
    let firsts: Vec<f64> = serde_json::from_value(f["first_command_offsets"].clone()).unwrap();
    assert!(firsts.len() >= 4, "{f}");
    for x in &firsts {
        assert!(*x <= 0.01, "a first command {x} rad from the arm: {f}");
    }
    assert_eq!(f["commands_far"], 0, "{f}");
    assert_eq!(a["ros"]["master_lost"], 1, "{a}");
    // The tracking lag measured: the largest offset of a sent command from the arm.
    let lag: Vec<f64> = serde_json::from_value(a["max_command_offset_rad"].clone()).unwrap();
    eprintln!("largest command offset per joint (rad): {lag:?}");
    let log = std::fs::read_to_string(dir.join("herb-baxter-1.log")).unwrap();
    for said in [
        "robot disabled",
        "robot e-stopped",
        "ROS master lost",
        "ROS master back",
        "robot ready",
    ] {
        assert!(log.contains(said), "{said}: {log}");
    }
}

/// The ROS master and the robot's node both restart between jobs: herb-baxter registers again
/// by itself (it is not restarted), and the next job packs. A missed grasp on the way is
/// retried.
#[test]
fn a_restarted_master_and_robot_are_found_again_and_the_next_job_packs() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-restart");
    let prefix = format!("ros{}restart", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir, Some(&generate_python_messages(&dir)));
    let master = ros.master("1");
    let report = dir.join("fake1.json");
    let fake = fake_baxter(&ros, &report, 0, &["--miss-grasps=1"]);
    let adapter = adapter(&ros, &cfg, "1", &[]);
    let (spec, truth) = empty_box();
    let mut camera = Camera::start(&ros, &cfg, &spec, &truth, 0, 0.0);
    let _hd = herbd(&cfg, &dir, &[]);
    let run = |objects: &str, n: usize| {
        let mut ctl = pack(&prefix, &["pack", "--objects", objects], &dir);
        let mut out = Follow::new(&mut ctl);
        out.wait_for(
            &format!("placed: {n} of {n} object"),
            Duration::from_secs(180),
        );
        let st = ctl.wait_for(Duration::from_secs(30));
        let summary = out.last_json().expect("herbctl's JSON summary");
        assert!(st.success(), "{summary}");
        assert_eq!(summary["placed"], n, "{summary}");
        summary
    };
    let first = run("003,005", 2);
    assert_eq!(
        first["faults"],
        serde_json::json!(["MissedGrasp"]),
        "{first}"
    );
    // Everything on the ROS side restarts: the master, the robot's node and the camera's node;
    // the adapters (herb-baxter, herb-camera) stay.
    let f1 = fake_report(fake, &report);
    assert_eq!(f1["missed_grasps"], 1, "{f1}");
    drop(master);
    std::thread::sleep(Duration::from_secs(1));
    let _master2 = ros.master("2");
    let report2 = dir.join("fake2.json");
    let fake2 = fake_baxter(&ros, &report2, 0, &[]);
    camera.restart_fake(&ros);
    for log in ["herb-baxter-1.log", "herb-camera.log"] {
        herb_testkit::wait_for_log(&dir.join(log), "registering again", Duration::from_secs(20));
    }
    run("011", 1);
    let a = adapter_summary(adapter);
    let f2 = fake_report(fake2, &report2);
    eprintln!("herb-baxter: {a}\nfake Baxter after the restart: {f2}");
    assert!(a["ros"]["reregistered"].as_u64().unwrap() >= 1, "{a}");
    assert!(f2["commands"].as_u64().unwrap() > 10, "{f2}");
    assert_eq!(f2["commands_far"], 0, "{f2}");
}

/// A real Baxter's joints droop while it is disabled, past herbd's limits: the fake Baxter
/// (enforcing the robot's own limits), disabled mid-job, sags its elbow (`left_e1`, 0.5 rad/s)
/// to the robot's limit, 0.05 rad past herbd's. Enabled again, the job resumes: herbd names the
/// joint (`OutsideLimits`, `left_e1 at ...`), brings it back inside slowly from where it stands
/// (the first command after the enable within 0.01 rad of the arm, none outside the robot's
/// limits, none far), and the job finishes.
#[test]
fn a_baxter_sagged_past_a_limit_while_disabled_resumes_and_finishes() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-sag");
    let prefix = format!("ros{}sag", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir, Some(&generate_python_messages(&dir)));
    let _master = ros.master("1");
    let report = dir.join("fake.json");
    let (lo, hi) = herb_robot::motion::baxter_left_arm_range();
    let list = |v: &[f64; 7]| v.map(|x| x.to_string()).join(",");
    let (lower, upper) = (
        format!("--lower={}", list(&lo)),
        format!("--upper={}", list(&hi)),
    );
    let fake = fake_baxter(
        &ros,
        &report,
        0,
        &[&lower, &upper, "--sag=1.0", "--sag-joints=3"],
    );
    let adapter = adapter(&ros, &cfg, "1", &[]);
    let (spec, truth) = empty_box();
    let _camera = Camera::start(&ros, &cfg, &spec, &truth, 0, 0.0);
    let _hd = herbd(&cfg, &dir, &[]);
    let mut ctl = pack(&prefix, &["pack", "--objects", "003,005"], &dir);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/2", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(700));
    fake.signal(libc::SIGUSR1); // disabled
    out.wait_for("FAULT RobotDisabled", Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(3)); // left_e1 sags to the robot's limit
    fake.signal(libc::SIGUSR1); // enabled again
    out.wait_for("left_e1 at 2.6180 rad", Duration::from_secs(10));
    let st = ctl.wait_for(Duration::from_secs(180));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 2, "{summary}");
    let a = adapter_summary(adapter);
    let f = fake_report(fake, &report);
    eprintln!("herbctl: {summary}\nherb-baxter: {a}\nfake Baxter: {f}");
    assert_eq!(f["out_of_limits"], 0, "{f}");
    assert_eq!(f["commands_far"], 0, "{f}");
    let firsts: Vec<f64> = serde_json::from_value(f["first_command_offsets"].clone()).unwrap();
    assert!(firsts.len() >= 2, "{f}");
    for x in &firsts {
        assert!(*x <= 0.01, "a first command {x} rad from the arm: {f}");
    }
    assert!(
        a["max_limit_excess_rad"].as_f64().unwrap() > 0.0,
        "commands came back from past herbd's limit: {a}"
    );
}
