//! A test's ROS 1 world: its own `rosmaster` on a free port and the environment its peers
//! share (Debian's ROS 1 packages; `scripts/install-ros1.sh`).

use crate::{Proc, spawn_env};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// The Python with rospy (Debian's; another `python3` may come first on PATH).
pub const PYTHON: &str = "/usr/bin/python3";

/// Whether rosmaster and rospy are here. Without them a test says it is skipped, except under
/// `CI=true`, where their absence fails it.
pub fn ros_available() -> bool {
    let master = Command::new("rosmaster").arg("--help").output().is_ok();
    let rospy = Command::new(PYTHON)
        .args([
            "-c",
            "import rospy, genpy, genmsg, numpy, std_msgs.msg, sensor_msgs.msg",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if master && rospy {
        return true;
    }
    let what =
        format!("rosmaster found: {master}, rospy and numpy importable by {PYTHON}: {rospy}");
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!(
            "ROS 1 is missing under CI=true ({what}); scripts/install-ros1.sh installs Debian's python3-rospy, python3-rosmaster, python3-genpy, python3-genmsg, python3-std-msgs, python3-sensor-msgs, python3-numpy"
        );
    }
    eprintln!("skipped: ROS 1 is not installed ({what})");
    false
}

/// A free TCP port on the loopback interface.
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// One test's ROS world: its folder, master port and the environment its peers share.
pub struct RosWorld {
    /// Logs and ROS_HOME go here.
    pub dir: PathBuf,
    /// The master's port.
    pub port: u16,
    env: Vec<(String, String)>,
    _slot: CoreSlot,
}

/// ROS worlds alive in this test process, and the signal that one ended.
static WORLDS: (Mutex<usize>, Condvar) = (Mutex::new(0), Condvar::new());

/// One of at most as many ROS worlds at once in a test process as the machine has cores, held
/// for the world's life. Their peers (rosmaster, rospy fakes, herbd's loop) are CPU-bound, and
/// `scripts/test.sh` runs one test thread more than the cores: with three worlds on two cores
/// the fake Baxter's joint states came late enough for herbd to fault `RobotSilent` (once in
/// four CI runs).
struct CoreSlot;

impl CoreSlot {
    fn take() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let (count, ended) = &WORLDS;
        let alive = count.lock().unwrap_or_else(|e| e.into_inner());
        let mut alive = ended
            .wait_while(alive, |n| *n >= cores)
            .unwrap_or_else(|e| e.into_inner());
        *alive += 1;
        Self
    }
}

impl Drop for CoreSlot {
    fn drop(&mut self) {
        let (count, ended) = &WORLDS;
        *count.lock().unwrap_or_else(|e| e.into_inner()) -= 1;
        ended.notify_one();
    }
}

impl RosWorld {
    /// A world in `dir` on a free port; `python_path`: extra modules for rospy peers. Waits while
    /// as many worlds as cores are alive in this process.
    pub fn new(dir: &Path, python_path: Option<&Path>) -> Self {
        let slot = CoreSlot::take();
        let port = free_port();
        let home = dir.join("roshome");
        std::fs::create_dir_all(&home).unwrap();
        let mut env = vec![
            ("ROS_MASTER_URI".into(), format!("http://127.0.0.1:{port}")),
            ("ROS_HOSTNAME".into(), "127.0.0.1".into()),
            ("ROS_HOME".into(), home.display().to_string()),
        ];
        if let Some(p) = python_path {
            env.push(("PYTHONPATH".into(), p.display().to_string()));
        }
        Self {
            dir: dir.into(),
            port,
            env,
            _slot: slot,
        }
    }

    /// The environment of the world's processes.
    pub fn env(&self) -> Vec<(&str, &str)> {
        self.env
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect()
    }

