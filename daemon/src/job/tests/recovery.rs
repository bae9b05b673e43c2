//! Faults and recovery: stale or stopped inputs, brakes, the resume from the measured state
//! (an arm past its limits included), stops, and jobs taken up from the journal.

use super::*;

#[test]
fn a_stale_joint_state_halts_at_once_and_nothing_is_commanded_until_the_resume() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.sag = 0.05e-3; // 0.05 rad/s while unpowered
    let mark = r.fx.out.len();
    r.until_event(200, StatusEvent::Braked);
    let s = r.last(StatusEvent::Fault);
    assert_eq!(s.fault, Fault::JointStateTimeout as u32);
    assert_eq!(
        r.count(is_brake),
        0,
        "the arm is not seen: no brake streamed"
    );
    assert!(matches!(r.phase(), Phase::Faulted { .. }));
    // Faulted: not one joint command, however long it lasts.
    let faulted = r.fx.out.len();
    r.ticks(2000);
    assert!(r.joints_since(faulted).is_empty(), "nothing while faulted");
    let sagged = r.q;
    assert!((sagged[1] - r.joints_since(mark).last().unwrap().position[1]) > 0.09);
    // Back: the first command is the measured (sagged) position, after the window.
    r.js_up = true;
    let back = r.fx.out.len();
    r.until_event(5000, StatusEvent::Resumed);
    let first = r.joints_since(back);
    let first = first.first().expect("commands after the resume");
    assert_eq!(first.position, sagged, "from the state measured after it");
    r.until_event(5000, StatusEvent::JobDone);
}

#[test]
fn joint_states_stopped_are_named_by_the_adapter_and_the_name_follows_it() {
    for (said, fault) in [
        (ArmBlocker::Disabled, Fault::RobotDisabled),
        (ArmBlocker::EStop, Fault::RobotEStop),
        (ArmBlocker::MasterLost, Fault::MasterLost),
        (ArmBlocker::RobotSilent, Fault::RobotSilent),
        (ArmBlocker::RobotError, Fault::RobotError),
    ] {
        let (mut r, _) = streaming();
        r.arm = Some(ArmBlocker::None);
        r.ticks(2);
        r.arm = Some(said);
        r.js_up = false;
        r.until_event(200, StatusEvent::Braked);
        assert_eq!(r.last(StatusEvent::Fault).fault, fault as u32);
        assert_eq!(r.count(is_brake), 0);
        // Refused while it lasts, with the reason in the detail.
        r.ticks(10);
        assert_eq!(
            r.submit(9, &[1]),
            (RejectReason::Busy, 0),
            "a job is still on"
        );
    }
    // An e-stop released into a disable: said once more.
    let (mut r, _) = streaming();
    r.arm = Some(ArmBlocker::EStop);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.arm = Some(ArmBlocker::Disabled);
    r.ticks(50);
    let faults: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Fault)
        .map(|s| s.fault)
        .collect();
    assert_eq!(
        faults,
        vec![Fault::RobotEStop as u32, Fault::RobotDisabled as u32]
    );
    // The adapter silent too (no status for 300 ms): JointStateTimeout, i.e. adapter silent.
    let mut r = Rig::new();
    r.arm = None;
    r.js_up = false;
    r.ticks(400);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::NotReady, Fault::JointStateTimeout as u32)
    );
    // Idle with the robot disabled: refused with the reason, which heartbeats carry too.
    let mut r = Rig::new();
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.ticks(200);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::NotReady, Fault::RobotDisabled as u32)
    );
    let hb =
        r.fx.out
            .iter()
            .rev()
            .find_map(|o| match o {
                Out::Status(s) if event(s) == StatusEvent::Heartbeat => Some(*s),
                _ => None,
            })
            .unwrap();
    assert_eq!(hb.fault, Fault::RobotDisabled as u32);
    r.js_up = true;
    r.arm = Some(ArmBlocker::None);
    r.ticks(200);
    assert_eq!(r.submit(2, &[1]), (RejectReason::None, 0));
}

