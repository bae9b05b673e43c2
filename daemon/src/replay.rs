//! Re-running a run log offline ([`crate::record`]): the job state machine is fed the
//! recorded inputs in their recorded order, the planner's requests are served by the same
//! [`PlannerCore`] herbd runs, the decisions by the same [`DecisionCore`] on the heightmaps
//! recorded for them (a search runs the count of rollouts its recorded budget allowed), and
//! every cycle's outputs, planner response and decision are compared with the recorded
//! digests. On an unmodified build
//! on the same kind of CPU a run is reproduced bit for bit; otherwise the first divergence is
//! reported. `herbd replay` and `herbd explain` are thin front ends.

use crate::config::{Config, ConfigFile};
use crate::decision::DecisionCore;
use crate::job::{Effects, Job, JobParams};
use crate::plan::{DecisionRequest, DecisionResponse, MotionPlan, NOT_A_SEARCH, Request, Response};
use crate::planner::PlannerCore;
use crate::record::{Entry, Log, OutDigest, catalog_digest};
use herb_ipc::{GripperAction, HeightmapFrame, Payload, RejectReason, Status, StatusEvent};
use herb_robot::motion::Setpoint;
use herb_search::SearchReport;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;

/// How to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// The BoxED folder to load meshes from, instead of the recorded one.
    pub boxed: Option<PathBuf>,
    /// Go on when the catalog or a model differs from the recorded digests.
    pub force: bool,
    /// Object index (0-based, in the packing order) to explain.
    pub explain: Option<u32>,
    /// Keep the arm's joint states at most this often (ns of their stamps) in
    /// [`Replayed::joint_states`]; `None` keeps none.
    pub joint_states_every_ns: Option<u64>,
}

/// The decision made for the explained object, re-made on its recorded heightmap.
#[derive(Debug)]
pub struct Explained {
    /// Decision request number.
    pub request: u64,
    /// Catalog type.
    pub object: u16,
    /// The heightmap it was decided on.
    pub frame: Box<HeightmapFrame>,
    /// The method (`search`, or the policy's name).
    pub method: String,
    /// The decision as re-made (placement or why there was none, what the budget allowed).
    pub response: DecisionResponse,
    /// A search's candidates: the rollouts it finished, their returns, the one chosen.
    pub search: Option<SearchReport>,
}

/// What a replay reproduced.
#[derive(Debug, Default)]
pub struct Replayed {
    /// Cycles replayed.
    pub cycles: u64,
    /// Joint commands reproduced.
    pub joint_commands: u64,
    /// Planner responses and decisions reproduced.
    pub responses: u64,
    /// Placements decided (`Decided` statuses).
    pub decisions: u64,
    /// Statuses other than heartbeats, with the cycle they came in (stamped with its time).
    pub statuses: Vec<(u64, Status)>,
    /// The heightmaps decisions were made on, by object index: (index, frame).
    pub decision_frames: Vec<(u32, Box<HeightmapFrame>)>,
    /// The explained object's decision, if asked for and reached.
    pub explained: Option<Explained>,
    /// The arm's measured joint angles (stamp, `s0 .. w2` in rad), thinned as
    /// [`ReplayOptions::joint_states_every_ns`] asks.
    pub joint_states: Vec<(u64, [f64; herb_ipc::DOF])>,
    /// The gripper's measured state each time it changed: (stamp, closed, holding).
    pub gripper_states: Vec<(u64, bool, bool)>,
}

/// How a replay ended.
#[derive(Debug)]
pub enum Outcome {
    /// Every recorded cycle and response reproduced.
    Reproduced,
    /// The log ends early (torn tail, dropped records); everything before reproduced.
    Incomplete(String),
    /// The first difference.
    Diverged {
        /// Cycle (1-based, in this segment).
        cycle: u64,
        /// Seconds since the segment's first cycle.
        at_s: f64,
        /// What differs.
        what: String,
    },
}

