//! Faults and recovery: a fault reported and braked (or the arm left to hold when unseen), the
//! stop, the resume from the measured state (an arm past its limits named and brought back),
//! and a job taken up from the journal after a restart.

use super::*;

impl Job {
    /// At a job's start or resume with the arm measured outside the joint limits (inside its
    /// own): reported as a fault naming the joint, while the planner brings it back inside
    /// before the first motion; the job goes on.
    pub(super) fn say_outside_limits(&mut self, fx: &mut impl Effects) {
        if let Some((fault, e)) = self.measured_excess() {
            self.fault = fault;
            self.excess = Some(e);
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
        }
    }

    /// Takes up the unfinished job `r` from the journal (an idle machine at start, before the
    /// first cycle): the next ticks report [`Fault::Restarted`] and hand the planner the job's
    /// order, then the job waits, faulted and commanding nothing, until its inputs are fresh,
    /// and resumes from the measured state (see the module's "Restart"). With `resume` false,
    /// the first tick reports the fault and ends the job, failed, instead.
    pub fn recover(&mut self, r: &JobRecord, resume: bool) {
        let count = (r.count as usize).min(MAX_JOB_OBJECTS);
        let index = (r.index as usize).min(count);
        let progress = Progress {
            objects: r.objects,
            ordered: r.ordered,
            // Until the planner answers, statuses name the current object from the submitted
            // list.
            order: if r.ordered { r.order } else { r.objects },
            count,
            index,
            done: (r.done as usize).min(index),
            ..Progress::NONE
        };
        let mut run = Run::new(r.job_id, progress, r.confirm_picks);
        run.placement = r.placement;
        // A placement in the journal was announced before the crash.
        run.announced = r.placement.is_some_and(|p| p.index as usize == index);
        self.run = Some(run);
        self.holding = r.holding;
        self.flip = r.flip;
        self.release_stamp = 0;
        self.fault = Fault::Restarted;
        self.set_phase(if resume {
            Phase::Recovering { asked: false }
        } else {
            Phase::Abandoning
        });
    }

    /// A fault: report, brake if moving and the arm is seen, hold (stopped, when the daemon
    /// stops: it is only reported).
    pub(super) fn raise(&mut self, fx: &mut impl Effects, fault: Fault) {
        self.fault = fault;
        self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
        if matches!(self.phase, Phase::Stopped { .. }) {
            return;
        }
        // What the brake leads to: the stop's end, a cancelled job's retreat, or the hold.
        let then = if self.stopping() {
            AfterBrake::Stop
        } else if self.cancelled() {
            AfterBrake::Retreat
        } else {
            AfterBrake::Hold
        };
        if fault.arm_unseen() {
            // No joint state: the adapter passes no command on; a brake streamed now would
            // only be a setpoint planned before the interruption.
            self.halt(fx, then);
        } else {
            self.begin_brake(fx, then);
        }
    }

    /// The last command moves the arm.
    pub(super) fn moving(&self) -> bool {
        self.out.cmd.velocity.iter().any(|v| *v != 0.0)
            || self.out.cmd.acceleration.iter().any(|a| *a != 0.0)
    }

    /// Brakes a moving arm (a Ruckig brake from the last command), `then` what follows; an arm
    /// at rest (or no buffer home) is halted at once.
    pub(super) fn begin_brake(&mut self, fx: &mut impl Effects, then: AfterBrake) {
        let moving = self.moving();
        let (seg, cursor) = match self.phase {
            Phase::Streaming { seg, cursor } => (seg, cursor),
            _ => (0, 0),
        };
        if moving && let Some(buf) = self.spare.take() {
            match fx.plan(Request::Brake {
                state: self.out.cmd,
                buf,
            }) {
                Ok(()) => {
                    self.set_phase(Phase::Braking {
                        cursor: None,
                        seg,
                        active_cursor: cursor,
                        then,
                    });
                    return;
                }
                Err(Request::Brake { buf, .. }) => self.spare = Some(buf),
                Err(_) => {}
            }
        }
        self.halt(fx, then);
    }

