//! Helpers for HERB's end-to-end tests with real processes: each test starts `herbd`, an
//! adapter and `herbctl` under its own service prefix, follows their output and stops them.
//! Test-only: no product crate depends on this one.

#![warn(missing_docs)]

use herb_robot::kinematics::LEFT_ARM;
use herb_robot::motion::JointLimits;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The repository's root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Binary `name` of package `package` in the running test's target folder (built by `cargo
/// test --workspace`; built here when a package is tested alone).
pub fn exe(name: &str, package: &str) -> PathBuf {
    let test = std::env::current_exe().expect("the test binary's path");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let p = test
        .parent()
        .and_then(Path::parent)
        .expect("a target folder")
        .join(name);
    if !p.exists() {
        let profile = if cfg!(debug_assertions) {
            vec![]
        } else {
            vec!["--release"]
        };
        let st = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
            .args(["build", "-p", package, "--bins"])
            .args(profile)
            .status()
            .expect("cargo runs");
        assert!(st.success(), "building {package} failed");
    }
    p
}

/// Joint limits for tests: the shipped position limits, and faster motion than the shipped
/// defaults (the URDF speed limits instead of 60 % of them, 3 x the accelerations and 6 x the
/// jerks) so an episode takes about a minute.
pub fn fast_limits() -> JointLimits {
    let mut l = JointLimits::baxter_left();
    l.velocity = LEFT_ARM.map(|j| j.max_velocity);
    l.acceleration = l.acceleration.map(|a| 3.0 * a);
    l.jerk = l.jerk.map(|j| 6.0 * j);
    l.validate_baxter_left()
        .expect("test limits within the URDF's");
    l
}

/// A herbd configuration for tests in `dir`: a unique prefix, placement `policy` (`blbf` or an
/// ONNX path), [`fast_limits`], 1 MB run-log segments, the job journal in `dir/state`.
pub fn config(dir: &Path, prefix: &str, policy: &str) -> PathBuf {
    #[derive(serde::Serialize)]
    struct Limits {
        limits: JointLimits,
    }
    let p = dir.join(format!("{prefix}.toml"));
    let limits = toml::to_string(&Limits {
        limits: fast_limits(),
    })
    .unwrap();
    let text = format!(
        r#"ipc_prefix = "{prefix}"
[loop]
report_interval_s = 5.0
[models]
sequence = "{seq}"
policy = "{policy}"
[record]
segment_mb = 1
keep_mb = 256
[journal]
dir = "{state}"
{limits}"#,
        seq = repo().join("models/sequence.json").display(),
        state = dir.join("state").display()
    );
    std::fs::write(&p, text).unwrap();
    p
}

/// A child process, killed when dropped.
pub struct Proc(pub Child);

impl Proc {
    /// Sends signal `sig`.
    pub fn signal(&self, sig: i32) {
        // SAFETY: kill on a child we own.
        unsafe { libc::kill(self.0.id() as i32, sig) };
    }

