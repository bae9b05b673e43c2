//! `herbd`, HERB's controller: its configuration, the fixed-rate control loop with the job
//! state machine, the planner thread (Beam-3 order and motion planning with `herb-robot`) and
//! the decision thread (a policy through `herb-decide`'s `Decider`, or the search, `herb-search`,
//! as that `Decider`'s policy), both off the loop; the job journal, run logs and their replay.

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
