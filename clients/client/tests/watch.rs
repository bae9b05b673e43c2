//! Following a job and reading herbd's state, against a scripted status publisher
//! (`common::Publisher`): the job's statuses only, its end, herbd lost and back (a restarted
//! publisher), given up after the reconnect time or when herbd comes back without the job, the
//! deadline; status snapshots.

mod common;

use common::{Publisher, Step, prefix, status};
use herb_client::{
    BACK_WITHOUT_JOB_AFTER, Client, DAEMON_LOST_AFTER, Fault, JobEvent, JobWatch, StatusError,
    StatusEvent, WatchError,
};
use std::time::{Duration, Instant};

const JOB: u64 = 4242;

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

/// Every event of `watch` with when it came, up to its end or error.
fn follow(watch: &mut JobWatch<'_>) -> (Vec<(Instant, JobEvent)>, Option<WatchError>) {
    let mut seen = Vec::new();
    for ev in watch {
        match ev {
            Ok(e) => seen.push((Instant::now(), e)),
            Err(e) => return (seen, Some(e)),
        }
    }
    (seen, None)
}

fn events_of(seen: &[(Instant, JobEvent)]) -> Vec<Option<StatusEvent>> {
    seen.iter()
        .filter_map(|(_, e)| match e {
            JobEvent::Status(s) => Some(StatusEvent::from_code(s.event)),
            _ => None,
        })
        .collect()
}

