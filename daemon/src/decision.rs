//! The decision worker: where each object goes, decided on its own thread while the arm picks
//! the object, so that neither the loop nor the planner (brakes, the next motion) waits for it.
//!
//! The loop sends a [`DecisionRequest`] when an object's pick starts and gets a
//! [`DecisionResponse`] back over two wait-free rings. The worker keeps the newest valid
//! heightmap (every cell checked once, on receipt, by the decision core, which keeps its copy;
//! a bad frame is dropped and counted), waits for one newer than the last release, and decides
//! with the configured method (`[decision] method`): the placement policy of `[models] policy`
//! through the [`herb_decide::Decider`], or the search ([`herb_search`], the default) as the
//! same `Decider`'s policy (the same heightmap check and the same z estimate). The search's twin is the
//! job's own (`[decision] twin = "job"`, the default: the job's decisions replayed, fitted to
//! the heightmaps; a new job id starts it from an empty box) or one built from the heightmap
//! alone. A search's time budget is not reproducible, so a response says what it allowed
//! (`allowed`: rollouts finished), and a replay runs exactly that count; the job's twin is
//! rebuilt from the same decisions and frames.
//!
//! A method that panics answers `Decision` (the job faults with that reason; the worker goes
//! on); one that hangs is caught by the job machine's `decision.timeout_s`.

use crate::config::{Config, DecisionMethod, DecisionTwin};
use crate::plan::{DecisionRequest, DecisionResponse, NOT_A_SEARCH};
use crate::planner::PlannerError;
use herb_core::{SharedCatalog, TypeIdx};
use herb_decide::policy::Policy;
use herb_decide::{DecideError, Decider, HeightmapView};
use herb_ipc::bus::{Bus, Pub, Sub};
use herb_ipc::{
    CandidateReport, DecisionReport, Fault, Header, HeightmapFrame, MAX_REPORTED_CANDIDATES,
    Services,
};
use herb_search::{
    Budget, ReleaseCheck, RobustRollouts, Search, SearchReport, SearchSettings, TwinKind,
    WorldConfig,
};
use iceoryx2::prelude::ipc;
use iceoryx2::sample::Sample;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Receives, for decision request `n` (from 0, in the order the loop sent them), the frame it
/// was decided on: `None` when none newer than the release came within the wait. Called on the
/// worker's thread (it may allocate).
pub type FrameLog = Box<dyn Fn(u64, Option<&HeightmapFrame>) + Send>;

/// Requests (and responses) the rings hold; the loop has at most one decision out.
const RING: usize = 4;
/// Longest wait for a heightmap stamped after the last release before a decision answers
/// `HeightmapTimeout` (the loop then asks again, within its own fresh-heightmap timeout).
const FRAME_WAIT: Duration = Duration::from_millis(500);
/// How often a waiting decision looks for a new frame.
const FRAME_POLL: Duration = Duration::from_millis(1);

/// How the worker decides.
enum Method {
    Policy(Decider),
    Search(Decider<Search>),
}

/// The worker's decisions without its thread and ports: herbd's worker and `herbctl replay`
/// run this same code.
pub struct DecisionCore {
    method: Method,
    budget: Budget,
    /// The job of the last decision: a decision of another job starts the method's episode
    /// (the search's job twin forgets the last job's objects).
    job: Option<u64>,
    /// The request's remaining objects as catalog types (kept between decisions).
    remaining: Vec<TypeIdx>,
}

impl DecisionCore {
    /// The method `cfg` configures, for `catalog` (the policy file is loaded here: a bad one
    /// is an error at start).
    pub fn new(cfg: &Config, catalog: SharedCatalog) -> Result<Self, PlannerError> {
        let clearance = cfg.models.clearance_m as f32;
        let d = &cfg.decision;
        let budget = Budget::Time(Duration::from_secs_f64(d.budget_s));
        let method = match d.method {
            DecisionMethod::Policy => Method::Policy(Decider::load(
                &cfg.models.resolved_policy(),
                catalog,
                clearance,
            )?),
            DecisionMethod::Search => {
                let settings = SearchSettings {
                    k: d.k,
                    budget,
                    horizon: (d.horizon > 0).then_some(d.horizon),
                    twin: match d.twin {
                        DecisionTwin::Heightmap => TwinKind::Heightmap,
                        DecisionTwin::Job => TwinKind::Job,
                    },
                    threads: d.search_threads(),
                    robust: RobustRollouts::assumed(
                        d.samples,
                        d.release_error_mm,
                        d.release_error_deg,
                    ),
                    push_gap: d.gap,
                    wall_gap: d.wall_gap,
                    // Checked when the configuration was read.
                    min_support: herb_search::support_rule(d.min_support).unwrap_or(None),
                    median: d.median,
                    release_check: if d.release_check {
                        ReleaseCheck::assumed(d.release_error_mm, d.release_error_deg)
                    } else {
                        None
                    },
                    ..SearchSettings::default()
                };
                // The twins release where the arm does: the same clearance.
                let world = WorldConfig {
                    clearance_m: clearance,
                    ..WorldConfig::default()
                };
                let search = Box::new(Search::new(catalog.clone(), world, settings));
                Method::Search(Decider::new(search, catalog, clearance))
            }
        };
        Ok(Self {
            method,
            budget,
            job: None,
            remaining: Vec::new(),
        })
    }

