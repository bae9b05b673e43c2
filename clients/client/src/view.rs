//! `herbctl watch`: what a person watching herbd needs on one screen, built from the statuses
//! it publishes (and, on a simulated cell, the loopback's outcomes). [`WatchView`] keeps the
//! state; [`WatchView::render`] draws it as text, a pure function of the state and the time,
//! so that it is tested without a terminal.

use herb_ipc::{Fault, JobState, NO_OBJECT, SimObject, SimOutcome, Status, StatusEvent};
use std::collections::VecDeque;
use std::fmt::Write;

/// Recent events kept on screen.
const RECENT: usize = 8;
/// Width of the progress bar (characters).
const BAR: usize = 30;
/// herbd heartbeats at 10 Hz: silent this long (s), it is reported lost.
pub const LOST_AFTER_S: f64 = 1.0;

/// The state of the view.
#[derive(Debug, Clone, Default)]
pub struct WatchView {
    /// IPC prefix watched.
    pub prefix: String,
    /// The newest status, and when it arrived (s, the caller's clock).
    last: Option<(Status, f64)>,
    /// The first status's cycle count and stamp (ns), for the loop rate.
    first: Option<(u64, u64)>,
    /// The current (or last) job's latest decision.
    decided: Option<Status>,
    /// The latest simulated outcome.
    outcome: Option<SimOutcome>,
    /// Recent events: wall-clock label and text.
    recent: VecDeque<(String, String)>,
    /// Faults seen since the view started.
    faults: u64,
}

impl WatchView {
    /// A view of herbd under `prefix`.
    pub fn new(prefix: &str) -> Self {
        Self {
            prefix: prefix.into(),
            ..Self::default()
        }
    }

    /// A status received at `t` (s) and wall-clock `wall` (a label such as `14:02:07`);
    /// `name` names an object type.
    pub fn status(&mut self, s: &Status, t: f64, wall: &str, name: &dyn Fn(u32) -> String) {
        if s.validate().is_err() {
            return;
        }
        if self.first.is_none() {
            self.first = Some((s.cycles, s.header.stamp_ns));
        }
        self.last = Some((*s, t));
        let Some(ev) = StatusEvent::from_code(s.event) else {
            return;
        };
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        let text = match ev {
            StatusEvent::Heartbeat => return,
            StatusEvent::Accepted => {
                self.decided = None;
                format!("job {} accepted: {} objects", s.job_id, s.objects_total)
            }
            StatusEvent::Decided => {
                self.decided = Some(*s);
                format!(
                    "object {}/{} ({}) decided in {:.3} ms",
                    s.object_index + 1,
                    s.objects_total,
                    name(s.object_type),
                    s.decision_ns as f64 / 1e6
                )
            }
            StatusEvent::Placed => format!(
                "object {} placed ({}/{})",
                s.object_index + 1,
                s.objects_done,
                s.objects_total
            ),
            StatusEvent::Fault => {
                self.faults += 1;
                match s.limit_words() {
                    Some(w) => format!("FAULT {fault:?}: {w}"),
                    None => format!("FAULT {fault:?} ({})", fault.describe()),
                }
            }
            StatusEvent::Skipped => format!(
                "object {}/{} ({}) skipped: {}; take it away from the pick station",
                s.object_index + 1,
                s.objects_total,
                name(s.object_type),
                fault.describe()
            ),
            StatusEvent::AwaitingObject => format!(
                "waiting for {} at the pick station (object {}/{}, try {})",
                name(s.object_type),
                s.object_index + 1,
                s.objects_total,
                s.attempt + 1
            ),
            StatusEvent::Braked if fault.arm_unseen() => {
                "halted: the robot stopped itself; herbd commands nothing until it is back".into()
            }
            StatusEvent::Braked => "braked: the arm stands still".into(),
            StatusEvent::Resumed => "resumed".into(),
            StatusEvent::JobDone => format!(
                "job {} DONE: {}/{} placed",
                s.job_id, s.objects_done, s.objects_total
            ),
            StatusEvent::JobFailed => format!(
                "job {} FAILED ({fault:?}): {}/{} placed",
                s.job_id, s.objects_done, s.objects_total
            ),
            StatusEvent::JobCancelled => format!(
                "job {} cancelled: {}/{} placed",
                s.job_id, s.objects_done, s.objects_total
            ),
            StatusEvent::Shutdown => "herbd shut down".into(),
        };
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back((wall.into(), text));
    }

