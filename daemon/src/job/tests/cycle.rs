//! One object's cycle: the decision beside the pick, the samples streamed, the grasp (after
//! the operator's confirmation when asked for), missed grasps, the release, whole jobs.

use super::*;

#[test]
fn the_next_decision_is_asked_for_on_a_frame_newer_than_the_release() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    // The first object's decision, by hand.
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(decided(&d));
    r.until_event(5000, StatusEvent::Placed);
    r.until(1000, "decision request", |o| matches!(o, Out::Decide(1)));
    let d = r.take_decision();
    assert_eq!(d.index, 1);
    assert!(r.job.release_stamp > 0);
    assert_eq!(d.after_stamp_ns, r.job.release_stamp);
}

#[test]
fn no_fresh_heightmap_within_fresh_heightmap_timeout_faults() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    let since = r.now;
    let t = params().timeouts.fresh_heightmap_ns;
    // The worker answers every request: no frame newer than the release came in time.
    let mut asked = 0;
    while r.now <= since + t + 2 * PERIOD && !r.events().contains(&StatusEvent::Fault) {
        r.tick();
        while !r.fx.decisions.is_empty() {
            let d = r.take_decision();
            asked += 1;
            r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
        }
    }
    assert!(asked > 1, "asked again after each timeout ({asked})");
    let s = r.last(StatusEvent::Fault);
    assert_eq!(s.fault, Fault::HeightmapTimeout as u32);
    assert!(r.now > since + t, "not before the timeout");
    // Held at the lift pose, at rest: faulted at once, no brake.
    assert_eq!(r.events().last(), Some(&StatusEvent::Braked));
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn the_workers_heightmap_timeout_asks_again_silently() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
    assert!(!r.events().contains(&StatusEvent::Fault), "no fault event");
    assert_eq!(
        r.job.status(StatusEvent::Heartbeat).fault,
        Fault::None as u32,
        "nor fault"
    );
    // and asks again
    r.tick();
    assert_eq!(r.fx.decisions.len(), 1);
    assert_eq!(r.fx.decisions[0].index, 0);
}

#[test]
fn a_full_planner_ring_keeps_waiting_and_retries() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    let resp = answer(r.take());
    r.fx.refuse = true;
    r.deliver(resp);
    r.ticks(20);
    assert_eq!(r.phase(), Phase::Starting);
    assert!(r.job.spare.is_some(), "the buffer stays home");
    r.fx.refuse = false;
    r.tick();
    assert_eq!(r.phase(), Phase::Planning);
}

#[test]
fn a_full_decision_ring_asks_again_on_a_later_tick() {
    let mut r = Rig::new();
    r.fx.refuse_decisions = true;
    r.decide_after = None;
    r.submit(7, &[1]);
    r.ticks(20);
    assert!(r.fx.decisions.is_empty());
    r.fx.refuse_decisions = false;
    r.tick();
    assert_eq!(r.fx.decisions.len(), 1, "asked once the ring has room");
}

#[test]
fn decided_is_reported_with_pose_and_latency_while_the_pick_streams() {
    let mut r = Rig::started(&[4, 5]);
    r.until_event(5000, StatusEvent::Decided);
    let s = r.last(StatusEvent::Decided);
    assert_eq!(
        (s.job_id, s.object_type, s.object_index, s.decision_ns),
        (7, 5, 0, DECISION_NS)
    );
    assert_eq!(s.pose, pose_of(0));
    assert!(matches!(r.phase(), Phase::Streaming { seg: 0, .. }));
}

