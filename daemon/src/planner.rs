//! The planner thread: everything `herbd` does that allocates or takes longer than a cycle.
//!
//! The loop sends it [`Request`]s and receives [`Response`]s over two wait-free SPSC rings
//! (`rtrb`); trajectory buffers ([`MotionPlan`]) are preallocated once and only move between
//! the threads, so the loop never allocates. The planner orders a job (Beam-3), decides each
//! placement from the newest heightmap (`herb_decide::Decider`: the decision the latency
//! budget is about), plans the gripper waypoints, solves inverse kinematics and samples
//! Ruckig trajectories at the loop period; it also computes brakes on request.

use crate::config::Config;
pub use crate::plan::{MAX_SEGMENTS, MotionPlan, Request, Response, Segment};
use herb_core::{SharedCatalog, TypeIdx};
use herb_decide::DecideError;
use herb_decide::Order;
use herb_decide::sequence::SequenceModel;
use herb_decide::{Decider, HeightmapView, Policy};
use herb_ipc::bus::{Bus, Sub};
use herb_ipc::{Fault, GripperAction, HeightmapFrame, MAX_JOB_OBJECTS, Services};
use herb_robot::cell::{CellConfig, lift_to, plan_waypoints};
use herb_robot::kinematics::{Arm, DOF, IkOptions};
use herb_robot::motion::MotionPlanner;
use iceoryx2::prelude::ipc;
use iceoryx2::sample::Sample;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Receives, for request number `n` (from 0, in the order the loop sent them), the frame it
/// was served with: `None` for a request that needs none, or when none newer than the release
/// came within the wait. Called on the planner thread (it may allocate).
pub type FrameLog = Box<dyn Fn(u64, Option<&HeightmapFrame>) + Send>;

/// Requests (and responses) the rings between the loop and the planner hold. The loop has at
/// most two requests out (an order or a plan, and a brake).
const RING: usize = 8;
/// Longest wait for a heightmap stamped after the last release before a plan fails with
/// `HeightmapTimeout` (the loop then waits and asks again).
const FRAME_WAIT: Duration = Duration::from_millis(500);
/// How often a waiting plan looks for a new frame.
const FRAME_POLL: Duration = Duration::from_millis(1);
/// Longest sleep with no request (the loop wakes the thread when it sends one).
const IDLE_PARK: Duration = Duration::from_millis(20);

/// The loop's ends of the rings.
pub struct PlannerLink {
    /// Requests to the planner.
    pub tx: rtrb::Producer<Request>,
    /// Its responses.
    pub rx: rtrb::Consumer<Response>,
    thread: std::thread::Thread,
    rejected_frames: Arc<AtomicU64>,
}

impl PlannerLink {
    /// Sends a request and wakes the planner; gives the request back if the ring is full.
    #[allow(clippy::result_large_err)] // moved, not copied around: the loop takes it back as is
    pub fn send(&mut self, r: Request) -> Result<(), Request> {
        match self.tx.push(r) {
            Ok(()) => {
                self.thread.unpark();
                Ok(())
            }
            Err(rtrb::PushError::Full(r)) => Err(r),
        }
    }

    /// Heightmap frames the planner dropped as invalid (a cell not finite or out of range, or
    /// a bad header or grid): never decided on, counted with the loop's rejected inputs.
    pub fn rejected_frames(&self) -> u64 {
        self.rejected_frames.load(Ordering::Relaxed)
    }
}

/// The planner's work without its thread and ports: ordering a job (Beam-3), deciding a
/// placement on a given heightmap, planning the motion. herbd's planner thread and
/// `herbctl replay` run this same code.
pub struct PlannerCore {
    decider: Decider,
    catalog: SharedCatalog,
    sequence: SequenceModel,
    cell: CellConfig,
    arm: Arm,
    ik: IkOptions,
    motion: MotionPlanner,
    /// The current job's order (from the last `Order` request).
    job_order: Vec<TypeIdx>,
}

/// The planner thread: the core, and the heightmaps it decides on.
struct Worker {
    core: PlannerCore,
    hm_sub: Sub<HeightmapFrame>,
    latest: Option<Sample<ipc::Service, HeightmapFrame, ()>>,
    /// Frames dropped as invalid (shared with the loop's statistics).
    rejected_frames: Arc<AtomicU64>,
    /// Where the frame each request was served with goes (run log), if recording.
    record: Option<FrameLog>,
    /// Requests handled (the run log numbers them from 0, as the loop does its responses).
    handled: u64,
    _bus: Bus,
}

