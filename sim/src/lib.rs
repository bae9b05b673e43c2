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
//! Shared definitions that training, evaluation and the daemon must agree on (the object
//! catalog, the heightmap grid, the observation layout, the z estimate, the placement lattice)
//! live in `herb-core`, without a physics engine, and are re-exported here under their old
//! paths.
#![warn(missing_docs)]

pub mod env;
pub mod eval;
pub mod field;
pub mod reserve;
pub mod teacher;

// The world, a crate of its own (herbd links it, through the search, without this crate),
// under its old path.
pub use herb_world as world;

// The domain core (no physics engine), re-exported under its old paths.
pub use herb_core::{
    boxed, catalog, error, features, frames, heightmap, hull, image, lattice, mesh, observation,
    paths, zestimate,
};

pub use catalog::{Catalog, ObjectShape, ObjectSpec, SharedCatalog, TypeIdx};

pub use env::{PackingEnv, RewardMode, StepInfo, StepResult, sample_objects};
pub use error::{Result, SimError};
pub use heightmap::{GridSpec, Heightmap};
pub use observation::ObsLayout;
pub use world::{ObjectReport, PackingWorld, PlacementOutcome, WorldConfig};
