//! One object's cycle: its decision asked for while its pick is planned, the samples streamed
//! one per tick, the grasp (after the operator's confirmation when the job asks for one), the
//! wait for the decision at the lift pose, the place, the release, a missed grasp retried or
//! skipped, and the next object.

use super::*;

impl Job {
    /// Starts the current object: its decision is asked for, and its pick planned meanwhile.
    pub(super) fn begin_object(&mut self, fx: &mut impl Effects, now: u64) {
        if let Some(r) = &mut self.run {
            r.decision_failed = None;
            r.confirmed = false;
            r.awaiting = false;
            r.decide_since = now;
        }
        self.ask_decision(fx, now);
        self.set_phase(Phase::Starting);
        self.request_motion(fx, Motion::Pick);
    }

    /// Asks the decision worker where the current object goes (again on a later tick if its
    /// ring is full).
    pub(super) fn ask_decision(&mut self, fx: &mut impl Effects, now: u64) {
        let after_stamp_ns = self.release_stamp;
        let Some(r) = &mut self.run else { return };
        let p = &r.progress;
        let req = DecisionRequest {
            job_id: r.job_id,
            index: p.index as u32,
            order: p.order,
            count: p.count as u32,
            after_stamp_ns,
        };
        match fx.decide(req) {
            Ok(()) => {
                r.deciding = Some((r.progress.index, now));
                r.decide_due = false;
            }
            Err(_) => r.decide_due = true,
        }
    }

    /// The picked object is held at the lift pose: its place is planned if its placement is
    /// decided; else the arm holds it there until the decision comes (the wait is counted),
    /// and a failed decision ends the job.
    pub(super) fn await_decision(&mut self, fx: &mut impl Effects, now: u64) {
        if let Some(f) = self.decision_failed() {
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
        } else if self.decided_pose().is_some() {
            self.request_place(fx, now);
        } else {
            if let Some(r) = &mut self.run
                && r.deciding.is_none()
                && !r.decide_due
            {
                r.decide_since = now;
                r.decide_due = true;
            }
            self.set_phase(Phase::AwaitDecision { since: now });
        }
    }

    /// Asks for the held object's place at its decided placement.
    pub(super) fn request_place(&mut self, fx: &mut impl Effects, now: u64) {
        self.set_phase(Phase::AwaitDecision { since: now });
        self.request_motion(fx, Motion::Place { flip: self.flip });
    }

    /// Asks the planner for the current object's `motion` (a place or a pick and place at its
    /// decided placement) when a trajectory buffer is home; the phase becomes `Planning`, or
    /// stays as it is (`Starting`, `AwaitDecision`) to ask again on a later tick.
    pub(super) fn request_motion(&mut self, fx: &mut impl Effects, motion: Motion) {
        let pose = match motion {
            Motion::Pick => [0.0; 4],
            Motion::Place { .. } | Motion::PickAndPlace => match self.decided_pose() {
                Some(p) => p,
                None => return,
            },
        };
        let Some(r) = self.run else { return };
        let (index, order) = (r.progress.index, r.progress.order);
        let Some(buf) = self.spare.take() else {
            return;
        };
        let req = Request::Plan {
            index: index as u32,
            object: order[index],
            from: self.out.cmd.position,
            motion,
            pose,
            buf,
        };
        match fx.plan(req) {
            Ok(()) => {
                self.set_phase(Phase::Planning);
                if r.confirm_picks && !r.confirmed && !matches!(motion, Motion::Place { .. }) {
                    // A pick: the operator is asked for the object now, while the arm comes;
                    // from now on a confirmation is taken.
                    if let Some(run) = &mut self.run {
                        run.awaiting = true;
                    }
                    self.emit(
                        fx,
                        StatusEvent::AwaitingObject,
                        self.current_type(),
                        [0.0; 4],
                        0,
                    );
                }
            }
            Err(Request::Plan { buf, .. }) => self.spare = Some(buf),
            Err(_) => {}
        }
    }