    /// As [`DecisionCore::new`] with `policy` instead of the configured method (the planner's
    /// property tests drive it with arbitrary policy outputs).
    pub fn with_policy(cfg: &Config, catalog: SharedCatalog, policy: Box<dyn Policy>) -> Self {
        Self {
            method: Method::Policy(Decider::new(policy, catalog, cfg.models.clearance_m as f32)),
            budget: Budget::Rollouts(0),
            job: None,
            remaining: Vec::new(),
        }
    }

    /// Checks `frame` and keeps its one copy for the next decisions
    /// ([`DecisionCore::decide_observed`]); a bad frame is refused, and they stay on the last
    /// good one.
    pub fn observe(&mut self, frame: &HeightmapFrame) -> Result<(), DecideError> {
        let view = HeightmapView {
            nx: frame.nx as usize,
            ny: frame.ny as usize,
            cell_m: frame.cell_m,
            cells: frame.cells(),
        };
        match &mut self.method {
            Method::Policy(p) => p.observe(view),
            Method::Search(s) => s.observe(view),
        }
    }

    /// Decides `req` on `frame` ([`DecisionCore::observe`] then
    /// [`DecisionCore::decide_observed`]; a frame refused answers `Decision`).
    pub fn decide(
        &mut self,
        req: &DecisionRequest,
        frame: &HeightmapFrame,
        allowed: Option<u32>,
    ) -> DecisionResponse {
        match self.observe(frame) {
            Ok(()) => self.decide_observed(req, allowed),
            Err(_) => DecisionResponse {
                outcome: Err(Fault::Decision),
                ..no_fresh_frame(req)
            },
        }
    }

    /// Decides `req` on the last frame observed. `allowed`: run that many rollouts instead of
    /// the time budget (a replay of what a recorded decision's budget allowed); ignored by a
    /// policy.
    pub fn decide_observed(
        &mut self,
        req: &DecisionRequest,
        allowed: Option<u32>,
    ) -> DecisionResponse {
        self.remaining.clear();
        self.remaining
            .extend(req.remaining().iter().map(|&o| TypeIdx(o)));
        let object = req.remaining().first().copied().unwrap_or(0);
        let t0 = Instant::now();
        if self.job.replace(req.job_id) != Some(req.job_id) {
            match &mut self.method {
                Method::Policy(p) => p.begin_episode(req.job_id),
                Method::Search(s) => s.begin_episode(req.job_id),
            }
        }
        let step = req.index as usize;
        let (d, allowed) = match (&mut self.method, self.remaining.is_empty()) {
            (_, true) => (Err(DecideError::NoFeasiblePlacement), NOT_A_SEARCH),
            (Method::Policy(p), false) => (p.decide(&self.remaining, step), NOT_A_SEARCH),
            (Method::Search(s), false) => {
                let budget = allowed.map_or(self.budget, |n| Budget::Rollouts(n as usize));
                s.policy_mut().set_budget(budget);
                let d = s.decide(&self.remaining, step);
                let finished = s.policy().report().finished.len() as u32;
                (d, finished)
            }
        };
        let decision_ns = t0.elapsed().as_nanos() as u64;
        DecisionResponse {
            job_id: req.job_id,
            index: req.index,
            object,
            outcome: d.map(|d| d.xyz_theta()).map_err(|e| match e {
                DecideError::NoFeasiblePlacement => Fault::NoFeasiblePlacement,
                _ => Fault::Decision,
            }),
            allowed,
            decision_ns,
        }
    }

