//! herbd's systemd notify protocol, without systemd: the test binds its own `NOTIFY_SOCKET`
//! (a Unix datagram socket, as systemd does), starts a real herbd on it and reads what arrives.
//!
//! 1. `READY=1` once herbd is up; `WATCHDOG=1` several times a second while its loop runs; none
//!    while the process is stopped (SIGSTOP: no cycle, no ping); again after SIGCONT;
//!    `STOPPING=1` after SIGTERM, and a clean exit.
//! 2. A `NOTIFY_SOCKET` nobody listens on: the failure is logged once, not per notification
//!    and not dropped, and herbd runs on.

use herb_testkit::{Proc, config, spawn_env, tmp};
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// `herbd` (built when this package is tested alone).
fn herbd() -> PathBuf {
    herb_testkit::exe("herbd", "herb-daemon")
}

/// The notifications that arrive on `sock` within `window`, with their arrival times.
fn collect(sock: &UnixDatagram, window: Duration) -> Vec<(Instant, String)> {
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    let t0 = Instant::now();
    while t0.elapsed() < window {
        sock.set_read_timeout(Some((window - t0.elapsed()).max(Duration::from_millis(1))))
            .unwrap();
        if let Ok(n) = sock.recv(&mut buf) {
            for line in String::from_utf8_lossy(&buf[..n]).lines() {
                out.push((Instant::now(), line.to_owned()));
            }
        }
    }
    out
}

/// Waits up to `limit` for `what` on `sock`; returns what came before it too.
fn wait_for(sock: &UnixDatagram, what: &str, limit: Duration) -> Vec<String> {
    let mut seen = Vec::new();
    let t0 = Instant::now();
    let mut buf = [0u8; 512];
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    while t0.elapsed() < limit {
        if let Ok(n) = sock.recv(&mut buf) {
            for line in String::from_utf8_lossy(&buf[..n]).lines() {
                seen.push(line.to_owned());
                if line == what {
                    return seen;
                }
            }
        }
    }
    panic!("no {what} within {limit:?}; received {seen:?}");
}

/// A herbd under its own prefix, configured in test folder `dir` (named `name`), told to
/// notify `socket`; its stderr goes to `herbd.log` in `dir`.
fn start_herbd(dir: &Path, name: &str, socket: &Path) -> Proc {
    let prefix = format!("herb_{}_{}", name.replace('-', "_"), std::process::id());
    let cfg = config(dir, &prefix, "blbf");
    spawn_env(
        &herbd(),
        &["--config", cfg.to_str().unwrap()],
        &[("NOTIFY_SOCKET", socket.to_str().unwrap())],
        &dir.join("herbd.log"),
    )
}

fn count(msgs: &[(Instant, String)], what: &str) -> usize {
    msgs.iter().filter(|(_, m)| m == what).count()
}

#[test]
fn herbd_speaks_the_notify_protocol_and_the_watchdog_follows_the_loop() {
    let dir = tmp("notify");
    let sock_path = dir.join("notify.sock");
    let _ = std::fs::remove_file(&sock_path);
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    let mut d = start_herbd(&dir, "notify", &sock_path);
    wait_for(&sock, "READY=1", Duration::from_secs(60));

    // Running: the reporter pings every 20 ms while the loop's cycle counter advances.
    let running = collect(&sock, Duration::from_secs(1));
    assert!(
        count(&running, "WATCHDOG=1") >= 10,
        "few watchdog pings while running: {running:?}"
    );

    // Stopped: no cycle, no ping (what was queued before the stop is drained first).
    d.signal(libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(100));
    collect(&sock, Duration::from_millis(50));
    let stopped = collect(&sock, Duration::from_millis(1500));
    d.signal(libc::SIGCONT);
    assert_eq!(
        count(&stopped, "WATCHDOG=1"),
        0,
        "watchdog pinged while the process was stopped: {stopped:?}"
    );
    wait_for(&sock, "WATCHDOG=1", Duration::from_secs(2));

    // SIGTERM: STOPPING=1, then a clean exit.
    d.signal(libc::SIGTERM);
    wait_for(&sock, "STOPPING=1", Duration::from_secs(10));
    let st = d.wait_for(Duration::from_secs(15));
    let log = std::fs::read_to_string(dir.join("herbd.log")).unwrap_or_default();
    assert!(st.success(), "herbd exited with {st:?}; log:\n{log}");
    assert!(
        !log.contains("event=notify_fail"),
        "no notification should have failed; log:\n{log}"
    );
}

#[test]
fn a_failing_notify_socket_is_logged_once_and_herbd_runs_on() {
    // A socket path nobody listens on: every notification fails.
    let dir = tmp("notify-dead");
    let dead = dir.join("nobody.sock");
    let _ = std::fs::remove_file(&dead);
    let mut d = start_herbd(&dir, "notify-dead", &dead);
    let log_path = dir.join("herbd.log");
    // Long enough for READY and dozens of watchdog pings to fail.
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(60) {
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        if log.contains("WATCHDOG=1") {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(1000));
    assert!(
        d.0.try_wait().unwrap().is_none(),
        "herbd must run on when notifications fail"
    );
    d.signal(libc::SIGTERM);
    let st = d.wait_for(Duration::from_secs(15));
    let log = std::fs::read_to_string(&log_path).unwrap();
    assert!(st.success(), "herbd exited with {st:?}; log:\n{log}");
    let first_failures: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("event=notify_failed "))
        .collect();
    // READY=1, WATCHDOG=1 and STOPPING=1 each fail; each is logged once.
    for notice in ["READY=1", "WATCHDOG=1", "STOPPING=1"] {
        assert_eq!(
            first_failures.iter().filter(|l| l.contains(notice)).count(),
            1,
            "{notice} failure not logged exactly once; log:\n{log}"
        );
    }
    // The final report counts the watchdog's many failures.
    let counted = log
        .lines()
        .find(|l| l.contains("event=notify_failures notice=\"WATCHDOG=1\""))
        .unwrap_or_else(|| panic!("no failure count at the end; log:\n{log}"));
    let n: u64 = counted
        .split_whitespace()
        .find_map(|w| w.strip_prefix("failed=")?.parse().ok())
        .unwrap();
    assert!(n > 10, "watchdog failures counted: {n}");
}
