//! End to end with real processes: `herbd`, `herb-loopback` and `herbctl` talk over iceoryx2
//! (each test under its own service prefix).
//!
//! 1. A BoxED episode (the session with the fewest objects) is packed: every placement is
//!    made, no joint command left the configured limits (the loopback checks each one), and
//!    the loop reported its deadline misses (herbd's final statistics and herbctl's summary).
//! 2. The loopback is killed mid-motion: the daemon reports the joint-state timeout, brakes,
//!    holds, and resumes the job when the loopback is restarted; the job completes.

use herb_client::{Client, JobEvent, SubmitError};
use herb_testkit::{Follow, Proc, config, last_json, lines, repo, shortest_session, spawn, tmp};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

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

/// With the shipped SAC policy (CS0.6, `[decision] method = "policy"`): herbd loads it and
/// decides every placement with it; the other tests decide by herbd's default, the search.
#[test]
fn packs_a_boxed_episode_end_to_end_with_real_processes() {
    pack_shortest_episode_with("episode", &repo().join("models/policy-cs06.onnx"));
}

/// The README's main command, `scripts/demo.sh`, as a newcomer runs it (on the shortest
/// session, with the binaries this test run built): it packs the episode, prints the verdict
/// and writes its picture and logs into its run folder.
#[test]
fn the_readme_demo_script_packs_an_episode() {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let bin = loopback_exe().parent().unwrap().to_owned();
    herb_testkit::exe("herbd", "herb-daemon");
    herb_testkit::exe("herbctl", "herbctl");
    let out = tmp("demo-script");
    let run = std::process::Command::new("bash")
        .arg(repo().join("scripts/demo.sh"))
        .arg(&session)
        .env("DEMO_BIN", &bin)
        .env("DEMO_OUT", &out)
        .env("HERB_BOXED", &root)
        .output()
        .expect("bash runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains(&format!("verdict: SUCCESS: {n}/{n} placed")),
        "{stdout}"
    );
    assert!(out.join("pack.png").is_file(), "{}", out.display());
    assert!(
        stdout.contains("herbd:") && stdout.contains("loopback:"),
        "{stdout}"
    );
}

/// With a policy of the candidate contract (the export fixture `candidates-smoke.onnx`, a
/// fixture, not a trained policy): herbd loads it through the same factory, gives it the rest
/// of the job, and decides every placement of the episode with it.
#[test]
fn packs_a_boxed_episode_with_a_candidate_policy() {
    pack_shortest_episode_with(
        "candidates",
        &repo().join("models/fixtures/candidates-smoke.onnx"),
    );
}

/// Packs the shortest BoxED episode with herbd placing by `policy`, and checks the job, the
/// loop's and the loopback's reports.
fn pack_shortest_episode_with(tag: &str, policy: &Path) {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let (dir, prefix, cfg) = setup_with(tag, policy.to_str().unwrap());
    // The policy decides, not the default search.
    let mut text = std::fs::read_to_string(&cfg).unwrap();
    text.push_str("\n[decision]\nmethod = \"policy\"\n");
    std::fs::write(&cfg, text).unwrap();
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let boxed = root.to_str().unwrap();
    let mut lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("loopback.log"),
    );
    let mut hd = spawn(
        &exe("herbd"),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("herbd.log"),
    );
    let picture = dir.join("pack.png");
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "--boxed",
            boxed,
            "pack",
            "--session",
            &session,
            "--json",
            "--timeout",
            "600",
            "--picture",
            picture.to_str().unwrap(),
        ],
        &dir.join("herbctl.log"),
    );
    let ctl_lines = lines(&mut ctl);
    let st = ctl.wait_for(Duration::from_secs(660));
    let summary = {
        let mut v = None;
        while let Ok(l) = ctl_lines.try_recv() {
            if let Ok(j) = serde_json::from_str::<serde_json::Value>(&l) {
                v = Some(j);
            }
        }
        v.expect("herbctl printed its JSON summary")
    };
    assert!(st.success(), "herbctl failed: {summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    assert_eq!(
        summary["placed"], n as u64,
        "every placement made: {summary}"
    );
    assert_eq!(summary["decisions"], n as u64);
    assert!(summary["deadline_misses"].is_u64(), "{summary}");
    assert!(picture.exists(), "picture of the final pack");

    let (hd_lines, lb_lines) = (lines(&mut hd), lines(&mut lb));
    hd.signal(libc::SIGTERM);
    assert!(
        hd.wait_for(Duration::from_secs(10)).success(),
        "herbd exits 0 on SIGTERM"
    );
    let stats = last_json(&hd_lines, "herbd_final");
    assert!(stats["cycles"].as_u64().unwrap() > 1000, "{stats}");
    assert!(
        stats["deadline_misses"].is_u64(),
        "the loop reports its deadline misses: {stats}"
    );
    assert_eq!(stats["decision_us"]["n"], n as u64);
    let log = std::fs::read_to_string(dir.join("herbd.log")).unwrap();
    let file = policy.file_name().unwrap().to_string_lossy();
    assert!(log.contains(&*file), "herbd ran {file}:\n{log}");
    lb.signal(libc::SIGTERM);
    assert!(lb.wait_for(Duration::from_secs(10)).success());
    let sim = last_json(&lb_lines, "loopback_final");
    assert!(sim["commands"].as_u64().unwrap() > 1000, "{sim}");
    assert_eq!(
        sim["commands_rejected"], 0,
        "every command within limits: {sim}"
    );
    assert_eq!(sim["max_limit_excess_rad"], 0.0, "{sim}");
    assert_eq!(sim["releases"], n as u64, "{sim}");
    assert_eq!(sim["world_error"], serde_json::Value::Null);
    eprintln!("episode {session} ({n} objects): {summary}\nherbd: {stats}\nloopback: {sim}");
    claims.check();
}

/// With the search deciding in the job's twin (herbd's default method and twin, a short
/// budget, its rollouts on two threads): the episode is packed with every decision made while
/// the arm picks, the run log replays bit for bit (each search re-run with the rollouts its
/// budget allowed, the job's twin rebuilt from the recorded decisions and heightmaps), and
/// `herbd explain` lists the candidates the search tried and the threads they ran on.
#[test]
fn packs_an_episode_with_the_search_and_replays_it_bit_for_bit() {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let (dir, prefix, cfg) = setup("search");
    let mut text = std::fs::read_to_string(&cfg).unwrap();
    // The rollouts on two threads: what the budget allowed replays alike whatever the timing.
    text.push_str("\n[decision]\nmethod = \"search\"\nbudget_s = 0.3\nk = 4\nthreads = 2\n");
    std::fs::write(&cfg, text).unwrap();
    let (cfg_s, boxed) = (cfg.to_str().unwrap(), root.to_str().unwrap());
    let runs = dir.join("runs");
    let _lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("loopback.log"),
    );
    let mut hd = spawn(
        &exe("herbd"),
        &[
            "--config",
            cfg_s,
            "--boxed",
            boxed,
            "--record",
            runs.to_str().unwrap(),
        ],
        &dir.join("herbd.log"),
    );
    let (st, out) = herbctl_output(
        &prefix,
        &[
            "--boxed",
            boxed,
            "pack",
            "--session",
            &session,
            "--json",
            "--timeout",
            "600",
        ],
    );
    let summary: serde_json::Value = out
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .unwrap_or_else(|| panic!("a JSON summary: {out}"));
    assert!(st.success(), "{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    assert_eq!(summary["placed"], n as u64, "{summary}");
    assert_eq!(summary["decisions"], n as u64, "{summary}");
    assert!(
        summary["decision_wait_s"].as_f64().unwrap() >= 0.0,
        "{summary}"
    );
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    logs.sort();
    let log = logs[0].to_str().unwrap();
    let (st, out) = herbd_output(&["--boxed", boxed, "replay", log]);
    assert!(st.success(), "{out}");
    assert!(out.contains("reproduced bit for bit"), "{out}");
    assert!(out.contains(&format!("{n} decisions")), "{out}");
    let pictures = dir.join("explain");
    let (st, out) = herbd_output(&[
        "--boxed",
        boxed,
        "explain",
        log,
        "--object",
        "1",
        "--out",
        pictures.to_str().unwrap(),
    ]);
    assert!(st.success(), "{out}");
    for want in [
        "method: search",
        "feasible candidates",
        "rollout",
        "on 2 threads",
        "placement",
    ] {
        assert!(out.contains(want), "{want}: {out}");
    }
}

