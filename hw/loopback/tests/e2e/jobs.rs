//! Jobs one after another: cancels, resets, missed grasps, interrupted packs and the
//! operator's confirmations, each job claiming only what it placed.

use super::*;

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
