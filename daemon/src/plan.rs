//! What the control loop exchanges with the planner thread (trajectory buffers, [`MotionPlan`],
//! that move between them, [`Request`]s and [`Response`]s) and with the decision worker
//! ([`DecisionRequest`], [`DecisionResponse`]). Plain data (no I/O), shared by the planner
//! ([`crate::planner`]), the decision worker ([`crate::decision`]), the job state machine
//! ([`crate::job`]) and its tests.

use crate::digest::Fnv;
use herb_ipc::{Fault, GripperAction, MAX_JOB_OBJECTS};
use herb_robot::kinematics::DOF;
use herb_robot::motion::{Setpoint, Setpoints};

/// Most segments in one object's plan.
pub const MAX_SEGMENTS: usize = 8;

/// One rest-to-rest move of a plan, and the gripper action at its end.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Segment {
    /// Index one past its last sample in [`MotionPlan::setpoints`].
    pub end: usize,
    /// Gripper action once the arm stands at the segment's end.
    pub then: Option<GripperAction>,
}

/// A trajectory buffer and what it is for. Two are allocated at start and reused.
#[derive(Debug, Clone)]
pub struct MotionPlan {
    /// Samples at the loop period.
    pub setpoints: Setpoints,
    /// Segments, in order.
    pub segments: [Segment; MAX_SEGMENTS],
    /// Segments used.
    pub n_segments: usize,
    /// Object index in the packing order.
    pub index: u32,
    /// Its catalog type.
    pub object: u16,
    /// Placement in B: x, y, z (m), yaw (rad); zeros for a pick.
    pub pose: [f32; 4],
    /// The gripper holds (or will hold) the object turned by a half turn
    /// ([`herb_robot::cell::pick_waypoints`]).
    pub flip: bool,
    /// Digest of everything above ([`MotionPlan::content_digest`]), set by the planner when it
    /// fills the plan (the loop records it without hashing samples).
    pub digest: u64,
}

impl MotionPlan {
    /// An empty plan holding `samples` samples at most.
    pub fn with_capacity(samples: usize) -> Self {
        Self {
            setpoints: Setpoints::with_capacity(samples),
            segments: [Segment::default(); MAX_SEGMENTS],
            n_segments: 0,
            index: 0,
            object: 0,
            pose: [0.0; 4],
            flip: false,
            digest: 0,
        }
    }

    /// Empties the plan for reuse (capacity kept).
    pub fn reset(&mut self) {
        self.setpoints.clear();
        self.n_segments = 0;
        self.pose = [0.0; 4];
        self.flip = false;
        self.digest = 0;
    }

    /// The digest of the plan's content: samples (bit for bit), segments, index, object, pose
    /// and grasp flip.
    pub fn content_digest(&self) -> u64 {
        let mut h = Fnv::new();
        for s in self.setpoints.as_slice() {
            for v in s.position.iter().chain(&s.velocity).chain(&s.acceleration) {
                h.f64(*v);
            }
        }
        for sg in self.segments() {
            h.u64(sg.end as u64)
                .u64(sg.then.map_or(u64::MAX, |a| a as u64));
        }
        h.u64(self.index as u64).u64(self.object as u64);
        for v in self.pose {
            h.u64(v.to_bits() as u64);
        }
        h.u64(self.flip as u64).finish()
    }

    /// Ends a segment at the last sample, with `then` to do there.
    pub fn push_segment(&mut self, then: Option<GripperAction>) {
        if self.n_segments < MAX_SEGMENTS {
            self.segments[self.n_segments] = Segment {
                end: self.setpoints.len(),
                then,
            };
            self.n_segments += 1;
        }
    }

    /// The segments used.
    pub fn segments(&self) -> &[Segment] {
        &self.segments[..self.n_segments]
    }
}

/// What the loop asks.
#[derive(Debug)]
pub enum Request {
    /// Order a job's objects (Beam-3), or, with `ordered`, take them as the job's order
    /// (a job recovered from the journal keeps the order it was started with).
    Order {
        /// Job id.
        job_id: u64,
        /// Objects (catalog type indices).
        objects: [u16; MAX_JOB_OBJECTS],
        /// Used.
        count: usize,
        /// The objects are already in packing order: no search.
        ordered: bool,
    },
    /// Plan `motion` for object `index` from rest at `from`.
    Plan {
        /// Index in the order.
        index: u32,
        /// Its type.
        object: u16,
        /// Current configuration (at rest).
        from: [f64; DOF],
        /// Which moves.
        motion: Motion,
        /// The placement (decided already) of a [`Motion::Place`] or [`Motion::PickAndPlace`].
        pose: [f32; 4],
        /// Buffer to fill.
        buf: Box<MotionPlan>,
    },
    /// Retreat straight up from rest at `from` to the transit height (for `held`, the type of
    /// the object in the gripper, if any): the move of a cancelled job. No segment when the
    /// gripper is already that high or the lift is out of reach.
    Retreat {
        /// Current configuration (at rest).
        from: [f64; DOF],
        /// The held object's type, if one is held.
        held: Option<u16>,
        /// Buffer to fill.
        buf: Box<MotionPlan>,
    },
    /// Brake from `state` to standstill.
    Brake {
        /// The last commanded state.
        state: Setpoint,
        /// Buffer to fill.
        buf: Box<MotionPlan>,
    },
}