#[test]
fn killing_the_loopback_mid_motion_brakes_reports_and_resumes() {
    let (dir, prefix, cfg) = setup("kill");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let lb_log = dir.join("loopback.log");
    let mut lb = spawn(&loopback_exe(), &["--config", cfg_s], &lb_log);
    let runs = dir.join("runs");
    let mut hd = spawn(
        &exe("herbd"),
        &["--config", cfg_s, "--record", runs.to_str().unwrap()],
        &dir.join("herbd.log"),
    );
    let mut ctl = pack_objects(&dir, &prefix, "003,005,011", 300, true);
    let mut ctl_out = Follow::new(&mut ctl);
    // The first object is decided; the arm is on its way: kill the arm.
    ctl_out.wait_for("object  1/3", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(700));
    lb.0.kill().unwrap();
    lb.0.wait().unwrap();
    ctl_out.wait_for("FAULT JointStateTimeout", Duration::from_secs(5));
    ctl_out.wait_for("halted", Duration::from_secs(5));
    // Holding while the arm is away.
    std::thread::sleep(Duration::from_secs(1));
    let _lb2 = spawn(
        &loopback_exe(),
        &["--config", cfg_s],
        &dir.join("loopback2.log"),
    );
    ctl_out.wait_for("resumed", Duration::from_secs(10));
    ctl_out.wait_for("placed: 3 of 3 objects", Duration::from_secs(120));
    let st = ctl.wait_for(Duration::from_secs(30));
    let mut summary = None;
    while let Ok(l) = ctl_out.rx.recv_timeout(Duration::from_millis(200)) {
        if let Ok(j) = serde_json::from_str::<serde_json::Value>(&l) {
            summary = Some(j);
        }
    }
    let summary = summary.expect("JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 3);
    let faults: Vec<String> = serde_json::from_value(summary["faults"].clone()).unwrap();
    assert!(
        faults.contains(&"JointStateTimeout".to_string()),
        "{summary}"
    );

    // The run log: replayed offline, bit for bit, brake, fault and resume
    // included; object 1 explained.
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    logs.sort();
    // The job is in the first segment (the test configuration's 1 MB segments close between
    // jobs: after it, a second one may have started).
    let log = logs[0].to_str().unwrap();
    let (st, out) = herbd_output(&["replay", log]);
    assert!(st.success(), "{out}");
    assert!(out.contains("reproduced bit for bit"), "{out}");
    // Three objects, and a new decision when one was started over after the resume.
    let decisions: u32 = out
        .split(" decisions")
        .next()
        .and_then(|h| h.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("a decision count");
    assert!((3..=4).contains(&decisions), "{out}");
    // A replay with other shapes (primitives instead of the BoxED meshes the run used) is
    // refused, and with --force it diverges at the first plan and says so.
    if herb_sim::paths::boxed_root_for_tests().is_some_and(|b| b.join("meshes").is_dir()) {
        let elsewhere = ["--boxed", "/nonexistent", "replay", log];
        let (st, out) = herbd_output(&elsewhere);
        assert_eq!(st.code(), Some(2), "{out}");
        assert!(out.contains("catalog"), "{out}");
        let (st, out) = herbd_output(&[&elsewhere[..], &["--force"]].concat());
        assert_eq!(st.code(), Some(1), "{out}");
        assert!(
            out.contains("DIVERGED") && out.contains("planner response"),
            "{out}"
        );
    }
    let pictures = dir.join("explain");
    let (st, out) = herbd_output(&[
        "explain",
        log,
        "--object",
        "1",
        "--out",
        pictures.to_str().unwrap(),
    ]);
    assert!(st.success(), "{out}");
    for want in [
        "method: search",
        "placement",
        "z ",
        "outcome: released",
        "decided in",
    ] {
        assert!(out.contains(want), "{want}: {out}");
    }
    assert!(pictures.join("object-1-before.png").is_file());
    assert!(pictures.join("object-1-after.png").is_file());
    // A log cut short (herbd killed) replays up to its end and says it is incomplete.
    let cut = dir.join("cut.log");
    let data = std::fs::read(log).unwrap();
    std::fs::write(&cut, &data[..data.len() * 2 / 3]).unwrap();
    let (st, out) = herbd_output(&["replay", cut.to_str().unwrap()]);
    assert_eq!(st.code(), Some(3), "{out}");
    assert!(out.contains("incomplete"), "{out}");
    claims.check();
}

#[test]
fn bad_jobs_and_payloads_are_rejected_with_a_reason_and_counted() {
    use herb_ipc::{JointCommand, JointState, PackJobRequest, RejectReason};
    let (dir, prefix, cfg) = setup("bad");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, _hd) = start_cell(&dir, &cfg);
    let client = client(&prefix);
    let services = client.services().clone();
    let bus = client.bus();
    // herbd's reply to `req` as it is (the client waits for herbd to serve).
    let reason = |req: PackJobRequest| {
        let deadline = Instant::now() + Duration::from_secs(30);
        let r = client.request(&req, deadline).expect("a reply from herbd");
        (r.validate().unwrap(), r.detail)
    };

    // Invalid jobs are rejected for what they are, whether or not the adapter is up.
    assert_eq!(
        reason(PackJobRequest::new(2, &[])),
        (RejectReason::Empty, 0)
    );
    assert_eq!(
        reason(PackJobRequest::new(3, &[1, 2, 999])),
        (RejectReason::UnknownObject, 2)
    );
    let many: Vec<u16> = (0..65).map(|i| i % 24).collect();
    assert_eq!(
        reason(PackJobRequest::new(4, &many)).0,
        RejectReason::TooMany
    );
    let mut old = PackJobRequest::new(5, &[1]);
    old.header.version = 0;
    assert_eq!(reason(old).0, RejectReason::Malformed);
    let mut nan_count = PackJobRequest::new(6, &[1]);
    nan_count.count = u32::MAX;
    assert_eq!(reason(nan_count).0, RejectReason::TooMany);

    // A valid job is accepted once herbd hears the adapter (NotReady before, retried by the
    // client); a second one while it runs is Busy (not queued).
    let mut not_ready = 0;
    client
        .submit(7, &[1, 3], Instant::now() + Duration::from_secs(30), |_| {
            not_ready += 1
        })
        .expect("accepted once herbd hears the adapter");
    // Now that the adapter and herbd publish (herbd heard the adapter), no second process may
    // speak for the arm or command it: the robot services take one publisher each, so a rogue
    // one is refused.
    assert!(
        bus.publisher::<JointState>(&services.joint_state())
            .is_err()
    );
    assert!(
        bus.publisher::<JointCommand>(&services.joint_command())
            .is_err()
    );

    let busy = client
        .submit(8, &[1], Instant::now() + Duration::from_secs(30), |_| {})
        .unwrap_err();
    assert!(
        matches!(
            busy,
            SubmitError::Rejected {
                reason: RejectReason::Busy,
                ..
            }
        ),
        "{busy:?}"
    );
    // A bad job while busy is answered with what is wrong with it, not Busy.
    let mut old = PackJobRequest::new(9, &[1]);
    old.header.version = 0;
    assert_eq!(reason(old).0, RejectReason::Malformed);
    assert_eq!(
        reason(PackJobRequest::new(10, &[1, 999])),
        (RejectReason::UnknownObject, 1)
    );

    // The daemon counts what it refused: 8 jobs and the NotReady ones, as requests; no sensor
    // input was bad.
    let want = 8 + not_ready;
    let counted = heartbeat_count(&client, |s| s.rejected_requests, |n| n >= want);
    assert_eq!(counted, want, "refused requests counted");
    assert_eq!(
        rejected_inputs(&client, |_| true),
        0,
        "no sensor input refused"
    );
    claims.check();
}

/// Heightmap frames with a valid header and grid but a NaN cell, injected by a second publisher
/// every 20 ms between the camera's frames, are dropped and counted; herbd decides on the
/// camera's good frames and the job completes (they used to fail the job with
/// a `Decision` fault, uncounted).
#[test]
fn bad_heightmap_frames_are_dropped_and_counted_not_decided_on() {
    use herb_adapter::{CameraPort, Heightmap};
    use herb_ipc::{Services, monotonic_ns};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let (dir, prefix, cfg) = setup("nanframe");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, _hd) = start_cell(&dir, &cfg);
    let services = Services::new(&prefix).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let injector = {
        let (services, stop) = (services.clone(), stop.clone());
        std::thread::spawn(move || {
            let bus = herb_ipc::bus::Bus::open("e2e-injector", &services).unwrap();
            let camera = CameraPort::open(&bus).unwrap();
            let spec = herb_sim::GridSpec::for_box(herb_sim::ObsLayout::CELL_M).unwrap();
            let mut cells = vec![0.0f32; spec.len()];
            cells[spec.len() / 2] = f32::NAN;
            let mut sent = 0u64;
            while !stop.load(Ordering::Relaxed) {
                let frame = Heightmap {
                    stamp_ns: monotonic_ns(),
                    nx: spec.nx as u32,
                    ny: spec.ny as u32,
                    cell_m: spec.cell,
                    objects: 0,
                    cells: &cells,
                };
                if camera.publish(sent + 1, &frame).is_ok() {
                    sent += 1;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            sent
        })
    };
    let client = client(&prefix);
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, true);
    let ctl_out = Follow::new(&mut ctl);
    let st = ctl.wait_for(Duration::from_secs(150));
    stop.store(true, Ordering::Relaxed);
    let sent = injector.join().unwrap();
    let mut summary = None;
    while let Ok(l) = ctl_out.rx.recv_timeout(Duration::from_millis(200)) {
        if let Ok(j) = serde_json::from_str::<serde_json::Value>(&l) {
            summary = Some(j);
        }
    }
    let summary = summary.expect("JSON summary");
    assert!(st.success(), "the job completes: {summary}");
    assert_eq!(summary["placed"], 2, "{summary}");
    assert_eq!(
        summary["faults"],
        serde_json::json!([]),
        "no fault: {summary}"
    );
    assert!(sent > 10, "the injector sent {sent} frames");
    let counted = rejected_inputs(&client, |n| n > 0);
    assert!(counted > 0, "bad frames counted in rejected_inputs");
    claims.check();
}

/// The loopback stalled mid-motion (SIGSTOP for 50 ms, six times; herbd's joint-state timeout
/// is 100 ms): its next joint state reports the speed over the real elapsed time, so herbd
/// rejects none of its own adapter's states (the speed was the distance over
/// a nominal 1 ms, above the 20 rad/s the wire allows).
#[test]
fn a_stalled_loopback_reports_real_speeds_and_nothing_is_rejected() {
    let (dir, prefix, cfg) = setup("stall");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (lb, _hd) = start_cell(&dir, &cfg);
    let client = client(&prefix);
    let rejected_now = || rejected_inputs(&client, |_| true);
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, true);
    let mut ctl_out = Follow::new(&mut ctl);
    ctl_out.wait_for("object  1/2", Duration::from_secs(60));
    // Before the stalls (herbctl's first tries may have been refused NotReady, and counted).
    let before = rejected_now();
    for _ in 0..6 {
        std::thread::sleep(Duration::from_millis(150));
        lb.signal(libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(50));
        lb.signal(libc::SIGCONT);
    }
    let st = ctl.wait_for(Duration::from_secs(120));
    assert!(st.success(), "the job completes");
    assert_eq!(
        rejected_now(),
        before,
        "herbd rejected its adapter's joint states"
    );
    claims.check();
}

