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

use herb_adapter::{CameraPort, Heightmap};
use herb_ipc::bus::Bus;
use herb_ipc::{Services, monotonic_ns};
use herb_robot::kinematics::LEFT_TOP_DOWN_NOMINAL;
use herb_testkit::{
    Follow, Proc, config, exe, fast_limits, last_json, lines, repo, spawn, spawn_env, tmp,
};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const PYTHON: &str = "/usr/bin/python3";

/// Whether rosmaster and rospy are here; under `CI=true` their absence fails the test.
fn ros_available() -> bool {
    let master = Command::new("rosmaster").arg("--help").output().is_ok();
    let rospy = Command::new(PYTHON)
        .args([
            "-c",
            "import rospy, genpy, genmsg, std_msgs.msg, sensor_msgs.msg",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if master && rospy {
        return true;
    }
    let what = format!("rosmaster found: {master}, rospy importable by {PYTHON}: {rospy}");
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!(
            "ROS 1 is missing under CI=true ({what}); .ci/run installs Debian's python3-rospy, python3-rosmaster, python3-genpy, python3-genmsg, python3-std-msgs, python3-sensor-msgs"
        );
    }
    eprintln!("skipped: ROS 1 is not installed ({what})");
    false
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// One test's ROS world: its folder, master port and the environment its peers share.
struct RosWorld {
    dir: PathBuf,
    port: u16,
    env: Vec<(String, String)>,
}

impl RosWorld {
    fn new(dir: &Path) -> Self {
        let port = free_port();
        let home = dir.join("roshome");
        std::fs::create_dir_all(&home).unwrap();
        let py = generate_python_messages(dir);
        let env = vec![
            ("ROS_MASTER_URI".into(), format!("http://127.0.0.1:{port}")),
            ("ROS_HOSTNAME".into(), "127.0.0.1".into()),
            ("ROS_HOME".into(), home.display().to_string()),
            ("PYTHONPATH".into(), py.display().to_string()),
        ];
        Self {
            dir: dir.into(),
            port,
            env,
        }
    }

    fn env(&self) -> Vec<(&str, &str)> {
        self.env
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect()
    }

    fn uri(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// Starts a master on the world's port and waits until it accepts connections.
    fn master(&self, tag: &str) -> Proc {
        let p = self.port.to_string();
        let m = spawn_env(
            Path::new("rosmaster"),
            &["--core", "-p", &p],
            &self.env(),
            &self.dir.join(format!("rosmaster-{tag}.log")),
        );
        let t0 = Instant::now();
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(
                t0.elapsed() < Duration::from_secs(15),
                "rosmaster did not start"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        m
    }

    fn fake_baxter(&self, report: &Path, corrupt_every: u32) -> Proc {
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
        let mut args: Vec<&str> = args.iter().map(String::as_str).collect();
        args.insert(0, script.to_str().unwrap());
        let log = self.dir.join("fake_baxter.log");
        let mut p = spawn_env(Path::new(PYTHON), &args, &self.env(), &log);
        // A fake that cannot start (arguments, imports) says so now, not as a timeout later.
        std::thread::sleep(Duration::from_millis(1500));
        if let Some(st) = p.0.try_wait().unwrap() {
            panic!(
                "fake Baxter exited ({st}): {}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
        }
        p
    }

    fn adapter(&self, cfg: &Path, tag: &str) -> Proc {
        spawn_env(
            Path::new(env!("CARGO_BIN_EXE_herb-baxter")),
            &[
                "--config",
                cfg.to_str().unwrap(),
                "--master-uri",
                &self.uri(),
            ],
            &self.env(),
            &self.dir.join(format!("herb-baxter-{tag}.log")),
        )
    }
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

/// The fixture camera: the empty box's heightmap under `prefix` every 100 ms until dropped.
struct FixtureCamera {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl FixtureCamera {
    fn start(prefix: &str) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let (s, prefix) = (stop.clone(), prefix.to_string());
        let thread = std::thread::spawn(move || {
            let catalog =
                herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::None("fixture".into()))
                    .unwrap();
            let world =
                herb_sim::PackingWorld::new(Arc::new(catalog), herb_sim::WorldConfig::default())
                    .unwrap();
            let hm = world.heightmap();
            let services = Services::new(&prefix).unwrap();
            let bus = Bus::open("fixture-camera", &services).unwrap();
            let camera = CameraPort::open(&bus).unwrap();
            let mut seq = 0;
            while !s.load(Ordering::Relaxed) {
                seq += 1;
                let frame = Heightmap {
                    stamp_ns: monotonic_ns(),
                    nx: hm.spec().nx as u32,
                    ny: hm.spec().ny as u32,
                    cell_m: hm.spec().cell,
                    objects: 0,
                    cells: hm.data(),
                };
                camera.publish(seq, &frame).unwrap();
                std::thread::sleep(Duration::from_millis(100));
            }
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for FixtureCamera {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn herbd(cfg: &Path, dir: &Path) -> Proc {
    spawn(
        &exe("herbd", "herb-daemon"),
        &["--config", cfg.to_str().unwrap()],
        &dir.join("herbd.log"),
    )
}

fn pack(prefix: &str, objects: &str, dir: &Path) -> Proc {
    spawn(
        &exe("herbctl", "herb-daemon"),
        &[
            "--prefix",
            prefix,
            "pack",
            "--objects",
            objects,
            "--json",
            "--timeout",
            "300",
        ],
        &dir.join("herbctl.log"),
    )
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

/// Three objects packed through ROS: every one decided and placed, every joint command sent
/// to the robot within the limits and addressed to the left arm's joints by name, the gripper
/// calibrated once then closed and opened once per object, the command timeout latched; one
/// joint state in 25 is bad (NaN, misspelt name, short array): each is refused and counted by
/// herb-baxter and never reaches herbd.
#[test]
fn packs_through_ros_with_a_fake_baxter() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-pack");
    let prefix = format!("ros{}pack", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir);
    let _master = ros.master("1");
    let report = dir.join("fake.json");
    let fake = ros.fake_baxter(&report, 25);
    let adapter = ros.adapter(&cfg, "1");
    let _camera = FixtureCamera::start(&prefix);
    let mut hd = herbd(&cfg, &dir);
    let mut ctl = pack(&prefix, "003,005,011", &dir);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("placed 3/3", Duration::from_secs(240));
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 3, "{summary}");
    assert_eq!(summary["decisions"], 3, "{summary}");
    let faults = summary["faults"].as_array().map_or(0, |f| f.len());
    assert_eq!(faults, 0, "no fault: {summary}");

    let hd_lines = lines(&mut hd);
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let stats = last_json(&hd_lines, "herbd_final");
    let a = adapter_summary(adapter);
    let f = fake_report(fake, &report);
    eprintln!("herbctl: {summary}\nherbd: {stats}\nherb-baxter: {a}\nfake Baxter: {f}");
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
        serde_json::json!(["close", "open", "close", "open", "close", "open"]),
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

/// The robot disabled mid-motion (its assembly state says so): herb-baxter withholds joint
/// state, herbd faults, brakes and reports; enabled again, the job resumes. Then the master
/// dies mid-motion: the same, and a new master on the same port lets the job finish.
#[test]
fn a_disabled_robot_or_a_lost_master_brakes_and_the_job_resumes() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-faults");
    let prefix = format!("ros{}faults", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let ros = RosWorld::new(&dir);
    let master = ros.master("1");
    let report = dir.join("fake.json");
    let fake = ros.fake_baxter(&report, 0);
    let adapter = ros.adapter(&cfg, "1");
    let _camera = FixtureCamera::start(&prefix);
    let _hd = herbd(&cfg, &dir);
    let mut ctl = pack(&prefix, "003,005,011", &dir);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/3", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(700));
    fake.signal(libc::SIGUSR1); // disabled
    out.wait_for("FAULT JointStateTimeout", Duration::from_secs(5));
    out.wait_for("braked", Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(1));
    fake.signal(libc::SIGUSR1); // enabled
    out.wait_for("resumed", Duration::from_secs(10));
    out.wait_for("object  2/3", Duration::from_secs(120));
    std::thread::sleep(Duration::from_millis(700));
    drop(master);
    out.wait_for("FAULT JointStateTimeout", Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(1));
    let _master2 = ros.master("2");
    out.wait_for("resumed", Duration::from_secs(10));
    out.wait_for("placed 3/3", Duration::from_secs(180));
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 3, "{summary}");
    let a = adapter_summary(adapter);
    let f = fake_report(fake, &report);
    eprintln!("herbctl: {summary}\nherb-baxter: {a}\nfake Baxter: {f}");
    assert_eq!(f["enable_toggles"], 2, "{f}");
    assert_eq!(f["out_of_limits"], 0, "{f}");
    assert_eq!(a["ros"]["master_lost"], 1, "{a}");
    let log = std::fs::read_to_string(dir.join("herb-baxter-1.log")).unwrap();
    for said in [
        "robot disabled",
        "ROS master lost",
        "ROS master back",
        "robot ready",
    ] {
        assert!(log.contains(said), "{said}: {log}");
    }
}