    /// A simulated outcome (loopback only).
    pub fn outcome(&mut self, o: &SimOutcome) {
        if o.validate().is_ok() {
            self.outcome = Some(*o);
        }
    }

    /// The view at time `t` (s, the clock of [`WatchView::status`]), as lines of text.
    pub fn render(&self, t: f64, name: &dyn Fn(u32) -> String) -> String {
        let mut out = String::new();
        let Some((s, at)) = self.last else {
            let _ = writeln!(
                out,
                "herbd (prefix {:?}): not heard yet; is it running with this prefix?",
                self.prefix
            );
            return out;
        };
        let state = JobState::from_code(s.state).unwrap_or(JobState::Idle);
        let ago = t - at;
        let health = if ago > LOST_AFTER_S {
            format!("LOST: no status for {ago:.1} s (last state {state:?})")
        } else {
            format!("{state:?}, heard {ago:.1} s ago")
        };
        let _ = writeln!(out, "herbd (prefix {:?}): {health}", self.prefix);
        // Job line and progress bar.
        if s.job_id != 0 && s.objects_total > 0 {
            let done = s.objects_done.min(s.objects_total);
            let filled = (done as usize * BAR) / s.objects_total as usize;
            let current = if s.object_type != NO_OBJECT {
                format!(
                    ", object {}/{} ({})",
                    (s.object_index + 1).min(s.objects_total),
                    s.objects_total,
                    name(s.object_type)
                )
            } else {
                String::new()
            };
            let _ = writeln!(
                out,
                "job {}: {done}/{} placed{current}",
                s.job_id, s.objects_total
            );
            let _ = writeln!(
                out,
                "  [{}{}] {:>3.0} %",
                "#".repeat(filled),
                ".".repeat(BAR - filled),
                100.0 * done as f64 / s.objects_total as f64
            );
        } else {
            let _ = writeln!(out, "job: none");
        }
        if let Some(d) = self
            .decided
            .filter(|d| d.job_id == s.job_id || s.job_id == 0)
        {
            let _ = writeln!(
                out,
                "  last decision: object {} at x {:+.3} y {:+.3} z {:.3} m, yaw {:+.2} rad, in {:.3} ms",
                d.object_index + 1,
                d.pose[0],
                d.pose[1],
                d.pose[2],
                d.pose[3],
                d.decision_ns as f64 / 1e6
            );
        }
        // Loop statistics.
        // Cycles over herbd's own stamps (a status from history arrives late).
        let rate = self.first.and_then(|(c0, st0)| {
            let dt = s.header.stamp_ns.saturating_sub(st0) as f64 / 1e9;
            (dt > 0.5).then(|| s.cycles.saturating_sub(c0) as f64 / dt)
        });
        let _ = writeln!(
            out,
            "loop: {} cycles{}, {} deadline misses ({:.4} %), worst cycle {:.1} us, {} sensor inputs and {} requests refused",
            s.cycles,
            rate.map_or(String::new(), |r| format!(" ({r:.0} Hz)")),
            s.deadline_misses,
            if s.cycles > 0 {
                100.0 * s.deadline_misses as f64 / s.cycles as f64
            } else {
                0.0
            },
            s.max_cycle_ns as f64 / 1000.0,
            s.rejected_inputs,
            s.rejected_requests
        );
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        // Between jobs the fault is why a job would be refused now; in a job, the last one.
        let said = match (fault, state) {
            (Fault::None, JobState::Idle) => "none: ready for a job".to_string(),
            (Fault::None, _) => "none".to_string(),
            (f, JobState::Idle) => format!("robot not ready: {}", f.describe()),
            (f, _) => format!("{f:?} ({}, the last one)", f.describe()),
        };
        let said = match s.limit_words() {
            Some(w) => format!("{said}: {w}"),
            None => said,
        };
        let _ = writeln!(
            out,
            "fault: {said}; {} fault events since watching",
            self.faults
        );
        if let Some(o) = &self.outcome {
            let outside = outside_objects(o, name);
            let _ = writeln!(
                out,
                "box (simulated): {} objects, {}, compactness {:.3}",
                o.objects,
                if outside.is_empty() {
                    "every one inside".to_string()
                } else {
                    format!("OUTSIDE: {}", outside.join(", "))
                },
                o.compactness
            );
        }
        let _ = writeln!(out, "recent:");
        for (wall, text) in &self.recent {
            let _ = writeln!(out, "  {wall}  {text}");
        }
        out
    }
}