/// The loopback stalled for 300 ms while the gripper holds an object (joint-state timeout,
/// brake, resume with the object still held): the placement is replanned, not decided again,
/// so every object is announced `Decided` once, with its decision time (the
/// replan was announced as a second `Decided` with `decision_ns` 0).
#[test]
fn a_resume_while_holding_announces_no_second_decision() {
    use herb_ipc::{GripperState, StatusEvent};
    let (dir, prefix, cfg) = setup("holdresume");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (lb, _hd) = start_cell(&dir, &cfg);
    let client = client(&prefix);
    let grip = client
        .bus()
        .subscriber::<GripperState>(&client.services().gripper_state())
        .unwrap();
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, true);
    let (mut decided, mut resumed, mut stalled, mut ended) = (Vec::new(), 0, false, None);
    let t0 = Instant::now();
    while ended.is_none() && t0.elapsed() < Duration::from_secs(120) {
        for s in client.statuses() {
            match StatusEvent::from_code(s.event) {
                Some(StatusEvent::Decided) => decided.push((s.object_index, s.decision_ns)),
                Some(StatusEvent::Resumed) => resumed += 1,
                Some(e @ (StatusEvent::JobDone | StatusEvent::JobFailed)) => ended = Some(e),
                _ => {}
            }
        }
        let mut holding = false;
        while let Ok(Some(g)) = grip.receive() {
            holding = g.payload().holding == 1;
        }
        if holding && !stalled {
            stalled = true;
            lb.signal(libc::SIGSTOP);
            std::thread::sleep(Duration::from_millis(300));
            lb.signal(libc::SIGCONT);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(ctl.wait_for(Duration::from_secs(30)).success());
    assert_eq!(ended, Some(StatusEvent::JobDone));
    assert!(stalled && resumed >= 1, "the stall faulted and resumed");
    assert_eq!(decided.len(), 2, "one Decided per object: {decided:?}");
    assert!(decided.iter().all(|&(_, ns)| ns > 0), "{decided:?}");
    assert_eq!(
        decided.iter().map(|d| d.0).collect::<Vec<_>>(),
        vec![0, 1],
        "{decided:?}"
    );
    claims.check();
}

/// herbd killed (SIGKILL: no last status can be sent) mid-job: herbctl notices the lost
/// heartbeat within a second and says "daemon lost" with the job's last known progress, instead
/// of waiting for its own timeout.
#[test]
fn a_killed_daemon_is_reported_lost_by_the_client() {
    let (dir, prefix, cfg) = setup("lost");
    let (_lb, hd) = start_cell(&dir, &cfg);
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "pack",
            "--objects",
            "003,005",
            "--timeout",
            "120",
            "--reconnect",
            "2",
        ],
        &dir.join("herbctl.log"),
    );
    let mut ctl_out = Follow::new(&mut ctl);
    ctl_out.wait_for("object  1/2", Duration::from_secs(60));
    hd.signal(libc::SIGKILL);
    let t0 = Instant::now();
    ctl_out.wait_for("herbd lost", Duration::from_secs(3));
    assert!(
        t0.elapsed() < Duration::from_secs(1),
        "noticed after {:?}",
        t0.elapsed()
    );
    // No herbd comes back within the 2 s it waits: it gives up.
    let st = ctl.wait_for(Duration::from_secs(10));
    let took = t0.elapsed();
    assert!(!st.success(), "the job did not finish");
    assert!(took < Duration::from_secs(4), "gave up after {took:?}");
    let err = std::fs::read_to_string(dir.join("herbctl.log")).unwrap();
    assert!(err.contains("daemon lost"), "{err}");
    assert!(
        err.contains("placed: 0 of 2 objects") && err.contains("object 1/2"),
        "{err}"
    );
}