/// Why a log cannot be replayed (before its first cycle).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recorded configuration does not parse.
    #[error("the recorded configuration: {0}")]
    Config(toml::de::Error),
    /// The recorded configuration does not validate (with this build's rules).
    #[error("the recorded configuration: {0}")]
    Invalid(herb_process::config_file::Invalid),
    /// The catalog cannot be built.
    #[error("catalog: {0}")]
    Catalog(herb_core::SimError),
    /// The catalog or a model differs from the recorded digests (and `force` was not given):
    /// what differs.
    #[error("{} (--force replays anyway)", .0.join("; "))]
    Differs(Vec<String>),
    /// The planner cannot be built (models).
    #[error(transparent)]
    Planner(#[from] crate::planner::PlannerError),
}

/// The machine's effects during a replay: digested as herbd digests them, and kept.
#[derive(Default)]
struct ReplayFx {
    digest: OutDigest,
    requests: VecDeque<Request>,
    decisions: VecDeque<DecisionRequest>,
    /// This cycle's outputs, described (for a divergence report).
    said: Vec<String>,
    statuses: Vec<Status>,
    joints: u64,
}

impl Effects for ReplayFx {
    fn reply(&mut self, job_id: u64, reason: RejectReason, detail: u32) {
        self.digest.reply(job_id, reason, detail);
        self.said
            .push(format!("reply to job {job_id}: {reason:?} ({detail})"));
    }
    fn cancel_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.digest.cancel_reply(job_id, reason);
        self.said
            .push(format!("cancel reply to job {job_id}: {reason:?}"));
    }
    fn confirm_reply(&mut self, job_id: u64, reason: RejectReason) {
        self.digest.confirm_reply(job_id, reason);
        self.said.push(format!(
            "pick confirmation reply to job {job_id}: {reason:?}"
        ));
    }
    fn status(&mut self, s: &Status) {
        self.digest.status(s);
        self.said.push(format!(
            "status {:?} job {} object {} fault {}",
            StatusEvent::from_code(s.event),
            s.job_id,
            s.object_index,
            s.fault
        ));
        self.statuses.push(*s);
    }
    fn joint(&mut self, c: &Setpoint) {
        self.digest.joint(c);
        self.said.push(format!("joint command {:?}", c.position));
        self.joints += 1;
    }
    fn gripper(&mut self, job_id: u64, action: GripperAction, object_type: u32) {
        self.digest.gripper(job_id, action, object_type);
        self.said
            .push(format!("gripper {action:?} (object {object_type})"));
    }
    fn plan(&mut self, r: Request) -> Result<(), Request> {
        self.digest.request(&r);
        self.said.push(match &r {
            Request::Order {
                job_id,
                count,
                ordered,
                ..
            } => format!("order job {job_id} ({count}, already ordered: {ordered})"),
            Request::Plan { index, motion, .. } => format!("plan object {index} ({motion:?})"),
            Request::Brake { .. } => "brake".into(),
            Request::Retreat { .. } => "retreat".into(),
        });
        self.requests.push_back(r);
        Ok(())
    }
    fn decide(&mut self, r: DecisionRequest) -> Result<(), DecisionRequest> {
        self.digest.decision_request(&r);
        self.said.push(format!("decide object {}", r.index));
        self.decisions.push_back(r);
        Ok(())
    }
}

