//! The contract's retry rules for submitting and cancelling a job, against a scripted herbd
//! (`common::FakeHerbd`): which answers are retried, how often, with which job id, and what a
//! client is told at the deadline.

mod common;

use common::{Answer, FakeHerbd, prefix, reply};
use herb_client::{
    CancelError, Client, Fault, NOT_READY_RETRY, PackOptions, RejectReason, StatusEvent,
    SubmitError, new_job_id,
};
use herb_ipc::PackJobRequest;
use std::time::{Duration, Instant};

fn never_cancel(_: &herb_ipc::CancelJobRequest) -> Option<RejectReason> {
    None
}

fn in_secs(s: f64) -> Instant {
    Instant::now() + Duration::from_secs_f64(s)
}

#[test]
fn not_ready_is_retried_with_the_same_job_id_until_accepted() {
    let p = prefix("notready");
    let faults = [
        Fault::RobotDisabled,
        Fault::RobotDisabled,
        Fault::HeightmapTimeout,
    ];
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        move |n, _| match faults.get(n) {
            Some(f) => Answer::Reply(RejectReason::NotReady, *f as u32),
            None => Answer::Reply(RejectReason::None, 0),
        },
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    let mut told = Vec::new();
    client
        .submit(77, &[1, 3, 5], in_secs(10.0), |f| told.push(f))
        .expect("accepted");
    // The reason handed over at every NotReady (herbctl says it when it changes).
    assert_eq!(told, faults);
    let got = herbd.received();
    assert_eq!(got.len(), 4, "{got:?}");
    for r in &got {
        assert_eq!(r.request.job_id, 77, "the same job id on every try");
        assert_eq!(r.request.objects(), &[1, 3, 5]);
    }
    for w in got.windows(2) {
        let gap = w[1].at - w[0].at;
        assert!(
            gap >= NOT_READY_RETRY - Duration::from_millis(5),
            "tried again after {gap:?}"
        );
        assert!(gap < Duration::from_secs(1), "tried again after {gap:?}");
        // Each try is a new request, stamped when sent.
        assert!(w[1].request.header.stamp_ns > w[0].request.header.stamp_ns);
    }
}

#[test]
fn every_other_rejection_is_returned_at_once_and_not_retried() {
    let p = prefix("rejections");
    let cases = [
        (RejectReason::Busy, 0),
        (RejectReason::Holding, 1),
        (RejectReason::Holding, herb_ipc::NO_OBJECT),
        (RejectReason::Empty, 0),
        (RejectReason::TooMany, 65),
        (RejectReason::UnknownObject, 2),
        (RejectReason::Malformed, 0),
        (RejectReason::ShuttingDown, 0),
    ];
    // The job id says which answer to give.
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        move |_, r| {
            let (reason, detail) = cases[r.job_id as usize - 1];
            Answer::Reply(reason, detail)
        },
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    for (i, &(reason, detail)) in cases.iter().enumerate() {
        let job_id = i as u64 + 1;
        let mut told = 0;
        let t0 = Instant::now();
        let e = client
            .submit(job_id, &[1], in_secs(10.0), |_| told += 1)
            .expect_err("rejected");
        assert!(
            matches!(e, SubmitError::Rejected { reason: r, detail: d } if r == reason && d == detail),
            "{reason:?}: {e:?}"
        );
        assert_eq!(told, 0);
        assert!(t0.elapsed() < Duration::from_secs(1), "{reason:?} at once");
        let tries = herbd
            .received()
            .iter()
            .filter(|r| r.request.job_id == job_id)
            .count();
        assert_eq!(tries, 1, "{reason:?} is not retried");
    }
}

#[test]
fn with_no_herbd_the_client_waits_for_one_until_the_deadline() {
    let p = prefix("noserver");
    let client = Client::connect(&p).unwrap();
    let t0 = Instant::now();
    let e = client
        .submit(5, &[1], in_secs(0.5), |_| panic!("no herbd says NotReady"))
        .expect_err("no herbd");
    assert!(matches!(e, SubmitError::NoReply), "{e:?}");
    assert_eq!(
        e.to_string(),
        "no reply from herbd (is it running with this prefix?)"
    );
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(500) && took < Duration::from_millis(1500),
        "{took:?}"
    );
}