impl Worker {
    /// Keeps the newest valid frame in `latest` (every cell checked: a bad frame is dropped and
    /// counted, the previous good one stays), waiting up to `wait` for one stamped after
    /// `after`; true when it has one.
    fn refresh_frame(&mut self, after: u64, wait: Duration) -> bool {
        let t0 = Instant::now();
        loop {
            self.drain_frames();
            let fresh = self
                .latest
                .as_ref()
                .is_some_and(|s| s.payload().header.stamp_ns > after);
            if fresh || t0.elapsed() > wait {
                break;
            }
            std::thread::sleep(FRAME_POLL);
        }
        self.latest
            .as_ref()
            .is_some_and(|s| s.payload().header.stamp_ns > after)
    }

    /// Receives every frame that arrived, checking every cell of each (on receipt, whether or
    /// not a decision needs it): a bad frame is dropped and counted, the newest good one kept.
    fn drain_frames(&mut self) {
        while let Ok(Some(s)) = self.hm_sub.receive() {
            if s.payload().validate().is_ok() {
                self.latest = Some(s);
            } else {
                self.rejected_frames.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Serves one request: the frame it needs (a plan that decides waits for one newer than
    /// the last release), recorded when a run log is written, then the core.
    fn handle(&mut self, r: Request) -> Response {
        let frame = match PlannerCore::frame_needed(&r) {
            Some(after) if self.refresh_frame(after, FRAME_WAIT) => {
                self.latest.as_ref().map(|s| s.payload())
            }
            _ => None,
        };
        if let Some(log) = &self.record {
            log(self.handled, PlannerCore::frame_needed(&r).and(frame));
        }
        self.handled += 1;
        self.core.handle(r, frame)
    }
}

impl PlannerCore {
    /// Loads the sequence model and the policy named by `cfg` for `catalog`.
    pub fn new(cfg: &Config, catalog: SharedCatalog) -> Result<Self, PlannerError> {
        let policy = herb_decide::load_policy(&cfg.models.resolved_policy(), &catalog)?;
        Self::with_policy(cfg, catalog, policy)
    }

    /// As [`PlannerCore::new`] with `policy` instead of the one `cfg` names (the planner's
    /// property tests drive it with arbitrary policy outputs).
    pub fn with_policy(
        cfg: &Config,
        catalog: SharedCatalog,
        policy: Box<dyn Policy>,
    ) -> Result<Self, PlannerError> {
        let sequence = SequenceModel::load(&cfg.models.sequence, &catalog)?;
        let decider = Decider::new(policy, catalog.clone(), cfg.models.clearance_m as f32);
        let limits = cfg.limits;
        Ok(Self {
            decider,
            catalog,
            sequence,
            cell: cfg.cell,
            arm: Arm::baxter_left().with_limits(&limits.lower, &limits.upper),
            ik: IkOptions::default(),
            motion: MotionPlanner::new(limits, cfg.period_s()),
            job_order: Vec::with_capacity(MAX_JOB_OBJECTS),
        })
    }

    /// Orders a job's objects (HERB's Beam-3, [`Order::HERB`]; kept as given when `ordered`, a
    /// recovered job's) and keeps the order for the decisions' lookahead.
    fn order(&mut self, objects: &[u16], ordered: bool) -> Option<Vec<TypeIdx>> {
        let v: Vec<TypeIdx> = objects.iter().map(|&o| TypeIdx(o)).collect();
        let order = if ordered {
            v
        } else {
            Order::HERB
                .order(&self.catalog, Some(&self.sequence), &v, 0)
                .ok()?
        };
        self.job_order.clear();
        self.job_order.extend_from_slice(&order);
        Some(order)
    }

    #[allow(clippy::too_many_arguments)]
    fn plan(
        &mut self,
        index: u32,
        object: u16,
        frame: Option<&HeightmapFrame>,
        from: [f64; DOF],
        reuse: Option<[f32; 4]>,
        pick: bool,
        buf: &mut MotionPlan,
    ) -> Result<(), Fault> {
        buf.reset();
        buf.index = index;
        buf.object = object;
        let ty = TypeIdx(object);
        let pose = match reuse {
            Some(p) => p,
            None => {
                let Some(frame) = frame else {
                    return Err(Fault::HeightmapTimeout);
                };
                let (p, ns) = self.decision(frame, object, index);
                buf.decision_ns = ns;
                buf.decided = true;
                p.map_err(|e| match e {
                    DecideError::NoFeasiblePlacement => Fault::NoFeasiblePlacement,
                    _ => Fault::Decision,
                })?
                .xyz_theta()
            }
        };
        buf.pose = pose;
        let h = self.catalog.shape(ty).extents().z as f64;
        let place = pose.map(|v| v as f64);
        let clear_top = herb_core::frames::SUCCESS_TOP_Z as f64;
        let w = plan_waypoints(&self.cell, &self.arm, &self.ik, h, place, &from, clear_top)
            .map_err(|_| Fault::Unreachable)?;
        let transit = self.cell.transit_z(h, clear_top);
        let mut cur = from;
        let mut go = |to: &[f64; DOF],
                      then,
                      buf: &mut MotionPlan,
                      m: &mut MotionPlanner|
         -> Result<(), Fault> {
            m.point_to_point(&cur, to, &mut buf.setpoints)
                .map_err(|_| Fault::Motion)?;
            buf.push_segment(then);
            cur = *to;
            Ok(())
        };
        if let Some(up) = lift_to(&self.arm, &self.ik, &from, transit) {
            go(&up, None, buf, &mut self.motion)?;
        }
        if pick {
            go(&w.pre_grasp, None, buf, &mut self.motion)?;
            go(&w.grasp, Some(GripperAction::Close), buf, &mut self.motion)?;
            go(&w.pre_grasp, None, buf, &mut self.motion)?;
        }
        go(&w.pre_place, None, buf, &mut self.motion)?;
        go(&w.place, Some(GripperAction::Open), buf, &mut self.motion)?;
        go(&w.pre_place, None, buf, &mut self.motion)?;
        Ok(())
    }

    /// Straight up from `from` to the transit height for the object `held` (none: an empty
    /// gripper); no segment when already there or out of reach.
    fn retreat(
        &mut self,
        from: [f64; DOF],
        held: Option<u16>,
        buf: &mut MotionPlan,
    ) -> Result<(), Fault> {
        buf.reset();
        let h = held.map_or(0.0, |t| self.catalog.shape(TypeIdx(t)).extents().z as f64);
        let transit = self
            .cell
            .transit_z(h, herb_core::frames::SUCCESS_TOP_Z as f64);
        if let Some(up) = lift_to(&self.arm, &self.ik, &from, transit) {
            self.motion
                .point_to_point(&from, &up, &mut buf.setpoints)
                .map_err(|_| Fault::Motion)?;
            buf.push_segment(None);
        }
        Ok(())
    }

    /// Decides where object `index` of the current job's order (type `object`) goes on
    /// `frame`; and the decision latency (ns), which is this call to the `Decider` alone.
    pub fn decision(
        &mut self,
        frame: &HeightmapFrame,
        object: u16,
        index: u32,
    ) -> (Result<herb_decide::Decision, DecideError>, u64) {
        let view = HeightmapView {
            nx: frame.nx as usize,
            ny: frame.ny as usize,
            cell_m: frame.cell_m,
            cells: frame.cells(),
        };
        let after = self.job_order.get(index as usize + 1..).unwrap_or(&[]);
        let t0 = Instant::now();
        let p = self
            .decider
            .decide(view, TypeIdx(object), index as usize, after);
        (p, t0.elapsed().as_nanos() as u64)
    }

    /// The catalog.
    pub fn catalog(&self) -> &SharedCatalog {
        &self.catalog
    }

    /// The stamp a request's frame must be newer than, for a plan that decides; else `None`
    /// (the request needs no frame).
    pub fn frame_needed(r: &Request) -> Option<u64> {
        match r {
            Request::Plan {
                place_only: false,
                repick: false,
                after_stamp_ns,
                ..
            } => Some(*after_stamp_ns),
            _ => None,
        }
    }

    /// Serves a request; a plan that decides does so on `frame` (none: `HeightmapTimeout`).
    /// Plans come back with their [`MotionPlan::digest`].
    pub fn handle(&mut self, r: Request, frame: Option<&HeightmapFrame>) -> Response {
        let mut resp = self.serve(r, frame);
        match &mut resp {
            Response::Planned(p) | Response::Braked(p) | Response::Failed { buf: p, .. } => {
                p.digest = p.content_digest();
            }
            _ => {}
        }
        resp
    }

    fn serve(&mut self, r: Request, frame: Option<&HeightmapFrame>) -> Response {
        match r {
            Request::Order {
                job_id,
                objects,
                count,
                ordered,
            } => match self.order(&objects[..count], ordered) {
                Some(v) => {
                    let mut order = [0u16; MAX_JOB_OBJECTS];
                    for (o, t) in order.iter_mut().zip(&v) {
                        *o = t.0;
                    }
                    Response::Ordered {
                        job_id,
                        order,
                        count,
                    }
                }
                None => Response::OrderFailed { job_id },
            },
            Request::Plan {
                index,
                object,
                from,
                place_only,
                repick,
                pose,
                mut buf,
                ..
            } => {
                let reuse = (place_only || repick).then_some(pose);
                match self.plan(index, object, frame, from, reuse, !place_only, &mut buf) {
                    Ok(()) => Response::Planned(buf),
                    Err(fault) => Response::Failed { fault, buf },
                }
            }
            Request::Retreat {
                from,
                held,
                mut buf,
            } => match self.retreat(from, held, &mut buf) {
                Ok(()) => Response::Planned(buf),
                Err(fault) => Response::Failed { fault, buf },
            },
            Request::Brake { state, mut buf } => {
                buf.reset();
                match self.motion.brake(&state, &mut buf.setpoints) {
                    Ok(_) => {
                        buf.push_segment(None);
                        Response::Braked(buf)
                    }
                    Err(_) => {
                        // Ruckig failed: stop where commanded (the adapter's own limits hold).
                        buf.reset();
                        Response::Failed {
                            fault: Fault::Motion,
                            buf,
                        }
                    }
                }
            }
        }
    }
}

/// Why the planner cannot start.
#[derive(Debug, thiserror::Error)]
pub enum PlannerError {
    /// The policy or the sequence model cannot be loaded.
    #[error(transparent)]
    Models(#[from] herb_decide::DecideError),
    /// The IPC prefix is not one.
    #[error(transparent)]
    Prefix(#[from] herb_ipc::BadPrefix),
    /// The planner's heightmap subscriber cannot be opened.
    #[error(transparent)]
    Bus(#[from] herb_ipc::bus::BusError),
    /// The thread cannot be started.
    #[error("cannot start the planner thread: {0}")]
    Thread(std::io::Error),
    /// The thread ended before it said it was ready.
    #[error("the planner thread died while starting")]
    Died,
}

/// Starts the planner thread: loads the catalog, sequence model and policy (errors come back
/// here, before the daemon reports ready), and opens its own heightmap subscriber.
pub fn spawn(
    cfg: &Config,
    catalog: SharedCatalog,
    stop: Arc<AtomicBool>,
    record: Option<FrameLog>,
) -> Result<(PlannerLink, JoinHandle<()>), PlannerError> {
    let (tx, req_rx) = rtrb::RingBuffer::<Request>::new(RING);
    let (resp_tx, rx) = rtrb::RingBuffer::<Response>::new(RING);
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), PlannerError>>();
    let cfg = cfg.clone();
    let shared_rejects = Arc::new(AtomicU64::new(0));
    let rejected_frames = shared_rejects.clone();
    let handle = std::thread::Builder::new()
        .name("herbd-planner".into())
        .spawn(move || {
            let setup = (|| -> Result<Worker, PlannerError> {
                let services = Services::new(&cfg.ipc_prefix)?;
                let bus = Bus::open("herbd-planner", &services)?;
                let hm_sub = bus.subscriber::<HeightmapFrame>(&services.heightmap())?;
                Ok(Worker {
                    core: PlannerCore::new(&cfg, catalog.clone())?,
                    hm_sub,
                    latest: None,
                    rejected_frames: rejected_frames.clone(),
                    record,
                    handled: 0,
                    _bus: bus,
                })
            })();
            let (mut w, mut req_rx, mut resp_tx) = match setup {
                Ok(w) => {
                    let _ = ready_tx.send(Ok(()));
                    (w, req_rx, resp_tx)
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            while !stop.load(Ordering::Relaxed) {
                while let Ok(r) = req_rx.pop() {
                    let resp = w.handle(r);
                    if resp_tx.push(resp).is_err() {
                        // The loop reads every cycle and has at most two requests out.
                        crate::logfmt::log("bug", &[("what", &"planner response ring full")]);
                    }
                }
                // Frames are checked as they come, not only when one is decided on.
                w.drain_frames();
                std::thread::park_timeout(IDLE_PARK);
            }
        })
        .map_err(PlannerError::Thread)?;
    let thread = handle.thread().clone();
    match ready_rx.recv() {
        Ok(Ok(())) => Ok((
            PlannerLink {
                tx,
                rx,
                thread,
                rejected_frames: shared_rejects,
            },
            handle,
        )),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(PlannerError::Died),
    }
}
