//! The cell's processes as the harness runs them: herb-loopback and herbd (each restarted as
//! systemd would after a kill, each incarnation logging to a file of its own), and the client
//! that packs random BoxED episodes back to back with `herbctl`.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One of the cell's long-lived processes.
pub struct Daemon {
    /// The binary.
    exe: PathBuf,
    /// Its arguments.
    args: Vec<String>,
    /// Log files are `<out>/<name>-<incarnation>.log`.
    name: &'static str,
    out: PathBuf,
    /// The running process.
    pub child: Option<Child>,
    /// Incarnations started so far.
    pub incarnations: u32,
}

impl Daemon {
    /// A process of `exe` with `args`, logging into `out`; not started.
    pub fn new(exe: PathBuf, args: Vec<String>, name: &'static str, out: &Path) -> Self {
        Self {
            exe,
            args,
            name,
            out: out.to_owned(),
            child: None,
            incarnations: 0,
        }
    }

    /// Starts a new incarnation.
    pub fn start(&mut self) -> Result<(), String> {
        self.incarnations += 1;
        let log = self.log(self.incarnations);
        let err = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
        let out = std::fs::File::create(log.with_extension("out"))
            .map_err(|e| format!("{}: {e}", log.display()))?;
        let child = Command::new(&self.exe)
            .args(&self.args)
            .stdout(out)
            .stderr(err)
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", self.exe.display()))?;
        self.child = Some(child);
        Ok(())
    }

    /// The log of incarnation `n`.
    pub fn log(&self, n: u32) -> PathBuf {
        self.out.join(format!("{}-{n}.log", self.name))
    }

    /// Its process id, while it runs.
    pub fn pid(&self) -> Option<i32> {
        self.child.as_ref().map(|c| c.id() as i32)
    }

    /// Sends `sig`.
    pub fn signal(&self, sig: i32) {
        if let Some(pid) = self.pid() {
            // SAFETY: kill on a child we own.
            unsafe { libc::kill(pid, sig) };
        }
    }

    /// Kills it (SIGKILL) and reaps it.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// Stops it with SIGTERM, waiting up to `limit`; returns how long it took and its exit
    /// code (`None` when it had to be killed).
    pub fn terminate(&mut self, limit: Duration) -> (Duration, Option<i32>) {
        let t0 = Instant::now();
        let Some(mut c) = self.child.take() else {
            return (Duration::ZERO, None);
        };
        // SAFETY: kill on a child we own.
        unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
        while t0.elapsed() < limit {
            if let Ok(Some(st)) = c.try_wait() {
                return (t0.elapsed(), st.code());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = c.kill();
        let _ = c.wait();
        (t0.elapsed(), None)
    }

    /// Whether it has exited by itself (a crash): reaps it.
    pub fn exited(&mut self) -> Option<std::process::ExitStatus> {
        let st = self.child.as_mut()?.try_wait().ok()??;
        self.child = None;
        Some(st)
    }
}

/// One pack job the client ran.
#[derive(Debug, Clone)]
pub struct ClientRun {
    /// The BoxED episode.
    pub session: String,
    /// herbctl's exit code (`None`: killed).
    pub code: Option<i32>,
    /// Seconds it ran.
    pub seconds: f64,
}

/// The client: `herbctl pack --session` of random BoxED episodes back to back, `herbctl reset`
/// between them, on a thread of its own.
pub struct Client {
    /// herbctl's pid while a `pack` runs (0: none).
    pub pack_pid: Arc<AtomicI32>,
    /// Every pack run so far.
    pub runs: Arc<Mutex<Vec<ClientRun>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Client {
    /// Starts packing `sessions` (picked by `pick`) with `herbctl` under `prefix`.
    pub fn start(
        herbctl: PathBuf,
        prefix: String,
        out: &Path,
        sessions: Vec<String>,
        mut pick: impl FnMut(usize) -> usize + Send + 'static,
    ) -> Self {
        let pack_pid = Arc::new(AtomicI32::new(0));
        let runs = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let log = out.join("herbctl.log");
        let thread = {
            let (pack_pid, runs, stop) = (pack_pid.clone(), runs.clone(), stop.clone());
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let session = sessions[pick(sessions.len())].clone();
                    let t0 = Instant::now();
                    let code = run_logged(
                        &herbctl,
                        &[
                            "--prefix",
                            &prefix,
                            "pack",
                            "--session",
                            &session,
                            "--timeout",
                            "1800",
                        ],
                        &log,
                        Some(&pack_pid),
                    );
                    runs.lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push(ClientRun {
                            session,
                            code,
                            seconds: t0.elapsed().as_secs_f64(),
                        });
                    if stop.load(Ordering::Relaxed) {
                        break;
                    }
                    // Empty the box for the next episode (refused while a job still runs: an
                    // orphan of a killed client, which is waited for).
                    for _ in 0..60 {
                        if run_logged(&herbctl, &["--prefix", &prefix, "reset"], &log, None)
                            == Some(0)
                            || stop.load(Ordering::Relaxed)
                        {
                            break;
                        }
                        std::thread::sleep(Duration::from_secs(2));
                    }
                }
            })
        };
        Self {
            pack_pid,
            runs,
            stop,
            thread: Some(thread),
        }
    }

    /// Asks it to start no new pack (the current one runs on).
    pub fn stop_soon(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Stops after the current pack (the caller ends it, e.g. by a cancel).
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs `exe args` to its end, appending its output to `log`; its exit code (`None`: killed by
/// a signal or not started). `pid` holds its process id while it runs.
pub fn run_logged(exe: &Path, args: &[&str], log: &Path, pid: Option<&AtomicI32>) -> Option<i32> {
    let open = || {
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .ok()
    };
    let (Some(out), Some(err)) = (open(), open()) else {
        return None;
    };
    let mut child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(err)
        .spawn()
        .ok()?;
    if let Some(p) = pid {
        p.store(child.id() as i32, Ordering::Relaxed);
    }
    let st = child.wait().ok();
    if let Some(p) = pid {
        p.store(0, Ordering::Relaxed);
    }
    st?.code()
}

/// A process's resident memory (KiB) and open file descriptors, from /proc.
pub fn rss_and_fds(pid: i32) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let rss = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count() as u64;
    Some((rss, fds))
}
