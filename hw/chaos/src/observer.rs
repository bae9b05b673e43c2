//! The observer: a process of its own on the bus (not herbd), reading what herbd commands and
//! reports and what the loopback says, and checking the cell's invariants all the time.

use herb_ipc::bus::{Bus, Sub};
use herb_ipc::{
    DOF, Fault, JointCommand, JointState, Services, SimOutcome, Status, StatusEvent, monotonic_ns,
};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A command further than this from the arm's measured position (rad, on any joint) is a
/// violation: herbd streams from where the arm is, and the loopback follows exactly.
pub const FAR_RAD: f64 = 0.1;
/// A joint state older than this (ns) is not compared with a command.
const FRESH_STATE_NS: u64 = 20_000_000;

/// A status event as herbd's log names it, with its job and object (1-based, as the log
/// writes `object=i/n`; 0 for none).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Event {
    /// The log's event name (`placed`, `job_done`...).
    pub name: &'static str,
    /// The job (0: none).
    pub job: u64,
    /// The object, 1-based; 0 when the line names none.
    pub object: u32,
}

/// herbd's log name of a status event (none for heartbeats).
pub fn log_name(e: StatusEvent) -> Option<&'static str> {
    use StatusEvent::*;
    Some(match e {
        Heartbeat => return None,
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
    })
}

/// The [`Event`] a status makes, as herbd's log line of it would say.
pub fn event_of(s: &Status) -> Option<Event> {
    let e = StatusEvent::from_code(s.event)?;
    let name = log_name(e)?;
    let names_object = matches!(
        e,
        StatusEvent::Decided
            | StatusEvent::Placed
            | StatusEvent::Fault
            | StatusEvent::Resumed
            | StatusEvent::AwaitingObject
            | StatusEvent::Skipped
    );
    let object = if names_object && s.object_index < s.objects_total {
        s.object_index + 1
    } else {
        0
    };
    let job = if e == StatusEvent::Shutdown {
        0
    } else {
        s.job_id
    };
    Some(Event { name, job, object })
}

/// One job as seen on the bus.
#[derive(Debug, Clone, Default)]
pub struct JobSeen {
    /// Objects in the job.
    pub objects: u32,
    /// Objects decided (0-based), and placed.
    pub decided: BTreeSet<u32>,
    /// Objects placed.
    pub placed: BTreeSet<u32>,
    /// How it ended: the event and the fault (`None` while it runs).
    pub end: Option<(StatusEvent, Fault)>,
    /// The loopback's last word on the box after a release of this job: every object inside.
    pub last_all_inside: Option<bool>,
    /// Faults reported during the job, by name.
    pub faults: BTreeMap<String, u32>,
}

/// What the observer found, shared with the harness.
#[derive(Debug, Default)]
pub struct Seen {
    /// Every job accepted, by id.
    pub jobs: BTreeMap<u64, JobSeen>,
    /// Every status event but heartbeats, in order, with when it was received (ns).
    pub events: Vec<(u64, Event)>,
    /// Violations of the invariants: when (ns) and what.
    pub violations: Vec<(u64, String)>,
    /// Joint commands checked against the arm's limits, and against the measured arm.
    pub commands_checked: u64,
    /// Of those, compared with a fresh joint state.
    pub commands_compared: u64,
    /// Largest distance of a command from the measured arm (rad).
    pub max_command_offset_rad: f64,
    /// The newest heartbeat.
    pub heartbeat: Option<Status>,
}