    /// The arm at rest, nothing streamed: `Stopped` for the stop, else `Faulted` (holding until
    /// the inputs are fresh; a cancelled job then ends where it stands).
    pub(super) fn halt(&mut self, fx: &mut impl Effects, then: AfterBrake) {
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        let recovered = self.recovered();
        self.set_phase(match then {
            AfterBrake::Stop => Phase::Stopped { recovered },
            AfterBrake::Hold | AfterBrake::Retreat => Phase::Faulted {
                healthy_since: None,
                recovered,
            },
        });
        self.emit(fx, StatusEvent::Braked, self.current_type(), [0.0; 4], 0);
    }

    /// The daemon stops: a moving arm brakes, then stops; a brake under way ends the stop; a
    /// job halted elsewhere is stopped where it is.
    pub(super) fn begin_stop(&mut self, fx: &mut impl Effects) {
        match self.phase {
            Phase::Streaming { .. } => {
                self.fault = Fault::Stop;
                self.begin_brake(fx, AfterBrake::Stop);
            }
            Phase::Braking {
                cursor,
                seg,
                active_cursor,
                ..
            } => self.set_phase(Phase::Braking {
                cursor,
                seg,
                active_cursor,
                then: AfterBrake::Stop,
            }),
            // Nothing runs: nothing to halt (the shutdown reports the idle state).
            Phase::Idle => self.set_phase(Phase::Stopped { recovered: false }),
            Phase::Stopped { .. } => {}
            _ => self.halt(fx, AfterBrake::Stop),
        }
    }

    pub(super) fn brake_step(
        &mut self,
        fx: &mut impl Effects,
        cursor: Option<usize>,
        seg: usize,
        active_cursor: usize,
        then: AfterBrake,
    ) {
        match cursor {
            None => {
                // Until the brake is computed (a cycle or two), go on along the plan, which is
                // within every limit, and hold at its segment end.
                if let Some(p) = &self.active
                    && let Some(sg) = p.segments().get(seg)
                    && active_cursor < sg.end
                    && let Some(s) = p.setpoints.get(active_cursor)
                {
                    self.out.cmd = *s;
                    self.set_phase(Phase::Braking {
                        cursor: None,
                        seg,
                        active_cursor: active_cursor + 1,
                        then,
                    });
                } else {
                    self.out.cmd.velocity = [0.0; DOF];
                    self.out.cmd.acceleration = [0.0; DOF];
                }
            }
            Some(k) => {
                let next = self
                    .brake
                    .as_ref()
                    .and_then(|b| b.setpoints.get(k).copied());
                match next {
                    Some(s) => {
                        self.out.cmd = s;
                        self.set_phase(Phase::Braking {
                            cursor: Some(k + 1),
                            seg,
                            active_cursor,
                            then,
                        });
                    }
                    None => {
                        if let Some(b) = self.brake.take() {
                            self.recycle(b);
                        }
                        if then == AfterBrake::Retreat {
                            self.out.cmd.velocity = [0.0; DOF];
                            self.out.cmd.acceleration = [0.0; DOF];
                            self.emit(fx, StatusEvent::Braked, self.current_type(), [0.0; 4], 0);
                            self.retreat(fx);
                        } else {
                            self.halt(fx, then);
                        }
                    }
                }
            }
        }
    }

    /// Resumes a faulted job (`recovered`: taken up from the journal, resumed for the first
    /// time; it commands again from here).
    pub(super) fn resume(&mut self, fx: &mut impl Effects, now: u64, recovered: bool) {
        // Re-synchronise to where the arm is.
        if let Some(j) = self.inputs.js {
            self.out.cmd = Setpoint::at_rest(j.position);
            self.out.from = j.position;
        }
        let held = self.inputs.gs.is_some_and(|g| g.holding == 1);
        self.emit(fx, StatusEvent::Resumed, self.current_type(), [0.0; 4], 0);
        self.resume_from_measured(fx, now, recovered, held);
        if self.run.is_some() {
            // The arm sagged past a limit while halted: named now, brought back in by the
            // first motion.
            self.say_outside_limits(fx);
        }
    }

