//! HERB's decision core: in which order to pack (the human-like sequence planner, Beam-3 over
//! a Markov chain of object-type transitions) and where to put each object (placement
//! policies behind one trait). Used by `herbd`, by the evaluation (`herb-sim eval`) and by
//! training.
//!
//! The observation layout, the z estimate and the object catalog are `herb-sim`'s (one
//! implementation each); this crate only decides.

#![warn(missing_docs)]

pub mod candidate;
pub mod decider;
pub mod error;
pub mod onnx;
pub mod order;
pub mod policy;
pub mod sequence;

pub use candidate::CandidatePolicy;
pub use decider::{Decider, Decision, HeightmapView};
pub use error::{DecideError, Result};
pub use onnx::OnnxPolicy;
pub use order::Order;
pub use policy::{Blbf, DecisionInput, Policy};
pub use sequence::{SequenceModel, beam3};

/// The placement policy named by `spec`: `blbf`, or the path of an ONNX model, loaded as a
/// [`CandidatePolicy`] when its inputs are the candidate contract's and as an [`OnnxPolicy`]
/// (the observation contract) otherwise; either refuses a model that breaks its contract.
pub fn load_policy(spec: &str, catalog: &herb_sim::Catalog) -> Result<Box<dyn Policy>> {
    if spec == "blbf" {
        return Ok(Box::new(Blbf::new()));
    }
    let path = std::path::Path::new(spec);
    let bytes = std::fs::read(path).map_err(|source| DecideError::Io {
        path: path.to_owned(),
        source,
    })?;
    match candidate::input_names(&bytes) {
        Ok(names) if names == candidate::INPUT_NAMES => Ok(Box::new(CandidatePolicy::from_bytes(
            path, &bytes, catalog,
        )?)),
        _ => Ok(Box::new(OnnxPolicy::load(path)?)),
    }
}
