//! herbd's claims against the simulated world's outcomes: a watcher on a prefix's `status` and
//! `sim/outcome` services, and a check that fails on any disagreement. What herbd says it placed
//! (each `Placed` status: its job and object type) must be what the loopback released (each
//! `SimOutcome`: its job and released type), in the same order, job by job; a `JobDone`'s
//! count must be the number of releases of that job.

use herb_ipc::bus::Bus;
use herb_ipc::{Services, SimOutcome, Status, StatusEvent};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// What one job was claimed and seen to do.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct JobRecord {
    /// Object types herbd reported `Placed`, in order.
    pub claimed: Vec<u32>,
    /// Object types the loopback released for this job, in order.
    pub released: Vec<u32>,
    /// Whether every object was inside the success volume after each release.
    pub all_inside: Vec<bool>,
    /// `objects_done` of the job's `JobDone`, if it ended so.
    pub done: Option<u32>,
}

/// Watches a prefix from a thread until dropped.
pub struct Claims {
    jobs: Arc<Mutex<BTreeMap<u64, JobRecord>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Claims {
    /// Starts watching `prefix` (before herbd and the loopback, or after: it keeps polling).
    pub fn watch(prefix: &str) -> Self {
        let jobs: Arc<Mutex<BTreeMap<u64, JobRecord>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let (j, s, prefix) = (jobs.clone(), stop.clone(), prefix.to_string());
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let services = Services::new(&prefix).expect("prefix");
            let bus = Bus::open("e2e-claims", &services).expect("bus");
            let status = bus
                .subscriber::<Status>(&services.status())
                .expect("status");
            let outcomes = bus
                .subscriber::<SimOutcome>(&services.sim_outcome())
                .expect("outcomes");
            let _ = ready_tx.send(());
            while !s.load(Ordering::Relaxed) {
                while let Ok(Some(m)) = status.receive() {
                    let m = *m.payload();
                    if m.validate().is_err() || m.job_id == 0 {
                        continue;
                    }
                    let mut jobs = j.lock().unwrap();
                    let r = jobs.entry(m.job_id).or_default();
                    match StatusEvent::from_code(m.event) {
                        Some(StatusEvent::Placed) => r.claimed.push(m.object_type),
                        Some(StatusEvent::JobDone) => r.done = Some(m.objects_done),
                        _ => {}
                    }
                }
                while let Ok(Some(o)) = outcomes.receive() {
                    let o = *o.payload();
                    if o.validate().is_err() {
                        continue;
                    }
                    let mut jobs = j.lock().unwrap();
                    let r = jobs.entry(o.job_id).or_default();
                    r.released.push(o.object_type);
                    r.all_inside.push(o.all_inside == 1);
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        });
        ready_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("the claims watcher starts");
        Self {
            jobs,
            stop,
            thread: Some(thread),
        }
    }

    /// The records so far, by job id.
    pub fn jobs(&self) -> BTreeMap<u64, JobRecord> {
        self.jobs.lock().unwrap().clone()
    }

    /// Fails (panics, naming the job) on any disagreement between herbd's claims and the
    /// world's outcomes, after a short wait for the last settle's outcome. Returns the
    /// records.
    pub fn check(&self) -> BTreeMap<u64, JobRecord> {
        let t0 = std::time::Instant::now();
        loop {
            let jobs = self.jobs();
            let agree = jobs.values().all(|r| r.claimed == r.released);
            if agree || t0.elapsed() > Duration::from_secs(5) {
                for (id, r) in &jobs {
                    assert_eq!(
                        r.claimed, r.released,
                        "job {id}: herbd claims it placed {:?}, the world saw {:?} released",
                        r.claimed, r.released
                    );
                    if let Some(done) = r.done {
                        assert_eq!(
                            done as usize,
                            r.released.len(),
                            "job {id}: JobDone with {done} placed, {} released",
                            r.released.len()
                        );
                    }
                }
                return jobs;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Claims {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
