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
pub mod method;
pub mod onnx;
pub mod order;
pub mod policy;
pub mod sequence;

pub use candidate::CandidatePolicy;
pub use decider::{Decider, Decision, HeightmapView};
pub use error::{DecideError, Result};
pub use method::Method;
pub use onnx::OnnxPolicy;
pub use order::Order;
pub use policy::{Blbf, DecisionInput, PackitSo3, Policy};
pub use sequence::{SequenceModel, beam3};

/// Which placement policy to run: the BLBF heuristic or an ONNX network. Written as `blbf` or
/// the model's path (in herbd's configuration, on command lines).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum PolicySpec {
    /// The PackIt SO(2) heuristic ([`Blbf`]).
    Blbf,
    /// An ONNX network of either contract, by path.
    Onnx(std::path::PathBuf),
}

impl std::str::FromStr for PolicySpec {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "" => Err("policy: empty (give blbf or the path of an ONNX model)".into()),
            "blbf" => Ok(Self::Blbf),
            path => Ok(Self::Onnx(path.into())),
        }
    }
}

impl TryFrom<String> for PolicySpec {
    type Error = String;

    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl From<PolicySpec> for String {
    fn from(p: PolicySpec) -> String {
        p.to_string()
    }
}

impl std::fmt::Display for PolicySpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Blbf => f.write_str("blbf"),
            Self::Onnx(p) => write!(f, "{}", p.display()),
        }
    }
}

/// The placement policy `spec` names. An ONNX model is loaded as a [`CandidatePolicy`] when its
/// inputs are the candidate contract's and as an [`OnnxPolicy`] (the observation contract)
/// otherwise; either refuses a model that breaks its contract.
pub fn load_policy(spec: &PolicySpec, catalog: &herb_sim::Catalog) -> Result<Box<dyn Policy>> {
    let path = match spec {
        PolicySpec::Blbf => return Ok(Box::new(Blbf::new())),
        PolicySpec::Onnx(p) => p.as_path(),
    };
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
