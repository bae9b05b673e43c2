//! # herb-sim: the HERB packing world
//!
//! A deterministic rapier3d simulation of the BoxED packing setup: the wooden box, the 24
//! household object types, placement with a heightmap-based z estimate, settling, the paper's
//! metrics and rewards, a Gymnasium-shaped episode API, the BoxED human sessions, and the
//! evaluation that runs them.
//!
//! Frames and units: SI, right-handed, z up; the box frame B (see [`frames`]) is used
//! everywhere. The BoxED Unity frame is converted once, in [`frames::unity_place_to_box`].
//!
//! Shared definitions that training, evaluation and the daemon must agree on live here, once:
//! the object catalog ([`catalog`]), the heightmap grid ([`heightmap`]), the observation layout
//! ([`observation`]) and the z estimate ([`zestimate`]).
#![warn(missing_docs)]

pub mod boxed;
pub mod catalog;
pub mod env;
pub mod error;
pub mod eval;
pub mod features;
pub mod frames;
pub mod heightmap;
pub mod hull;
pub mod image;
pub mod lattice;
pub mod mesh;
pub mod observation;
pub mod paths;
#[cfg(feature = "picture")]
pub mod picture;
pub mod reserve;
pub mod teacher;
pub mod world;
pub mod zestimate;

pub use catalog::{Catalog, ObjectShape, ObjectSpec, SharedCatalog, TypeIdx};

pub use env::{PackingEnv, RewardMode, StepInfo, StepResult};
pub use error::{Result, SimError};
pub use heightmap::{GridSpec, Heightmap};
pub use observation::ObsLayout;
pub use world::{ObjectReport, PackingWorld, PlacementOutcome, WorldConfig};