/// A second herbd on a prefix in use exits non-zero naming the running one, and the first goes
/// on serving (both used to answer jobs and drive the same arm).
#[test]
fn a_second_daemon_on_a_prefix_in_use_refuses_to_start() {
    let (dir, prefix, cfg) = setup("second");
    let cfg_s = cfg.to_str().unwrap();
    let (_lb, first) = start_cell(&dir, &cfg);
    // Up once it has said which policy it runs (its start-up line).
    let t0 = Instant::now();
    while !std::fs::read_to_string(dir.join("herbd.log")).is_ok_and(|l| l.contains("event=start "))
    {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "herbd did not start"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut second = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd2.log"));
    let st = second.wait_for(Duration::from_secs(10));
    assert!(!st.success(), "the second herbd must not run");
    let err = std::fs::read_to_string(dir.join("herbd2.log")).unwrap();
    let pid = first.0.id().to_string();
    assert!(
        err.contains("another herbd") && err.contains(&pid),
        "names the running one (pid {pid}): {err}"
    );
    // The first still serves: a job completes.
    let mut ctl = pack_objects(&dir, &prefix, "003", 120, false);
    assert!(ctl.wait_for(Duration::from_secs(120)).success());
}

/// Joint states from the arm's publisher whose sequence or stamp goes backwards are refused and
/// counted, not acted on. The test process plays the arm's adapter.
#[test]
fn joint_states_going_backwards_are_rejected_and_counted() {
    use herb_ipc::{Header, JointState, Services, Status, StatusEvent, monotonic_ns};
    let (dir, prefix, cfg) = setup("order");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    let services = Services::new(&prefix).unwrap();
    let bus = herb_ipc::bus::Bus::open("e2e-fake-arm", &services).unwrap();
    let arm = bus
        .publisher::<JointState>(&services.joint_state())
        .unwrap();
    let status = bus.subscriber::<Status>(&services.status()).unwrap();
    let state = |seq, stamp_ns| JointState {
        header: Header {
            seq,
            stamp_ns,
            ..Header::now(seq)
        },
        position: [0.0; 7],
        velocity: [0.0; 7],
    };
    let rejected_after = |arm: &herb_ipc::bus::Pub<JointState>, next: &mut u64| {
        // Keep the arm alive for a few heartbeats and read the newest count.
        let mut counted = None;
        for _ in 0..60 {
            *next += 1;
            arm.send_copy(state(*next, monotonic_ns())).unwrap();
            while let Ok(Some(s)) = status.receive() {
                if s.payload().event == StatusEvent::Heartbeat as u32 {
                    counted = Some(s.payload().rejected_inputs);
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        counted.expect("herbd heartbeats")
    };
    let mut next = 0;
    let t0 = Instant::now();
    while status.receive().ok().flatten().is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "herbd did not start"
        );
        arm.send_copy(state(next + 1, monotonic_ns())).unwrap();
        next += 1;
        std::thread::sleep(Duration::from_millis(10));
    }
    let before = rejected_after(&arm, &mut next);
    arm.send_copy(state(next - 5, monotonic_ns())).unwrap(); // sequence backwards
    next += 1;
    arm.send_copy(state(next, monotonic_ns() - 50_000_000))
        .unwrap(); // stamp backwards
    let after = rejected_after(&arm, &mut next);
    assert_eq!(after - before, 2, "two out-of-order states refused");
    claims.check();
}

/// Two jobs one after the other: every simulated outcome carries the job that released the
/// object, and a subscriber joining afterwards gets the last one from history with the second
/// job's id, so nobody mistakes an earlier job's outcome for their own.
#[test]
fn outcomes_carry_their_job_across_jobs() {
    use herb_ipc::{SimOutcome, StatusEvent};
    let (dir, prefix, cfg) = setup("jobids");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, _hd) = start_cell(&dir, &cfg);
    let client = client(&prefix);
    let (bus, services) = (client.bus(), client.services());
    let outcomes = bus
        .subscriber::<SimOutcome>(&services.sim_outcome())
        .unwrap();
    let (mut accepted, mut released, mut late_seen) = (Vec::new(), Vec::new(), Vec::new());
    let mut late = None;
    for objects in ["003,005", "011"] {
        let mut ctl = pack_objects(&dir, &prefix, objects, 120, false);
        assert!(ctl.wait_for(Duration::from_secs(150)).success());
        std::thread::sleep(Duration::from_millis(1500)); // the last release settles
        for s in client.statuses() {
            if s.event == StatusEvent::Accepted as u32 {
                accepted.push(s.job_id);
            }
        }
        while let Ok(Some(o)) = outcomes.receive() {
            released.push(o.payload().job_id);
        }
        if let Some(l) = &late {
            while let Ok(Some(o)) = herb_ipc::bus::Sub::<SimOutcome>::receive(l) {
                late_seen.push(o.payload().job_id);
            }
        }
        // A subscriber joining between the jobs: history hands it the first job's last outcome.
        late.get_or_insert_with(|| {
            bus.subscriber::<SimOutcome>(&services.sim_outcome())
                .unwrap()
        });
    }
    assert_eq!(accepted.len(), 2, "{accepted:?}");
    assert_ne!(accepted[0], accepted[1]);
    assert_eq!(
        released,
        vec![accepted[0], accepted[0], accepted[1]],
        "each outcome names its job"
    );
    assert_eq!(
        late_seen,
        vec![accepted[0], accepted[1]],
        "the late subscriber tells the earlier job's outcome from the new one"
    );
    claims.check();
}

/// `herbctl reset` empties the loopback's box between jobs, so the next job starts in an empty
/// box, and is refused while a job runs (a second job was packed on top).
#[test]
fn the_box_is_reset_between_jobs_and_not_during_one() {
    use herb_ipc::{Services, SimOutcome};
    let (dir, prefix, cfg) = setup("reset");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let _lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s],
        &dir.join("loopback.log"),
    );
    // Recorded in 1 MB segments (the test configuration's): several, cut between jobs.
    let runs = dir.join("runs");
    let mut hd = spawn(
        &exe("herbd"),
        &["--config", cfg_s, "--record", runs.to_str().unwrap()],
        &dir.join("herbd.log"),
    );
    let services = Services::new(&prefix).unwrap();
    let bus = herb_ipc::bus::Bus::open("e2e-test", &services).unwrap();
    let outcomes = bus
        .subscriber::<SimOutcome>(&services.sim_outcome())
        .unwrap();
    let reset = |log: &str| {
        spawn(
            &exe("herbctl"),
            &["--prefix", &prefix, "reset"],
            &dir.join(log),
        )
        .wait_for(Duration::from_secs(20))
    };
    // During a job: refused, the job goes on.
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, false);
    let mut ctl_out = Follow::new(&mut ctl); // kept: it drains herbctl's output
    ctl_out.wait_for("object  1/2", Duration::from_secs(60));
    assert!(!reset("reset-busy.log").success(), "no reset during a job");
    let err = std::fs::read_to_string(dir.join("reset-busy.log")).unwrap();
    assert!(err.contains("is running"), "{err}");
    assert!(ctl.wait_for(Duration::from_secs(150)).success());
    std::thread::sleep(Duration::from_millis(1500)); // the last release settles
    let mut last = None;
    while let Ok(Some(o)) = outcomes.receive() {
        last = Some(o.payload().objects);
    }
    assert_eq!(last, Some(2), "two objects in the box after the first job");
    // Between jobs: the box is emptied, and the next job's first object is alone in it.
    assert!(reset("reset.log").success());
    let mut ctl = pack_objects(&dir, &prefix, "011", 120, false);
    assert!(ctl.wait_for(Duration::from_secs(150)).success());
    std::thread::sleep(Duration::from_millis(1500));
    let mut last = None;
    while let Ok(Some(o)) = outcomes.receive() {
        last = Some(o.payload().objects);
    }
    assert_eq!(last, Some(1), "the second job packed an empty box");

    // The run log rotated between the jobs; every segment replays on its own, bit for bit,
    // a later one from the snapshot it starts with.
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    logs.sort();
    assert!(logs.len() >= 2, "{logs:?}");
    let mut decisions = 0;
    for log in &logs {
        let (st, out) = herbd_output(&["replay", log.to_str().unwrap()]);
        assert!(st.success(), "{}: {out}", log.display());
        assert!(out.contains("reproduced bit for bit"), "{out}");
        decisions += out
            .split(" decisions")
            .next()
            .and_then(|h| h.rsplit(' ').next())
            .and_then(|n| n.parse::<u32>().ok())
            .expect("a decision count");
    }
    assert_eq!(decisions, 3, "the two jobs' decisions, each in one segment");
    claims.check();
}

#[test]
fn sigterm_mid_motion_brakes_reports_and_exits_zero() {
    let (dir, prefix, cfg) = setup("sigterm");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, mut hd) = start_cell(&dir, &cfg);
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, false);
    let mut ctl_out = Follow::new(&mut ctl);
    ctl_out.wait_for("object  1/2", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(500));
    let hd_out = lines(&mut hd);
    hd.signal(libc::SIGTERM);
    ctl_out.wait_for("braked", Duration::from_secs(5));
    ctl_out.wait_for("herbd shut down", Duration::from_secs(5));
    assert!(
        hd.wait_for(Duration::from_secs(10)).success(),
        "herbd exits 0 after braking"
    );
    let stats = last_json(&hd_out, "herbd_final");
    assert!(stats["deadline_misses"].is_u64(), "{stats}");
    assert_eq!(
        ctl.wait_for(Duration::from_secs(10)).code(),
        Some(1),
        "the job did not finish"
    );
    claims.check();
}

