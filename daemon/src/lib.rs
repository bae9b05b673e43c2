//! `herbd`, HERB's controller: its configuration, the fixed-rate control loop with the job
//! state machine, and the planner thread that runs the decision core (`herb-decide`) and the
//! motion planning (`herb-robot`) off the loop.

#![warn(missing_docs)]

pub mod config;
pub mod controller;
pub mod planner;

pub use herb_decide::{
    Blbf, CandidatePolicy, DecideError, DecisionInput, OnnxPolicy, Policy, Result, SequenceModel,
    beam3, candidate, error, load_policy, onnx, policy, sequence,
};
pub use herb_robot::{cell, kinematics, motion};
