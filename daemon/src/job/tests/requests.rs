//! The machine's inputs: requests answered with their reason (pack, cancel, the gripper
//! holding), orders, and what makes the cell not ready.

use super::*;

#[test]
fn bad_requests_are_answered_with_reason_and_detail_and_counted() {
    let mut r = Rig::new();
    let ok = |r: &Rig| {
        let mut q = PackJobRequest::new(5, &[1, 2, 3]);
        q.header = Header::at(1, r.now);
        q
    };
    let mut v0 = ok(&r);
    v0.header.version = 0;
    let mut id0 = ok(&r);
    id0.job_id = 0;
    let mut empty = ok(&r);
    empty.count = 0;
    let mut too_many = ok(&r);
    too_many.count = 65;
    let mut huge = ok(&r);
    huge.count = u32::MAX;
    let mut unknown = ok(&r);
    unknown.objects[2] = CATALOG as u16;
    let cases = [
        (v0, (RejectReason::Malformed, 0)),
        (id0, (RejectReason::Malformed, 0)),
        (empty, (RejectReason::Empty, 0)),
        (too_many, (RejectReason::TooMany, 65)),
        (huge, (RejectReason::TooMany, u32::MAX)),
        (unknown, (RejectReason::UnknownObject, 2)),
    ];
    for (req, want) in &cases {
        assert_eq!(r.request(req), *want, "{req:?}");
    }
    assert_eq!(r.job.rejected_requests(), cases.len() as u64);
    assert_eq!(r.job.rejected_inputs(), 0, "requests are counted apart");
    assert_eq!(r.phase(), Phase::Idle);
    assert_eq!(r.count(|o| matches!(o, Out::Plan(_))), 0, "nothing ordered");
    assert!(r.events().is_empty(), "no status but heartbeats");
}

#[test]
fn a_malformed_request_while_busy_gets_its_reason_not_busy() {
    let mut r = Rig::started(&[1]);
    assert_eq!(r.submit(8, &[]), (RejectReason::Empty, 0));
    assert_eq!(r.submit(8, &[1, 99]), (RejectReason::UnknownObject, 1));
    assert_eq!(r.submit(8, &[1]), (RejectReason::Busy, 0));
}

#[test]
fn not_ready_without_joint_state_gripper_state_or_a_recent_heightmap() {
    // Never heard from the arm.
    let mut r = Rig::new();
    r.job = Job::new(params(), buffer(), buffer());
    let joint = Fault::JointStateTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, joint));
    // Joint states stale (100 ms), then fresh again.
    let mut r = Rig::new();
    r.js_up = false;
    r.ticks(100);
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, joint));
    r.js_up = true;
    r.tick();
    assert_eq!(r.submit(2, &[1]), (RejectReason::None, 0));
    // Gripper states stale (200 ms).
    let mut r = Rig::new();
    r.gs_up = false;
    r.ticks(199);
    assert_eq!(
        r.submit(1, &[1]),
        (RejectReason::None, 0),
        "199 ms is fresh"
    );
    let mut r = Rig::new();
    r.gs_up = false;
    r.ticks(200);
    let grip = Fault::GripperStateTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, grip));
    // No heightmap for 2 s: the camera counts too.
    let mut r = Rig::new();
    r.camera_up = false;
    r.ticks(2000);
    let camera = Fault::HeightmapTimeout as u32;
    assert_eq!(r.submit(1, &[1]), (RejectReason::NotReady, camera));
    assert_eq!(r.job.rejected_requests(), 1);
}

#[test]
fn a_second_job_while_one_runs_is_busy_and_not_queued() {
    let mut r = Rig::started(&[1]);
    r.ticks(2);
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
    r.until_event(5000, StatusEvent::JobDone);
    r.ticks(200);
    assert_eq!(
        r.count(|o| *o == Out::Plan("order")),
        1,
        "job 8 never started"
    );
    assert!(r.statuses().iter().all(|s| s.job_id != 8));
}