#[test]
fn a_gripper_state_timeout_brakes_a_seen_arm_then_commands_nothing() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(300, "brake", is_brake);
    r.until_event(300, StatusEvent::Braked);
    let after = r.fx.out.len();
    r.ticks(500);
    assert!(r.joints_since(after).is_empty(), "nothing while faulted");
}

#[test]
fn stale_gripper_state_and_stale_heightmap_are_faults_and_joint_state_comes_first() {
    let (mut r, _) = streaming();
    r.gs_up = false;
    r.until_event(300, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::GripperStateTimeout as u32
    );

    // (waiting for the next object's frame: longer than a scripted plan)
    let mut r = Rig::started(&[1, 2]);
    r.until_event(5000, StatusEvent::Decided);
    r.camera_up = false;
    r.until_event(2500, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::HeightmapTimeout as u32
    );

    // All three stale at once: the joint state is named.
    let (mut r, _) = streaming();
    r.js_up = false;
    r.gs_up = false;
    r.camera_up = false;
    r.until_event(2500, StatusEvent::Fault);
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::JointStateTimeout as u32
    );
}

#[test]
fn a_fault_at_rest_is_braked_at_once_without_a_brake() {
    // Ordering.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    // Waiting for a heightmap.
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.camera_up = false;
    r.frame_stamp = Some(0);
    r.gs_up = false;
    r.until_event(300, StatusEvent::Braked);
    // At the gripper.
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn a_failed_brake_or_a_full_ring_enters_faulted_where_it_stands() {
    let (mut r, _) = streaming();
    r.auto = false;
    r.ticks(2);
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(200, "brake", is_brake);
    let Request::Brake { buf, .. } = r.take() else {
        panic!()
    };
    r.deliver(Response::Failed {
        fault: Fault::Motion,
        buf,
    });
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert!(matches!(r.phase(), Phase::Faulted { .. }));

    let (mut r, _) = streaming();
    r.ticks(2);
    r.fx.refuse = true;
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until_event(200, StatusEvent::Braked);
    assert_eq!(r.count(is_brake), 0);
    assert!(r.job.spare.is_some(), "the brake buffer stays home");
}

#[test]
fn invalid_future_and_out_of_order_states_and_bad_frames_are_rejected_not_latched() {
    let mut r = Rig::new();
    r.js_up = false;
    r.gs_up = false;
    let now = r.now;
    let before = r.job.inputs.js;
    let mut bad = r.js(now);
    bad.position[2] = f64::NAN;
    r.job.joint_state(1, &bad, now, now);
    let future = r.js(now + MAX_FUTURE_STAMP_NS + 1);
    r.job.joint_state(1, &future, now, now);
    let old = JointState {
        header: Header::at(1, now),
        ..r.js(now)
    };
    r.job.joint_state(1, &old, now, now); // seq goes back
    assert_eq!(r.job.inputs.js, before);
    assert_eq!(r.job.rejected_inputs(), 3);
    // 1 ms ahead is allowed; later is allowed only if the clock at receipt is past it.
    let ahead = r.js(now + MAX_FUTURE_STAMP_NS);
    r.job.joint_state(1, &ahead, now, now);
    let late = r.js(now + 5 * MS);
    r.job.joint_state(1, &late, now, now + 5 * MS);
    assert_eq!(r.job.inputs.js, Some(late));
    assert_eq!(r.job.rejected_inputs(), 3);
    // Gripper states likewise.
    let mut g = r.gs(now);
    g.holding = 2;
    r.job.gripper_state(2, &g, now, now);
    assert_eq!(r.job.rejected_inputs(), 4);
    // A frame with a bad grid or header.
    let stamp = r.job.inputs.hm_stamp;
    r.frame.nx = 0;
    r.frame.header.stamp_ns = now + 1;
    let f = r.frame.clone();
    r.job.heightmap(&f, now);
    assert_eq!((r.job.rejected_inputs(), r.job.inputs.hm_stamp), (5, stamp));
}

#[test]
fn the_adapter_back_resumes_after_the_window_from_the_measured_position() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.q[1] += 0.1; // moved while away
    r.js_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    assert_eq!(r.now - back, params().timeouts.resume_after_ns);
    assert_eq!(r.job.out.cmd, Setpoint::at_rest(r.q));
    r.until_event(5000, StatusEvent::JobDone);
}

