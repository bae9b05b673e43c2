//! The planner thread: everything `herbd` does that allocates or takes longer than a cycle.
//!
//! The loop sends it [`Request`]s and receives [`Response`]s over two wait-free SPSC rings
//! (`rtrb`); trajectory buffers ([`MotionPlan`]) are preallocated once and only move between
//! the threads, so the loop never allocates. The planner orders a job (Beam-3), plans the
//! gripper waypoints of a pick and of a place, solves inverse kinematics and samples Ruckig
//! trajectories at the loop period; it also computes brakes on request. Placements are decided
//! elsewhere, while the arm picks ([`crate::decision`]).

use crate::config::Config;
pub use crate::plan::{MAX_SEGMENTS, Motion, MotionPlan, Request, Response, Segment};
use herb_core::{SharedCatalog, TypeIdx};
use herb_decide::Order;
use herb_decide::sequence::SequenceModel;
use herb_ipc::{Fault, GripperAction, MAX_JOB_OBJECTS};
use herb_robot::cell::{CellConfig, lift_to, pick_waypoints, place_waypoints, plan_waypoints};
use herb_robot::kinematics::{Arm, DOF, IkOptions};
use herb_robot::motion::MotionPlanner;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Requests (and responses) the rings between the loop and the planner hold. The loop has at
/// most two requests out (an order or a plan, and a brake).
const RING: usize = 8;
/// Longest sleep with no request (the loop wakes the thread when it sends one).
const IDLE_PARK: Duration = Duration::from_millis(20);

/// The loop's ends of the rings.
pub struct PlannerLink {
    /// Requests to the planner.
    pub tx: rtrb::Producer<Request>,
    /// Its responses.
    pub rx: rtrb::Consumer<Response>,
    thread: std::thread::Thread,
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
}

/// The planner's work without its thread and ports: ordering a job (Beam-3) and planning the
/// motion. herbd's planner thread and `herbd replay` run this same code.
pub struct PlannerCore {
    catalog: SharedCatalog,
    sequence: SequenceModel,
    cell: CellConfig,
    arm: Arm,
    ik: IkOptions,
    motion: MotionPlanner,
    /// The arm's own position limits (wider than the configured ones).
    hard: ([f64; DOF], [f64; DOF]),
    /// `[recovery] recover_speed` and `recover_margin_rad`.
    recover: (f64, f64),
}

impl PlannerCore {
    /// Loads the sequence model `cfg` names, for `catalog`.
    pub fn new(cfg: &Config, catalog: SharedCatalog) -> Result<Self, PlannerError> {
        let sequence = SequenceModel::load(&cfg.models.sequence, &catalog)?;
        let limits = cfg.limits;
        Ok(Self {
            catalog,
            sequence,
            cell: cfg.cell,
            arm: Arm::baxter_left().with_limits(&limits.lower, &limits.upper),
            ik: IkOptions::default(),
            motion: MotionPlanner::new(limits, cfg.period_s()),
            hard: herb_robot::motion::baxter_left_arm_range(),
            recover: (cfg.recovery.recover_speed, cfg.recovery.recover_margin_rad),
        })
    }

    /// A start outside the configured limits (an arm that sagged while disabled): the slow
    /// move back inside as the plan's first segment ([`MotionPlanner::into_limits`]). Returns
    /// where the rest of the plan starts. A start beyond the arm's own limits is refused
    /// ([`Fault::BeyondArmLimits`]).
    fn back_inside_limits(
        &mut self,
        from: [f64; DOF],
        buf: &mut MotionPlan,
    ) -> Result<[f64; DOF], Fault> {
        let (speed, margin) = self.recover;
        let hard = (&self.hard.0, &self.hard.1);
        match self
            .motion
            .into_limits(&from, hard, speed, margin, &mut buf.setpoints)
        {
            Ok(None) => Ok(from),
            Ok(Some(_)) => {
                buf.push_segment(None);
                Ok(buf.setpoints.as_slice().last().map_or(from, |s| s.position))
            }
            Err(herb_robot::motion::MotionError::BadState { .. }) => Err(Fault::BeyondArmLimits),
            Err(_) => Err(Fault::Motion),
        }
    }

    /// Orders a job's objects (HERB's Beam-3, [`Order::HERB`]; kept as given when `ordered`, a
    /// recovered job's).
    fn order(&self, objects: &[u16], ordered: bool) -> Option<Vec<TypeIdx>> {
        let v: Vec<TypeIdx> = objects.iter().map(|&o| TypeIdx(o)).collect();
        if ordered {
            return Some(v);
        }
        Order::HERB
            .order(&self.catalog, Some(&self.sequence), &v, 0)
            .ok()
    }