    pub(super) fn step(&mut self, now: u64, fx: &mut impl Effects) {
        // The decision runs beside the motion: asked again when due, and given up when it does
        // not come in time (a hung worker never holds the arm).
        let live = self.run.is_some_and(|r| !r.cancelled)
            && matches!(
                self.phase,
                Phase::Starting
                    | Phase::Planning
                    | Phase::Streaming { .. }
                    | Phase::Gripper { .. }
                    | Phase::AwaitOperator { .. }
                    | Phase::Regrasp { .. }
                    | Phase::AwaitDecision { .. }
            );
        if live && self.decision_failed().is_none() && self.decided_pose().is_none() {
            if self
                .run
                .is_some_and(|r| r.decide_due && r.deciding.is_none())
            {
                self.ask_decision(fx, now);
            }
            let timeout = self.p.decision_timeout_ns;
            if let Some(r) = &mut self.run
                && let Some((_, at)) = r.deciding
                && now.saturating_sub(at) > timeout
            {
                r.deciding = None;
                r.decision_failed = Some(Fault::Decision);
            }
        }
        match self.phase {
            Phase::Idle | Phase::Ordering | Phase::Planning => {}
            // A job cancelled before the stop ends cancelled where it stands.
            Phase::Stopped { .. } if self.cancelled() => self.finish(fx, StatusEvent::JobCancelled),
            Phase::Stopped { .. } => {}
            Phase::Starting => self.request_motion(fx, Motion::Pick),
            Phase::AwaitDecision { since } => {
                if let Some(f) = self.decision_failed() {
                    self.add_wait(now, since);
                    self.fault = f;
                    self.finish(fx, StatusEvent::JobFailed);
                } else if self.decided_pose().is_some() {
                    self.request_motion(fx, Motion::Place { flip: self.flip });
                    if self.phase == Phase::Planning {
                        self.add_wait(now, since);
                    }
                }
            }
            Phase::Streaming { seg, cursor } => self.stream(fx, now, seg, cursor),
            Phase::Gripper { action, seg, since } => self.grip(fx, now, action, seg, since),
            Phase::AwaitOperator { seg } => {
                if self.run.is_some_and(|r| r.confirmed && !r.cancelled) {
                    self.next_segment(fx, now, seg + 1);
                }
            }
            Phase::Regrasp { since } => self.regrasp(fx, now, since),
            Phase::Braking {
                cursor,
                seg,
                active_cursor,
                then,
            } => self.brake_step(fx, cursor, seg, active_cursor, then),
            Phase::Retreating { asked: false } => self.retreat(fx),
            Phase::Retreating { asked: true } | Phase::Recovering { asked: true } => {}
            Phase::Abandoning => {
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.finish(fx, StatusEvent::JobFailed);
            }
            Phase::Recovering { asked: false } => {
                let Some(r) = self.run else { return };
                let p = &r.progress;
                let (objects, ordered) = if p.ordered {
                    (p.order, true)
                } else {
                    (p.objects, false)
                };
                let order = Request::Order {
                    job_id: r.job_id,
                    objects,
                    count: p.count,
                    ordered,
                };
                if fx.plan(order).is_ok() {
                    self.set_phase(Phase::Recovering { asked: true });
                    self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                }
            }
            Phase::Faulted {
                healthy_since,
                recovered,
            } => {
                if self.cancelled() {
                    // Cancelled where it stopped (its inputs may be gone: no retreat).
                    self.finish(fx, StatusEvent::JobCancelled);
                    return;
                }
                if self.run.is_none() {
                    return;
                }
                if let Some(why) = self.not_ready(now) {
                    self.set_phase(Phase::Faulted {
                        healthy_since: None,
                        recovered,
                    });
                    // The arm adapter said more about the joint states that stopped (or it
                    // changed: an e-stop became a disable): say it once.
                    // (An adapter that says "ready" while its first joint state is on the way
                    // changes nothing.)
                    let ready_said =
                        self.inputs.arm_blocker == ArmBlocker::None && self.arm_status_fresh(now);
                    let limits = matches!(why, Fault::OutsideLimits | Fault::BeyondArmLimits);
                    if (why.arm_unseen() && self.fault.arm_unseen() && !ready_said || limits)
                        && why != self.fault
                    {
                        // A held job that the arm's position keeps from resuming: said once,
                        // naming the joint.
                        self.fault = why;
                        if limits {
                            self.excess = self.measured_excess().map(|(_, e)| e);
                        }
                        self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                    }
                    return;
                }
                let since = healthy_since.unwrap_or(now);
                // Resume once both trajectory buffers are home (a plan may still be in flight).
                let resuming =
                    now - since >= self.p.timeouts.resume_after_ns && self.spare.is_some();
                // A recovered job is the journal's, commanding nothing, until it resumes.
                self.set_phase(Phase::Faulted {
                    healthy_since: Some(since),
                    recovered: recovered && !resuming,
                });
                if resuming {
                    self.resume(fx, now, recovered);
                }
            }
        }
    }

    pub(super) fn grip(
        &mut self,
        fx: &mut impl Effects,
        now: u64,
        action: GripperAction,
        seg: usize,
        since: u64,
    ) {
        let Some(g) = self.inputs.gs else { return };
        let reached = match action {
            GripperAction::Close => g.closed == 1 && g.holding == 1,
            GripperAction::Open => g.closed == 0,
        };
        if reached && g.header.stamp_ns >= since {
            match action {
                GripperAction::Close => self.holding = true,
                GripperAction::Open => {
                    self.holding = false;
                    self.release_stamp = g.header.stamp_ns;
                    let (ty, pose) = self
                        .active
                        .as_ref()
                        .map(|p| (p.object as u32, p.pose))
                        .unwrap_or((NO_OBJECT, [0.0; 4]));
                    let mut dns = 0;
                    if let Some(r) = &mut self.run {
                        r.progress.done += 1;
                        dns = r.decision_ns;
                    }
                    self.emit(fx, StatusEvent::Placed, ty, pose, dns);
                    self.next_object();
                }
            }
            self.next_segment(fx, now, seg + 1);
        } else if now.saturating_sub(since) > self.p.timeouts.gripper_action_ns {
            if action == GripperAction::Close && g.holding == 0 {
                // Closed on nothing (or not holding in time): open, then pick again or skip.
                self.fault = Fault::MissedGrasp;
                if let Some(r) = &mut self.run {
                    r.progress.missed += 1;
                }
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.out.grip_cmd = GripperAction::Open;
                self.out.grip_object = NO_OBJECT;
                self.out.grip_due = true;
                self.set_phase(Phase::Regrasp { since: now });
                return;
            }
            self.fault = Fault::Gripper;
            self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
            self.finish(fx, StatusEvent::JobFailed);
        }
    }