#[test]
fn a_flapping_adapter_restarts_the_resume_window() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    r.ticks(400);
    r.js_up = false;
    r.ticks(150); // stale again
    r.js_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    assert_eq!(r.now - back, params().timeouts.resume_after_ns);
}

#[test]
fn a_resume_while_holding_replans_only_the_placement_at_the_same_pose() {
    let mut r = Rig::started(&[1]);
    r.until(3000, "close", is_close);
    r.ticks(3); // holding, carrying
    assert!(r.job.holding);
    r.auto = false;
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until_event(200, StatusEvent::Fault);
    r.respond(); // the brake
    r.until_event(50, StatusEvent::Braked);
    r.gs_up = true;
    r.until_plan(1000);
    assert_eq!(r.events().last(), Some(&StatusEvent::Resumed));
    let Request::Plan { motion, pose, .. } = r.take() else {
        panic!()
    };
    assert_eq!(motion, Motion::Place { flip: false });
    assert_eq!(pose, [0.1, 0.2, 0.05, 0.3]);
    let resp = answer(Request::Plan {
        index: 0,
        object: 1,
        from: r.q,
        motion,
        pose,
        buf: buffer(),
    });
    // (the buffer in flight is the rig's; a fresh one stands in for it)
    r.deliver(resp);
    r.auto = true;
    r.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        r.events(),
        vec![Accepted, Decided, Fault, Braked, Resumed, Placed, JobDone],
        "no second Decided"
    );
    assert_eq!(r.last(Placed).pose, [0.1, 0.2, 0.05, 0.3]);
}

#[test]
fn an_object_lost_while_away_is_reported_and_picked_again_for_its_placement() {
    let mut r = Rig::started(&[1]);
    r.until(3000, "close", is_close);
    r.ticks(3);
    r.js_up = false;
    r.gs_up = false;
    r.until_event(300, StatusEvent::Braked);
    // The adapter restarts: the gripper is open, the object fell; closing grasps nothing.
    r.closed = false;
    r.holding = false;
    r.grasps = false;
    r.js_up = true;
    r.gs_up = true;
    r.tick();
    let back = r.now;
    r.until_event(5000, StatusEvent::Resumed);
    let ev = r.events();
    assert_eq!(
        &ev[ev.len() - 2..],
        &[StatusEvent::Resumed, StatusEvent::Fault]
    );
    assert_eq!(r.last(StatusEvent::Fault).fault, Fault::ObjectLost as u32);
    assert!(back > 0);
    r.grasps = true; // the object, back at the pick station, is there to grasp
    r.until_event(5000, StatusEvent::JobDone);
    // Picked again and placed where it was decided: one decision, announced once.
    let decided: Vec<Status> = r
        .statuses()
        .into_iter()
        .filter(|s| event(s) == StatusEvent::Decided)
        .collect();
    assert_eq!(decided.len(), 1);
    assert_eq!(r.last(StatusEvent::Placed).pose, decided[0].pose);
}

#[test]
fn a_resume_after_the_last_placement_finishes_the_job() {
    let mut r = Rig::started(&[1]);
    r.until_event(5000, StatusEvent::Placed);
    r.ticks(2); // retreating
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    r.until_event(5000, StatusEvent::JobDone);
    let ev = r.events();
    assert_eq!(
        &ev[ev.len() - 2..],
        &[StatusEvent::Resumed, StatusEvent::JobDone]
    );
}