/// `herbctl cancel` mid-motion: the arm brakes and retreats, the job ends
/// `JobCancelled` (herbctl cancel exits 0; the client that submitted it sees the end and exits
/// 1), the arm then stands still, and the next job runs.
#[test]
fn a_job_cancelled_mid_motion_brakes_retreats_and_the_next_job_runs() {
    use herb_ipc::{JointState, Services};
    let (dir, prefix, cfg) = setup("cancel");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, _hd) = start_cell(&dir, &cfg);
    let herbctl = |args: &[&str]| herbctl_output(&prefix, args);
    let mut ctl = pack_objects(&dir, &prefix, "003,005", 120, false);
    let mut ctl_out = Follow::new(&mut ctl);
    ctl_out.wait_for("object  1/2", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(300)); // moving
    let (st, out_of_cancel) = herbctl(&["cancel"]);
    assert!(st.success(), "herbctl cancel: {out_of_cancel}");
    assert!(
        out_of_cancel.contains("braked") && out_of_cancel.contains("cancelled"),
        "{out_of_cancel}"
    );
    // "cancelling job <id>"
    let out_job_id = |out: &str| {
        out.split_whitespace()
            .skip_while(|w| *w != "job")
            .nth(1)
            .expect("a job id")
            .to_string()
    };
    ctl_out.wait_for("job cancelled", Duration::from_secs(10));
    assert!(
        !ctl.wait_for(Duration::from_secs(10)).success(),
        "the submitting client reports the job did not complete"
    );
    // Standing still: two joint states 200 ms apart at the same configuration.
    let services = Services::new(&prefix).unwrap();
    let bus = herb_ipc::bus::Bus::open("e2e-test", &services).unwrap();
    let js = bus
        .subscriber::<JointState>(&services.joint_state())
        .unwrap();
    let latest = || {
        std::thread::sleep(Duration::from_millis(200));
        let mut q = None;
        while let Ok(Some(s)) = js.receive() {
            q = Some(s.payload().position);
        }
        q.expect("joint states")
    };
    let (a, b) = (latest(), latest());
    assert!(
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9),
        "{a:?} {b:?}"
    );
    // Cancelled once: nothing runs now, and that job id is not running.
    let (st, out) = herbctl(&["cancel"]);
    assert!(!st.success() && out.contains("no job is running"), "{out}");
    let job = out_job_id(&out_of_cancel);
    let (st, out) = herbctl(&["cancel", "--job", &job]);
    assert!(!st.success() && out.contains("is not running"), "{out}");
    let mut next = pack_objects(&dir, &prefix, "011", 120, false);
    assert!(
        next.wait_for(Duration::from_secs(150)).success(),
        "the next job runs"
    );
    claims.check();
}

/// herbd killed with SIGKILL while it carries an object. Restarted on the same
/// state directory, it reports the unfinished job from its journal, waits for fresh inputs,
/// places the held object where it was decided and completes the job: every object is released
/// into the box exactly once, and the journal is gone at the end. A corrupt journal is then
/// reported and set aside, and herbd starts and serves.
#[test]
fn a_job_survives_herbd_killed_mid_motion() {
    use herb_ipc::{Fault, SimOutcome, Status, StatusEvent};
    let (dir, prefix, cfg) = setup("crash");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let journal = dir.join("state").join(herb_daemon::journal::FILE);
    let (_lb, mut hd) = start_cell(&dir, &cfg);
    let client = client(&prefix);
    let (bus, services) = (client.bus(), client.services());
    let outcomes = bus
        .subscriber::<SimOutcome>(&services.sim_outcome())
        .unwrap();
    // This client gives up when herbd is lost (the test follows the restarted job itself;
    // herbctl_follows_a_job_across_a_daemon_crash_and_restart has herbctl wait for it).
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "pack",
            "--objects",
            "003,005,011",
            "--timeout",
            "300",
            "--reconnect",
            "0",
        ],
        &dir.join("herbctl.log"),
    );
    let mut events: Vec<Status> = Vec::new();
    let mut released: Vec<SimOutcome> = Vec::new();
    let drain_outcomes = |released: &mut Vec<SimOutcome>| {
        while let Ok(Some(o)) = outcomes.receive() {
            released.push(*o.payload());
        }
    };
    let drain = |events: &mut Vec<Status>, released: &mut Vec<SimOutcome>| {
        events.extend(
            client
                .statuses()
                .filter(|s| s.event != StatusEvent::Heartbeat as u32),
        );
        drain_outcomes(released);
    };
    // Kill herbd while the arm carries object 2 (index 1 of the order), once the journal has
    // it held: the journal, not the gripper or the statuses, says which object is held (herbd
    // decides object 2 while the arm still carries object 1, and on a loaded machine it may
    // write the journal a while after the gripper closed).
    let t0 = Instant::now();
    let carrying_second = || {
        std::fs::read(&journal)
            .ok()
            .and_then(|b| herb_daemon::job::JobRecord::decode(&b).ok())
            .is_some_and(|r| r.index == 1 && r.holding)
    };
    while !carrying_second() {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "object 2 never journalled as held: {events:?}"
        );
        drain(&mut events, &mut released);
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(100));
    hd.signal(libc::SIGKILL);
    hd.wait_for(Duration::from_secs(5));
    drain(&mut events, &mut released);
    let job_id = events[0].job_id;
    let before = std::fs::read_to_string(&journal).expect("the journal of the killed job");
    assert!(before.contains("\"holding\": true"), "{before}");
    assert!(ctl.wait_for(Duration::from_secs(10)).code() != Some(0));

    // The restart takes the job up: followed as a client does, waiting for herbd to come
    // back with the job, to its end.
    let limit = Duration::from_secs(120);
    let mut job = client.watch(job_id, Instant::now() + limit, limit);
    let mut hd2 = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd2.log"));
    while !job.is_finished() {
        match job.poll() {
            Ok(Some(JobEvent::Status(s))) if s.event != StatusEvent::Heartbeat as u32 => {
                events.push(s)
            }
            Ok(Some(_)) => {}
            Ok(None) => {
                drain_outcomes(&mut released);
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => panic!("the job did not complete after the restart: {e}: {events:?}"),
        }
    }
    assert_eq!(
        job.end().map(|s| s.event),
        Some(StatusEvent::JobDone as u32),
        "{events:?}"
    );
    std::thread::sleep(Duration::from_millis(1500)); // the last release settles
    drain(&mut events, &mut released);
    let log = std::fs::read_to_string(dir.join("herbd2.log")).unwrap();
    assert!(
        log.contains(&format!("event=job_recovered job={job_id} action=resume")),
        "{log}"
    );
    let after_restart: Vec<(u32, u32)> = events
        .iter()
        .skip_while(|s| s.fault != Fault::Restarted as u32)
        .map(|s| (s.event, s.object_index))
        .collect();
    assert_eq!(
        after_restart.first(),
        Some(&(StatusEvent::Fault as u32, 1)),
        "{events:?}"
    );
    assert!(
        after_restart.contains(&(StatusEvent::Resumed as u32, 1)),
        "{events:?}"
    );
    // Every object released into the box once, by this job.
    let mine: Vec<&SimOutcome> = released.iter().filter(|o| o.job_id == job_id).collect();
    let mut types: Vec<u32> = mine.iter().map(|o| o.object_type).collect();
    types.sort_unstable();
    let catalog =
        herb_sim::Catalog::builtin(&herb_sim::paths::MeshSource::None("ids only".into())).unwrap();
    let mut want: Vec<u32> = ["003", "005", "011"]
        .iter()
        .map(|id| catalog.by_id(id).unwrap().0 as u32)
        .collect();
    want.sort_unstable();
    assert_eq!(types, want, "each object released once");
    assert_eq!(mine.last().unwrap().objects, 3);
    let done = events
        .iter()
        .find(|s| s.event == StatusEvent::JobDone as u32)
        .unwrap();
    assert_eq!((done.objects_done, done.objects_total), (3, 3));
    // The journal ends with the job.
    let t0 = Instant::now();
    while journal.exists() {
        assert!(t0.elapsed() < Duration::from_secs(2), "journal left behind");
        std::thread::sleep(Duration::from_millis(20));
    }

    // A corrupt journal: reported, set aside, and herbd serves.
    hd2.signal(libc::SIGTERM);
    assert!(hd2.wait_for(Duration::from_secs(10)).success());
    std::fs::write(&journal, b"{\"format\": \"herb-job-jour").unwrap();
    let _hd3 = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd3.log"));
    let mut ctl = pack_objects(&dir, &prefix, "003", 120, false);
    assert!(ctl.wait_for(Duration::from_secs(120)).success());
    let log = std::fs::read_to_string(dir.join("herbd3.log")).unwrap();
    assert!(
        log.contains("event=journal_set_aside") && log.contains("corrupt or truncated"),
        "{log}"
    );
    let aside: Vec<_> = std::fs::read_dir(dir.join("state"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with("job.json.bad-"))
        .collect();
    assert_eq!(aside.len(), 1, "{aside:?}");
    claims.check();
}

/// Reads the loopback's final summary after SIGTERM.
fn loopback_summary(mut lb: Proc) -> serde_json::Value {
    let rx = lines(&mut lb);
    lb.signal(libc::SIGTERM);
    assert!(lb.wait_for(Duration::from_secs(10)).success());
    last_json(&rx, "loopback_final")
}

/// The arm disabled mid-motion, then e-stopped mid-motion, sagging each time while unpowered
/// (0.05 rad/s, as a real arm): herbd names each fault, commands nothing while the arm cannot
/// move, and after each re-enable the first command that reaches the arm is within 0.01 rad of
/// where the arm sagged to (never the setpoint held from before); the job finishes.
#[test]
fn re_enabling_a_sagged_arm_never_jumps() {
    let (dir, prefix, cfg) = setup("reenable");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--sag", "0.05"],
        &dir.join("loopback.log"),
    );
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    let mut ctl = pack_objects(&dir, &prefix, "003,005,011", 300, true);
    let mut out = Follow::new(&mut ctl);
    for (signal, fault) in [
        (libc::SIGUSR1, "FAULT RobotDisabled"),
        (libc::SIGUSR2, "FAULT RobotEStop"),
    ] {
        out.wait_for("decision", Duration::from_secs(120));
        std::thread::sleep(Duration::from_millis(700));
        lb.signal(signal);
        out.wait_for(fault, Duration::from_secs(5));
        // Unpowered for 2 s: the arm sags about 0.1 rad on s1.
        std::thread::sleep(Duration::from_secs(2));
        lb.signal(signal);
        out.wait_for("resumed", Duration::from_secs(10));
    }
    out.wait_for("placed: 3 of 3 objects", Duration::from_secs(180));
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 3, "{summary}");
    let sim = loopback_summary(lb);
    eprintln!("herbctl: {summary}\nloopback: {sim}");
    let firsts: Vec<f64> =
        serde_json::from_value(sim["first_command_offsets_rad"].clone()).unwrap();
    // The job's first command, then one after each of the two re-enables.
    assert_eq!(firsts.len(), 3, "{sim}");
    for f in &firsts {
        assert!(*f <= 0.01, "a first command {f} rad from the arm: {sim}");
    }
    assert_eq!(
        sim["commands_refused"], 0,
        "herbd sent nothing stale: {sim}"
    );
    claims.check();
}