    /// After a missed grasp: once the gripper reports open, pick again with the same placement
    /// (at most `grasp_retries` times), else skip the object.
    pub(super) fn regrasp(&mut self, fx: &mut impl Effects, now: u64, since: u64) {
        let Some(g) = self.inputs.gs else { return };
        let opened = g.closed == 0 && g.header.stamp_ns >= since;
        if !opened {
            if now.saturating_sub(since) > self.p.timeouts.gripper_action_ns {
                self.fault = Fault::Gripper;
                self.emit(fx, StatusEvent::Fault, self.current_type(), [0.0; 4], 0);
                self.finish(fx, StatusEvent::JobFailed);
            }
            return;
        }
        if self.cancelled() {
            self.retreat(fx);
            return;
        }
        if let Some(f) = self.decision_failed() {
            // Its decision failed meanwhile: the job ends here, the gripper open.
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
            return;
        }
        if self.progress().missed <= self.p.grasp_retries {
            // The same object picked again; its decision (made or still coming) stands. A
            // person feeding the station puts it back and confirms this try.
            if let Some(r) = &mut self.run {
                r.confirmed = false;
                r.awaiting = false;
            }
            self.set_phase(Phase::Starting);
            self.request_motion(fx, Motion::Pick);
            return;
        }
        // Given up: skipped with its reason, the job goes on.
        self.emit(fx, StatusEvent::Skipped, self.current_type(), [0.0; 4], 0);
        self.next_object();
        if self.progress().index >= self.progress().count {
            self.finish(fx, StatusEvent::JobDone);
        } else {
            self.begin_object(fx, now);
        }
    }

    pub(super) fn next_segment(&mut self, fx: &mut impl Effects, now: u64, seg: usize) {
        let n = self.active.as_ref().map_or(0, |p| p.n_segments);
        if seg < n {
            let start = self
                .active
                .as_ref()
                .map_or(0, |p| if seg == 0 { 0 } else { p.segments[seg - 1].end });
            self.set_phase(Phase::Streaming { seg, cursor: start });
        } else if self.cancelled() {
            self.finish(fx, StatusEvent::JobCancelled);
        } else if self.holding {
            // Picked: the place once its placement is decided.
            self.await_decision(fx, now);
        } else if self.progress().index >= self.progress().count {
            self.finish(fx, StatusEvent::JobDone);
        } else {
            self.begin_object(fx, now);
        }
    }

    pub(super) fn stream(&mut self, fx: &mut impl Effects, now: u64, seg: usize, cursor: usize) {
        let Some(p) = &self.active else { return };
        let Some(sg) = p.segments().get(seg).copied() else {
            self.next_segment(fx, now, seg);
            return;
        };
        if cursor < sg.end {
            if let Some(s) = p.setpoints.get(cursor) {
                self.out.cmd = *s;
            }
            self.set_phase(Phase::Streaming {
                seg,
                cursor: cursor + 1,
            });
            return;
        }
        // At the segment's end, at rest.
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        if let Some(f) = self.decision_failed()
            && !self.holding
        {
            // The decision failed and nothing is held: the job ends at this standstill.
            self.fault = f;
            self.finish(fx, StatusEvent::JobFailed);
            return;
        }
        let grasp_next = p
            .segments()
            .get(seg + 1)
            .is_some_and(|n| n.then == Some(GripperAction::Close));
        let unconfirmed = self.run.is_some_and(|r| r.confirm_picks && !r.confirmed);
        if sg.then.is_none() && grasp_next && unconfirmed {
            // Above the station: no descent before the operator says the object is there.
            self.set_phase(Phase::AwaitOperator { seg });
            return;
        }
        match sg.then {
            Some(action) => {
                self.out.grip_cmd = action;
                self.out.grip_object = if action == GripperAction::Close {
                    p.object as u32
                } else {
                    NO_OBJECT
                };
                self.out.grip_due = true;
                self.set_phase(Phase::Gripper {
                    action,
                    seg,
                    since: now,
                });
            }
            None => self.next_segment(fx, now, seg + 1),
        }
    }

    /// Counts a wait at the lift pose for the current object's decision, since `since`.
    pub(super) fn add_wait(&mut self, now: u64, since: u64) {
        if let Some(r) = &mut self.run {
            r.progress.wait_ns += now.saturating_sub(since);
        }
    }
}