    /// The master's URI.
    pub fn uri(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// Starts a master on the world's port and waits until it accepts connections.
    pub fn master(&self, tag: &str) -> Proc {
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

    /// Starts rospy script `script` with `args` (its log `dir/<tag>.log`), and checks after
    /// `settle` that it is still running (a fixture that cannot start says so now, not as a
    /// timeout later).
    pub fn python(&self, script: &Path, args: &[String], tag: &str, settle: Duration) -> Proc {
        let mut all: Vec<&str> = vec![script.to_str().unwrap()];
        all.extend(args.iter().map(String::as_str));
        let log = self.dir.join(format!("{tag}.log"));
        let mut p = spawn_env(Path::new(PYTHON), &all, &self.env(), &log);
        std::thread::sleep(settle);
        if let Some(st) = p.0.try_wait().unwrap() {
            panic!(
                "{tag} exited ({st}): {}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
        }
        p
    }
}

/// A camera pose for tests (the optical frame in B: translation, quaternion x, y, z, w): 0.6 m
/// above the floor, 4 cm off centre, tilted 12 degrees about x and 5 about y.
pub const TEST_CAMERA_POSE: [f64; 7] = [
    0.04,
    -0.09,
    0.6,
    0.993575331,
    -0.004559468,
    -0.043380436,
    -0.104428975,
];

/// The fake depth camera (`hw/camera/tests/fake_camera.py`, a fixture) and herb-camera in
/// `ros`, showing `truth` (a heightmap of grid `spec`) from [`TEST_CAMERA_POSE`]; herb-camera
/// publishes under the prefix of herbd's configuration `cfg`.
pub struct Camera {
    /// The fake camera.
    pub fake: Proc,
    /// herb-camera.
    pub adapter: Proc,
    /// Where the fake writes the cells its image saw (one byte per cell).
    pub seen: PathBuf,
    /// Where the fake writes its report on SIGTERM.
    pub report: PathBuf,
    /// The fake's script and arguments (to restart it).
    fake_args: (PathBuf, Vec<String>),
}

impl Camera {
    /// Starts both; `bad_every` and `info_after_s` as in the fake's `--bad-every` and
    /// `--info-after`.
    pub fn start(
        ros: &RosWorld,
        cfg: &Path,
        spec: &herb_sim::GridSpec,
        truth: &[f32],
        bad_every: u32,
        info_after_s: f64,
    ) -> Self {
        use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS};
        let dir = &ros.dir;
        let truth_file = dir.join("truth.f32");
        let bytes: Vec<u8> = truth.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&truth_file, bytes).unwrap();
        let p = TEST_CAMERA_POSE;
        let cam_toml = dir.join("camera.toml");
        std::fs::write(
            &cam_toml,
            format!(
                "[pose]\ntranslation = [{}, {}, {}]\nrotation = [{}, {}, {}, {}]\n",
                p[0], p[1], p[2], p[3], p[4], p[5], p[6]
            ),
        )
        .unwrap();
        let (seen, report) = (dir.join("seen.u8"), dir.join("fake_camera.json"));
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| x.to_string())
                .collect::<Vec<_>>()
                .join(",")
        };
        let box_dims = [BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS].map(f64::from);
        let args = vec![
            format!("--truth={}", truth_file.display()),
            format!("--nx={}", spec.nx),
            format!("--ny={}", spec.ny),
            format!("--cell={}", spec.cell),
            format!("--box={}", list(&box_dims)),
            format!("--pose={}", list(&p)),
            format!("--seen={}", seen.display()),
            format!("--report={}", report.display()),
            format!("--bad-every={bad_every}"),
            format!("--info-after={info_after_s}"),
        ];
        let script = crate::repo().join("hw/camera/tests/fake_camera.py");
        let fake = ros.python(&script, &args, "fake_camera", Duration::from_millis(500));
        let fake_args = (script, args);
        let adapter = spawn_env(
            &crate::exe("herb-camera", "herb-camera"),
            &[
                "--config",
                cfg.to_str().unwrap(),
                "--camera",
                cam_toml.to_str().unwrap(),
                "--master-uri",
                &ros.uri(),
            ],
            &ros.env(),
            &dir.join("herb-camera.log"),
        );
        Self {
            fake,
            adapter,
            seen,
            report,
            fake_args,
        }
    }

    /// Stops the fake camera and starts it again in `ros` (a camera node restarted with its
    /// master); herb-camera keeps running.
    pub fn restart_fake(&mut self, ros: &RosWorld) {
        self.fake.signal(libc::SIGTERM);
        let _ = self.fake.wait_for(Duration::from_secs(10));
        let (script, args) = &self.fake_args;
        self.fake = ros.python(script, args, "fake_camera2", Duration::from_millis(500));
    }
}