/// The first grasp closes on nothing: herbd reports `MissedGrasp`, opens, picks again at the
/// same placement (one decision) and packs the job; the next job packs too.
#[test]
fn a_missed_grasp_is_retried_and_the_cell_goes_on() {
    let (dir, prefix, cfg) = setup("missed");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--miss-grasps", "1"],
        &dir.join("loopback.log"),
    );
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    for (objects, n) in [("003,005", 2), ("011", 1)] {
        let mut ctl = pack_objects(&dir, &prefix, objects, 300, true);
        let mut out = Follow::new(&mut ctl);
        out.wait_for(
            &format!("placed: {n} of {n} object"),
            Duration::from_secs(180),
        );
        let st = ctl.wait_for(Duration::from_secs(30));
        let summary = out.last_json().expect("herbctl's JSON summary");
        assert!(st.success(), "{summary}");
        assert_eq!(summary["placed"], n, "{summary}");
        assert_eq!(
            summary["decisions"], n,
            "one decision per object: {summary}"
        );
        if n == 2 {
            assert_eq!(
                summary["faults"],
                serde_json::json!(["MissedGrasp"]),
                "{summary}"
            );
        }
        assert_eq!(summary["sim"]["all_inside"], true, "{summary}");
    }
    let sim = loopback_summary(lb);
    assert_eq!(sim["missed_grasps"], 1, "{sim}");
    assert_eq!(sim["releases"], 3, "{sim}");
    claims.check();
}

/// A disabled robot between jobs: `herbctl pack` says "robot not ready: robot disabled" within
/// a second and waits; `herbctl status` shows the reason; enabled again, the job runs.
#[test]
fn a_job_for_a_disabled_robot_says_why_and_waits() {
    let (dir, prefix, cfg) = setup("notready");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s],
        &dir.join("loopback.log"),
    );
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    // Ready first (herbd's heartbeat says so), then disabled.
    let t0 = Instant::now();
    loop {
        let (_, text) = herbctl_output(&prefix, &["status"]);
        if text.contains("fault None") || text.contains("fault: None") {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "never ready: {text}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    lb.signal(libc::SIGUSR1);
    std::thread::sleep(Duration::from_millis(300));
    let (_, text) = herbctl_output(&prefix, &["status"]);
    assert!(text.contains("RobotDisabled"), "{text}");
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "pack",
            "--objects",
            "003",
            "--timeout",
            "120",
        ],
        &dir.join("herbctl.log"),
    );
    let asked = Instant::now();
    let mut out = Follow::new(&mut ctl);
    // Said at the first refusal, not at the job's 120 s timeout: within 5 s even on a loaded
    // machine (a tighter bound measured the machine's load, not herbctl).
    out.wait_for("robot not ready: robot disabled", Duration::from_secs(5));
    eprintln!("said after {:?}", asked.elapsed());
    lb.signal(libc::SIGUSR1);
    out.wait_for("placed: 1 of 1 object", Duration::from_secs(120));
    assert!(ctl.wait_for(Duration::from_secs(30)).success());
    claims.check();
}

/// The log's name of a status event (herbd's `event=` key).
fn log_name(ev: herb_ipc::StatusEvent) -> &'static str {
    use herb_ipc::StatusEvent::*;
    match ev {
        Heartbeat => "heartbeat",
        Accepted => "accepted",
        Decided => "decided",
        Placed => "placed",
        Fault => "fault",
        Braked => "braked",
        Resumed => "resumed",
        JobDone => "job_done",
        JobFailed => "job_failed",
        Shutdown => "shutdown",
        JobCancelled => "job_cancelled",
        Skipped => "skipped",
        AwaitingObject => "awaiting_object",
    }
}