/// The moves of an object's plan. The pick does not wait for the placement: the decision is
/// made meanwhile ([`DecisionRequest`]), and the place is planned when it arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// Up to the transit height, above the pick station, the grasp (close), and back up: the
    /// object is held at the lift pose. The plan says which way it is held ([`MotionPlan::flip`]).
    Pick,
    /// The held object (taken as `flip` says) carried to its placement, released (open), and
    /// the gripper back up.
    Place {
        /// The object is held turned by a half turn.
        flip: bool,
    },
    /// The pick and the place of an object whose placement was decided before (a grasp that
    /// missed, a resume before the grasp): the grasp and release turns chosen together.
    PickAndPlace,
}

/// What the loop asks the decision worker: where object `index` of the job's order goes, on a
/// heightmap stamped after `after_stamp_ns` (the last release).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecisionRequest {
    /// Job id.
    pub job_id: u64,
    /// Index in the order.
    pub index: u32,
    /// The job's packing order (the objects after `index` are what a search rolls out).
    pub order: [u16; MAX_JOB_OBJECTS],
    /// Used.
    pub count: u32,
    /// Oldest acceptable heightmap stamp (exclusive).
    pub after_stamp_ns: u64,
}

impl DecisionRequest {
    /// The object to place and those after it, in order.
    pub fn remaining(&self) -> &[u16] {
        let n = (self.count as usize).min(MAX_JOB_OBJECTS);
        self.order[..n].get(self.index as usize..).unwrap_or(&[])
    }
}

/// `allowed` of a decision that is not a search.
pub const NOT_A_SEARCH: u32 = u32::MAX;

/// What the decision worker answers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecisionResponse {
    /// Job id of the request.
    pub job_id: u64,
    /// Index of the request.
    pub index: u32,
    /// The object's type.
    pub object: u16,
    /// The placement in B (x, y, z in m, yaw in rad), or why there is none:
    /// `HeightmapTimeout` (no valid frame newer than the release came in time; ask again),
    /// `NoFeasiblePlacement`, or `Decision` (the method failed).
    pub outcome: Result<[f32; 4], Fault>,
    /// What the budget allowed: the rollouts a search finished, which a replay runs as a count
    /// ([`NOT_A_SEARCH`] for a policy).
    pub allowed: u32,
    /// The decision's latency, ns (not reproducible: a replay injects the recorded one).
    pub decision_ns: u64,
}

impl DecisionResponse {
    /// The digest of everything but the latency: what a replay compares.
    pub fn digest(&self) -> u64 {
        let mut h = Fnv::new();
        h.u64(6)
            .u64(self.job_id)
            .u64(self.index as u64)
            .u64(self.object as u64);
        match self.outcome {
            Ok(p) => {
                h.u64(0);
                for v in p {
                    h.u64(v.to_bits() as u64);
                }
            }
            Err(f) => {
                h.u64(1).u64(f as u64);
            }
        }
        h.u64(self.allowed as u64).finish()
    }
}

/// What the planner answers.
#[derive(Debug)]
pub enum Response {
    /// The packing order.
    Ordered {
        /// Job id.
        job_id: u64,
        /// Ordered objects.
        order: [u16; MAX_JOB_OBJECTS],
        /// Used.
        count: usize,
    },
    /// The job could not be ordered.
    OrderFailed {
        /// Job id.
        job_id: u64,
    },
    /// A plan for an object, or a retreat.
    Planned(Box<MotionPlan>),
    /// A brake trajectory.
    Braked(Box<MotionPlan>),
    /// Planning failed; the buffer comes back.
    Failed {
        /// Why.
        fault: Fault,
        /// The buffer.
        buf: Box<MotionPlan>,
    },
}

impl Response {
    /// The digest of a response as the loop receives it (a plan's by its
    /// [`MotionPlan::digest`], filled by the planner): what a replay compares.
    pub fn digest(&self) -> u64 {
        let mut h = Fnv::new();
        match self {
            Response::Ordered {
                job_id,
                order,
                count,
            } => {
                h.u64(1).u64(*job_id);
                for o in &order[..*count] {
                    h.u64(*o as u64);
                }
            }
            Response::OrderFailed { job_id } => {
                h.u64(2).u64(*job_id);
            }
            Response::Planned(p) => {
                h.u64(3).u64(p.digest);
            }
            Response::Braked(p) => {
                h.u64(4).u64(p.digest);
            }
            Response::Failed { fault, .. } => {
                h.u64(5).u64(*fault as u64);
            }
        }
        h.finish()
    }
}
