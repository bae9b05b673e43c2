//! Faults and bad input from the adapters and clients: a killed or stalled loopback, bad jobs,
//! payloads, heightmap frames and joint states are refused, counted and survived.

use super::*;

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