/// herbd stopped with SIGTERM 20 times, idle or mid-job: every run's log ends its events with
/// `event=shutdown`, and the log's events are exactly the status stream's (heartbeats aside),
/// in order: nothing lost, nothing added.
#[test]
fn every_event_reaches_the_log_before_herbd_exits_on_sigterm() {
    let (dir, prefix, cfg) = setup("logs");
    let cfg_s = cfg.to_str().unwrap();
    let _lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s],
        &dir.join("loopback.log"),
    );
    let client = Client::connect_as(&prefix, "e2e-log-test").unwrap();
    let mut with_shutdown = 0;
    // The status stream's events (heartbeats aside), read often so that the subscriber stays
    // connected to each new herbd's publisher.
    let drain = |into: &mut Vec<String>, for_: Duration| {
        let t0 = Instant::now();
        loop {
            for s in client.statuses() {
                let ev = herb_ipc::StatusEvent::from_code(s.event).unwrap();
                if ev != herb_ipc::StatusEvent::Heartbeat {
                    into.push(log_name(ev).to_string());
                }
            }
            if t0.elapsed() >= for_ {
                return;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    for run in 0..20 {
        let log = dir.join(format!("herbd-{run}.log"));
        // A job stopped mid-way would be taken up from the journal by the next herbd, whose
        // first events come before this subscriber connects: each run starts without one.
        let _ = std::fs::remove_file(dir.join("state/job.json"));
        let mut streamed = Vec::new();
        let mut hd = spawn(&exe("herbd"), &["--config", cfg_s], &log);
        herb_testkit::wait_for_log(&log, "event=start", Duration::from_secs(30));
        // Connected once a heartbeat came through.
        let mut heartbeats = 0;
        while heartbeats == 0 {
            heartbeats += client
                .statuses()
                .filter(|s| s.event == herb_ipc::StatusEvent::Heartbeat as u32)
                .count();
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut ctl = None;
        if run % 2 == 1 {
            // Mid-job: the arm moving (a few tenths of a second after the job starts).
            ctl = Some(pack_objects(&dir, &prefix, "003,005", 120, false));
            let t0 = Instant::now();
            while !streamed.iter().any(|e| e == "decided") {
                drain(&mut streamed, Duration::from_millis(20));
                assert!(
                    t0.elapsed() < Duration::from_secs(60),
                    "run {run}: no decision"
                );
            }
            drain(&mut streamed, Duration::from_millis(300));
        } else {
            drain(&mut streamed, Duration::from_millis(200));
        }
        hd.signal(libc::SIGTERM);
        let t0 = Instant::now();
        while hd.0.try_wait().unwrap().is_none() {
            drain(&mut streamed, Duration::from_millis(5));
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "run {run}: herbd did not exit"
            );
        }
        drain(&mut streamed, Duration::from_millis(50));
        assert!(hd.wait_for(Duration::from_secs(1)).success(), "run {run}");
        if let Some(mut c) = ctl {
            let _ = c.wait_for(Duration::from_secs(10));
        }
        let text = std::fs::read_to_string(&log).unwrap();
        let logged: Vec<String> = text
            .lines()
            .filter_map(|l| l.split("event=").nth(1))
            .map(|r| r.split(' ').next().unwrap_or("").to_string())
            .filter(|e| {
                streamed.contains(e)
                    || [
                        "accepted",
                        "decided",
                        "placed",
                        "fault",
                        "braked",
                        "resumed",
                        "job_done",
                        "job_failed",
                        "shutdown",
                        "job_cancelled",
                        "skipped",
                    ]
                    .contains(&e.as_str())
            })
            .collect();
        assert_eq!(logged, streamed, "run {run}:\n{text}");
        if logged.last().map(String::as_str) == Some("shutdown") {
            with_shutdown += 1;
        }
    }
    assert_eq!(with_shutdown, 20);
}

/// Cancelled while the gripper holds the cracker box (type 1): the next job, for the tomato soup
/// can (type 3), is refused `Holding` (never a placement of the held box claimed as the can);
/// once the box is taken out (`herbctl reset` on the loopback), the job runs, and herbd's claims
/// (each `Placed`, `JobDone`'s count) agree with what the simulated world saw released.
#[test]
fn a_job_after_a_cancel_while_holding_never_claims_what_it_did_not_place() {
    let (dir, prefix, cfg) = setup("holding");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let (_lb, _hd) = start_cell(&dir, &cfg);
    let mut ctl = pack_objects(&dir, &prefix, "003", 120, false);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/1", Duration::from_secs(60));
    // Holding: the gripper state says so.
    let services = herb_ipc::Services::new(&prefix).unwrap();
    let bus = herb_ipc::bus::Bus::open("e2e-holding", &services).unwrap();
    let gs = bus
        .subscriber::<herb_ipc::GripperState>(&services.gripper_state())
        .unwrap();
    let t0 = Instant::now();
    'held: loop {
        while let Ok(Some(s)) = gs.receive() {
            if s.payload().holding == 1 {
                break 'held;
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "never held");
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(200)); // carrying
    let (st, text) = herbctl_output(&prefix, &["cancel"]);
    assert!(st.success(), "{text}");
    out.wait_for("job cancelled", Duration::from_secs(20));
    let _ = ctl.wait_for(Duration::from_secs(10));
    // The next job is refused while the box is in the gripper.
    let (st, text) = herbctl_output(&prefix, &["pack", "--objects", "005", "--timeout", "30"]);
    assert!(!st.success(), "{text}");
    assert!(text.contains("the gripper holds 003 cracker box"), "{text}");
    // Taken out, the job runs and places the can.
    let (st, text) = herbctl_output(&prefix, &["reset"]);
    assert!(st.success(), "{text}");
    let (st, text) = herbctl_output(
        &prefix,
        &["pack", "--objects", "005", "--timeout", "120", "--json"],
    );
    assert!(st.success(), "{text}");
    let jobs = claims.check();
    let placed: Vec<&JobRecordRef> = jobs.values().filter(|r| !r.claimed.is_empty()).collect();
    assert_eq!(placed.len(), 1, "one job placed something: {jobs:?}");
    assert_eq!(
        placed[0].claimed,
        vec![3],
        "the can, and only the can: {jobs:?}"
    );
}

type JobRecordRef = herb_testkit::claims::JobRecord;

/// Thirty frames with a bad cell (NaN, infinite, 5 m above the floor, 1 m below it), sent while
/// herbd is idle (no decision needs them; no other camera): each is checked on receipt and
/// counted in `rejected_inputs`, and nothing else is.
#[test]
fn bad_heightmap_cells_are_counted_on_receipt_outside_any_decision() {
    use herb_adapter::{CameraPort, Heightmap};
    use herb_ipc::monotonic_ns;
    let (dir, prefix, cfg) = setup("badcells");
    let _hd = spawn(
        &exe("herbd"),
        &["--config", cfg.to_str().unwrap()],
        &dir.join("herbd.log"),
    );
    herb_testkit::wait_for_log(
        &dir.join("herbd.log"),
        "event=start",
        Duration::from_secs(30),
    );
    let client = Client::connect_as(&prefix, "e2e-badcells").unwrap();
    let before = rejected_inputs(&client, |_| true);
    let camera = CameraPort::open(client.bus()).unwrap();
    let spec = herb_sim::GridSpec::for_box(herb_sim::ObsLayout::CELL_M).unwrap();
    let bad = [f32::NAN, f32::INFINITY, 5.0, -1.0];
    for k in 0..30u64 {
        let mut cells = vec![0.01f32; spec.len()];
        cells[(k as usize * 997) % spec.len()] = bad[k as usize % bad.len()];
        let frame = Heightmap {
            stamp_ns: monotonic_ns(),
            nx: spec.nx as u32,
            ny: spec.ny as u32,
            cell_m: spec.cell,
            objects: 0,
            cells: &cells,
        };
        camera.publish(k + 1, &frame).expect("published");
        // Frames at the planner's pace or slower (its queue keeps the newest two).
        std::thread::sleep(Duration::from_millis(50));
    }
    let counted = rejected_inputs(&client, |n| n >= before + 30);
    assert_eq!(
        counted - before,
        30,
        "every bad frame counted, nothing else"
    );
}

/// herbd SIGKILLed mid-job and restarted on its journal: the `herbctl pack` that submitted the
/// job says herbd was lost, waits, sees it back with the same job, and follows it to its end
/// (exit 0, every object placed), the claims agreeing with the world.
#[test]
fn herbctl_follows_a_job_across_a_daemon_crash_and_restart() {
    let (dir, prefix, cfg) = setup("follow");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let (_lb, mut hd) = start_cell(&dir, &cfg);
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "pack",
            "--objects",
            "003,005",
            "--timeout",
            "240",
            "--json",
        ],
        &dir.join("herbctl.log"),
    );
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/2", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(600));
    hd.signal(libc::SIGKILL);
    let _ = hd.wait_for(Duration::from_secs(5));
    out.wait_for("herbd lost", Duration::from_secs(3));
    std::thread::sleep(Duration::from_secs(1));
    let _hd2 = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd2.log"));
    out.wait_for("herbd back", Duration::from_secs(30));
    out.wait_for("placed: 2 of 2 objects", Duration::from_secs(120));
    let st = ctl.wait_for(Duration::from_secs(30));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 2, "{summary}");
    claims.check();
}

/// An arm that stands past herbd's joint limit (inside its own) when a job comes, as a real
/// Baxter's elbow after it sagged while disabled (the loopback started there with `--start`):
/// with `[recovery] outside_limits = "refuse"` the job is refused as "robot not ready" naming the
/// joint, where and the limit (`herbctl pack` and `herbctl status`); with the default
/// ("recover") the job names it, herbd brings the joint back inside slowly from where it stands
/// (the first command at the arm) and the job packs.
#[test]
fn a_job_for_an_arm_past_a_limit_is_refused_or_brought_back_inside() {
    let (dir, prefix, cfg) = setup("pastlimit");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let limits = herb_testkit::fast_limits();
    let mut start = herb_robot::kinematics::LEFT_TOP_DOWN_NOMINAL;
    start[3] = limits.upper[3] + 0.03; // left_e1, inside the arm's own limit (0.05 past)
    let start_s = start.map(|v| v.to_string()).join(",");
    let cfg_s = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, &format!("--start={start_s}")],
        &dir.join("loopback.log"),
    );
    // Refused, naming the joint.
    let refuse = dir.join("refuse.toml");
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(
        &refuse,
        format!("{text}\n[recovery]\noutside_limits = \"refuse\"\n"),
    )
    .unwrap();
    let mut hd = spawn(
        &exe("herbd"),
        &["--config", refuse.to_str().unwrap()],
        &dir.join("herbd-refuse.log"),
    );
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "pack",
            "--objects",
            "003",
            "--timeout",
            "60",
        ],
        &dir.join("herbctl-refused.log"),
    );
    let mut out = Follow::new(&mut ctl);
    // One line says both (a second wait would need a second line, which herbctl need not print).
    out.wait_for("left_e1 at 2.5980 rad", Duration::from_secs(30));
    let said = out.seen.last().unwrap();
    assert!(said.contains("robot not ready"), "{said}");
    let (_, text) = herbctl_output(&prefix, &["status"]);
    assert!(
        text.contains("OutsideLimits") && text.contains("left_e1"),
        "{text}"
    );
    ctl.signal(libc::SIGKILL);
    let _ = ctl.wait_for(Duration::from_secs(10));
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    // Brought back inside by the job's first motion, which packs.
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    let mut ctl = pack_objects(&dir, &prefix, "003", 120, true);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("left_e1 at 2.5980 rad", Duration::from_secs(30));
    let st = ctl.wait_for(Duration::from_secs(120));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 1, "{summary}");
    assert_eq!(
        summary["faults"],
        serde_json::json!(["OutsideLimits"]),
        "{summary}"
    );
    let sim = loopback_summary(lb);
    eprintln!("herbctl: {summary}\nloopback: {sim}");
    let firsts: Vec<f64> =
        serde_json::from_value(sim["first_command_offsets_rad"].clone()).unwrap();
    assert!(firsts[0] <= 0.001, "the first command at the arm: {sim}");
    // Past herbd's limit only on the way back in: never farther out than the arm stood.
    let excess = sim["max_limit_excess_rad"].as_f64().unwrap();
    assert!(excess > 0.0 && excess <= 0.03 + 1e-9, "{sim}");
    assert_eq!(sim["commands_refused"], 0, "{sim}");
    claims.check();
}

