//! herbd's own life: killed, stopped by SIGTERM, restarted on its journal, a second daemon on
//! the same prefix, and the client following it through all of that.

use super::*;

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

/// The worst stop found: SIGTERM while the arm moves in a job, with herbd's stderr a pipe
/// that nobody reads (full: its log writer blocks in `write`, as when journald stalls) and
/// the arm adapter stopped (SIGSTOP) the moment before. herbd used to wait for its log writer
/// for ever; it exits within 2 s of the signal, cut short by its stop's deadline (exit 3).
#[test]
fn sigterm_ends_herbd_within_2_s_with_a_blocked_log_and_a_stopped_adapter() {
    let (dir, prefix, cfg) = setup("stopdeadline");
    // Statistics every 100 ms (its shortest) into a pipe of one page.
    let text = std::fs::read_to_string(&cfg)
        .unwrap()
        .replace("report_interval_s = 5.0", "report_interval_s = 0.1");
    std::fs::write(&cfg, text).unwrap();
    let cfg_s = cfg.to_str().unwrap();
    let lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s],
        &dir.join("loopback.log"),
    );
    let mut hd = Command::new(exe("herbd"))
        .args(["--config", cfg_s])
        .current_dir(repo())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("herbd starts");
    // herbd's log is read until the job runs, then no more.
    let reading = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let reader = {
        let reading = reading.clone();
        let mut err = std::io::BufReader::new(hd.stderr.take().expect("herbd's stderr"));
        std::thread::spawn(move || {
            use std::io::BufRead;
            let mut line = String::new();
            while reading.load(std::sync::atomic::Ordering::Relaxed) {
                line.clear();
                if err.read_line(&mut line).unwrap_or(0) == 0 {
                    break;
                }
            }
            err
        })
    };
    let mut ctl = pack_objects(&dir, &prefix, "003,005,011", 120, false);
    let mut ctl_out = Follow::new(&mut ctl);
    ctl_out.wait_for("object  1/3", Duration::from_secs(60));
    reading.store(false, std::sync::atomic::Ordering::Relaxed);
    let unread = reader.join().expect("the reader");
    {
        use std::os::fd::AsRawFd;
        let fd = unread.get_ref().as_raw_fd();
        // SAFETY: fcntl and ioctl on the pipe we hold; `queued` is written by FIONREAD.
        unsafe { libc::fcntl(fd, libc::F_SETPIPE_SZ, 4096) };
        let size = unsafe { libc::fcntl(fd, libc::F_GETPIPE_SZ) };
        let t0 = Instant::now();
        loop {
            let mut queued: libc::c_int = 0;
            unsafe { libc::ioctl(fd, libc::FIONREAD, &mut queued) };
            // Full: no room for another statistics line.
            if queued + 400 >= size {
                break;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(90),
                "herbd's log did not fill the pipe ({queued} of {size} bytes)"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    // The writer is blocked on the full pipe now (its next line does not fit).
    std::thread::sleep(Duration::from_millis(500));
    assert!(hd.try_wait().unwrap().is_none(), "herbd runs");
    lb.signal(libc::SIGSTOP);
    // SAFETY: kill on a child we own.
    unsafe { libc::kill(hd.id() as i32, libc::SIGTERM) };
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = hd.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "herbd still runs 5 s after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    let took = t0.elapsed();
    lb.signal(libc::SIGCONT);
    assert!(
        took <= Duration::from_secs(2),
        "herbd took {took:?} to exit after SIGTERM"
    );
    // Cut short by its stop's deadline (exit 3): its log writer was blocked.
    assert_eq!(status.code(), Some(3), "exit status {status:?}");
    drop(unread);
    let _ = ctl.wait_for(Duration::from_secs(10));
}