    /// [`DecisionCore::decide_observed`], with a panic of the method answered `Decision`
    /// (logged): the worker goes on with the next request.
    pub fn decide_guarded(
        &mut self,
        req: &DecisionRequest,
        allowed: Option<u32>,
    ) -> DecisionResponse {
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.decide_observed(req, allowed)
        })) {
            Ok(resp) => resp,
            Err(_) => {
                crate::logfmt::log(
                    "error",
                    &[
                        ("what", &"the decision method panicked"),
                        ("index", &req.index),
                    ],
                );
                DecisionResponse {
                    outcome: Err(Fault::Decision),
                    ..no_fresh_frame(req)
                }
            }
        }
    }

    /// What `d`, this core's last decision, was, for viewers: the method, and a search's
    /// candidates with their rollouts' returns.
    pub fn report(&self, d: &DecisionResponse) -> DecisionReport {
        let mut r = DecisionReport {
            header: Header::now(0),
            job_id: d.job_id,
            object_index: d.index,
            object_type: d.object as u32,
            method: 0,
            feasible: 0,
            allowed: 0,
            count: 0,
            pose: d.outcome.unwrap_or([0.0; 4]),
            decided: d.outcome.is_ok() as u32,
            reserved: 0,
            decision_ns: d.decision_ns,
            candidates: [CandidateReport::default(); MAX_REPORTED_CANDIDATES],
        };
        if let Some(rep) = self.search_report() {
            r.method = 1;
            r.feasible = rep.candidates as u32;
            r.allowed = rep.finished.len() as u32;
            for (slot, (c, o)) in r.candidates.iter_mut().zip(&rep.finished) {
                *slot = CandidateReport {
                    x: o.placement.x,
                    y: o.placement.y,
                    yaw: o.placement.theta(),
                    ret: o.ret,
                    packed: o.packed as u32,
                    flags: o.success as u32 | (((rep.chosen == Some(*c)) as u32) << 1),
                };
                r.count += 1;
            }
        }
        r
    }

    /// The last search's report (`None` for a policy).
    pub fn search_report(&self) -> Option<&SearchReport> {
        match &self.method {
            Method::Search(s) => Some(s.policy().report()),
            Method::Policy(_) => None,
        }
    }

    /// The search's settings (`None` for a policy).
    pub fn search_settings(&self) -> Option<&SearchSettings> {
        match &self.method {
            Method::Search(s) => Some(s.policy().settings()),
            Method::Policy(_) => None,
        }
    }

    /// The method's name (`search`, or the policy's).
    pub fn name(&self) -> &str {
        match &self.method {
            Method::Policy(p) => p.policy_name(),
            Method::Search(_) => "search",
        }
    }
}

/// The answer to `req` when no heightmap newer than its release came within the worker's wait
/// (`HeightmapTimeout`: the loop asks again).
pub fn no_fresh_frame(req: &DecisionRequest) -> DecisionResponse {
    DecisionResponse {
        job_id: req.job_id,
        index: req.index,
        object: req.remaining().first().copied().unwrap_or(0),
        outcome: Err(Fault::HeightmapTimeout),
        allowed: NOT_A_SEARCH,
        decision_ns: 0,
    }
}

/// The loop's ends of the decision rings.
pub struct DecisionLink {
    /// Requests to the worker.
    pub tx: rtrb::Producer<DecisionRequest>,
    /// Its responses.
    pub rx: rtrb::Consumer<DecisionResponse>,
    thread: std::thread::Thread,
    rejected_frames: Arc<AtomicU64>,
}

impl DecisionLink {
    /// Sends a request and wakes the worker; gives the request back if the ring is full.
    #[allow(clippy::result_large_err)] // moved, not copied around: the loop takes it back
    pub fn send(&mut self, r: DecisionRequest) -> Result<(), DecisionRequest> {
        match self.tx.push(r) {
            Ok(()) => {
                self.thread.unpark();
                Ok(())
            }
            Err(rtrb::PushError::Full(r)) => Err(r),
        }
    }

    /// Heightmap frames the worker dropped as invalid (a cell not finite or out of range, or a
    /// bad header or grid): never decided on, counted with the loop's rejected inputs.
    pub fn rejected_frames(&self) -> u64 {
        self.rejected_frames.load(Ordering::Relaxed)
    }
}

/// The worker thread: the core, and the heightmaps it decides on.
struct Worker {
    core: DecisionCore,
    hm_sub: Sub<HeightmapFrame>,
    /// Where each decision's report goes (viewers).
    report: Pub<DecisionReport>,
    seq: u64,
    latest: Option<Sample<ipc::Service, HeightmapFrame, ()>>,
    rejected_frames: Arc<AtomicU64>,
    record: Option<FrameLog>,
    handled: u64,
    _bus: Bus,
}

