//! What the machine publishes and keeps: commands held at the limits, heartbeats, the order
//! of a tick's outputs, snapshots, no allocation, the journal's record.

use super::*;

#[test]
fn a_command_outside_the_limits_is_held_and_counted() {
    let mut r = Rig::started(&[1]);
    r.auto = false;
    r.tick();
    r.respond();
    r.until_plan(50);
    let Response::Planned(mut p) = answer(r.take()) else {
        panic!()
    };
    // Sample 2 past the upper limit of joint 0.
    let mut s = p.setpoints.as_slice().to_vec();
    s[2].position[0] = params().upper[0] + 0.01;
    p.setpoints.clear();
    for x in s {
        p.setpoints.push(x).unwrap();
    }
    r.deliver(Response::Planned(p));
    let mark = r.fx.out.len();
    r.ticks(3);
    assert_eq!(
        r.joints_since(mark).len(),
        2,
        "the third sample is not sent"
    );
    assert_eq!(r.job.limit_holds(), 1);
}

#[test]
fn heartbeats_every_100_ms_carry_the_state() {
    let mut r = Rig::new();
    let mut beats = vec![];
    for _ in 0..1000 {
        let mark = r.fx.out.len();
        r.tick();
        for o in &r.fx.out[mark..] {
            if let Out::Status(s) = o
                && event(s) == StatusEvent::Heartbeat
            {
                beats.push((r.now, s.state));
            }
        }
    }
    assert_eq!(beats.len(), 10);
    assert!(
        beats
            .windows(2)
            .all(|w| w[1].0 - w[0].0 == HEARTBEAT_PERIOD_NS)
    );
    assert!(beats.iter().all(|b| b.1 == JobState::Idle as u32));
}

#[test]
fn outputs_of_a_tick_come_status_then_joint_then_gripper_then_heartbeat() {
    let (mut r, _) = streaming();
    r.grasps = false;
    // Find the tick that reaches the grasp.
    loop {
        let mark = r.fx.out.len();
        r.tick();
        let out = r.fx.out[mark..].to_vec();
        if out.iter().any(is_close) {
            let j = out.iter().position(|o| matches!(o, Out::Joint(_))).unwrap();
            let g = out
                .iter()
                .position(|o| matches!(o, Out::Gripper { .. }))
                .unwrap();
            assert!(j < g, "{out:?}");
            if let Some(h) = out.iter().position(|o| matches!(o, Out::Status(_))) {
                assert!(g < h, "the heartbeat comes last: {out:?}");
            }
            break;
        }
    }
    // A Placed status comes before the tick's joint command.
    let mut r = Rig::started(&[1, 2]);
    loop {
        let mark = r.fx.out.len();
        r.tick();
        let out = r.fx.out[mark..].to_vec();
        if let Some(p) = out
            .iter()
            .position(|o| matches!(o, Out::Status(s) if event(s) == StatusEvent::Placed))
        {
            let j = out.iter().position(|o| matches!(o, Out::Joint(_))).unwrap();
            assert!(p < j, "{out:?}");
            break;
        }
    }
}

#[test]
fn a_restored_snapshot_behaves_as_the_original() {
    let mut a = Rig::started(&[1, 2]);
    a.until_event(10_000, StatusEvent::JobDone);
    a.ticks(37);
    let snap = a.job.snapshot().expect("idle");
    let mut b = Rig::new();
    b.job.restore(&snap);
    assert_eq!(b.job.snapshot(), Some(snap));
    // Same clock, same arm, same inputs from here: the same outputs.
    (b.now, b.q, b.js_seq, b.gs_seq, b.last_frame) = (a.now, a.q, a.js_seq, a.gs_seq, a.last_frame);
    b.frame.header = a.frame.header;
    let (ma, mb) = (a.fx.out.len(), b.fx.out.len());
    for r in [&mut a, &mut b] {
        assert_eq!(r.submit(9, &[3, 4]), (RejectReason::None, 0));
        r.until_event(10_000, StatusEvent::JobDone);
    }
    assert_eq!(a.fx.out[ma..], b.fx.out[mb..]);
    // Not while a job runs.
    assert!(Rig::started(&[1]).job.snapshot().is_none());
}

#[test]
fn a_whole_job_with_a_fault_and_a_resume_allocates_nothing() {
    // The counter counts.
    let probe = counting::allocations(|| {
        std::hint::black_box(vec![0u8; 16]);
    });
    assert_eq!(probe, 1);
    let mut r = Rig::started(&[1, 2, 3]);
    // The rig's own records are preallocated, so that every allocation counted is the job's.
    r.fx.out.reserve(100_000);
    r.fx.sent.reserve(16);
    r.fx.decisions.reserve(16);
    r.decision_sent.reserve(16);
    let n = counting::allocations(|| {
        // Into the second object's carry, then the adapter goes away and comes back.
        let mut placed = 0;
        for _ in 0..10_000 {
            let mark = r.fx.out.len();
            r.tick();
            placed += r.fx.out[mark..]
                .iter()
                .filter(|o| matches!(o, Out::Status(s) if s.event == StatusEvent::Placed as u32))
                .count();
            if placed == 1 && matches!(r.phase(), Phase::Streaming { seg: 2, .. }) {
                break;
            }
        }
        r.js_up = false;
        r.ticks(300);
        r.js_up = true;
        for _ in 0..20_000 {
            r.tick();
            if r.phase() == Phase::Idle {
                break;
            }
        }
    });
    use StatusEvent::*;
    let ev = r.events();
    assert!(ev.contains(&Braked) && ev.contains(&Resumed), "{ev:?}");
    assert_eq!(ev.last(), Some(&JobDone), "{ev:?}");
    assert_eq!(n, 0, "allocations during the job");
}

#[test]
fn the_journal_record_follows_the_job_and_ends_with_it() {
    let mut r = Rig::started(&[1, 2]);
    assert_eq!(r.job.journal().phase, ObjectPhase::Ordering);
    assert_eq!(r.job.journal().objects(), &[1, 2]);
    assert_eq!(r.job.journal().order(), None);
    let mut phases = vec![ObjectPhase::Ordering];
    let mut last = r.job.journal();
    while !r.events().contains(&StatusEvent::JobDone) {
        r.tick();
        let j = r.job.journal();
        if j.job_id != 0 && phases.last() != Some(&j.phase) {
            phases.push(j.phase);
        }
        if j.job_id != 0 {
            assert_eq!(j.order(), Some(&[2u16, 1][..]), "the planner's order");
            // A placement is journaled only for the current object, with its release.
            if let Some(p) = j.placement {
                assert_eq!(p.index, j.index);
            }
            if j.phase == ObjectPhase::Carrying {
                assert!(j.holding && j.placement.is_some(), "{j:?}");
            }
        }
        last = j;
        assert!(r.now < 20_000 * MS, "no JobDone");
    }
    use ObjectPhase::*;
    assert_eq!(
        phases,
        vec![
            Ordering, Deciding, Moving, Carrying, Moving, Deciding, Moving, Carrying, Moving
        ]
    );
    assert_eq!(last, JobRecord::NONE);
}
