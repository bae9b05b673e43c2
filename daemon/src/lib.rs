//! `herbd`, HERB's controller: its configuration, the fixed-rate control loop with the job
//! state machine, and the planner thread that runs the decision core (`herb-decide`) and the
//! motion planning (`herb-robot`) off the loop.

#![warn(missing_docs)]

pub mod cellcal;
pub mod config;
pub mod controller;
pub mod decision;
pub mod digest;
pub mod job;
pub mod journal;
pub mod logfmt;
pub mod notify;
pub mod plan;
pub mod planner;
pub mod record;
pub mod replay;
pub mod watch;