#[test]
fn a_stop_while_streaming_brakes_then_finishes_without_a_fault_event() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.auto = false;
    r.stop = true;
    r.tick();
    assert!(!r.finished, "braking");
    assert_eq!(r.fx.out.iter().filter(|o| is_brake(o)).count(), 1);
    assert!(!r.events().contains(&StatusEvent::Fault));
    r.respond();
    let mut n = 0;
    while !r.finished {
        r.tick();
        n += 1;
        assert!(n < 20);
    }
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert_eq!(r.last(StatusEvent::Braked).fault, Fault::Stop as u32);
}

/// The planner never answers the stop's brake (stuck behind a long plan): the stop does not
/// wait for it past [`STOP_LIMIT_NS`]; the arm is held where the last command put it (zero
/// velocity) and the loop may exit, so herbd exits within 2 s of SIGTERM whatever it does.
#[test]
fn a_stop_whose_brake_never_comes_ends_at_the_stop_limit() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.auto = false;
    r.stop = true;
    r.tick();
    let began = r.now;
    assert!(!r.finished, "braking");
    while !r.finished {
        r.tick();
        assert!(
            r.now - began <= STOP_LIMIT_NS + 2 * PERIOD,
            "still not stopped"
        );
    }
    assert!(
        r.now - began >= STOP_LIMIT_NS,
        "waited for the brake until the limit"
    );
    let last = r.joints_since(0).last().copied().expect("commands");
    assert!(last.velocity.iter().all(|v| *v == 0.0), "{last:?}");
}

#[test]
fn a_stop_while_idle_halts_nothing_and_finishes_idle() {
    // Nothing runs: nothing is halted, and the shutdown reports the idle state.
    let mut r = Rig::new();
    r.stop = true;
    r.tick();
    assert!(r.finished);
    assert_eq!(r.events(), vec![]);
    let s = r.job.status(StatusEvent::Shutdown);
    assert_eq!((s.job_id, s.object_type), (0, NO_OBJECT));
    assert_eq!(s.state, JobState::Idle as u32);
}

#[test]
fn a_stop_while_planning_drops_the_late_plan_and_blocks_resume() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    r.stop = true;
    r.tick();
    assert!(r.finished);
    r.respond();
    assert!(!r.events().contains(&StatusEvent::Decided));
    let mark = r.fx.out.len();
    r.ticks(1000);
    assert!(!r.events().contains(&StatusEvent::Resumed));
    assert_eq!(r.count(is_plan), 1);
    assert!(
        r.joints_since(mark)
            .iter()
            .all(|c| c.velocity == [0.0; DOF])
    );
}

#[test]
fn a_recovered_job_holding_its_object_places_it_where_it_was_decided() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    // Carrying it to its placement (the place planned).
    while a
        .job
        .journal()
        .placement
        .is_none_or(|p| p.release_q.is_none())
    {
        a.tick();
    }
    a.ticks(50);
    let rec = a.job.journal();
    assert!(rec.holding && rec.phase == ObjectPhase::Carrying, "{rec:?}");
    let decided = rec.placement.unwrap().pose;

    let mut b = restarted(&a, &rec, true);
    b.auto = false;
    let mark = b.fx.out.len();
    b.tick();
    // The fault is reported and the planner gets the journal's order, unsearched.
    assert_eq!(
        b.last(StatusEvent::Fault).fault,
        herb_ipc::Fault::Restarted as u32
    );
    let Request::Order {
        objects,
        count,
        ordered,
        ..
    } = b.take()
    else {
        panic!("an order")
    };
    assert!(ordered);
    assert_eq!(&objects[..count], &[2, 1]);
    b.deliver(answer(Request::Order {
        job_id: 7,
        objects,
        count,
        ordered,
    }));
    b.auto = true;
    // Nothing is commanded before the inputs have been fresh for the resume window.
    b.until_event(2000, StatusEvent::Resumed);
    let resumed =
        b.fx.out
            .iter()
            .position(|o| matches!(o, Out::Status(s) if event(s) == StatusEvent::Resumed))
            .unwrap();
    assert!(
        b.fx.out[mark..resumed]
            .iter()
            .all(|o| !matches!(o, Out::Joint(_))),
        "no joint command before the resume"
    );
    assert!(
        b.fx.out[resumed..].iter().any(is_plan),
        "the placement is planned at the resume"
    );
    b.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Placed, Decided, Placed, JobDone]
    );
    let placed: Vec<Status> = b
        .statuses()
        .into_iter()
        .filter(|s| event(s) == Placed)
        .collect();
    assert_eq!(
        placed[0].pose, decided,
        "placed where decided before the crash"
    );
    assert_eq!(
        (placed[0].object_type, placed[1].object_type),
        (2, 1),
        "each object once, in the order"
    );
    assert_eq!(b.last(JobDone).objects_done, 2);
    assert_eq!(b.job.journal(), JobRecord::NONE);
}

