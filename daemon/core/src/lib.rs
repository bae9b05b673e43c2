//! # herb-core: what every HERB process agrees on
//!
//! The domain core without a physics engine: the box frame B and the success volume
//! ([`frames`]), the 24 object types and their convex hulls ([`catalog`], [`hull`], [`mesh`]),
//! the heightmap grid ([`heightmap`]), the z estimate of a placement on a heightmap
//! ([`zestimate`]), the observation layout ([`observation`]), the placement lattice of feasible
//! candidates ([`lattice`]) and their features ([`features`]), and where the BoxED data is
//! read from ([`paths`]). herbd, the hardware adapters, the rapier3d packing world
//! (`herb-sim`) and the decision core (`herb-decide`) all use these, once.
//!
//! Frames and units: SI, right-handed, z up; the box frame B is used everywhere.
#![warn(missing_docs)]

pub mod boxed;
pub mod catalog;
pub mod error;
pub mod features;
pub mod frames;
pub mod heightmap;
pub mod hull;
pub mod image;
pub mod lattice;
pub mod mesh;
pub mod observation;
pub mod paths;
pub mod zestimate;

pub use catalog::{Catalog, ObjectShape, ObjectSpec, SharedCatalog, TypeIdx};
pub use error::{Result, SimError};
pub use heightmap::{GridSpec, Heightmap};
pub use observation::ObsLayout;