/// The observer's handle.
pub struct Observer {
    /// What it found so far.
    pub seen: Arc<Mutex<Seen>>,
    /// Objects placed and jobs accepted so far: the cell's progress.
    pub progress: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Observer {
    /// Starts observing the cell under `prefix`.
    pub fn start(prefix: &str) -> Result<Self, String> {
        let services = Services::new(prefix).map_err(|e| e.to_string())?;
        let seen = Arc::new(Mutex::new(Seen::default()));
        let progress = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = {
            let (seen, progress, stop) = (seen.clone(), progress.clone(), stop.clone());
            std::thread::Builder::new()
                .name("chaos-observer".into())
                .spawn(move || {
                    let ports = Ports::open(&services);
                    let ok = ports.is_ok();
                    let _ = ready_tx.send(ports.as_ref().err().cloned());
                    if let (true, Ok(p)) = (ok, ports) {
                        observe(p, &seen, &progress, &stop);
                    }
                })
                .map_err(|e| e.to_string())?
        };
        match ready_rx.recv_timeout(Duration::from_secs(30)) {
            Ok(None) => Ok(Self {
                seen,
                progress,
                stop,
                thread: Some(thread),
            }),
            Ok(Some(e)) => Err(e),
            Err(_) => Err("the observer did not open its ports in 30 s".into()),
        }
    }

    /// Stops observing (what was seen stays in [`Observer::seen`]).
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Ports {
    status: Sub<Status>,
    cmd: Sub<JointCommand>,
    js: Sub<JointState>,
    outcome: Sub<SimOutcome>,
    _bus: Bus,
}

impl Ports {
    fn open(s: &Services) -> Result<Self, String> {
        let bus = Bus::open("herb-chaos-observer", s).map_err(|e| e.to_string())?;
        let e = |e: herb_ipc::bus::BusError| e.to_string();
        Ok(Self {
            status: bus.subscriber(&s.status()).map_err(e)?,
            cmd: bus.subscriber(&s.joint_command()).map_err(e)?,
            js: bus.subscriber(&s.joint_state()).map_err(e)?,
            outcome: bus.subscriber(&s.sim_outcome()).map_err(e)?,
            _bus: bus,
        })
    }
}

fn observe(p: Ports, seen: &Mutex<Seen>, progress: &AtomicU64, stop: &AtomicBool) {
    let (lo, hi) = herb_robot::motion::baxter_left_arm_range();
    let mut q: Option<([f64; DOF], u64)> = None;
    while !stop.load(Ordering::Relaxed) {
        let now = monotonic_ns();
        let mut s = seen.lock().unwrap_or_else(|e| e.into_inner());
        while let Ok(Some(m)) = p.js.receive() {
            if m.payload().validate().is_ok() {
                q = Some((m.payload().position, now));
            }
        }
        while let Ok(Some(m)) = p.cmd.receive() {
            let c = m.payload();
            let wide = [herb_ipc::MAX_JOINT_ABS_RAD; DOF];
            if let Err(e) = c.validate(&wide.map(|v| -v), &wide) {
                s.violations
                    .push((now, format!("herbd sent a malformed joint command: {e}")));
                continue;
            }
            s.commands_checked += 1;
            if let Some(j) = (0..DOF).find(|&j| c.position[j] < lo[j] || c.position[j] > hi[j]) {
                s.violations.push((
                    now,
                    format!(
                        "command outside the arm's limits: joint {} at {:.4} rad ({:.4}..{:.4})",
                        herb_ipc::JOINT_NAMES[j],
                        c.position[j],
                        lo[j],
                        hi[j]
                    ),
                ));
            }
            if let Some((qm, at)) = q
                && now.saturating_sub(at) < FRESH_STATE_NS
            {
                s.commands_compared += 1;
                let off = (0..DOF)
                    .map(|j| (c.position[j] - qm[j]).abs())
                    .fold(0.0, f64::max);
                s.max_command_offset_rad = s.max_command_offset_rad.max(off);
                if off > FAR_RAD {
                    s.violations.push((
                        now,
                        format!("command {off:.3} rad from the measured arm (at most {FAR_RAD})"),
                    ));
                }
            }
        }
        while let Ok(Some(m)) = p.outcome.receive() {
            let o = m.payload();
            if o.validate().is_ok()
                && let Some(j) = s.jobs.get_mut(&o.job_id)
            {
                j.last_all_inside = Some(o.all_inside == 1);
            }
        }
        while let Ok(Some(m)) = p.status.receive() {
            let st = *m.payload();
            if st.validate().is_err() {
                s.violations
                    .push((now, "herbd published an invalid status".into()));
                continue;
            }
            status(&mut s, &st, now, progress);
        }
        drop(s);
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// One status: the job's record and the invariants on it.
fn status(s: &mut Seen, st: &Status, now: u64, progress: &AtomicU64) {
    let Some(ev) = StatusEvent::from_code(st.event) else {
        return;
    };
    if ev == StatusEvent::Heartbeat {
        s.heartbeat = Some(*st);
        return;
    }
    if let Some(e) = event_of(st) {
        s.events.push((now, e));
    }
    let fault = Fault::from_code(st.fault).unwrap_or(Fault::None);
    let mut bad = Vec::new();
    if ev == StatusEvent::Accepted {
        s.jobs.entry(st.job_id).or_default().objects = st.objects_total;
        progress.fetch_add(1, Ordering::Relaxed);
    }
    if ev == StatusEvent::Shutdown || st.job_id == 0 {
        return;
    }
    let j = s.jobs.entry(st.job_id).or_default();
    j.objects = j.objects.max(st.objects_total);
    match ev {
        StatusEvent::Decided if !j.decided.insert(st.object_index) => bad.push(format!(
            "job {} object {} decided twice",
            st.job_id,
            st.object_index + 1
        )),
        StatusEvent::Placed => {
            progress.fetch_add(1, Ordering::Relaxed);
            if !j.placed.insert(st.object_index) {
                bad.push(format!(
                    "job {} object {} placed twice",
                    st.job_id,
                    st.object_index + 1
                ));
            }
        }
        StatusEvent::Fault => *j.faults.entry(format!("{fault:?}")).or_default() += 1,
        StatusEvent::JobDone | StatusEvent::JobFailed | StatusEvent::JobCancelled => {
            if let Some((prev, _)) = j.end {
                bad.push(format!(
                    "job {} ended twice ({prev:?}, then {ev:?})",
                    st.job_id
                ));
            }
            j.end = Some((ev, fault));
            if ev == StatusEvent::JobFailed && fault == Fault::None {
                bad.push(format!("job {} failed without a named fault", st.job_id));
            }
            if ev == StatusEvent::JobDone && j.last_all_inside == Some(false) {
                bad.push(format!(
                    "job {} done while the loopback says an object is outside",
                    st.job_id
                ));
            }
        }
        _ => {}
    }
    for b in bad {
        s.violations.push((now, b));
    }
}