#[test]
fn a_restart_while_waiting_for_a_decision_decides_again_and_places_it_as_it_is_held() {
    let mut a = Rig::started(&[1, 2]);
    a.decide_after = None;
    while !matches!(a.phase(), Phase::AwaitDecision { .. }) {
        a.tick();
        assert!(a.now < 20_000 * MS);
    }
    let mut rec = a.job.journal();
    assert!(rec.holding && rec.placement.is_none(), "{rec:?}");
    assert_eq!(rec.phase, ObjectPhase::Carrying);
    // Say its pick took it turned by a half turn: the place must turn it back.
    rec.flip = true;
    let mut b = restarted(&a, &rec, true);
    b.until_event(2000, StatusEvent::Resumed);
    b.auto = false;
    b.until_plan(200);
    let Request::Plan {
        index,
        motion,
        pose,
        ..
    } = b.take()
    else {
        panic!("a plan")
    };
    assert_eq!(
        (index, motion, pose),
        (0, Motion::Place { flip: true }, pose_of(0))
    );
    b.auto = true;
    b.deliver(answer(Request::Plan {
        index,
        object: 2,
        from: b.q,
        motion,
        pose,
        buf: buffer(),
    }));
    b.until_event(8000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Decided, Placed, Decided, Placed, JobDone]
    );
}

#[test]
fn a_release_the_journal_missed_counts_the_object_placed_once() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    a.until(3000, "open", is_open);
    // The crash comes after the open command, before the gripper's answer reached the journal.
    let rec = a.job.journal();
    assert!(rec.holding, "{rec:?}");
    a.closed = false;
    a.holding = false;
    let mut b = restarted(&a, &rec, true);
    b.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        b.events(),
        vec![Fault, Resumed, Placed, Decided, Placed, JobDone]
    );
    // One decision: only the second object is picked.

    // Away from the release configuration, the same journal means the object was lost: it is
    // picked again.
    let mut c = restarted(&a, &rec, true);
    c.q[0] += 0.1;
    c.until_event(5000, StatusEvent::JobDone);
    assert!(
        c.statuses()
            .iter()
            .any(|s| s.fault == herb_ipc::Fault::ObjectLost as u32)
    );
    // Both objects picked: the first again, picked and placed in one plan where it was decided
    // before the crash (announced then, so only the second's Decided is sent now); the second
    // picked, then placed once decided.
    assert_eq!(
        c.count(is_plan),
        3,
        "the first's pick and place, the second's pick, its place"
    );
    assert_eq!(
        c.events()
            .iter()
            .filter(|e| **e == StatusEvent::Decided)
            .count(),
        1,
        "the first was announced before the crash"
    );
}

#[test]
fn an_abandoned_job_ends_failed_without_moving() {
    let mut a = Rig::started(&[1, 2]);
    a.until(3000, "close", is_close);
    let rec = a.job.journal();
    let mut b = restarted(&a, &rec, false);
    let mark = b.fx.out.len();
    b.ticks(1000);
    use StatusEvent::*;
    assert_eq!(b.events(), vec![Fault, JobFailed]);
    assert_eq!(b.last(JobFailed).fault, herb_ipc::Fault::Restarted as u32);
    assert!(b.joints_since(mark).is_empty());
    assert_eq!(b.count(|o| matches!(o, Out::Plan(_))), 0);
    assert_eq!(b.job.journal(), JobRecord::NONE);
    // The abandoned job's object is still in the gripper: the next job is refused until it is
    // taken out, then runs.
    assert_eq!(b.submit(8, &[3]), (RejectReason::Holding, NO_OBJECT));
    b.holding = false;
    b.closed = false;
    b.ticks(2);
    assert_eq!(b.submit(9, &[3]), (RejectReason::None, 0));
    b.until_event(5000, JobDone);
}

