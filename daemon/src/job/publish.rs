//! What the machine publishes and keeps: the commands and the heartbeat each tick (joint
//! commands checked against the limits), the statuses, the job's record for the journal and
//! the run log's snapshots.

use super::*;

impl Job {
    /// A status with `event` about no particular object, as the machine stands (the shell's
    /// `Shutdown`).
    pub fn status(&self, event: StatusEvent) -> Status {
        self.status_of(event, NO_OBJECT, [0.0; 4], 0)
    }

    /// The state between jobs, when no job runs and both buffers are home (else `None`).
    pub fn snapshot(&self) -> Option<JobSnapshot> {
        let between =
            matches!(self.phase, Phase::Idle | Phase::Stopped { .. }) && self.run.is_none();
        if !between || self.active.is_none() || self.spare.is_none() {
            return None;
        }
        Some(JobSnapshot {
            inputs: self.inputs,
            commands: self.out,
            job: self.record(),
            release_stamp: self.release_stamp,
            fault: self.fault,
            stopping: self.stopping(),
        })
    }

    /// Takes up the state of `s` (an idle machine's), keeping this machine's buffers and
    /// parameters.
    pub fn restore(&mut self, s: &JobSnapshot) {
        self.inputs = s.inputs;
        self.out = s.commands;
        self.set_phase(if s.stopping {
            Phase::Stopped { recovered: false }
        } else {
            Phase::Idle
        });
        let r = &s.job;
        self.run = None;
        let count = (r.count as usize).min(MAX_JOB_OBJECTS);
        self.last = Progress {
            objects: r.objects,
            ordered: r.ordered,
            order: r.order,
            count,
            index: r.index as usize,
            done: r.done as usize,
            ..Progress::NONE
        };
        self.holding = r.holding;
        self.flip = r.flip;
        self.release_stamp = s.release_stamp;
        self.fault = s.fault;
        self.excess = None;
    }

    /// The job as the machine holds it, whatever its phase (between jobs: the last job's
    /// objects, order and counts, `job_id` 0, no placement); the placement only if it is the
    /// current object's. The order is the machine's even before the job is ordered: statuses
    /// name the current object from it.
    pub(super) fn record(&self) -> JobRecord {
        let phase = match self.phase {
            Phase::Idle => ObjectPhase::Idle,
            Phase::Stopped { .. } if self.run.is_none() => ObjectPhase::Idle,
            Phase::Ordering => ObjectPhase::Ordering,
            Phase::Starting | Phase::Planning | Phase::AwaitDecision { .. } if self.holding => {
                ObjectPhase::Carrying
            }
            Phase::Starting | Phase::Planning | Phase::AwaitDecision { .. } => {
                ObjectPhase::Deciding
            }
            Phase::Streaming { .. } | Phase::Gripper { .. } | Phase::Retreating { .. }
                if self.holding =>
            {
                ObjectPhase::Carrying
            }
            Phase::Streaming { .. }
            | Phase::Gripper { .. }
            | Phase::AwaitOperator { .. }
            | Phase::Regrasp { .. }
            | Phase::Retreating { .. } => ObjectPhase::Moving,
            Phase::Braking { .. }
            | Phase::Faulted { .. }
            | Phase::Recovering { .. }
            | Phase::Abandoning
            | Phase::Stopped { .. } => ObjectPhase::Halted,
        };
        let p = self.progress();
        // Past the job's objects the machine reads nothing: kept as zeros.
        let (mut objects, mut order) = ([0; MAX_JOB_OBJECTS], [0; MAX_JOB_OBJECTS]);
        objects[..p.count].copy_from_slice(&p.objects[..p.count]);
        order[..p.count].copy_from_slice(&p.order[..p.count]);
        JobRecord {
            job_id: self.job_id(),
            count: p.count as u16,
            objects,
            ordered: p.ordered,
            order,
            index: p.index as u16,
            done: p.done as u16,
            holding: self.holding,
            flip: self.flip,
            phase,
            placement: self
                .run
                .and_then(|r| r.placement)
                .filter(|pl| pl.index as usize == p.index),
            confirm_picks: self.run.is_some_and(|r| r.confirm_picks),
        }
    }

    /// The running job as the journal keeps it ([`JobRecord::NONE`] between jobs and while a
    /// cancelled job retreats: a cancelled job is not taken up again); until the job is
    /// ordered, its order is the objects as submitted. Allocates nothing; the loop compares it
    /// with the last one it handed to the writer.
    pub fn journal(&self) -> JobRecord {
        if self.run.is_none_or(|r| r.cancelled)
            || matches!(self.phase, Phase::Idle | Phase::Retreating { .. })
        {
            return JobRecord::NONE;
        }
        let mut r = self.record();
        if !r.ordered {
            r.order = r.objects;
        }
        r
    }