#[test]
fn a_job_while_braking_or_faulted_is_busy() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(200);
    r.respond();
    r.ticks(2); // streaming
    r.job.p.timeouts.gripper_state_ns = 20 * MS; // soon stale: the arm is seen, it brakes
    r.gs_up = false;
    r.until(200, "brake", is_brake);
    assert!(matches!(r.phase(), Phase::Braking { .. }));
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
    r.respond();
    r.until_event(50, StatusEvent::Braked);
    assert!(matches!(r.phase(), Phase::Faulted { .. }));
    assert_eq!(r.submit(8, &[2]), (RejectReason::Busy, 0));
}

#[test]
fn a_job_after_a_stop_is_shutting_down() {
    let mut r = Rig::new();
    r.stop = true;
    r.tick();
    assert!(r.finished);
    assert_eq!(r.submit(1, &[1]), (RejectReason::ShuttingDown, 0));
    // A malformed one still hears what is wrong with it.
    assert_eq!(r.submit(0, &[1]), (RejectReason::Malformed, 0));
}

#[test]
fn an_accepted_job_replies_orders_reports_and_holds_the_measured_position() {
    let mut r = Rig::new();
    r.q[3] += 0.25; // the arm is somewhere
    r.tick();
    let mark = r.fx.out.len();
    assert_eq!(r.submit(7, &[4, 5, 6]), (RejectReason::None, 0));
    let out = &r.fx.out[mark..];
    assert_eq!(
        out[0],
        Out::Reply {
            job_id: 7,
            reason: RejectReason::None,
            detail: 0
        }
    );
    assert_eq!(out[1], Out::Plan("order"));
    let Out::Status(s) = out[2] else {
        panic!("{out:?}")
    };
    assert_eq!(
        (event(&s), s.job_id, s.objects_total, s.state, s.fault),
        (
            StatusEvent::Accepted,
            7,
            3,
            JobState::Running as u32,
            Fault::None as u32
        )
    );
    let Request::Order {
        job_id,
        objects,
        count,
        ..
    } = r.take()
    else {
        panic!("an order")
    };
    assert_eq!((job_id, &objects[..count]), (7, &[4u16, 5, 6][..]));
    let mark = r.fx.out.len();
    r.tick();
    assert_eq!(r.joints_since(mark), vec![Setpoint::at_rest(r.q)]);
}

#[test]
fn ordered_starts_the_pick_and_asks_for_the_decision_at_once() {
    let mut r = Rig::new();
    r.auto = false;
    r.decide_after = None;
    r.submit(7, &[4, 5, 6]);
    r.ticks(5);
    assert_eq!(r.phase(), Phase::Ordering);
    let resp = answer(r.take());
    r.deliver(resp);
    // The decision is asked for on the job's order (reversed by the script), on a heightmap
    // newer than the last release (none yet)...
    let d = r.take_decision();
    assert_eq!((d.job_id, d.index, d.after_stamp_ns), (7, 0, 0));
    assert_eq!(d.remaining(), &[6, 5, 4]);
    // ...and the pick is planned meanwhile, from rest where the arm stands.
    let Request::Plan {
        index,
        object,
        from,
        motion,
        ..
    } = r.take()
    else {
        panic!("a plan")
    };
    assert_eq!((index, object, from, motion), (0, 6, r.q, Motion::Pick));
    assert_eq!(r.phase(), Phase::Planning);
}

#[test]
fn ordered_for_another_job_is_ignored() {
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.deliver(Response::Ordered {
        job_id: 6,
        order: [9; MAX_JOB_OBJECTS],
        count: 1,
    });
    r.ticks(3);
    assert_eq!(r.phase(), Phase::Ordering);
    assert_eq!(r.job.progress().order[0], 0);
}