/// Disabled mid-motion, the arm sags past herbd's limit on s1 (inside the arm's own): enabled
/// again, the job resumes, says which joint is outside, where and which limit (a Fault status,
/// the job still running), streams from where the arm stands (commands between it and the
/// limit pass the guard) and finishes. Configured to refuse, the job holds, says so once, and
/// a new job is refused as not ready, naming the joint, until the arm is moved inside.
#[test]
fn an_arm_sagged_past_a_limit_is_named_and_the_job_resumes_or_holds() {
    let (mut r, _) = streaming();
    r.ticks(5);
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    let upper = r.job.p.upper[1];
    r.q[1] = upper + 0.0034; // sagged past 0.997 to 1.0004
    r.ticks(50);
    r.arm = Some(ArmBlocker::None);
    r.js_up = true;
    r.until_event(2_000, StatusEvent::Resumed);
    r.tick();
    let f = *fault_statuses(&r).last().unwrap();
    assert_eq!(f.fault, Fault::OutsideLimits as u32);
    assert_eq!(f.state, JobState::Running as u32, "not a halt");
    let (joint, q, bound) = f.limit_excess().expect("the joint named");
    assert_eq!(joint, 1);
    assert!((q as f64 - (upper + 0.0034)).abs() < 1e-6 && (bound as f64 - upper).abs() < 1e-6);
    assert!(
        f.limit_words().unwrap().starts_with("left_s1 at "),
        "{:?}",
        f.limit_words()
    );
    let holds = r.job.limit_holds();
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 1);
    assert_eq!(
        r.job.limit_holds(),
        holds,
        "no command held back on the way"
    );

    // Refuse: the job holds where it is, says why once, and the next job is refused.
    let (mut r, _) = streaming();
    r.job.p.outside = OutsideLimits::Refuse;
    r.ticks(5);
    r.arm = Some(ArmBlocker::Disabled);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    r.q[1] = upper + 0.0034;
    r.arm = Some(ArmBlocker::None);
    r.js_up = true;
    r.ticks(2_000);
    assert!(!r.events().contains(&StatusEvent::Resumed));
    let said: Vec<u32> = fault_statuses(&r).iter().map(|s| s.fault).collect();
    assert_eq!(
        said,
        vec![Fault::RobotDisabled as u32, Fault::OutsideLimits as u32],
        "said once"
    );
    assert_eq!(r.job.state(), JobState::Faulted);
    // Moved inside by hand: it resumes.
    r.q[1] = upper - 0.01;
    r.until_event(2_000, StatusEvent::Resumed);
    run_to_done(&mut r);
    r.q[1] = upper + 0.0034;
    r.ticks(200);
    assert_eq!(
        r.submit(5, &[1]),
        (RejectReason::NotReady, Fault::OutsideLimits as u32)
    );
    r.ticks(150);
    let hb =
        r.fx.out
            .iter()
            .rev()
            .find_map(|o| match o {
                Out::Status(s) if event(s) == StatusEvent::Heartbeat => Some(*s),
                _ => None,
            })
            .unwrap();
    assert_eq!(
        hb.limit_excess().map(|e| e.0),
        Some(1),
        "the heartbeat names the joint"
    );
    assert_eq!(r.job.rejected_requests(), 1);
    // Beyond the arm's own limit: refused whatever the setting.
    r.job.p.outside = OutsideLimits::Recover;
    r.q[1] = r.job.p.arm_range.1[1] + 0.01;
    r.ticks(150);
    assert_eq!(
        r.submit(6, &[1]),
        (RejectReason::NotReady, Fault::BeyondArmLimits as u32)
    );
}