#[test]
fn a_decision_before_the_lift_costs_no_wait() {
    let mut r = Rig::started(&[1, 2, 3]);
    let mut waited = false;
    while !r.events().contains(&StatusEvent::JobDone) {
        r.tick();
        waited |= matches!(r.phase(), Phase::AwaitDecision { .. });
        assert!(r.now < 10_000 * MS + 60_000 * MS, "the job ends");
    }
    let done = r.last(StatusEvent::JobDone);
    assert_eq!((done.objects_done, done.decision_wait_ms), (3, 0));
    // The place is asked for at the lift, with the decision already in: one planning round
    // trip, not a wait.
    assert!(!waited || r.job.progress().wait_ns < 5 * PERIOD);
    // Every object: decided once, picked, then placed where decided.
    let placed: Vec<_> = r
        .statuses()
        .into_iter()
        .filter(|s| event(s) == StatusEvent::Placed)
        .map(|s| s.pose)
        .collect();
    assert_eq!(placed, vec![pose_of(0), pose_of(1), pose_of(2)]);
}

#[test]
fn a_decision_after_the_lift_holds_the_object_there_and_counts_the_wait() {
    let mut r = Rig::started(&[1, 2]);
    // The pick (three scripted segments and a grasp) takes well under 2 s; the decision 2 s.
    r.decide_after = Some(2000);
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS, "never held waiting");
    }
    let Phase::AwaitDecision { since } = r.phase() else {
        unreachable!()
    };
    assert!(r.job.holding, "held at the lift pose");
    assert!(!r.events().contains(&StatusEvent::Decided));
    // Held still: commands at rest where the lift ended, and nothing planned meanwhile.
    let (mark, q, plans) = (r.fx.out.len(), r.q, r.count(is_plan));
    r.ticks(100);
    let held = r.joints_since(mark);
    assert!(!held.is_empty());
    assert!(
        held.iter()
            .all(|c| c.position == q && c.velocity == [0.0; DOF])
    );
    assert_eq!(r.count(is_plan), plans);
    r.until_event(3000, StatusEvent::Decided);
    let first_wait_ms = (r.now - since) / MS;
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 2);
    assert!(
        done.decision_wait_ms as u64 >= first_wait_ms && first_wait_ms > 0,
        "the wait is counted: {} ms reported, {first_wait_ms} ms for the first object",
        done.decision_wait_ms
    );
}

#[test]
fn new_heightmaps_during_a_decision_ask_for_nothing_more() {
    let mut r = Rig::started(&[1]);
    r.decide_after = Some(1500);
    r.until_event(5000, StatusEvent::Decided);
    // About 15 frames came in meanwhile: one request, decided on the frame the worker took.
    assert_eq!(r.count(|o| matches!(o, Out::Decide(_))), 1);
    assert_eq!(run_to_done(&mut r).objects_done, 1);
}

#[test]
fn a_failed_decision_before_the_grasp_ends_the_job_at_the_next_standstill_gripper_open() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::NoFeasiblePlacement));
    r.until_event(2000, StatusEvent::JobFailed);
    let s = r.last(StatusEvent::JobFailed);
    assert_eq!(s.fault, Fault::NoFeasiblePlacement as u32);
    assert_eq!(r.count(is_close), 0, "never grasped");
    assert!(!r.holding);
    assert_eq!(r.job.out.cmd.velocity, [0.0; DOF], "at rest");
    assert_eq!(r.phase(), Phase::Idle);
}

#[test]
fn a_failed_decision_after_the_grasp_ends_the_job_at_the_lift_pose_holding_the_object() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    r.until(2000, "close", is_close);
    let d = r.take_decision();
    r.deliver_decision(failed_decision(&d, Fault::Decision));
    r.until_event(2000, StatusEvent::JobFailed);
    assert_eq!(r.last(StatusEvent::JobFailed).fault, Fault::Decision as u32);
    assert!(r.holding, "held, not dropped");
    assert_eq!(r.job.out.cmd.velocity, [0.0; DOF], "at rest after the lift");
    assert!(!r.events().contains(&StatusEvent::Placed));
}