    /// The rest of [`Job::resume`]: what the job does next, from the measured state.
    pub(super) fn resume_from_measured(
        &mut self,
        fx: &mut impl Effects,
        now: u64,
        recovered: bool,
        held: bool,
    ) {
        if recovered && !self.take_up_measured_state(fx, held, now) {
            return;
        }
        if self.progress().index >= self.progress().count {
            self.finish(fx, StatusEvent::JobDone);
            return;
        }
        if self.holding && !held {
            self.fault = Fault::ObjectLost;
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
            self.holding = false;
        }
        // The current object's decided placement, if any: a resume does not decide again.
        let decided = self.decided_pose();
        if held && !self.holding && decided.is_some() {
            // The grasp closed while the job was halted: the current object is in the gripper.
            self.holding = true;
        }
        self.out.grip_cmd = if self.holding {
            GripperAction::Close
        } else {
            GripperAction::Open
        };
        self.out.grip_object = if self.holding {
            self.current_type()
        } else {
            NO_OBJECT
        };
        if self.decision_failed().is_some() {
            // Its decision failed while the job was halted: nothing more to do.
            self.await_decision(fx, now);
        } else if self.holding {
            // Placed where it was decided; or, not decided yet, held until it is.
            self.await_decision(fx, now);
        } else if decided.is_some() {
            // Halted before the grasp, or the object was lost from the gripper: pick it (again)
            // and place it where it was decided (nothing was released since); one decision,
            // announced once.
            self.set_phase(Phase::Starting);
            self.request_motion(fx, Motion::PickAndPlace);
            if self.phase == Phase::Starting {
                // No buffer home yet: the pick alone, the place once it is held.
                self.request_motion(fx, Motion::Pick);
            }
        } else {
            // Not decided yet: decided on a heightmap taken after the resume (a decision
            // still out is answered first, on an older one: its answer is kept).
            self.release_stamp = self.release_stamp.max(now);
            if self.run.is_some_and(|r| r.deciding.is_none()) {
                self.begin_object(fx, now);
            } else {
                self.set_phase(Phase::Starting);
                self.request_motion(fx, Motion::Pick);
            }
        }
    }

    /// A recovered job's first resume: what the journal said, checked against the measured
    /// gripper (`held`) and arm. False when the job cannot go on (it has been ended).
    pub(super) fn take_up_measured_state(
        &mut self,
        fx: &mut impl Effects,
        held: bool,
        now: u64,
    ) -> bool {
        let index = self.progress().index;
        let placement = self
            .run
            .and_then(|r| r.placement)
            .filter(|p| p.index as usize == index);
        let at_release = |p: &Placement| {
            self.inputs.js.is_some_and(|j| {
                p.release_q.is_some_and(|release| {
                    j.position
                        .iter()
                        .zip(&release)
                        .all(|(q, r)| (q - r).abs() <= RELEASE_Q_TOL_RAD)
                })
            })
        };
        match placement {
            // Released at its placement before the journal heard of it: placed.
            Some(p) if self.holding && !held && at_release(&p) => {
                self.holding = false;
                self.release_stamp = now;
                if let Some(r) = &mut self.run {
                    r.progress.done += 1;
                }
                self.emit(fx, StatusEvent::Placed, self.current_type(), p.pose, 0);
                if let Some(r) = &mut self.run {
                    r.progress.index += 1;
                    r.announced = false;
                    r.placement = None;
                }
            }
            // In the gripper (perhaps closed just before the crash): placed where decided, or,
            // picked before its decision came, held until it is decided (on a heightmap taken
            // after the resume) and placed as the journal says it was taken.
            _ if held => self.holding = true,
            // Not in the gripper: picked (again, as ObjectLost says, if the journal had it held).
            _ => {}
        }
        true
    }
}