    /// Plans `motion` for object `index` (type `object`) from rest at `from`, to `pose` for a
    /// place.
    fn plan(
        &mut self,
        index: u32,
        object: u16,
        from: [f64; DOF],
        motion: Motion,
        pose: [f32; 4],
        buf: &mut MotionPlan,
    ) -> Result<(), Fault> {
        buf.reset();
        buf.index = index;
        buf.object = object;
        let from = self.back_inside_limits(from, buf)?;
        let h = self.catalog.shape(TypeIdx(object)).extents().z as f64;
        let place = pose.map(|v| v as f64);
        let clear_top = herb_core::frames::SUCCESS_TOP_Z as f64;
        let transit = self.cell.transit_z(h, clear_top);
        let (cell, arm, ik) = (&self.cell, &self.arm, &self.ik);
        // The waypoints: the pick's (pre-grasp, grasp), the place's (pre-place, release), and
        // which way the object is held.
        type Pair = Option<([f64; DOF], [f64; DOF])>;
        let (pick, release, flip): (Pair, Pair, bool) = match motion {
            Motion::Pick => [false, true]
                .into_iter()
                .find_map(|flip| {
                    pick_waypoints(cell, arm, ik, h, &from, clear_top, flip)
                        .ok()
                        .map(|w| (Some(w), None, flip))
                })
                .ok_or(Fault::Unreachable)?,
            Motion::Place { flip } => {
                let w = place_waypoints(cell, arm, ik, h, place, &from, clear_top, flip)
                    .map_err(|_| Fault::Unreachable)?;
                (None, Some(w), flip)
            }
            Motion::PickAndPlace => {
                let w = plan_waypoints(cell, arm, ik, h, place, &from, clear_top)
                    .map_err(|_| Fault::Unreachable)?;
                (
                    Some((w.pre_grasp, w.grasp)),
                    Some((w.pre_place, w.place)),
                    w.flip,
                )
            }
        };
        buf.flip = flip;
        if release.is_some() {
            buf.pose = pose;
        }
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
        if let Some((pre_grasp, grasp)) = pick {
            go(&pre_grasp, None, buf, &mut self.motion)?;
            go(&grasp, Some(GripperAction::Close), buf, &mut self.motion)?;
            go(&pre_grasp, None, buf, &mut self.motion)?;
        }
        if let Some((pre_place, place_q)) = release {
            go(&pre_place, None, buf, &mut self.motion)?;
            go(&place_q, Some(GripperAction::Open), buf, &mut self.motion)?;
            go(&pre_place, None, buf, &mut self.motion)?;
        }
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
        let from = self.back_inside_limits(from, buf)?;
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

    /// The catalog.
    pub fn catalog(&self) -> &SharedCatalog {
        &self.catalog
    }

    /// Serves a request. Plans come back with their [`MotionPlan::digest`].
    pub fn handle(&mut self, r: Request) -> Response {
        let mut resp = self.serve(r);
        match &mut resp {
            Response::Planned(p) | Response::Braked(p) | Response::Failed { buf: p, .. } => {
                p.digest = p.content_digest();
            }
            _ => {}
        }
        resp
    }

    fn serve(&mut self, r: Request) -> Response {
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
                motion,
                pose,
                mut buf,
            } => match self.plan(index, object, from, motion, pose, &mut buf) {
                Ok(()) => Response::Planned(buf),
                Err(fault) => Response::Failed { fault, buf },
            },
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
    /// The decision worker's heightmap subscriber cannot be opened.
    #[error(transparent)]
    Bus(#[from] herb_ipc::bus::BusError),
    /// A thread cannot be started.
    #[error("cannot start the planner or decision thread: {0}")]
    Thread(std::io::Error),
    /// A thread ended before it said it was ready.
    #[error("the planner or decision thread died while starting")]
    Died,
}

/// Starts the planner thread: loads the sequence model (errors come back here, before the
/// daemon reports ready).
pub fn spawn(
    cfg: &Config,
    catalog: SharedCatalog,
    stop: Arc<AtomicBool>,
) -> Result<(PlannerLink, JoinHandle<()>), PlannerError> {
    let (tx, req_rx) = rtrb::RingBuffer::<Request>::new(RING);
    let (resp_tx, rx) = rtrb::RingBuffer::<Response>::new(RING);
    let cfg = cfg.clone();
    let handle = spawn_server(
        "herbd-planner",
        move || PlannerCore::new(&cfg, catalog),
        stop,
        (req_rx, resp_tx),
        |core, r| core.handle(r),
        |_| {},
    )?;
    let thread = handle.thread().clone();
    Ok((PlannerLink { tx, rx, thread }, handle))
}

/// Starts a thread called `name` that builds its state with `setup` (its error comes back
/// here, before the daemon reports ready), then, until `stop`, answers each request of the
/// ring with `serve`, and between rounds runs `idle` and sleeps until woken (or
/// [`IDLE_PARK`]). herbd's planner and decision threads.
pub(crate) fn spawn_server<W, Q, A>(
    name: &str,
    setup: impl FnOnce() -> Result<W, PlannerError> + Send + 'static,
    stop: Arc<AtomicBool>,
    (mut requests, mut answers): (rtrb::Consumer<Q>, rtrb::Producer<A>),
    mut serve: impl FnMut(&mut W, Q) -> A + Send + 'static,
    mut idle: impl FnMut(&mut W) + Send + 'static,
) -> Result<JoinHandle<()>, PlannerError>
where
    W: 'static,
    Q: Send + 'static,
    A: Send + 'static,
{
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), PlannerError>>();
    let what = name.to_owned();
    let handle = std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let mut w = match setup() {
                Ok(w) => {
                    let _ = ready_tx.send(Ok(()));
                    w
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            while !stop.load(Ordering::Relaxed) {
                while let Ok(r) = requests.pop() {
                    let a = serve(&mut w, r);
                    if answers.push(a).is_err() {
                        // The loop reads every cycle and has few requests out.
                        crate::logfmt::log(
                            "bug",
                            &[("what", &"response ring full"), ("thread", &what)],
                        );
                    }
                }
                idle(&mut w);
                std::thread::park_timeout(IDLE_PARK);
            }
        })
        .map_err(PlannerError::Thread)?;
    match ready_rx.recv() {
        Ok(Ok(())) => Ok(handle),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(PlannerError::Died),
    }
}