#[test]
fn a_hung_decision_fails_the_job_after_the_decision_timeout() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.until(50, "decision request", |o| matches!(o, Out::Decide(0)));
    let asked = r.now;
    r.until_event(30_000, StatusEvent::JobFailed);
    assert_eq!(r.last(StatusEvent::JobFailed).fault, Fault::Decision as u32);
    assert!(r.now >= asked + params().decision_timeout_ns);
    assert!(r.holding, "held at the lift pose");
    // The late answer changes nothing.
    let d = r.take_decision();
    let n = r.statuses().len();
    r.deliver_decision(decided(&d));
    r.ticks(5);
    assert!(
        !r.statuses()[n..]
            .iter()
            .any(|s| event(s) == StatusEvent::Decided)
    );
}

#[test]
fn a_cancel_while_waiting_for_a_decision_retreats_and_ignores_the_late_decision() {
    let mut r = Rig::started(&[1, 2]);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    assert_eq!(r.cancel(7), RejectReason::None);
    r.until_event(2000, StatusEvent::JobCancelled);
    let d = r.take_decision();
    r.deliver_decision(decided(&d));
    r.ticks(5);
    assert!(!r.events().contains(&StatusEvent::Decided));
    assert_eq!(r.phase(), Phase::Idle);
}

#[test]
fn a_stop_while_waiting_for_a_decision_lets_herbd_exit_at_once() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    r.stop = true;
    r.tick();
    assert!(r.finished, "at rest: nothing to brake");
    assert_eq!(r.count(is_brake), 0);
}

#[test]
fn a_worker_that_never_finds_a_frame_faults_at_the_fresh_heightmap_timeout() {
    // The loop sees frames (their headers are fine) but the decision worker rejects every one
    // (a bad cell): its 500 ms waits must not restart the loop's fresh-heightmap clock.
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.tick(); // ordered: the pick starts, the decision is asked for
    let start = r.now;
    let t = params().timeouts.fresh_heightmap_ns;
    while !r.events().contains(&StatusEvent::Fault) {
        assert!(
            r.now < start + t + 1000 * MS,
            "no fault after {} ms",
            (r.now - start) / MS
        );
        if !r.fx.decisions.is_empty() {
            let d = r.take_decision();
            r.ticks(500); // the worker's wait
            r.deliver_decision(failed_decision(&d, Fault::HeightmapTimeout));
        }
        r.tick();
    }
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        Fault::HeightmapTimeout as u32
    );
    assert!(r.now > start + t);
}

#[test]
fn planner_failures_fail_the_job_with_their_fault() {
    for fault in [
        Fault::Unreachable,
        Fault::Decision,
        Fault::Motion,
        Fault::NoFeasiblePlacement,
    ] {
        let mut r = Rig::started(&[1]);
        r.auto = false;
        r.tick();
        r.respond();
        r.until_plan(50);
        let Request::Plan { buf, .. } = r.take() else {
            panic!()
        };
        r.deliver(Response::Failed { fault, buf });
        let s = r.last(StatusEvent::JobFailed);
        assert_eq!(
            (s.job_id, s.state, s.fault),
            (7, JobState::Failed as u32, fault as u32)
        );
        assert_eq!(r.phase(), Phase::Idle);
        assert!(
            r.job.spare.is_some() && r.job.active.is_some(),
            "buffers home"
        );
        // Both buffers home: the next job plans.
        r.auto = true;
        assert_eq!(r.submit(8, &[1]), (RejectReason::None, 0));
        r.until_event(5000, StatusEvent::JobDone);
    }
}

