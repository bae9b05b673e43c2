//! The one registry of placement methods.
//!
//! [`Method`] names every way Table I places objects, for the CLI, the bindings and the tables;
//! [`Method::placer`] builds any of them from one [`MethodSettings`] as a
//! [`herb_sim::eval::Placer`] of the one episode loop ([`herb_sim::eval::run_episode`]).
//!
//! This crate joins the two halves that never meet otherwise: the decision core
//! (`herb-decide`: the policies herbd ships, without a physics engine) and the physics world
//! with its research rules and the search (`herb-sim`).

#![warn(missing_docs)]

pub mod method;
pub mod placer;

pub use method::Method;
pub use placer::{DeciderPlacer, HeldOutPlacer, MethodSettings, PackitPlacer};
