//! End to end with real processes: `herbd`, `herb-loopback` and `herbctl` talk over iceoryx2
//! (each test under its own service prefix). One test binary; the tests are grouped by what
//! they exercise, and the helpers every group shares live here:
//!
//! - [`pack`]: an episode packed with each decision method, and the README's demo script;
//! - [`faults`]: the adapters' and clients' faults and bad input, refused, counted, survived;
//! - [`daemon`]: herbd killed, stopped, restarted on its journal, or started twice;
//! - [`jobs`]: jobs one after another (cancels, resets, missed grasps, the operator's close);
//! - [`arm`]: a sagged, disabled or out-of-limit arm.

use herb_client::{Client, JobEvent, SubmitError};
use herb_testkit::{Follow, Proc, config, last_json, lines, repo, shortest_session, spawn, tmp};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

mod arm;
mod daemon;
mod faults;
mod jobs;
mod pack;

fn loopback_exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_herb-loopback"))
}

/// `herbd` / `herbctl` (built when this package is tested alone).
fn exe(name: &str) -> PathBuf {
    let package = if name == "herbctl" {
        "herbctl"
    } else {
        "herb-daemon"
    };
    herb_testkit::exe(name, package)
}

/// `herbctl pack --objects <objects>` under `prefix`, logging to `dir/herbctl.log`.
fn pack_objects(dir: &Path, prefix: &str, objects: &str, timeout_s: u32, json: bool) -> Proc {
    let timeout = timeout_s.to_string();
    let mut args = vec!["--prefix", prefix, "pack", "--objects", objects];
    if json {
        args.push("--json");
    }
    args.extend(["--timeout", &timeout]);
    spawn(&exe("herbctl"), &args, &dir.join("herbctl.log"))
}

/// Runs herbctl under `prefix` to its end (it gives up on its own): exit status, stdout and
/// stderr.
fn herbctl_output(prefix: &str, args: &[&str]) -> (ExitStatus, String) {
    let o = Command::new(exe("herbctl"))
        .args(["--prefix", prefix])
        .args(args)
        .current_dir(repo())
        .output()
        .expect("herbctl runs");
    let text = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    (o.status, text)
}

/// Runs one of herbd's offline tools (`replay`, `explain`) to its end: exit status, stdout and
/// stderr.
fn herbd_output(args: &[&str]) -> (ExitStatus, String) {
    let o = Command::new(exe("herbd"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("herbd runs");
    let text = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    (o.status, text)
}

/// A client of the herbd under `prefix` (its status subscribed now).
fn client(prefix: &str) -> Client {
    Client::connect_as(prefix, "e2e-test").unwrap()
}

/// herbd's count of rejected sensor inputs from the heartbeats `client` receives: the newest
/// one once `done` holds for it, or after 5 s (panics if no heartbeat came at all).
fn rejected_inputs(client: &Client, done: impl Fn(u64) -> bool) -> u64 {
    heartbeat_count(client, |s| s.rejected_inputs, done)
}

/// [`rejected_inputs`] for `count` of the heartbeat (e.g. the refused requests).
fn heartbeat_count(
    client: &Client,
    count: impl Fn(&herb_ipc::Status) -> u64,
    done: impl Fn(u64) -> bool,
) -> u64 {
    let heartbeat = herb_ipc::StatusEvent::Heartbeat as u32;
    let mut counted = None;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(5) && !counted.is_some_and(&done) {
        for s in client.statuses().filter(|s| s.event == heartbeat) {
            counted = Some(count(&s));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    counted.expect("herbd heartbeats")
}

/// The loopback and herbd on configuration `cfg`, logging into `dir`; they run while the
/// handles live.
fn start_cell(dir: &Path, cfg: &Path) -> (Proc, Proc) {
    let cfg = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg],
        &dir.join("loopback.log"),
    );
    let hd = spawn(&exe("herbd"), &["--config", cfg], &dir.join("herbd.log"));
    (lb, hd)
}

/// A temporary folder, a unique prefix and a configuration (BLBF placements) for test `tag`.
fn setup(tag: &str) -> (PathBuf, String, PathBuf) {
    setup_with(tag, "blbf")
}

/// [`setup`] with the given placement policy.
fn setup_with(tag: &str, policy: &str) -> (PathBuf, String, PathBuf) {
    let dir = tmp(tag);
    let prefix = format!("e2e{}{tag}", std::process::id());
    let cfg = config(&dir, &prefix, policy);
    (dir, prefix, cfg)
}

/// Reads the loopback's final summary after SIGTERM.
fn loopback_summary(mut lb: Proc) -> serde_json::Value {
    let rx = lines(&mut lb);
    lb.signal(libc::SIGTERM);
    assert!(lb.wait_for(Duration::from_secs(10)).success());
    last_json(&rx, "loopback_final")
}