#[test]
fn a_plan_arriving_after_a_fault_is_recycled_and_the_resume_waits_for_it() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    assert!(matches!(r.phase(), Phase::Planning));
    // The adapter goes away while the planner works.
    r.js_up = false;
    r.until_event(200, StatusEvent::Braked);
    r.js_up = true;
    let resume = params().timeouts.resume_after_ns / PERIOD;
    r.ticks(resume as usize + 10);
    assert!(
        matches!(r.phase(), Phase::Faulted { .. }),
        "no resume while the plan is out"
    );
    let late = r.take();
    let resp = answer(late);
    r.deliver(resp);
    assert!(
        matches!(r.phase(), Phase::Faulted { .. }),
        "a late plan is not used"
    );
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::Resumed));
    // Starts the pick over; the decision asked for before the fault comes now.
    r.auto = true;
    r.decide_after = Some(1);
    r.until_event(5000, StatusEvent::JobDone);
    assert_eq!(
        r.events(),
        vec![
            StatusEvent::Accepted,
            StatusEvent::Fault,
            StatusEvent::Braked,
            StatusEvent::Resumed,
            StatusEvent::Decided,
            StatusEvent::Placed,
            StatusEvent::JobDone
        ]
    );
}

#[test]
fn samples_are_streamed_one_per_tick_bit_for_bit_and_segment_ends_are_at_rest() {
    let (mut r, samples) = streaming();
    let mark = r.fx.out.len();
    r.ticks(SEG + 1);
    let sent = r.joints_since(mark);
    assert_eq!(&sent[..SEG], &samples[..SEG]);
    // The segment's end: same position, at rest.
    assert_eq!(sent[SEG], Setpoint::at_rest(samples[SEG - 1].position));
    // Then the next segment (no action at the first one's end).
    let mark = r.fx.out.len();
    r.tick();
    assert_eq!(r.joints_since(mark), vec![samples[SEG]]);
}

#[test]
fn close_is_sent_at_once_with_the_object_type_and_the_arm_waits_at_rest() {
    let (mut r, _) = streaming();
    r.grasps = false; // the gripper closes on nothing
    r.until(3000, "close", is_close);
    let Some(Out::Gripper {
        job_id,
        object_type,
        ..
    }) =
        r.fx.out
            .iter()
            .rev()
            .find(|o| matches!(o, Out::Gripper { .. }))
    else {
        panic!()
    };
    assert_eq!((*job_id, *object_type), (7, 3));
    let Phase::Gripper { action, .. } = r.phase() else {
        panic!("{:?}", r.phase())
    };
    assert_eq!(action, GripperAction::Close);
    let mark = r.fx.out.len();
    r.ticks(50);
    let held = r.joints_since(mark);
    assert!(held.iter().all(|c| *c == Setpoint::at_rest(r.q)), "at rest");
}

#[test]
fn close_waits_for_a_state_stamped_after_the_command() {
    let (mut r, _) = streaming();
    r.gs_lag = 3 * MS; // the adapter's states describe the gripper 3 ms ago
    r.until(3000, "close", is_close);
    let Phase::Gripper { since, .. } = r.phase() else {
        panic!()
    };
    // The gripper is closed and holding from the next state on, but those states are stamped
    // before the command until the lag has passed.
    let mut left = 0;
    while matches!(r.phase(), Phase::Gripper { .. }) {
        r.tick();
        left += 1;
        assert!(left < 100);
    }
    assert_eq!(
        r.now - since,
        3 * MS,
        "left the wait at the first state stamped at `since`"
    );
    assert!(r.job.holding);
}

#[test]
fn open_reports_placed_and_the_release_stamp_gates_the_next_plan() {
    let mut r = Rig::started(&[1, 2]);
    r.gs_lag = 2 * MS;
    r.until_event(5000, StatusEvent::Placed);
    let s = r.last(StatusEvent::Placed);
    assert_eq!(
        (s.objects_done, s.object_index, s.object_type, s.decision_ns),
        (1, 0, 2, DECISION_NS)
    );
    assert_eq!(s.pose, [0.1, 0.2, 0.05, 0.3]);
    // The release is when the open gripper was observed, not when it was reported.
    assert_eq!(r.job.release_stamp, r.now - 2 * MS);
    assert!(!r.job.holding);
    assert_eq!(r.job.progress().index, 1);
}