#[test]
fn a_herbd_started_after_the_client_gets_the_job() {
    let p = prefix("late");
    let client = Client::connect(&p).unwrap();
    let herbd = FakeHerbd::start(
        &p,
        Duration::from_millis(400),
        |_, _| Answer::Reply(RejectReason::None, 0),
        never_cancel,
    );
    let t0 = Instant::now();
    client
        .submit(9, &[2], in_secs(10.0), |_| {})
        .expect("accepted once herbd serves");
    assert!(t0.elapsed() >= Duration::from_millis(400));
    let got = herbd.received();
    assert!(!got.is_empty() && got.iter().all(|r| r.request.job_id == 9));
}

#[test]
fn a_request_without_a_reply_is_sent_again_after_the_reply_wait() {
    let p = prefix("silent");
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        |n, _| {
            if n == 0 {
                Answer::Silent
            } else {
                Answer::Reply(RejectReason::None, 0)
            }
        },
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    let t0 = Instant::now();
    client
        .submit(11, &[4], in_secs(10.0), |_| {})
        .expect("accepted on the second try");
    let took = t0.elapsed();
    assert!(
        took >= herb_client::REPLY_WAIT && took < Duration::from_secs(4),
        "{took:?}"
    );
    let got = herbd.received();
    assert_eq!(got.len(), 2);
    assert!(got.iter().all(|r| r.request.job_id == 11));
}

#[test]
fn a_robot_never_ready_ends_at_the_deadline_with_the_last_reason() {
    let p = prefix("neverready");
    let _herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        |n, _| {
            let why = if n < 2 {
                Fault::JointStateTimeout
            } else {
                Fault::RobotEStop
            };
            Answer::Reply(RejectReason::NotReady, why as u32)
        },
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    let mut told = Vec::new();
    let e = client
        .submit(13, &[1], in_secs(1.0), |f| told.push(f))
        .expect_err("never ready");
    assert!(
        matches!(e, SubmitError::NotReady(Fault::RobotEStop)),
        "{e:?}"
    );
    assert_eq!(e.to_string(), "robot not ready: robot e-stopped");
    assert!(told.len() >= 3, "{told:?}");
    // A detail that names no fault is read as the arm adapter being silent.
    let q = prefix("neverready2");
    let _herbd = FakeHerbd::start(
        &q,
        Duration::ZERO,
        |_, _| Answer::Reply(RejectReason::NotReady, 999),
        never_cancel,
    );
    let client = Client::connect(&q).unwrap();
    let e = client.submit(13, &[1], in_secs(0.3), |_| {}).unwrap_err();
    assert!(
        matches!(e, SubmitError::NotReady(Fault::JointStateTimeout)),
        "{e:?}"
    );
}

#[test]
fn a_malformed_reply_is_an_error() {
    let p = prefix("badreply");
    let mut bad = reply(0, RejectReason::None, 0);
    bad.header.version = 0;
    let _herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        move |_, _| Answer::Raw(bad),
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    let e = client.submit(3, &[1], in_secs(5.0), |_| {}).unwrap_err();
    assert!(matches!(e, SubmitError::MalformedReply(_)), "{e:?}");
}

#[test]
fn a_raw_request_returns_herbds_reply_as_it_is() {
    let p = prefix("raw");
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        |_, r| {
            if r.header.version == 0 {
                Answer::Reply(RejectReason::Malformed, 0)
            } else {
                Answer::Reply(RejectReason::NotReady, Fault::RobotDisabled as u32)
            }
        },
        never_cancel,
    );
    let client = Client::connect(&p).unwrap();
    let mut old = PackJobRequest::new(21, &[1]);
    old.header.version = 0;
    let r = client.request(&old, in_secs(5.0)).unwrap();
    assert_eq!(r.validate(), Ok(RejectReason::Malformed));
    assert_eq!(r.job_id, 21);
    // NotReady is returned, not retried.
    let r = client
        .request(&PackJobRequest::new(22, &[1]), in_secs(5.0))
        .unwrap();
    assert_eq!(r.validate(), Ok(RejectReason::NotReady));
    assert_eq!(r.detail, Fault::RobotDisabled as u32);
    assert_eq!(herbd.received().len(), 2);
    // Sent as it is: the header too.
    assert_eq!(herbd.received()[0].request.header, old.header);
}

