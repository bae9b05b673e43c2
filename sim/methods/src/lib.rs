//! The one registry of placement methods.
//!
//! [`Method`] names every way Table I places objects, for the CLI, the bindings and the tables;
//! [`Method::placer`] builds any of them from one [`MethodSettings`] as a
//! [`herb_sim::eval::Placer`] of the one episode loop ([`herb_sim::eval::run_episode`]).
//!
//! This crate joins what herbd ships to decide (`herb-decide`: the policies and the `Decider`;
//! `herb-search`: the search, a policy of that `Decider`) with the evaluation's world and its
//! research rules (`herb-sim`): Table I's policies and search run through the `Decider`, as in
//! herbd.

#![warn(missing_docs)]

pub mod evaluation;
pub mod method;
pub mod placer;

pub use evaluation::{EvalRun, EvalSettings, Row};
pub use method::Method;
pub use placer::{
    DeciderPlacer, HeldOutPlacer, MethodSettings, PackitPlacer, load_policy_once, policy_file_reads,
};