/// The configuration, catalog, planner and decision method of a recorded run, checked against
/// its digests.
fn rebuild(
    log: &Log,
    opts: &ReplayOptions,
) -> Result<(Config, PlannerCore, DecisionCore), ReplayError> {
    let h = &log.header;
    let mut cfg: Config = toml::from_str(&h.config_toml).map_err(ReplayError::Config)?;
    if let Some(b) = &opts.boxed {
        cfg.models.boxed = Some(b.clone());
    }
    cfg.validate().map_err(ReplayError::Invalid)?;
    let root = herb_core::paths::boxed_root(cfg.models.boxed.as_deref());
    let meshes = herb_core::paths::mesh_source(None, root.as_deref());
    let catalog = herb_core::Catalog::builtin(&meshes).map_err(ReplayError::Catalog)?;
    let mut differ = Vec::new();
    if catalog_digest(&catalog) != h.catalog {
        differ.push(format!(
            "the catalog (meshes from {meshes:?}) differs from the run's"
        ));
    }
    let file = |p: &std::path::Path| std::fs::read(p).map(|b| crate::digest::of(&b));
    if let Some(p) = cfg.models.policy_file()
        && file(&p).ok() != Some(h.policy)
    {
        differ.push(format!("the policy {} differs from the run's", p.display()));
    }
    if file(&cfg.models.sequence).ok() != Some(h.sequence) {
        differ.push(format!(
            "the sequence model {} differs from the run's",
            cfg.models.sequence.display()
        ));
    }
    if !differ.is_empty() && !opts.force {
        return Err(ReplayError::Differs(differ));
    }
    let catalog = Arc::new(catalog);
    let core = PlannerCore::new(&cfg, catalog.clone())?;
    let decider = DecisionCore::new(&cfg, catalog)?;
    Ok((cfg, core, decider))
}