#[test]
fn pack_submits_and_follows_the_job_under_one_id() {
    use common::{Publisher, Step, status};
    let p = prefix("pack");
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        |n, _| {
            if n == 0 {
                Answer::Reply(RejectReason::NotReady, Fault::HeightmapTimeout as u32)
            } else {
                Answer::Reply(RejectReason::None, 0)
            }
        },
        never_cancel,
    );
    let job_id = 0x5150;
    let statuses = Publisher::new(
        &p,
        vec![
            Step::Heartbeats(0, Duration::from_millis(300)),
            Step::Send(status(job_id, StatusEvent::Accepted)),
            Step::Send(status(job_id, StatusEvent::Decided)),
            Step::Send(status(job_id, StatusEvent::Placed)),
            Step::Send(status(job_id, StatusEvent::JobDone)),
            Step::Heartbeats(0, Duration::from_millis(300)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    let options = PackOptions {
        job_id: Some(job_id),
        timeout: Duration::from_secs(20),
        reconnect: Duration::from_secs(5),
    };
    let mut told = Vec::new();
    let watch = client
        .pack(&[1, 2], &options, |f| told.push(f))
        .expect("accepted");
    assert_eq!(told, [Fault::HeightmapTimeout]);
    assert_eq!(watch.job_id(), job_id);
    statuses.go();
    let end = watch.wait().expect("the job ends");
    assert_eq!(end.event, StatusEvent::JobDone as u32);
    assert_eq!(end.job_id, job_id);
    assert!(herbd.received().iter().all(|r| r.request.job_id == job_id));
}

#[test]
fn job_ids_are_non_zero_odd_and_carry_the_process() {
    let a = new_job_id();
    std::thread::sleep(Duration::from_millis(1));
    let b = new_job_id();
    assert_ne!(a, b);
    for id in [a, b] {
        assert_eq!(id & 1, 1);
        assert_eq!(id & 0xfffe, std::process::id() as u64 & 0xfffe);
    }
    assert_eq!(PackOptions::default().job_id, None);
}

#[test]
fn cancel_says_what_herbd_answered() {
    let p = prefix("cancel");
    let herbd = FakeHerbd::start(
        &p,
        Duration::ZERO,
        |_, _| Answer::Silent,
        |r| match r.job_id {
            1 => Some(RejectReason::None),
            2 => Some(RejectReason::NoSuchJob),
            3 => Some(RejectReason::ShuttingDown),
            _ => None,
        },
    );
    let client = Client::connect(&p).unwrap();
    client.cancel(1).expect("accepted");
    let e = client.cancel(2).unwrap_err();
    assert!(matches!(e, CancelError::NotRunning { job_id: 2 }), "{e:?}");
    assert_eq!(e.to_string(), "job 2 is not running");
    let e = client.cancel(3).unwrap_err();
    assert!(
        matches!(e, CancelError::Refused(RejectReason::ShuttingDown)),
        "{e:?}"
    );
    // No reply: given up after the reply wait, not sent again.
    let t0 = Instant::now();
    let e = client.cancel(4).unwrap_err();
    assert!(matches!(e, CancelError::NoReply), "{e:?}");
    assert!(t0.elapsed() >= herb_client::REPLY_WAIT);
    let ids: Vec<u64> = herbd
        .cancels
        .lock()
        .unwrap()
        .iter()
        .map(|c| c.job_id)
        .collect();
    assert_eq!(ids, [1, 2, 3, 4]);
}

#[test]
fn cancel_without_a_herbd_fails_at_once() {
    let client = Client::connect(&prefix("cancelnone")).unwrap();
    let t0 = Instant::now();
    let e = client.cancel(1).unwrap_err();
    assert!(matches!(e, CancelError::NoServer), "{e:?}");
    assert_eq!(e.to_string(), "no herbd serves this prefix");
    assert!(t0.elapsed() < Duration::from_secs(1));
}