/// How `o` crosses the success volume, e.g. `over the +x wall by 8 mm`; `None` when inside.
pub fn crossing(o: &SimObject) -> Option<String> {
    (o.bound != 0).then(|| format!("over the {} by {:.0} mm", o.bound_name(), o.over_m * 1000.0))
}

/// Every object of `outcome` outside the success volume, numbered by its place in the box and
/// named by `name`, e.g. `object 3 (011) over the +x wall by 8 mm`.
pub fn outside_objects(outcome: &SimOutcome, name: &dyn Fn(u32) -> String) -> Vec<String> {
    outcome
        .objects_listed()
        .iter()
        .enumerate()
        .filter_map(|(i, o)| {
            crossing(o).map(|c| format!("object {} ({}) {c}", i + 1, name(o.object_type)))
        })
        .collect()
}

/// `HH:MM:SS` UTC of a `std::time::SystemTime`.
pub fn wall_label(t: std::time::SystemTime) -> String {
    let s = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
        % 86_400;
    format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

#[cfg(test)]
mod tests {
    use super::*;
    use herb_ipc::Header;

    fn status(event: StatusEvent, cycles: u64) -> Status {
        Status {
            header: Header::at(cycles + 1, cycles * 1_000_000),
            job_id: 42,
            event: event as u32,
            state: JobState::Running as u32,
            fault: Fault::None as u32,
            objects_total: 4,
            objects_done: 1,
            object_index: 1,
            object_type: 3,
            decision_wait_ms: 0,
            pose: [0.01, -0.02, 0.05, 1.5],
            decision_ns: 412_000,
            cycles,
            deadline_misses: 2,
            rejected_inputs: 0,
            max_cycle_ns: 85_100,
            rejected_requests: 0,
            limit_joint: herb_ipc::NO_JOINT,
            limit_position_rad: 0.0,
            limit_bound_rad: 0.0,
            attempt: 0,
            waiting_for: 0,
            reserved: 0,
        }
    }

    #[test]
    fn between_jobs_the_view_says_why_the_robot_is_not_ready() {
        let name = |t: u32| format!("type{t}");
        let mut v = WatchView::new("herb");
        let mut hb = status(StatusEvent::Heartbeat, 1000);
        hb.job_id = 0;
        hb.state = JobState::Idle as u32;
        hb.fault = Fault::RobotDisabled as u32;
        v.status(&hb, 1.0, "10:00:00", &name);
        let text = v.render(1.1, &name);
        assert!(
            text.contains("fault: robot not ready: robot disabled;"),
            "{text}"
        );
        hb.fault = Fault::None as u32;
        v.status(&hb, 1.2, "10:00:00", &name);
        assert!(
            v.render(1.3, &name)
                .contains("fault: none: ready for a job;")
        );
    }

    #[test]
    fn the_view_shows_progress_loop_faults_and_a_lost_daemon() {
        let name = |t: u32| format!("type{t}");
        let mut v = WatchView::new("herb");
        assert!(v.render(0.0, &name).contains("not heard yet"));
        v.status(
            &status(StatusEvent::Heartbeat, 1000),
            1.0,
            "10:00:00",
            &name,
        );
        v.status(&status(StatusEvent::Decided, 1500), 1.5, "10:00:00", &name);
        let mut f = status(StatusEvent::Fault, 2000);
        f.fault = Fault::JointStateTimeout as u32;
        f.state = JobState::Faulted as u32;
        v.status(&f, 2.0, "10:00:01", &name);
        let text = v.render(2.1, &name);
        for want in [
            "Faulted, heard 0.1 s ago",
            "job 42: 1/4 placed, object 2/4 (type3)",
            "[#######.......................]  25 %",
            "last decision: object 2 at x +0.010 y -0.020 z 0.050 m, yaw +1.50 rad, in 0.412 ms",
            "loop: 2000 cycles (1000 Hz), 2 deadline misses (0.1000 %), worst cycle 85.1 us",
            "fault: JointStateTimeout (adapter silent: no joint state from the arm adapter, the last one); 1 fault events",
            "10:00:01  FAULT JointStateTimeout (adapter silent: no joint state from the arm adapter)",
        ] {
            assert!(text.contains(want), "{want:?} in\n{text}");
        }
        assert!(v.render(3.5, &name).contains("LOST: no status for 1.5 s"));
        assert_eq!(
            wall_label(std::time::UNIX_EPOCH + std::time::Duration::from_secs(86_400 + 3_725)),
            "01:02:05"
        );
    }
}