#[test]
fn a_watch_hands_out_its_jobs_statuses_to_the_end() {
    let p = prefix("follow");
    let mut bad = status(JOB, StatusEvent::Placed);
    bad.objects_done = 9; // more than the job's objects: invalid
    let publisher = Publisher::new(
        &p,
        vec![
            Step::Send(status(0, StatusEvent::Heartbeat)),
            Step::Send(status(JOB, StatusEvent::Accepted)),
            Step::Send(status(JOB + 1, StatusEvent::Accepted)),
            Step::Send(status(JOB, StatusEvent::Decided)),
            Step::Send(bad),
            Step::Send(status(JOB + 1, StatusEvent::JobDone)),
            Step::Send(status(JOB, StatusEvent::Placed)),
            Step::Send(status(JOB, StatusEvent::JobDone)),
            Step::Heartbeats(0, ms(300)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    let mut watch = client.watch(JOB, Instant::now() + Duration::from_secs(20), ms(0));
    publisher.go();
    let (seen, err) = follow(&mut watch);
    assert_eq!(err, None);
    assert_eq!(
        events_of(&seen),
        [
            Some(StatusEvent::Accepted),
            Some(StatusEvent::Decided),
            Some(StatusEvent::Placed),
            Some(StatusEvent::JobDone)
        ]
    );
    assert!(watch.is_finished());
    assert_eq!(watch.end().unwrap().event, StatusEvent::JobDone as u32);
    assert_eq!(watch.latest().unwrap().event, StatusEvent::JobDone as u32);
    assert!(matches!(watch.poll(), Ok(None)));
}

#[test]
fn every_end_event_ends_a_watch() {
    for (i, end) in herb_client::END_EVENTS.into_iter().enumerate() {
        let p = prefix(&format!("end{i}"));
        let publisher = Publisher::new(
            &p,
            vec![
                Step::Send(status(JOB, StatusEvent::Accepted)),
                Step::Send(status(JOB, end)),
            ],
        );
        let client = Client::connect(&p).unwrap();
        let watch = client.watch(JOB, Instant::now() + Duration::from_secs(20), ms(0));
        publisher.go();
        let s = watch.wait().expect("ended");
        assert_eq!(s.event, end as u32);
    }
}

#[test]
fn a_herbd_that_comes_back_with_the_job_is_followed_to_the_end() {
    let p = prefix("back");
    let mut restarted = status(JOB, StatusEvent::Fault);
    restarted.fault = Fault::Restarted as u32;
    let publisher = Publisher::new(
        &p,
        vec![
            Step::Send(status(JOB, StatusEvent::Accepted)),
            Step::Heartbeats(JOB, ms(300)),
            // Killed: silent for 1.2 s, then restarted with the job (its journal).
            Step::Sleep(ms(1200)),
            Step::Restart,
            Step::Send(restarted),
            Step::Heartbeats(JOB, ms(300)),
            Step::Send(status(JOB, StatusEvent::Resumed)),
            Step::Send(status(JOB, StatusEvent::JobDone)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    let mut watch = client.watch(JOB, Instant::now() + Duration::from_secs(30), ms(10_000));
    publisher.go();
    let (seen, err) = follow(&mut watch);
    assert_eq!(err, None, "{seen:?}");
    let lost = seen
        .iter()
        .position(|(_, e)| matches!(e, JobEvent::Lost { .. }))
        .expect("herbd reported lost");
    let JobEvent::Lost { silent_for } = seen[lost].1 else {
        unreachable!()
    };
    assert!(silent_for > DAEMON_LOST_AFTER, "{silent_for:?}");
    let back = seen
        .iter()
        .position(|(_, e)| *e == JobEvent::Back)
        .expect("herbd reported back");
    assert!(lost < back);
    // Back is followed by the status that brought the job back.
    assert!(matches!(seen[back + 1].1, JobEvent::Status(s) if s.job_id == JOB));
    assert_eq!(seen.iter().filter(|(_, e)| *e == JobEvent::Back).count(), 1);
    let after = events_of(&seen[back..]);
    assert!(after.contains(&Some(StatusEvent::Resumed)), "{after:?}");
    assert_eq!(watch.end().unwrap().event, StatusEvent::JobDone as u32);
}

#[test]
fn without_reconnect_time_a_silent_herbd_ends_the_watch_at_once() {
    let p = prefix("noreconnect");
    let publisher = Publisher::new(&p, vec![Step::Send(status(JOB, StatusEvent::Accepted))]);
    let client = Client::connect(&p).unwrap();
    let mut watch = client.watch(JOB, Instant::now() + Duration::from_secs(20), ms(0));
    publisher.go();
    let (seen, err) = follow(&mut watch);
    let last_heard = seen.last().expect("the job's status").0;
    assert!(
        !seen.iter().any(|(_, e)| matches!(e, JobEvent::Lost { .. })),
        "{seen:?}"
    );
    match err {
        Some(WatchError::DaemonLost { job_id, silent_for }) => {
            assert_eq!(job_id, JOB);
            assert!(silent_for > DAEMON_LOST_AFTER, "{silent_for:?}");
        }
        e => panic!("{e:?}"),
    }
    let took = last_heard.elapsed();
    assert!(took >= DAEMON_LOST_AFTER && took < ms(1500), "{took:?}");
    assert!(watch.is_finished());
}

#[test]
fn a_herbd_silent_longer_than_the_reconnect_time_ends_the_watch() {
    let p = prefix("waitedout");
    let publisher = Publisher::new(&p, vec![Step::Send(status(JOB, StatusEvent::Accepted))]);
    let client = Client::connect(&p).unwrap();
    let reconnect = ms(1000);
    let mut watch = client.watch(JOB, Instant::now() + Duration::from_secs(20), reconnect);
    publisher.go();
    let (seen, err) = follow(&mut watch);
    let heard = seen[0].0;
    let lost = seen
        .iter()
        .find(|(_, e)| matches!(e, JobEvent::Lost { .. }))
        .expect("lost first")
        .0;
    assert!(lost - heard >= DAEMON_LOST_AFTER);
    assert!(
        matches!(err, Some(WatchError::DaemonLost { silent_for, .. }) if silent_for >= DAEMON_LOST_AFTER + reconnect),
        "{err:?}"
    );
    let took = heard.elapsed();
    assert!(took < ms(3000), "{took:?}");
}

#[test]
fn a_herbd_back_without_the_job_ends_the_watch() {
    let p = prefix("without");
    let publisher = Publisher::new(
        &p,
        vec![
            Step::Send(status(JOB, StatusEvent::Accepted)),
            Step::Sleep(ms(900)),
            Step::Restart,
            // Back idle: no journal had the job.
            Step::Heartbeats(0, ms(6000)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    let mut watch = client.watch(JOB, Instant::now() + Duration::from_secs(30), ms(60_000));
    let t0 = Instant::now();
    publisher.go();
    let (seen, err) = follow(&mut watch);
    assert!(
        seen.iter().any(|(_, e)| matches!(e, JobEvent::Lost { .. })),
        "{seen:?}"
    );
    assert_eq!(err, Some(WatchError::CameBackWithoutJob { job_id: JOB }));
    let took = t0.elapsed();
    assert!(
        took >= ms(900) + BACK_WITHOUT_JOB_AFTER && took < ms(6500),
        "{took:?}"
    );
}

#[test]
fn the_deadline_ends_a_watch() {
    let p = prefix("deadline");
    let publisher = Publisher::new(&p, vec![Step::Heartbeats(JOB, ms(3000))]);
    let client = Client::connect(&p).unwrap();
    let t0 = Instant::now();
    let watch = client.watch(JOB, t0 + ms(600), ms(0));
    publisher.go();
    assert_eq!(watch.wait(), Err(WatchError::TimedOut { job_id: JOB }));
    let took = t0.elapsed();
    assert!(took >= ms(600) && took < ms(1500), "{took:?}");
}

#[test]
fn status_is_herbds_newest_heartbeat_and_current_job_its_job() {
    let p = prefix("status");
    let publisher = Publisher::new(
        &p,
        vec![
            Step::Heartbeats(JOB, ms(1500)),
            Step::Heartbeats(0, ms(3000)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    publisher.go();
    let s = client.status(Duration::from_secs(5)).expect("a heartbeat");
    assert_eq!(s.event, StatusEvent::Heartbeat as u32);
    assert_eq!(s.job_id, JOB);
    assert_eq!(client.current_job(Duration::from_secs(1)), Ok(Some(JOB)));
    std::thread::sleep(ms(1700));
    assert_eq!(client.current_job(Duration::from_secs(1)), Ok(None));
}

#[test]
fn without_herbd_there_is_no_status() {
    let client = Client::connect(&prefix("nostatus")).unwrap();
    let t0 = Instant::now();
    assert_eq!(client.status(ms(300)), Err(StatusError::NoHeartbeat));
    assert!(t0.elapsed() >= ms(300));
    assert_eq!(client.current_job(ms(200)), Err(StatusError::NoHeartbeat));
}

#[test]
fn statuses_hand_out_the_valid_ones_received() {
    let p = prefix("cell");
    let mut bad = status(JOB, StatusEvent::Decided);
    bad.event = 99;
    let publisher = Publisher::new(
        &p,
        vec![
            Step::Send(status(JOB, StatusEvent::Accepted)),
            Step::Send(bad),
            Step::Send(status(JOB + 1, StatusEvent::Decided)),
        ],
    );
    let client = Client::connect(&p).unwrap();
    publisher.go();
    std::thread::sleep(ms(500));
    let got: Vec<(u64, u32)> = client.statuses().map(|s| (s.job_id, s.event)).collect();
    assert_eq!(
        got,
        [
            (JOB, StatusEvent::Accepted as u32),
            (JOB + 1, StatusEvent::Decided as u32)
        ]
    );
    assert_eq!(client.statuses().count(), 0, "read once");
}