/// Ctrl-C on `herbctl pack`. Before herbd accepted the job (no herbd yet), it exits 130 saying
/// no job was started. Mid-motion, it cancels its job: herbd brakes, retreats and ends the job
/// `JobCancelled`, herbctl says so and exits 130, nothing more is released and the arm stands
/// still. `pack --detach` returns at acceptance with the command that cancels the job, which
/// does.
#[test]
fn an_interrupted_pack_cancels_its_job_and_brakes_the_arm() {
    use herb_ipc::{JobState, JointState, Services, Status, StatusEvent};
    let (dir, prefix, cfg) = setup("interrupt");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let released = || -> usize { claims.jobs().values().map(|r| r.released.len()).sum() };
    // Waiting for a herbd: nothing to cancel. Signals are caught once it says it submits.
    let mut early = pack_objects(&dir, &prefix, "003", 60, false);
    let mut early_out = Follow::new(&mut early);
    herb_testkit::wait_for_log(
        &dir.join("herbctl.log"),
        "submitting job",
        Duration::from_secs(10),
    );
    early.signal(libc::SIGINT);
    early_out.wait_for("no job was started", Duration::from_secs(5));
    assert_eq!(early.wait_for(Duration::from_secs(5)).code(), Some(130));

    let (_lb, _hd) = start_cell(&dir, &cfg);
    let watcher = client(&prefix);
    let services = Services::new(&prefix).unwrap();
    let bus = herb_ipc::bus::Bus::open("e2e-interrupt", &services).unwrap();
    let js = bus
        .subscriber::<JointState>(&services.joint_state())
        .unwrap();
    // The fastest joint's measured speed now (rad/s).
    let speed = || {
        let mut v = None;
        while let Ok(Some(m)) = js.receive() {
            v = Some(
                m.payload()
                    .velocity
                    .iter()
                    .fold(0.0f64, |a, x| a.max(x.abs())),
            );
        }
        v
    };
    let mut ctl = pack_objects(&dir, &prefix, "003,005,011", 120, true);
    let mut out = Follow::new(&mut ctl);
    out.wait_for("object  1/3", Duration::from_secs(60));
    // Interrupted while the arm moves (on its way to the pick station).
    let t0 = Instant::now();
    while speed().is_none_or(|v| v < 0.3) {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the arm never moved"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let at_interrupt = released();
    ctl.signal(libc::SIGINT);
    out.wait_for("interrupted: cancelling job", Duration::from_secs(5));
    out.wait_for(
        "cancelled: the arm braked and retreated",
        Duration::from_secs(20),
    );
    let st = ctl.wait_for(Duration::from_secs(10));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert_eq!(st.code(), Some(130), "{summary}");
    assert_eq!(summary["state"], "Cancelled", "{summary}");
    assert_eq!(summary["interrupted"], "signal", "{summary}");
    let job = summary["job_id"].as_u64().unwrap();
    let seen: Vec<Status> = watcher.statuses().collect();
    let ev = |e: StatusEvent| seen.iter().any(|s| s.job_id == job && s.event == e as u32);
    assert!(ev(StatusEvent::Braked) && ev(StatusEvent::JobCancelled));
    // Nothing released after the interrupt; herbd idle; the arm still (its measured speeds).
    assert_eq!(summary["placed"], at_interrupt as u64, "{summary}");
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(released(), at_interrupt, "{:?}", claims.jobs());
    let s = watcher.status(Duration::from_secs(2)).unwrap();
    assert_eq!((s.job_id, s.state), (0, JobState::Idle as u32), "{s:?}");
    let still = speed().expect("joint states");
    assert!(still < 1e-3, "the arm moves at {still} rad/s");

    // Detached: it returns once the job runs; the command it prints cancels the job.
    let (st, text) = herbctl_output(
        &prefix,
        &["pack", "--objects", "011", "--detach", "--timeout", "60"],
    );
    assert!(st.success(), "{text}");
    let cancel: Vec<&str> = text
        .lines()
        .find_map(|l| l.strip_prefix("cancel it: "))
        .unwrap_or_else(|| panic!("a cancel command: {text}"))
        .split_whitespace()
        .collect();
    assert_eq!(
        cancel[..5],
        ["herbctl", "--prefix", &prefix, "cancel", "--job"]
    );
    let detached = cancel[5];
    assert!(text.contains(&format!("job {detached} accepted")), "{text}");
    assert!(
        text.contains(&format!("herbctl --prefix {prefix} watch")),
        "{text}"
    );
    let o = Command::new(exe("herbctl"))
        .args(&cancel[1..])
        .output()
        .expect("herbctl runs");
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains(&format!("job {detached} cancelled")),
        "{said}"
    );
    claims.check();
}

/// A job fed by hand (`herbctl pack --operator`): at each try of each pick herbctl asks for the
/// object, and the arm waits above the station, the gripper open, until the operator presses
/// Enter; only then does it close (the first grasp misses: the retry asks again, for the same
/// object). `--operator-wait` confirms by itself.
#[test]
fn an_operator_job_confirms_each_object_before_the_close() {
    use herb_ipc::{GripperAction, GripperCommand};
    use std::io::Write;
    let (dir, prefix, cfg) = setup("operator");
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let _lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--miss-grasps", "1"],
        &dir.join("loopback.log"),
    );
    let _hd = spawn(&exe("herbd"), &["--config", cfg_s], &dir.join("herbd.log"));
    let client = client(&prefix);
    let grips = client
        .bus()
        .subscriber::<GripperCommand>(&client.services().gripper_command())
        .unwrap();
    // Whether herbd commanded a close since the last call.
    let closed = || {
        let mut any = false;
        while let Ok(Some(g)) = grips.receive() {
            any |= g.payload().action == GripperAction::Close as u32;
        }
        any
    };
    let mut ctl = Proc(
        Command::new(exe("herbctl"))
            .args(["--prefix", &prefix, "pack", "--objects", "003,005"])
            .args(["--operator", "--json", "--timeout", "200"])
            .current_dir(repo())
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::fs::File::create(dir.join("herbctl.log")).unwrap())
            .spawn()
            .unwrap(),
    );
    let mut stdin = ctl.0.stdin.take().unwrap();
    let mut out = Follow::new(&mut ctl);
    // Two objects, the first asked for twice (its first grasp misses).
    for (what, k) in [("003", 0), ("003", 1), ("005", 2)] {
        out.wait_for(&format!("operator: put {what}"), Duration::from_secs(120));
        if k == 1 {
            assert!(
                out.seen.iter().any(|l| l.contains("again")),
                "{:?}",
                out.seen
            );
        }
        let _ = closed();
        // The arm comes above the station and waits there: no close, however long.
        std::thread::sleep(Duration::from_secs(4));
        assert!(
            !closed(),
            "closed before the confirmation ({what}, ask {k})"
        );
        writeln!(stdin).unwrap();
        out.wait_for("confirmed", Duration::from_secs(10));
        let t0 = Instant::now();
        while !closed() {
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "no close after Enter"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    let st = ctl.wait_for(Duration::from_secs(120));
    let summary = out.last_json().expect("herbctl's JSON summary");
    assert!(st.success(), "{summary}");
    assert_eq!(summary["placed"], 2, "{summary}");
    // --operator-wait: confirmed by itself.
    let (st, text) = herbctl_output(
        &prefix,
        &[
            "pack",
            "--objects",
            "011",
            "--operator",
            "--operator-wait",
            "0.5",
            "--timeout",
            "120",
        ],
    );
    assert!(st.success(), "{text}");
    assert!(
        text.contains("the arm descends in 0.5 s") && text.contains("confirmed"),
        "{text}"
    );
    claims.check();
}