#[test]
fn a_missed_grasp_opens_and_picks_again_at_the_same_placement_without_a_new_decision() {
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    let Phase::Gripper { since, .. } = r.phase() else {
        panic!()
    };
    let t = params().timeouts.gripper_action_ns;
    while r.now < since + t {
        r.tick();
    }
    assert!(matches!(r.phase(), Phase::Gripper { .. }), "not yet");
    r.grasps = true; // the operator puts the object there
    r.tick();
    assert_eq!(
        r.last(StatusEvent::Fault).fault,
        herb_ipc::Fault::MissedGrasp as u32
    );
    assert!(matches!(r.phase(), Phase::Regrasp { .. }));
    r.until(100, "open", is_open);
    r.until_event(5000, StatusEvent::JobDone);
    use StatusEvent::*;
    let decided = r.events().iter().filter(|e| **e == Decided).count();
    assert_eq!(decided, 1, "announced once: {:?}", r.events());
    let s = r.last(JobDone);
    assert_eq!(
        (s.objects_done, s.fault),
        (1, herb_ipc::Fault::MissedGrasp as u32)
    );
    assert_eq!(r.count(is_brake), 0, "the arm was at rest");
}

#[test]
fn grasps_missed_past_the_retries_skip_the_object_and_the_job_goes_on() {
    let mut r = Rig::started(&[1, 2]);
    r.grasps = false;
    r.until_event(20_000, StatusEvent::Skipped);
    let s = r.last(StatusEvent::Skipped);
    assert_eq!(s.fault, Fault::MissedGrasp as u32);
    r.grasps = true;
    r.until_event(10_000, StatusEvent::JobDone);
    let ev = r.events();
    let misses = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Fault && s.fault == Fault::MissedGrasp as u32)
        .count();
    assert_eq!(misses, 1 + params().grasp_retries as usize, "{ev:?}");
    let done = r.last(StatusEvent::JobDone);
    assert_eq!((done.objects_done, done.objects_total), (1, 2));
    // The next job starts from an open gripper.
    let mark = r.fx.out.len();
    assert_eq!(r.submit(8, &[3]), (RejectReason::None, 0));
    r.tick();
    assert!(r.fx.out[mark..].iter().any(is_open), "opened at the start");
}

#[test]
fn the_gripper_command_repeats_every_100_ms_while_a_job_runs() {
    let (mut r, _) = streaming();
    r.grasps = false;
    r.until(3000, "close", is_close);
    let first = r.now;
    let mut at = vec![];
    while r.now < first + 350 * MS {
        let mark = r.fx.out.len();
        r.tick();
        if r.fx.out[mark..]
            .iter()
            .any(|o| matches!(o, Out::Gripper { .. }))
        {
            at.push(r.now - first);
        }
    }
    assert_eq!(at, vec![100 * MS, 200 * MS, 300 * MS]);
}

#[test]
fn the_last_placement_reports_job_done_then_the_job_id_is_cleared() {
    let mut r = Rig::started(&[1, 2, 3]);
    r.until_event(10000, StatusEvent::JobDone);
    let s = r.last(StatusEvent::JobDone);
    assert_eq!(
        (s.job_id, s.state, s.objects_done, s.objects_total),
        (7, JobState::Done as u32, 3, 3)
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(150);
    assert!(r.joints_since(mark).is_empty(), "no command after the job");
    let hb = r.fx.out[mark..]
        .iter()
        .find_map(|o| match o {
            Out::Status(s) => Some(*s),
            _ => None,
        })
        .expect("a heartbeat");
    assert_eq!((hb.job_id, hb.state), (0, JobState::Idle as u32));
}

#[test]
fn a_three_object_job_reports_the_golden_event_sequence() {
    let mut r = Rig::started(&[10, 11, 12]);
    r.until_event(10000, StatusEvent::JobDone);
    use StatusEvent::*;
    assert_eq!(
        r.events(),
        vec![
            Accepted, Decided, Placed, Decided, Placed, Decided, Placed, JobDone
        ]
    );
    let types: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == Placed)
        .map(|s| s.object_type)
        .collect();
    assert_eq!(types, vec![12, 11, 10], "in the planner's order");
    let closes = r.count(|o| {
        matches!(
            o,
            Out::Gripper {
                action: GripperAction::Close,
                ..
            }
        )
    });
    assert!(closes >= 3);
    assert_eq!(r.job.limit_holds(), 0);
}