#[test]
fn order_failed_fails_the_job_with_decision() {
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.take();
    r.deliver(Response::OrderFailed { job_id: 7 });
    let s = r.last(StatusEvent::JobFailed);
    assert_eq!(
        (s.job_id, s.state, s.fault),
        (7, JobState::Failed as u32, Fault::Decision as u32)
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(3);
    assert!(r.joints_since(mark).is_empty(), "no command without a job");
}

#[test]
fn order_failed_for_another_job_or_after_ordering_is_ignored() {
    // A stale reply for an earlier job.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[4]);
    r.deliver(Response::OrderFailed { job_id: 6 });
    assert_eq!(r.phase(), Phase::Ordering);
    // One for this job, once it is ordered (the planner answers each order once; a repeat
    // is a bug elsewhere, and must not fail a job mid-motion).
    let resp = answer(r.take());
    r.deliver(resp);
    r.deliver(Response::OrderFailed { job_id: 7 });
    assert_eq!(r.phase(), Phase::Planning);
    assert!(!r.events().contains(&StatusEvent::JobFailed));
}

#[test]
fn cancel_requests_are_answered_with_their_reason() {
    let mut r = Rig::new();
    assert_eq!(r.cancel(0), RejectReason::Malformed);
    assert_eq!(r.cancel(7), RejectReason::NoSuchJob, "no job runs");
    r.submit(7, &[1]);
    assert_eq!(r.cancel(8), RejectReason::NoSuchJob, "another job runs");
    assert_eq!(r.job.rejected_requests(), 3);
    assert_eq!(r.cancel(7), RejectReason::None);
    assert_eq!(
        r.cancel(7),
        RejectReason::None,
        "a repeat is accepted again"
    );
    r.until_event(3000, StatusEvent::JobCancelled);
    assert_eq!(r.count(is_retreat), 1, "and changes nothing");
    assert_eq!(r.cancel(7), RejectReason::NoSuchJob, "over");
    let mut r = Rig::started(&[1]);
    r.stop = true;
    r.tick();
    assert_eq!(r.cancel(7), RejectReason::ShuttingDown);
}

#[test]
fn a_cancel_while_moving_brakes_retreats_and_reports_cancelled() {
    let (mut r, _) = streaming();
    r.ticks(3);
    assert_eq!(r.cancel(7), RejectReason::None);
    assert_eq!(r.count(is_brake), 1, "brakes at once");
    r.auto = false;
    r.tick();
    r.respond(); // the brake
    r.until(50, "retreat", is_retreat);
    let Request::Retreat { from, held, buf } = r.take() else {
        panic!()
    };
    assert_eq!(
        (from, held),
        (r.q, None),
        "from where it stopped, holding nothing"
    );
    let resp = answer(Request::Retreat { from, held, buf });
    let Response::Planned(p) = &resp else {
        panic!()
    };
    let up = p.setpoints.as_slice().to_vec();
    r.deliver(resp);
    let mark = r.fx.out.len();
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert_eq!(
        r.joints_since(mark)[..SEG],
        up[..],
        "the retreat, sample for sample"
    );
    use StatusEvent::*;
    assert_eq!(r.events(), vec![Accepted, Decided, Braked, JobCancelled]);
    let s = r.last(JobCancelled);
    assert_eq!(
        (s.job_id, s.state, s.fault, s.objects_done),
        (
            7,
            JobState::Cancelled as u32,
            herb_ipc::Fault::None as u32,
            0
        )
    );
    assert_eq!(r.phase(), Phase::Idle);
    let mark = r.fx.out.len();
    r.ticks(20);
    assert!(r.joints_since(mark).is_empty(), "no command after the job");
    // Both buffers are home: the next job runs.
    r.auto = true;
    assert_eq!(r.submit(8, &[2]), (RejectReason::None, 0));
    r.until_event(5000, JobDone);
}

#[test]
fn a_cancel_at_rest_retreats_without_a_brake() {
    // Holding the next object at the lift pose, waiting for its decision.
    let mut r = Rig::started(&[1, 2]);
    r.until_event(5000, StatusEvent::Placed);
    r.decide_after = None;
    while !matches!(r.phase(), Phase::AwaitDecision { .. }) {
        r.tick();
        assert!(r.now < 20_000 * MS);
    }
    r.cancel(7);
    assert_eq!(r.count(is_retreat), 1);
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert_eq!(r.last(StatusEvent::JobCancelled).objects_done, 1);
    // At the gripper, holding the object: the retreat takes its height into account.
    let (mut r, _) = streaming();
    r.until(3000, "close", is_close);
    r.auto = false;
    r.tick(); // holding
    r.cancel(7);
    let Request::Retreat { held, .. } = r.take() else {
        panic!()
    };
    assert_eq!(held, Some(3));
    assert_eq!(r.count(is_brake), 0);
    // Ordering.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.cancel(7);
    assert!(matches!(r.phase(), Phase::Retreating { asked: true }));
    r.auto = true;
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
    assert!(!r.events().contains(&StatusEvent::Decided));
}

#[test]
fn a_cancel_while_planning_waits_for_the_plan_then_retreats() {
    let mut r = Rig::started(&[1]);
    r.decide_after = None;
    r.auto = false;
    r.tick();
    r.respond(); // ordered
    r.until_plan(50);
    r.cancel(7);
    r.ticks(5);
    assert_eq!(
        r.count(is_retreat),
        0,
        "the only spare buffer is with the planner"
    );
    r.respond(); // the plan comes back: not used
    assert!(!r.events().contains(&StatusEvent::Decided));
    assert_eq!(r.count(is_retreat), 1);
    r.auto = true;
    r.until_event(SEG + 5, StatusEvent::JobCancelled);
}

#[test]
fn a_cancel_of_a_faulted_job_ends_it_where_it_stands() {
    let (mut r, _) = streaming();
    r.ticks(2);
    r.js_up = false;
    r.until_event(300, StatusEvent::Braked);
    r.cancel(7);
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::JobCancelled));
    assert_eq!(r.count(is_retreat), 0);
    let s = r.last(StatusEvent::JobCancelled);
    assert_eq!(
        s.fault,
        Fault::JointStateTimeout as u32,
        "the last fault stays reported"
    );
}