    pub(super) fn publish(&mut self, now: u64, fx: &mut impl Effects) {
        if self.commanding() {
            // Faulted, nothing moves the arm: the robot holds by itself, and the next command
            // is planned from the state measured when the job resumes.
            let halted = matches!(self.phase, Phase::Faulted { .. } | Phase::Stopped { .. });
            let q = self.out.cmd.position;
            // Inside the limits, or between them and where the arm stood when the job started
            // or resumed (the way back in from a sag past a limit).
            let from = &self.out.from;
            let inside = (0..DOF).all(|i| {
                q[i] >= self.p.lower[i].min(from[i]) && q[i] <= self.p.upper[i].max(from[i])
            });
            if !halted {
                if inside {
                    fx.joint(&self.out.cmd);
                } else {
                    // Never reached by planned samples (checked by the planner); a guard.
                    self.out.limit_holds += 1;
                }
            }
            if self.out.grip_due || now.saturating_sub(self.out.grip_sent_at) >= GRIPPER_REPEAT_NS {
                self.out.grip_due = false;
                self.out.grip_sent_at = now;
                fx.gripper(self.job_id(), self.out.grip_cmd, self.out.grip_object);
            }
        }
        if now.saturating_sub(self.out.last_heartbeat) >= HEARTBEAT_PERIOD_NS {
            self.out.last_heartbeat = now;
            // Between jobs, a heartbeat's fault says why a job would be refused now.
            if self.run.is_none() {
                self.fault = self.not_ready(now).unwrap_or(Fault::None);
                if matches!(self.fault, Fault::OutsideLimits | Fault::BeyondArmLimits) {
                    self.excess = self.measured_excess().map(|(_, e)| e);
                }
            }
            self.emit(fx, StatusEvent::Heartbeat, self.current_type(), [0.0; 4], 0);
        }
    }

    pub(super) fn status_of(
        &self,
        event: StatusEvent,
        object_type: u32,
        pose: [f32; 4],
        dns: u64,
    ) -> Status {
        let state = match event {
            StatusEvent::JobDone => JobState::Done,
            StatusEvent::JobFailed => JobState::Failed,
            StatusEvent::JobCancelled => JobState::Cancelled,
            _ => self.state(),
        };
        let p = self.progress();
        let waiting_for = match (self.run, event) {
            (_, StatusEvent::JobDone | StatusEvent::JobFailed | StatusEvent::JobCancelled) => {
                JobWait::None
            }
            (Some(r), _) if r.confirm_picks && r.awaiting && !r.cancelled => JobWait::Confirmation,
            (Some(_), _)
                if matches!(self.phase, Phase::AwaitDecision { .. })
                    && self.decided_pose().is_none() =>
            {
                JobWait::Decision
            }
            _ => JobWait::None,
        };
        let mut s = Status {
            header: Header::at(0, 0),
            job_id: self.job_id(),
            event: event as u32,
            state: state as u32,
            fault: self.fault as u32,
            objects_total: p.count as u32,
            objects_done: p.done.min(p.count) as u32,
            object_index: p.index as u32,
            object_type,
            decision_wait_ms: (p.wait_ns / 1_000_000).min(u32::MAX as u64) as u32,
            pose,
            decision_ns: dns,
            cycles: 0,
            deadline_misses: 0,
            rejected_inputs: self.inputs.rejected,
            max_cycle_ns: 0,
            rejected_requests: self.inputs.rejected_requests,
            limit_joint: NO_JOINT,
            limit_position_rad: 0.0,
            limit_bound_rad: 0.0,
            attempt: p.missed,
            waiting_for: waiting_for as u32,
            reserved: 0,
        };
        if matches!(self.fault, Fault::OutsideLimits | Fault::BeyondArmLimits)
            && let Some(e) = self.excess
            && e.position.is_finite()
        {
            s.limit_joint = e.joint as u32;
            s.limit_position_rad = e.position as f32;
            s.limit_bound_rad = e.bound as f32;
        }
        s
    }

    pub(super) fn emit(
        &self,
        fx: &mut impl Effects,
        event: StatusEvent,
        object_type: u32,
        pose: [f32; 4],
        decision_ns: u64,
    ) {
        fx.status(&self.status_of(event, object_type, pose, decision_ns));
    }
}