/// A job fed by a person (`CONFIRM_PICKS`): each try of each pick asks for the object
/// (`AwaitingObject`, with the try), and the arm holds above the station, the gripper not
/// closed, until the confirmation for that object and try comes; a confirmation for another
/// try or object, or for a job that does not ask, is refused (`NotAwaited`). After a missed
/// grasp, the retry asks again.
#[test]
fn a_job_fed_by_hand_waits_above_the_station_for_each_confirmation() {
    let mut r = Rig::new();
    r.grasps = false; // the first grasp misses
    let mut req = PackJobRequest::new(1, &[3]);
    req.flags = PackJobRequest::CONFIRM_PICKS;
    assert_eq!(r.request(&req).0, RejectReason::None);
    r.until_event(500, StatusEvent::AwaitingObject);
    let asked = r.last(StatusEvent::AwaitingObject);
    assert_eq!((asked.object_index, asked.attempt), (0, 0));
    // The arm goes above the station and stays there: no close.
    r.ticks(3 * SEG);
    assert!(
        matches!(r.phase(), Phase::AwaitOperator { .. }),
        "{:?}",
        r.phase()
    );
    let closes = |r: &Rig| {
        r.fx.out
            .iter()
            .filter(|o| {
                matches!(
                    o,
                    Out::Gripper {
                        action: GripperAction::Close,
                        ..
                    }
                )
            })
            .count()
    };
    assert_eq!(closes(&r), 0);
    let confirm = |r: &mut Rig, index: u32, attempt: u32| {
        let c = ConfirmPickRequest::new(r.job.job_id(), index, attempt);
        r.job.confirm_request(&c, &mut r.fx);
        match r.fx.out.last() {
            Some(Out::ConfirmReply { reason, .. }) => *reason,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(confirm(&mut r, 0, 1), RejectReason::NotAwaited);
    assert_eq!(confirm(&mut r, 1, 0), RejectReason::NotAwaited);
    r.ticks(50);
    assert_eq!(closes(&r), 0, "still waiting");
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::None);
    r.until_event(10_000, StatusEvent::Fault);
    assert_eq!(r.last(StatusEvent::Fault).fault, Fault::MissedGrasp as u32);
    r.grasps = true;
    // The retry asks again, for try 1, and waits.
    r.until_event(10_000, StatusEvent::AwaitingObject);
    assert_eq!(r.last(StatusEvent::AwaitingObject).attempt, 1);
    let before = closes(&r);
    r.ticks(3 * SEG);
    assert_eq!(closes(&r), before);
    assert_eq!(
        confirm(&mut r, 0, 0),
        RejectReason::NotAwaited,
        "the last try's"
    );
    assert_eq!(confirm(&mut r, 0, 1), RejectReason::None);
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 1);
    assert_eq!(r.job.rejected_requests(), 3);
    // A job that does not ask never waits and refuses confirmations.
    let mut r = Rig::started(&[3]);
    r.ticks(10);
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::NotAwaited);
    run_to_done(&mut r);
    assert!(!r.events().contains(&StatusEvent::AwaitingObject));
}