#[test]
fn a_failed_or_empty_retreat_still_ends_the_job_cancelled() {
    // The planner cannot lift the arm: cancelled where it stands, with the reason.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.take();
    r.cancel(7);
    let Request::Retreat { buf, .. } = r.take() else {
        panic!()
    };
    r.deliver(Response::Failed {
        fault: Fault::Unreachable,
        buf,
    });
    let s = r.last(StatusEvent::JobCancelled);
    assert_eq!(s.fault, Fault::Unreachable as u32);
    // Already at the transit height: no segment, cancelled at once.
    let mut r = Rig::new();
    r.auto = false;
    r.submit(7, &[1]);
    r.take();
    r.cancel(7);
    let Request::Retreat { mut buf, .. } = r.take() else {
        panic!()
    };
    buf.reset();
    r.deliver(Response::Planned(buf));
    r.tick();
    assert_eq!(r.events().last(), Some(&StatusEvent::JobCancelled));
}

#[test]
fn a_job_is_refused_while_the_gripper_holds_an_object_and_names_it() {
    // Cancelled while carrying: the object stays in the gripper.
    let mut r = Rig::started(&[4]);
    r.until(3000, "close", is_close);
    r.ticks(3);
    assert!(r.job.holding);
    r.job.cancel_request(&CancelJobRequest::new(7), &mut r.fx);
    r.until_event(5000, StatusEvent::JobCancelled);
    assert!(r.holding, "still held");
    // The gripper says what it holds when it knows: else herbd's belief, the cancelled job's
    // current object (type 4).
    assert_eq!(r.submit(8, &[5]), (RejectReason::Holding, 4));
    r.holding = false;
    r.closed = false;
    r.ticks(2);
    assert_eq!(r.submit(9, &[5]), (RejectReason::None, 0));
    r.until_event(5000, StatusEvent::JobDone);
    let placed: Vec<u32> = r
        .statuses()
        .iter()
        .filter(|s| event(s) == StatusEvent::Placed)
        .map(|s| s.object_type)
        .collect();
    assert_eq!(placed, vec![5], "only the new job's object");
}
