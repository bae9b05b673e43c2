//! A scripted stand-in for herbd (fixture): its pack-job and cancel-job servers answer as a
//! test says, its status publisher sends what a test scripts. Each test runs under its own
//! prefix.

#![allow(dead_code)] // each test file uses a part

use herb_ipc::bus::{Bus, Pub};
use herb_ipc::{
    CancelJobReply, CancelJobRequest, Fault, Header, JobState, NO_OBJECT, PackJobReply,
    PackJobRequest, RejectReason, Services, Status, StatusEvent,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A prefix of this process for test `tag`.
pub fn prefix(tag: &str) -> String {
    format!("hc{}{tag}", std::process::id())
}

/// How the fake answers one pack-job request.
#[derive(Debug, Clone, Copy)]
pub enum Answer {
    /// A well-formed reply with this reason and detail.
    Reply(RejectReason, u32),
    /// No reply (the request is dropped).
    Silent,
    /// This reply as it is (the job id is set to the request's).
    Raw(PackJobReply),
}

/// A reply to `job_id`: `reason`, `detail`.
pub fn reply(job_id: u64, reason: RejectReason, detail: u32) -> PackJobReply {
    PackJobReply {
        header: Header::now(1),
        job_id,
        accepted: (reason == RejectReason::None) as u32,
        reason: reason as u32,
        detail,
        reserved: 0,
    }
}

/// A pack-job request as the fake received it, and when.
#[derive(Debug, Clone, Copy)]
pub struct Received {
    pub at: Instant,
    pub request: PackJobRequest,
}

/// The fake's servers, run by a thread until dropped.
pub struct FakeHerbd {
    pub requests: Arc<Mutex<Vec<Received>>>,
    pub cancels: Arc<Mutex<Vec<CancelJobRequest>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

type PackAnswers = Box<dyn FnMut(usize, &PackJobRequest) -> Answer + Send>;
type CancelAnswers = Box<dyn FnMut(&CancelJobRequest) -> Option<RejectReason> + Send>;

impl FakeHerbd {
    /// Serves `prefix` after `delay` (returns at once; with no delay, once serving): the n-th
    /// pack-job request (from 0) is answered `pack(n, request)`, a cancel `cancel(request)`
    /// (`None`: no reply).
    pub fn start(
        prefix: &str,
        delay: Duration,
        pack: impl FnMut(usize, &PackJobRequest) -> Answer + Send + 'static,
        cancel: impl FnMut(&CancelJobRequest) -> Option<RejectReason> + Send + 'static,
    ) -> Self {
        let requests: Arc<Mutex<Vec<Received>>> = Arc::default();
        let cancels: Arc<Mutex<Vec<CancelJobRequest>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::channel();
        let (r, c, s, prefix) = (
            requests.clone(),
            cancels.clone(),
            stop.clone(),
            prefix.to_string(),
        );
        let mut pack: PackAnswers = Box::new(pack);
        let mut cancel: CancelAnswers = Box::new(cancel);
        let thread = std::thread::spawn(move || {
            std::thread::sleep(delay);
            let services = Services::new(&prefix).unwrap();
            let bus = Bus::open("fake-herbd", &services).unwrap();
            let jobs = bus.job_server().unwrap();
            let cancels = bus.cancel_server().unwrap();
            let _ = ready_tx.send(());
            while !s.load(Ordering::Relaxed) {
                while let Ok(Some(active)) = jobs.receive() {
                    let request = *active.payload();
                    let n = {
                        let mut r = r.lock().unwrap();
                        r.push(Received {
                            at: Instant::now(),
                            request,
                        });
                        r.len() - 1
                    };
                    match pack(n, &request) {
                        Answer::Reply(reason, detail) => {
                            let _ = active.send_copy(reply(request.job_id, reason, detail));
                        }
                        Answer::Silent => {}
                        Answer::Raw(mut raw) => {
                            raw.job_id = request.job_id;
                            let _ = active.send_copy(raw);
                        }
                    }
                }
                while let Ok(Some(active)) = cancels.receive() {
                    let request = *active.payload();
                    c.lock().unwrap().push(request);
                    if let Some(reason) = cancel(&request) {
                        let _ = active.send_copy(CancelJobReply {
                            header: Header::now(1),
                            job_id: request.job_id,
                            accepted: (reason == RejectReason::None) as u32,
                            reason: reason as u32,
                        });
                    }
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        if delay.is_zero() {
            ready_rx
                .recv_timeout(Duration::from_secs(10))
                .expect("the fake herbd serves");
        }
        Self {
            requests,
            cancels,
            stop,
            thread: Some(thread),
        }
    }

    /// The pack-job requests received so far.
    pub fn received(&self) -> Vec<Received> {
        self.requests.lock().unwrap().clone()
    }
}

impl Drop for FakeHerbd {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A status of `job_id` (0: idle) with `event`.
pub fn status(job_id: u64, event: StatusEvent) -> Status {
    let state = match (job_id, event) {
        (0, _) => JobState::Idle,
        (_, StatusEvent::JobDone) => JobState::Done,
        (_, StatusEvent::JobFailed) => JobState::Failed,
        (_, StatusEvent::JobCancelled) => JobState::Cancelled,
        _ => JobState::Running,
    };
    Status {
        header: Header::now(1),
        job_id,
        event: event as u32,
        state: state as u32,
        fault: Fault::None as u32,
        objects_total: 2,
        objects_done: 0,
        object_index: 0,
        object_type: NO_OBJECT,
        decision_wait_ms: 0,
        pose: [0.0; 4],
        decision_ns: 0,
        cycles: 0,
        deadline_misses: 0,
        rejected_inputs: 0,
        max_cycle_ns: 0,
        rejected_requests: 0,
        limit_joint: herb_ipc::NO_JOINT,
        limit_position_rad: 0.0,
        limit_bound_rad: 0.0,
        attempt: 0,
        waiting_for: 0,
        reserved: 0,
    }
}

/// One step of a scripted status publisher.
#[derive(Debug, Clone, Copy)]
pub enum Step {
    /// Publish this status (stamped and numbered when sent).
    Send(Status),
    /// Publish heartbeats of `job_id` (0: idle) at 10 Hz for this long.
    Heartbeats(u64, Duration),
    /// Publish nothing for this long.
    Sleep(Duration),
    /// Close the publisher and its node (herbd killed) and open new ones (restarted).
    Restart,
}

/// Publishes `script` on `prefix`'s status service from a thread, once `go` is called.
pub struct Publisher {
    go: mpsc::Sender<()>,
    thread: Option<JoinHandle<()>>,
}

impl Publisher {
    /// Opens the publisher (returns once it is open) and waits for [`Publisher::go`].
    pub fn new(prefix: &str, script: Vec<Step>) -> Self {
        let (go_tx, go_rx) = mpsc::channel::<()>();
        let (ready_tx, ready_rx) = mpsc::channel();
        let prefix = prefix.to_string();
        let thread = std::thread::spawn(move || {
            let services = Services::new(&prefix).unwrap();
            let open = |n: u32| {
                let bus = Bus::open(&format!("fake-herbd-{n}"), &services).unwrap();
                let p = bus.publisher::<Status>(&services.status()).unwrap();
                (p, bus)
            };
            let mut port = Some(open(0));
            let mut seq = 0;
            let _ = ready_tx.send(());
            if go_rx.recv().is_err() {
                return;
            }
            let mut send = |port: &Option<(Pub<Status>, Bus)>, mut s: Status| {
                seq += 1;
                s.header = Header::now(seq);
                if let Some((p, _)) = port {
                    p.send_copy(s).unwrap();
                }
            };
            let mut restarts = 0;
            for step in script {
                match step {
                    Step::Send(s) => send(&port, s),
                    Step::Heartbeats(job_id, d) => {
                        let t0 = Instant::now();
                        while t0.elapsed() < d {
                            send(&port, status(job_id, StatusEvent::Heartbeat));
                            std::thread::sleep(Duration::from_millis(100));
                        }
                    }
                    Step::Sleep(d) => std::thread::sleep(d),
                    Step::Restart => {
                        drop(port.take());
                        restarts += 1;
                        port = Some(open(restarts));
                    }
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            // Idle, quietly, until the test ends (dropping a publisher is not herbd's end).
            let _ = go_rx.recv();
        });
        ready_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("the status publisher opens");
        Self {
            go: go_tx,
            thread: Some(thread),
        }
    }

    /// Starts the script.
    pub fn go(&self) {
        self.go.send(()).unwrap();
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        // Once to start the script if the test did not, once to end the thread.
        let _ = self.go.send(());
        let _ = self.go.send(());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
