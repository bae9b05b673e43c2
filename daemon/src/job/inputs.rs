//! What reaches the job state machine: sensor inputs (latched when valid, counted when not),
//! pack-job, cancel and pick-confirmation requests (answered with their reason), the planner's
//! and the decision worker's responses, and whether the cell can take a job (input health, an
//! arm outside its limits).

use super::*;

impl Job {
    /// A joint state from `publisher` (iceoryx2's id), received at `received_ns`: latched when
    /// valid, not from the future and in order; else counted as rejected.
    pub fn joint_state(&mut self, publisher: u128, m: &JointState, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.js_order.accept(publisher, &m.header) =>
            {
                self.inputs.js = Some(*m);
                self.inputs.js_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// A gripper state, as [`Job::joint_state`].
    pub fn gripper_state(&mut self, publisher: u128, m: &GripperState, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.gs_order.accept(publisher, &m.header) =>
            {
                self.inputs.gs = Some(*m);
                self.inputs.gs_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// The arm adapter's status, as [`Job::joint_state`].
    pub fn arm_status(&mut self, publisher: u128, m: &ArmStatus, now: u64, received_ns: u64) {
        match m.validate() {
            Ok(())
                if not_from_the_future(m.header.stamp_ns, now, received_ns)
                    && self.inputs.arm_order.accept(publisher, &m.header) =>
            {
                self.inputs.arm_blocker =
                    ArmBlocker::from_code(m.blocker).unwrap_or(ArmBlocker::None);
                self.inputs.arm_at = m.header.stamp_ns;
            }
            _ => self.inputs.rejected += 1,
        }
    }

    /// A heightmap frame, read in place: only its header and grid are checked here (the
    /// planner checks every cell of the frame it decides on).
    pub fn heightmap(&mut self, f: &HeightmapFrame, now: u64) {
        match f.validate_meta() {
            Ok(()) => {
                self.inputs.hm_rx_at = now;
                self.inputs.hm_stamp = self.inputs.hm_stamp.max(f.header.stamp_ns);
            }
            Err(_) => self.inputs.rejected += 1,
        }
    }

    /// A pack-job request: answered through [`Effects::reply`] (a malformed request gets what
    /// is wrong with it whatever the state; then `ShuttingDown`, `Busy`, `NotReady`), and
    /// started when accepted.
    pub fn job_request(&mut self, r: &PackJobRequest, now: u64, fx: &mut impl Effects) {
        let verdict = r.validate(self.p.catalog_len).and_then(|()| {
            if self.stopping() {
                Err((RejectReason::ShuttingDown, 0))
            } else if self.is_running_request(r) {
                // A repeat of the running job's request (its reply was slow or lost): accepted
                // again, nothing restarts.
                Err((RejectReason::None, 0))
            } else if self.phase != Phase::Idle {
                Err((RejectReason::Busy, 0))
            } else if let Some(why) = self.not_ready(now) {
                Err((RejectReason::NotReady, why as u32))
            } else if let Some(g) = self.inputs.gs.filter(|g| g.holding == 1) {
                // What the gripper holds is the truth: never start a job that would place it.
                let known = (g.object_type != NO_OBJECT).then_some(g.object_type);
                let believed = self.holding.then(|| self.current_type());
                Err((
                    RejectReason::Holding,
                    known.or(believed).unwrap_or(NO_OBJECT),
                ))
            } else {
                Ok(())
            }
        });
        let (reason, detail) = verdict.err().unwrap_or((RejectReason::None, 0));
        if reason != RejectReason::None {
            // A joint outside its limits is named by the next heartbeat ([`Job::publish`]).
            self.inputs.rejected_requests += 1;
        }
        let repeat = reason == RejectReason::None && self.is_running_request(r);
        fx.reply(r.job_id, reason, detail);
        if reason == RejectReason::None && !repeat {
            self.start_job(r, fx);
        }
    }

    /// `r` asks for the job that runs: its id, its objects and its flags.
    fn is_running_request(&self, r: &PackJobRequest) -> bool {
        self.run.is_some_and(|j| {
            j.job_id == r.job_id
                && j.progress.objects.get(..j.progress.count) == Some(r.objects())
                && j.confirm_picks == (r.flags & PackJobRequest::CONFIRM_PICKS != 0)
        })
    }

    /// A cancel request: answered through [`Effects::cancel_reply`] (`Malformed`, then
    /// `ShuttingDown`, then `NoSuchJob` unless it names the running job; a repeat is accepted
    /// again). The arm brakes if it moves, then retreats straight up; a job waiting on a fault
    /// is cancelled where it stands. Either way `JobCancelled` ends the job.
    pub fn cancel_request(&mut self, r: &CancelJobRequest, fx: &mut impl Effects) {
        let reason = match r.validate() {
            Err(e) => e,
            Ok(()) if self.stopping() => RejectReason::ShuttingDown,
            Ok(()) if self.job_id() == 0 || r.job_id != self.job_id() => RejectReason::NoSuchJob,
            Ok(()) => RejectReason::None,
        };
        if reason != RejectReason::None {
            self.inputs.rejected_requests += 1;
        }
        fx.cancel_reply(r.job_id, reason);
        let Some(run) = &mut self.run else { return };
        if reason != RejectReason::None || run.cancelled {
            return;
        }
        run.cancelled = true;
        match self.phase {
            Phase::Streaming { .. } if self.moving() => self.begin_brake(fx, AfterBrake::Retreat),
            // Braking for a fault: the retreat follows the brake.
            Phase::Braking {
                cursor,
                seg,
                active_cursor,
                then: AfterBrake::Hold,
            } => self.set_phase(Phase::Braking {
                cursor,
                seg,
                active_cursor,
                then: AfterBrake::Retreat,
            }),
            // At rest: retreat now.
            Phase::Ordering
            | Phase::Starting
            | Phase::AwaitDecision { .. }
            | Phase::Streaming { .. }
            | Phase::AwaitOperator { .. }
            | Phase::Gripper { .. } => self.retreat(fx),
            // Planning: when the plan comes back. Braking: when it ends. Faulted: next tick.
            _ => {}
        }
    }

    /// A pick confirmation: answered through [`Effects::confirm_reply`] (`Malformed`,
    /// `ShuttingDown`, `NoSuchJob` unless it names the running job; `None` for a repeat of the
    /// confirmation accepted for the current try, which changes nothing; `NotAwaited` unless
    /// herbd awaits this
    /// object and try now: the job asks for confirmations, sent its `AwaitingObject` and took
    /// no confirmation since). Accepted, the arm descends to the grasp once it stands above the
    /// station.
    pub fn confirm_request(&mut self, r: &ConfirmPickRequest, fx: &mut impl Effects) {
        let this = (r.object_index, r.attempt);
        let reason = match r.validate() {
            Err(e) => e,
            Ok(()) if self.stopping() => RejectReason::ShuttingDown,
            Ok(()) if self.job_id() == 0 || r.job_id != self.job_id() => RejectReason::NoSuchJob,
            Ok(())
                if self.run.is_some_and(|j| j.last_confirmed == Some(this))
                    && this == (self.progress().index as u32, self.progress().missed) =>
            {
                // A repeat of the accepted confirmation for the current try.
                RejectReason::None
            }
            Ok(())
                if !self
                    .run
                    .is_some_and(|j| j.confirm_picks && j.awaiting && !j.cancelled)
                    || self.holding
                    || r.object_index as usize != self.progress().index
                    || r.attempt != self.progress().missed =>
            {
                RejectReason::NotAwaited
            }
            Ok(()) => {
                if let Some(j) = &mut self.run {
                    j.confirmed = true;
                    j.awaiting = false;
                    j.last_confirmed = Some(this);
                }
                RejectReason::None
            }
        };
        if reason != RejectReason::None {
            self.inputs.rejected_requests += 1;
        }
        fx.confirm_reply(r.job_id, reason);
    }

    /// Asks for the retreat of a cancelled job (when a buffer is home; else on a later tick).
    pub(super) fn retreat(&mut self, fx: &mut impl Effects) {
        self.out.cmd.velocity = [0.0; DOF];
        self.out.cmd.acceleration = [0.0; DOF];
        self.set_phase(Phase::Retreating { asked: false });
        let Some(buf) = self.spare.take() else {
            return;
        };
        let held = self.holding || self.inputs.gs.is_some_and(|g| g.holding == 1);
        let p = self.progress();
        let req = Request::Retreat {
            from: self.out.cmd.position,
            held: held.then(|| p.order.get(p.index).copied()).flatten(),
            buf,
        };
        match fx.plan(req) {
            Ok(()) => self.set_phase(Phase::Retreating { asked: true }),
            Err(Request::Retreat { buf, .. }) => self.spare = Some(buf),
            Err(_) => {}
        }
    }

    pub(super) fn start_job(&mut self, r: &PackJobRequest, fx: &mut impl Effects) {
        let n = r.objects().len();
        let mut objects = [0u16; MAX_JOB_OBJECTS];
        objects[..n].copy_from_slice(r.objects());
        let progress = Progress {
            objects,
            count: n,
            ..Progress::NONE
        };
        let confirm_picks = r.flags & PackJobRequest::CONFIRM_PICKS != 0;
        self.run = Some(Run::new(r.job_id, progress, confirm_picks));
        // What outlives a job, taken up from the measured state: the gripper's, and no release
        // or fault of an earlier job.
        self.holding = self.inputs.gs.is_some_and(|g| g.holding == 1);
        self.flip = false;
        self.release_stamp = 0;
        self.fault = Fault::None;
        self.excess = None;
        let q = self.inputs.js.map(|j| j.position).unwrap_or_default();
        self.out.cmd = Setpoint::at_rest(q);
        self.out.from = q;
        // A known gripper state to start from: open, unless it holds something (which the job
        // then deals with as its first object's grasp would: it is never dropped here).
        if !self.holding {
            self.out.grip_cmd = GripperAction::Open;
            self.out.grip_object = NO_OBJECT;
            self.out.grip_due = true;
        }
        let _ = fx.plan(Request::Order {
            job_id: r.job_id,
            objects,
            count: n,
            ordered: false,
        });
        self.set_phase(Phase::Ordering);
        self.emit(fx, StatusEvent::Accepted, NO_OBJECT, [0.0; 4], 0);
        self.say_outside_limits(fx);
    }

    /// The measured arm outside the configured joint limits, and what it means: `None` when
    /// inside (or nothing measured yet); `BeyondArmLimits` past the arm's own limits;
    /// else `OutsideLimits`.
    pub(super) fn measured_excess(&self) -> Option<(Fault, Excess)> {
        let q = self.inputs.js?.position;
        let (lo, hi) = &self.p.arm_range;
        if let Some(e) = excess_of(&q, lo, hi) {
            return Some((Fault::BeyondArmLimits, e));
        }
        excess_of(&q, &self.p.lower, &self.p.upper).map(|e| (Fault::OutsideLimits, e))
    }

    /// One planner response.
    pub fn planner_response(&mut self, resp: Response, now: u64, fx: &mut impl Effects) {
        match resp {
            Response::Ordered {
                job_id,
                order,
                count,
            } if job_id == self.job_id() => {
                if let Some(r) = &mut self.run {
                    r.progress.order = order;
                    r.progress.count = count;
                    r.progress.ordered = true;
                }
                match self.phase {
                    Phase::Ordering => self.begin_object(fx, now),
                    Phase::Recovering { .. } | Phase::Abandoning => {
                        self.set_phase(Phase::Faulted {
                            healthy_since: None,
                            recovered: true,
                        })
                    }
                    _ => {}
                }
            }
            Response::Ordered { .. } => {}
            Response::OrderFailed { job_id }
                if job_id == self.job_id()
                    && matches!(
                        self.phase,
                        Phase::Ordering | Phase::Recovering { .. } | Phase::Abandoning
                    ) =>
            {
                self.fault = Fault::Decision;
                self.finish(fx, StatusEvent::JobFailed);
            }
            // A stale reply (an earlier job's) changes nothing.
            Response::OrderFailed { .. } => {}
            Response::Planned(plan) if matches!(self.phase, Phase::Retreating { .. }) => {
                if let Some(old) = self.active.take() {
                    self.recycle(old);
                }
                self.active = Some(plan);
                self.set_phase(Phase::Streaming { seg: 0, cursor: 0 });
            }
            Response::Planned(plan) => {
                let planning = matches!(self.phase, Phase::Planning);
                if planning && !self.cancelled() {
                    if let Some(old) = self.active.take() {
                        self.recycle(old);
                    }
                    // A place (or pick and place) knows where the gripper opens: journaled, so
                    // that a restart tells a released object from a held one.
                    if let Some(q) = release_q(&plan)
                        && let Some(r) = &mut self.run
                    {
                        r.placement = Some(Placement {
                            index: plan.index as u16,
                            pose: plan.pose,
                            release_q: Some(q),
                        });
                    }
                    self.flip = plan.flip;
                    self.active = Some(plan);
                    self.set_phase(Phase::Streaming { seg: 0, cursor: 0 });
                } else {
                    self.recycle(plan);
                    if planning && self.cancelled() {
                        self.retreat(fx);
                    }
                }
            }
            Response::Braked(buf) => {
                if let Phase::Braking {
                    seg,
                    active_cursor,
                    then,
                    ..
                } = self.phase
                {
                    self.brake = Some(buf);
                    self.set_phase(Phase::Braking {
                        cursor: Some(0),
                        seg,
                        active_cursor,
                        then,
                    });
                } else {
                    self.recycle(buf);
                }
            }
            Response::Failed { fault, buf } => {
                self.recycle(buf);
                match self.phase {
                    Phase::Planning if self.cancelled() => self.retreat(fx),
                    Phase::Planning => {
                        self.fault = fault;
                        self.finish(fx, StatusEvent::JobFailed);
                    }
                    // No brake: halted where the plan stops.
                    Phase::Braking { then, .. } => self.halt(fx, then),
                    // No way up: the arm stays where it stopped.
                    Phase::Retreating { .. } => {
                        self.fault = fault;
                        self.finish(fx, StatusEvent::JobCancelled);
                    }
                    _ => {}
                }
            }
        }
    }

    /// One decision from the worker. A stale one (an earlier job's or object's, or one the
    /// machine stopped waiting for) changes nothing.
    pub fn decision_response(&mut self, d: DecisionResponse, now: u64, fx: &mut impl Effects) {
        let Some(r) = &mut self.run else { return };
        let index = r.progress.index;
        let awaited = d.job_id == r.job_id
            && r.deciding.is_some_and(|(i, _)| i == d.index as usize)
            && index == d.index as usize;
        if !awaited {
            return;
        }
        r.deciding = None;
        match d.outcome {
            Ok(pose) => {
                r.placement = Some(Placement {
                    index: index as u16,
                    pose,
                    release_q: None,
                });
                r.decision_ns = d.decision_ns;
                // An object already announced (its place was planned before a fault or a
                // restart) is not announced again: its `Placed` carries the pose.
                if !std::mem::replace(&mut r.announced, true) {
                    self.emit(
                        fx,
                        StatusEvent::Decided,
                        self.current_type(),
                        pose,
                        d.decision_ns,
                    );
                }
                if let Phase::AwaitDecision { since } = self.phase {
                    self.add_wait(now, since);
                    self.request_place(fx, now);
                }
            }
            // No valid frame newer than the release within the worker's wait: asked again,
            // until the fresh-heightmap timeout (from when the object began waiting) says it
            // is a fault.
            Err(Fault::HeightmapTimeout) => {
                if now.saturating_sub(r.decide_since) > self.p.timeouts.fresh_heightmap_ns {
                    r.decide_since = now;
                    self.raise(fx, Fault::HeightmapTimeout);
                } else {
                    r.decide_due = true;
                }
            }
            Err(f) => r.decision_failed = Some(f),
        }
    }

    /// Why a job cannot run now, if it cannot: the stale input's fault (see
    /// [`Job::stale_input`]), or the missing one's.
    pub(super) fn not_ready(&self, now: u64) -> Option<Fault> {
        if self.inputs.js.is_none() {
            Some(self.joint_fault(now))
        } else if self.inputs.gs.is_none() {
            Some(Fault::GripperStateTimeout)
        } else if let Some(f) = self.stale_input(now) {
            Some(f)
        } else {
            // Outside the arm's own limits: never moved. Outside herbd's only: brought back
            // in by the job's first motion, unless configured to refuse.
            match self.measured_excess() {
                Some((Fault::BeyondArmLimits, _)) => Some(Fault::BeyondArmLimits),
                Some((f, _)) if self.p.outside == OutsideLimits::Refuse => Some(f),
                _ => None,
            }
        }
    }

    /// The fault for joint states that stopped: what the arm adapter says, if it spoke after
    /// the last joint state and recently (within three of its periods; an adapter that says
    /// the robot can move while no joint state comes: the robot is silent); else the adapter
    /// itself is silent (stopped, killed: its last word came before its last joint state).
    pub(super) fn joint_fault(&self, now: u64) -> Fault {
        let said_recently = self.arm_status_fresh(now) && self.inputs.arm_at > self.inputs.js_at;
        match self.inputs.arm_blocker {
            _ if !said_recently => Fault::JointStateTimeout,
            ArmBlocker::None => Fault::RobotSilent,
            b => b.fault(),
        }
    }

    /// The arm adapter spoke within three of its status periods.
    pub(super) fn arm_status_fresh(&self, now: u64) -> bool {
        self.inputs.arm_at != 0 && now.saturating_sub(self.inputs.arm_at) < 3 * ARM_STATUS_PERIOD_NS
    }

    pub(super) fn stale_input(&self, now: u64) -> Option<Fault> {
        if now.saturating_sub(self.inputs.js_at) >= self.p.timeouts.joint_state_ns {
            Some(self.joint_fault(now))
        } else if now.saturating_sub(self.inputs.gs_at) >= self.p.timeouts.gripper_state_ns {
            Some(Fault::GripperStateTimeout)
        } else if now.saturating_sub(self.inputs.hm_rx_at) >= self.p.timeouts.heightmap_ns {
            Some(Fault::HeightmapTimeout)
        } else {
            None
        }
    }

    pub(super) fn check_health(&mut self, now: u64, fx: &mut impl Effects) {
        match self.phase {
            Phase::Idle
            | Phase::Braking { .. }
            | Phase::Faulted { .. }
            | Phase::Recovering { .. }
            | Phase::Abandoning
            | Phase::Stopped { .. } => {}
            _ => {
                if let Some(f) = self.stale_input(now) {
                    self.raise(fx, f);
                }
            }
        }
    }
}
