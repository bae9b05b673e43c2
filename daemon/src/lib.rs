//! HERB's decision core: in which order to pack (the human-like sequence planner, Beam-3 over
//! a Markov chain of object-type transitions) and where to put each object (placement
//! policies behind one trait). Used by `herbd`, by the evaluation (`herb-sim eval`) and by
//! training.
//!
//! The observation layout, the z estimate and the object catalog are `herb-sim`'s (one
//! implementation each); this crate only decides.

#![warn(missing_docs)]

pub mod cell;
pub mod config;
pub mod controller;
pub mod error;
pub mod evaluate;
pub mod kinematics;
pub mod motion;
pub mod onnx;
pub mod planner;
pub mod policy;
pub mod sequence;

pub use error::{DecideError, Result};
pub use onnx::OnnxPolicy;
pub use policy::{Blbf, DecisionInput, Policy};
pub use sequence::{SequenceModel, beam3};