/// Replays one segment; `Err` when it cannot start (configuration, catalog, models).
pub fn replay(log: &Log, opts: &ReplayOptions) -> Result<(Outcome, Replayed), ReplayError> {
    let (cfg, mut core, mut decider) = rebuild(log, opts)?;
    let samples = cfg.trajectory_samples();
    let buffer = || Box::new(MotionPlan::with_capacity(samples));
    let mut job = Job::new(
        JobParams::from_config(&cfg, core.catalog().len()),
        buffer(),
        buffer(),
    );
    let (mut k, mut kd) = (0u64, 0u64);
    if let Some((before, s)) = &log.snapshot {
        job.restore(s);
        (k, kd) = (before.requests, before.decisions);
    }
    let mut fx = ReplayFx::default();
    let mut out = Replayed::default();
    let (mut now, mut t0) = (0u64, None);
    let mut frame = Box::new(
        HeightmapFrame::from_bytes(&vec![0u8; std::mem::size_of::<HeightmapFrame>()])
            .expect("zeros are a frame"),
    );
    let diverged = |out: &Replayed, now: u64, t0: Option<u64>, what: String| Outcome::Diverged {
        cycle: out.cycles,
        at_s: now.saturating_sub(t0.unwrap_or(now)) as f64 * 1e-9,
        what,
    };
    for e in &log.entries {
        match *e {
            Entry::Cycle(t) => {
                now = t;
                t0.get_or_insert(t);
                out.cycles += 1;
                fx.digest = OutDigest::new();
                fx.said.clear();
            }
            Entry::Js(p, r, m) => {
                if let Some(every) = opts.joint_states_every_ns {
                    let due = out
                        .joint_states
                        .last()
                        .is_none_or(|(t, _)| m.header.stamp_ns >= t.saturating_add(every));
                    if due {
                        out.joint_states.push((m.header.stamp_ns, m.position));
                    }
                }
                job.joint_state(p, &m, now, r)
            }
            Entry::Gs(p, r, m) => {
                let state = (m.closed != 0, m.holding != 0);
                if out.gripper_states.last().map(|g| (g.1, g.2)) != Some(state) {
                    out.gripper_states
                        .push((m.header.stamp_ns, state.0, state.1));
                }
                job.gripper_state(p, &m, now, r)
            }
            Entry::Arm(p, r, m) => job.arm_status(p, &m, now, r),
            Entry::Frame(meta) => {
                let mut b = frame.as_bytes().to_vec();
                b[..meta.len()].copy_from_slice(&meta);
                *frame = HeightmapFrame::from_bytes(&b).expect("same length");
                job.heightmap(&frame, now);
            }
            Entry::Resp(rec) => {
                let Some(req) = fx.requests.pop_front() else {
                    let what = format!(
                        "the run received planner response {k}, which the replay never asked for"
                    );
                    return Ok((diverged(&out, now, t0, what), out));
                };
                let resp = core.handle(req);
                if resp.digest() != rec.digest {
                    let what = format!(
                        "planner response {k} differs: recorded digest {:016x}, replayed {:016x} ({})",
                        rec.digest,
                        resp.digest(),
                        describe(&resp)
                    );
                    return Ok((diverged(&out, now, t0, what), out));
                }
                out.responses += 1;
                k += 1;
                job.planner_response(resp, now, &mut fx);
            }
            Entry::Decision(rec) => {
                let Some(req) = fx.decisions.pop_front() else {
                    let what =
                        format!("the run received decision {kd}, which the replay never asked for");
                    return Ok((diverged(&out, now, t0, what), out));
                };
                let used = match log.decision_frames.get(&kd) {
                    Some(Some(d)) => match log.frames.get(d) {
                        Some(f) => Some(f.as_ref()),
                        None => {
                            return Ok((
                                Outcome::Incomplete(format!(
                                    "the frame of decision {kd} is missing"
                                )),
                                out,
                            ));
                        }
                    },
                    Some(None) => None,
                    None => {
                        return Ok((
                            Outcome::Incomplete(format!("no frame recorded for decision {kd}")),
                            out,
                        ));
                    }
                };
                let allowed = (rec.allowed != NOT_A_SEARCH).then_some(rec.allowed);
                let mut d = match used {
                    Some(f) => {
                        out.decision_frames.push((req.index, Box::new(*f)));
                        decider.decide(&req, f, allowed)
                    }
                    None => crate::decision::no_fresh_frame(&req),
                };
                // Time is not reproducible: the measured latency is the recorded one.
                d.decision_ns = rec.decision_ns;
                if let (Some(f), true) = (used, opts.explain == Some(req.index)) {
                    out.explained = Some(Explained {
                        request: kd,
                        object: d.object,
                        frame: Box::new(*f),
                        method: decider.name().to_owned(),
                        response: d,
                        search: decider.search_report().cloned(),
                    });
                }
                if d.digest() != rec.digest {
                    let what = format!(
                        "decision {kd} differs: recorded digest {:016x}, replayed {:016x} (object {}: {:?}, allowed {})",
                        rec.digest,
                        d.digest(),
                        d.index,
                        d.outcome,
                        d.allowed
                    );
                    return Ok((diverged(&out, now, t0, what), out));
                }
                out.responses += 1;
                kd += 1;
                job.decision_response(d, now, &mut fx);
            }
            Entry::Job(r) => job.job_request(&r, now, &mut fx),
            Entry::Cancel(r) => job.cancel_request(&r, &mut fx),
            Entry::Confirm(r) => job.confirm_request(&r, &mut fx),
            Entry::Tick(stop, digest) => {
                job.tick(now, stop, &mut fx);
                for s in fx.statuses.drain(..) {
                    if s.event == StatusEvent::Decided as u32 {
                        out.decisions += 1;
                    }
                    if s.event != StatusEvent::Heartbeat as u32 {
                        // Stamped with the cycle's time, as herbd stamps what it publishes.
                        let mut s = s;
                        s.header.stamp_ns = now;
                        out.statuses.push((out.cycles, s));
                    }
                }
                out.joint_commands += std::mem::take(&mut fx.joints);
                if fx.digest.finish() != digest {
                    let what = format!(
                        "the outputs differ (recorded digest {digest:016x}, replayed {:016x}); replayed: {}",
                        fx.digest.finish(),
                        fx.said.join("; ")
                    );
                    return Ok((diverged(&out, now, t0, what), out));
                }
            }
        }
    }
    Ok(match &log.incomplete {
        Some(why) => (Outcome::Incomplete(why.clone()), out),
        None => (Outcome::Reproduced, out),
    })
}

fn describe(r: &Response) -> String {
    match r {
        Response::Ordered { job_id, count, .. } => format!("job {job_id} ordered, {count} objects"),
        Response::OrderFailed { job_id } => format!("job {job_id} not ordered"),
        Response::Planned(p) => format!(
            "plan of object {} at {:?}, {} samples",
            p.index,
            p.pose,
            p.setpoints.len()
        ),
        Response::Braked(p) => format!("brake, {} samples", p.setpoints.len()),
        Response::Failed { fault, .. } => format!("failed: {fault:?}"),
    }
}