/// A confirmation counts only while herbd awaits it: one sent before the `AwaitingObject` (the
/// job just accepted) is refused `NotAwaited` and not kept, so the arm still waits above the
/// station; every status meanwhile says what the job waits for (`waiting_for`), so a client
/// that connects late sees the wait; a repeat of the accepted confirmation is answered as
/// accepted again, is not counted as refused and changes nothing.
#[test]
fn a_confirmation_before_herbd_asks_is_refused_and_the_wait_is_in_every_heartbeat() {
    let mut r = Rig::new();
    let mut req = PackJobRequest::new(1, &[3]);
    req.flags = PackJobRequest::CONFIRM_PICKS;
    assert_eq!(r.request(&req).0, RejectReason::None);
    let confirm = |r: &mut Rig, index: u32, attempt: u32| {
        let c = ConfirmPickRequest::new(r.job.job_id(), index, attempt);
        r.job.confirm_request(&c, &mut r.fx);
        match r.fx.out.last() {
            Some(Out::ConfirmReply { reason, .. }) => *reason,
            other => panic!("{other:?}"),
        }
    };
    let heartbeat = |r: &Rig| {
        *r.fx
            .out
            .iter()
            .rev()
            .find_map(|o| match o {
                Out::Status(s) if s.event == StatusEvent::Heartbeat as u32 => Some(s),
                _ => None,
            })
            .expect("a heartbeat")
    };
    // Accepted, not yet asked: the confirmation for the very object and try is refused.
    assert!(!r.events().contains(&StatusEvent::AwaitingObject));
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::NotAwaited);
    assert_eq!(r.job.rejected_requests(), 1);
    r.until_event(500, StatusEvent::AwaitingObject);
    let asked = r.last(StatusEvent::AwaitingObject);
    assert_eq!(asked.waiting_for, JobWait::Confirmation as u32);
    // The early confirmation was not kept: the arm waits above the station, and every
    // heartbeat says so, with the object and try.
    r.ticks(3 * SEG);
    assert!(
        matches!(r.phase(), Phase::AwaitOperator { .. }),
        "{:?}",
        r.phase()
    );
    let beat = heartbeat(&r);
    assert_eq!(
        (beat.waiting_for, beat.object_index, beat.attempt),
        (JobWait::Confirmation as u32, 0, 0)
    );
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::None);
    // The reply was slow: the client sends it again; accepted again, not counted.
    assert_eq!(confirm(&mut r, 0, 0), RejectReason::None);
    assert_eq!(r.job.rejected_requests(), 1);
    r.ticks(200);
    assert_eq!(
        heartbeat(&r).waiting_for,
        JobWait::None as u32,
        "the wait ended with the confirmation"
    );
    let done = run_to_done(&mut r);
    assert_eq!(
        (done.objects_done, done.waiting_for),
        (1, JobWait::None as u32)
    );
    // Once the job moved on, the old confirmation is another try's: refused.
    assert_eq!(r.job.rejected_requests(), 1);
}

/// A repeat of the running job's request (same id, objects and flags: its reply was lost) is
/// answered as accepted and restarts nothing; the same id with other objects is `Busy`.
#[test]
fn a_repeated_pack_request_is_accepted_again_and_restarts_nothing() {
    let mut r = Rig::new();
    let req = PackJobRequest::new(1, &[3, 5]);
    assert_eq!(r.request(&req).0, RejectReason::None);
    r.ticks(300);
    let accepted = r
        .events()
        .iter()
        .filter(|e| **e == StatusEvent::Accepted)
        .count();
    assert_eq!(r.request(&req).0, RejectReason::None);
    r.ticks(10);
    assert_eq!(
        r.events()
            .iter()
            .filter(|e| **e == StatusEvent::Accepted)
            .count(),
        accepted,
        "nothing restarted"
    );
    assert_eq!(r.job.rejected_requests(), 0);
    assert_eq!(
        r.request(&PackJobRequest::new(1, &[3])).0,
        RejectReason::Busy
    );
    assert_eq!(
        r.request(&PackJobRequest::new(2, &[3, 5])).0,
        RejectReason::Busy
    );
    assert_eq!(r.job.rejected_requests(), 2);
    let done = run_to_done(&mut r);
    assert_eq!(done.objects_done, 2);
}