    /// Waits for the exit; panics after `limit`.
    pub fn wait_for(&mut self, limit: Duration) -> ExitStatus {
        let t0 = Instant::now();
        loop {
            if let Some(st) = self.0.try_wait().unwrap() {
                return st;
            }
            assert!(t0.elapsed() < limit, "process did not exit in {limit:?}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `exe` with `args` in the repository, stdout piped, stderr to `log`.
pub fn spawn(exe: &Path, args: &[&str], log: &Path) -> Proc {
    spawn_env(exe, args, &[], log)
}

/// [`spawn`] with extra environment variables.
pub fn spawn_env(exe: &Path, args: &[&str], env: &[(&str, &str)], log: &Path) -> Proc {
    let err = std::fs::File::create(log).unwrap();
    Proc(
        Command::new(exe)
            .args(args)
            .envs(env.iter().copied())
            .current_dir(repo())
            .stdout(Stdio::piped())
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", exe.display())),
    )
}

/// Lines of a child's stdout, as they come.
pub fn lines(p: &mut Proc) -> mpsc::Receiver<String> {
    let out = p.0.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    rx
}

/// A child's stdout lines, followed until an expected one appears.
pub struct Follow {
    /// The lines not yet read.
    pub rx: mpsc::Receiver<String>,
    /// The lines read so far.
    pub seen: Vec<String>,
}

impl Follow {
    /// Follows `p`'s stdout.
    pub fn new(p: &mut Proc) -> Self {
        Self {
            rx: lines(p),
            seen: Vec::new(),
        }
    }

    /// Waits for a line containing `what`; panics with everything seen after `limit`.
    pub fn wait_for(&mut self, what: &str, limit: Duration) {
        let t0 = Instant::now();
        while t0.elapsed() < limit {
            if let Ok(l) = self.rx.recv_timeout(Duration::from_millis(100)) {
                self.seen.push(l.clone());
                if l.contains(what) {
                    return;
                }
            }
        }
        panic!(
            "no {what:?} within {limit:?}; the process said:\n{}",
            self.seen.join("\n")
        );
    }

    /// The last JSON object printed (reads to the end of the stream, 200 ms at a time).
    pub fn last_json(&mut self) -> Option<serde_json::Value> {
        let mut v = None;
        for l in self.seen.iter().cloned().chain(std::iter::from_fn(|| {
            self.rx.recv_timeout(Duration::from_millis(200)).ok()
        })) {
            if let Ok(j) = serde_json::from_str::<serde_json::Value>(&l) {
                v = Some(j);
            }
        }
        v
    }
}

/// The value under `key` of the last JSON line on `rx` holding it (reads until 5 s pass with
/// no line); panics if none did.
pub fn last_json(rx: &mpsc::Receiver<String>, key: &str) -> serde_json::Value {
    let mut found = None;
    while let Ok(l) = rx.recv_timeout(Duration::from_secs(5)) {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&l)
            && v.get(key).is_some()
        {
            found = Some(v[key].clone());
        }
    }
    found.unwrap_or_else(|| panic!("no {key} line"))
}

/// The BoxED session with the fewest objects (ties: name) and its object count.
pub fn shortest_session(root: &Path) -> (String, usize) {
    let catalog =
        herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::None("t".into())).unwrap();
    let (sessions, _) = herb_sim::boxed::load_all(root, &catalog).unwrap();
    sessions
        .iter()
        .map(|s| {
            (
                s.episode(&catalog).objects.len(),
                s.episode(&catalog).name.clone(),
            )
        })
        .min()
        .map(|(n, name)| (name, n))
        .unwrap()
}

/// Waits until the file `log` contains `what`; panics with the file after `limit`.
pub fn wait_for_log(log: &Path, what: &str, limit: Duration) {
    let t0 = Instant::now();
    loop {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        if text.contains(what) {
            return;
        }
        assert!(
            t0.elapsed() < limit,
            "no {what:?} in {} within {limit:?}:\n{text}",
            log.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A test scene: the box floor with a 6 x 4 cm block 5 cm high and a 5 x 5 cm block 10 cm high.
pub fn two_blocks(spec: &herb_sim::GridSpec) -> Vec<f32> {
    let mut t = vec![0.0f32; spec.len()];
    for row in 0..spec.ny {
        for col in 0..spec.nx {
            let (x, y) = spec.cell_centre(col, row);
            let i = row * spec.nx + col;
            if (x + 0.08).abs() < 0.03 && (y - 0.03).abs() < 0.02 {
                t[i] = 0.05;
            }
            if (x - 0.07).abs() < 0.025 && (y + 0.04).abs() < 0.025 {
                t[i] = 0.10;
            }
        }
    }
    t
}

/// A heightmap `hm` against its `truth` (grid `spec`): panics if any cell is lower than the
/// truth by more than `tol` (a camera must never see a hole that is not there); returns how
/// many cells that `seen` holds for lie away from the truth's edges (the truth flat within 3
/// cells) and the largest absolute error among them.
pub fn compare_to_truth(
    spec: &herb_sim::GridSpec,
    truth: &[f32],
    hm: &[f32],
    seen: impl Fn(usize) -> bool,
    tol: f32,
) -> (usize, f32) {
    let (mut flat, mut worst, r) = (0usize, 0.0f32, 3usize);
    for row in 0..spec.ny {
        for col in 0..spec.nx {
            let i = row * spec.nx + col;
            assert!(
                hm[i] >= truth[i] - tol,
                "cell ({col}, {row}) {} below the truth {}",
                hm[i],
                truth[i]
            );
            let flat_here = row >= r
                && col >= r
                && row + r < spec.ny
                && col + r < spec.nx
                && (row - r..=row + r)
                    .all(|rr| (col - r..=col + r).all(|cc| truth[rr * spec.nx + cc] == truth[i]));
            if flat_here && seen(i) {
                flat += 1;
                worst = worst.max((hm[i] - truth[i]).abs());
            }
        }
    }
    (flat, worst)
}

/// A temporary folder for test `name` of this process.
pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("herb-e2e-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}
pub mod claims;
pub mod ros;