impl Worker {
    /// Keeps the newest valid frame, waiting up to `wait` for one stamped after `after`; true
    /// when it has one.
    fn refresh_frame(&mut self, after: u64, wait: Duration) -> bool {
        let t0 = Instant::now();
        loop {
            self.drain_frames();
            let fresh = self
                .latest
                .as_ref()
                .is_some_and(|s| s.payload().header.stamp_ns > after);
            if fresh || t0.elapsed() > wait {
                return fresh;
            }
            std::thread::sleep(FRAME_POLL);
        }
    }

    /// Receives every frame that arrived: the header checked here, the grid and every cell by
    /// the core, which keeps its copy ([`DecisionCore::observe`], the frame's one check). A bad
    /// frame is dropped and counted, the newest good one kept.
    fn drain_frames(&mut self) {
        while let Ok(Some(s)) = self.hm_sub.receive() {
            let frame = s.payload();
            if frame.validate_meta().is_ok() && self.core.observe(frame).is_ok() {
                self.latest = Some(s);
            } else {
                self.rejected_frames.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Serves one request: a frame newer than the release (recorded when a run log is
    /// written), then the core ([`DecisionCore::decide_guarded`]).
    fn handle(&mut self, r: DecisionRequest) -> DecisionResponse {
        let fresh = self.refresh_frame(r.after_stamp_ns, FRAME_WAIT);
        let frame = self.latest.as_ref().filter(|_| fresh).map(|s| s.payload());
        if let Some(log) = &self.record {
            log(self.handled, frame);
        }
        self.handled += 1;
        if frame.is_none() {
            return no_fresh_frame(&r);
        }
        // On the frame just checked and copied as it arrived (the newest good one).
        let d = self.core.decide_guarded(&r, None);
        // With the job's twin, whether the rollouts ran in it (this thread may format).
        if let Some(j) = self.core.search_report().and_then(|s| s.job) {
            crate::logfmt::log(
                "job_twin",
                &[
                    ("index", &r.index),
                    ("objects", &j.objects),
                    ("used", &j.used),
                    ("mean_diff_mm", &format_args!("{:.2}", 1e3 * j.mean_diff_m)),
                    ("cells_off_pct", &format_args!("{:.2}", 100.0 * j.off)),
                    ("fit_ms", &format_args!("{:.1}", 1e3 * j.fit.as_secs_f64())),
                ],
            );
        }
        let mut report = self.core.report(&d);
        self.seq += 1;
        report.header = Header::now(self.seq);
        // For viewers only: a full queue or no subscriber loses nothing herbd needs.
        let _ = self.report.send_copy(report);
        d
    }
}

/// Starts the decision worker: loads the method (errors come back here, before the daemon
/// reports ready) and opens its own heightmap subscriber.
pub fn spawn(
    cfg: &Config,
    catalog: SharedCatalog,
    stop: Arc<AtomicBool>,
    record: Option<FrameLog>,
) -> Result<(DecisionLink, JoinHandle<()>), PlannerError> {
    let (tx, req_rx) = rtrb::RingBuffer::<DecisionRequest>::new(RING);
    let (resp_tx, rx) = rtrb::RingBuffer::<DecisionResponse>::new(RING);
    let cfg = cfg.clone();
    let shared_rejects = Arc::new(AtomicU64::new(0));
    let rejected_frames = shared_rejects.clone();
    let setup = move || -> Result<Worker, PlannerError> {
        let services = Services::new(&cfg.ipc_prefix)?;
        let bus = Bus::open("herbd-decide", &services)?;
        let hm_sub = bus.subscriber::<HeightmapFrame>(&services.heightmap())?;
        let report = bus.publisher::<DecisionReport>(&services.decision())?;
        Ok(Worker {
            core: DecisionCore::new(&cfg, catalog)?,
            hm_sub,
            report,
            seq: 0,
            latest: None,
            rejected_frames,
            record,
            handled: 0,
            _bus: bus,
        })
    };
    let handle = crate::planner::spawn_server(
        "herbd-decide",
        setup,
        stop,
        (req_rx, resp_tx),
        |w, r| w.handle(r),
        // Frames are checked as they come, not only when one is decided on.
        |w| w.drain_frames(),
    )?;
    let thread = handle.thread().clone();
    Ok((
        DecisionLink {
            tx,
            rx,
            thread,
            rejected_frames: shared_rejects,
        },
        handle,
    ))
}
