//! HERB's decision core: in which order to pack (the human-like sequence planner, Beam-3 over
//! a Markov chain of object-type transitions) and where to put each object (placement
//! policies behind one trait). Used by `herbd`, by the evaluation (`herb-sim eval`) and by
//! training.
//!
//! The observation layout, the z estimate and the object catalog are `herb-core`'s (one
//! implementation each); this crate only decides. It links no physics engine: the search
//! (`herb-search`, a [`Policy`] of its own), the registry of every evaluated method
//! (`herb-methods`) and the evaluation (`herb-sim`) sit on top.

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
pub use error::{DecideError, ModelReadError, NameError, Result};
pub use onnx::OnnxPolicy;
pub use order::Order;
pub use policy::{Blbf, DecisionInput, PackitSo3, PlanarPose, Policy};
pub use sequence::{SequenceModel, beam3, beam3_last};

/// Which placement policy to run: the BLBF heuristic, one of the shipped policies or an ONNX
/// network. Written as `blbf`, a shipped policy's name (`cs06`, `cs09`) or the model's path
/// (in herbd's configuration, on command lines).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum PolicySpec {
    /// The PackIt SO(2) heuristic ([`Blbf`]).
    Blbf,
    /// A shipped policy by name: `policy-<name>.onnx` in the models folder
    /// ([`PolicySpec::resolved`]).
    Shipped(Shipped),
    /// An ONNX network of either contract, by path.
    Onnx(std::path::PathBuf),
}

/// The policies shipped in `models/`: the one-step students of the candidate contract in
/// HERB's order, trained with the CS0.6 and CS0.9 rewards (`models/README.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shipped {
    /// `models/policy-cs06.onnx` (reward CS0.6).
    Cs06,
    /// `models/policy-cs09.onnx` (reward CS0.9).
    Cs09,
}

impl Shipped {
    /// Every shipped policy.
    pub const ALL: [Shipped; 2] = [Self::Cs06, Self::Cs09];

    /// Its name in configurations and on command lines.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Cs06 => "cs06",
            Self::Cs09 => "cs09",
        }
    }

    /// Its file name in the models folder.
    pub fn file_name(&self) -> String {
        format!("policy-{}.onnx", self.name())
    }
}

impl PolicySpec {
    /// The models folder of the repository, relative to its root: where [`load_policy`] looks
    /// for a shipped policy that was not [`resolved`](PolicySpec::resolved) against another.
    pub const DEFAULT_MODELS_DIR: &'static str = "models";

    /// This spec with a shipped policy's name turned into its file in `models_dir`; the others
    /// unchanged.
    pub fn resolved(&self, models_dir: &std::path::Path) -> PolicySpec {
        match self {
            Self::Shipped(s) => Self::Onnx(models_dir.join(s.file_name())),
            other => other.clone(),
        }
    }
}

impl std::str::FromStr for PolicySpec {
    type Err = NameError;

    fn from_str(s: &str) -> std::result::Result<Self, NameError> {
        match s {
            "" => Err(NameError::EmptyPolicy),
            "blbf" => Ok(Self::Blbf),
            name if let Some(&s) = Shipped::ALL.iter().find(|s| s.name() == name) => {
                Ok(Self::Shipped(s))
            }
            path => Ok(Self::Onnx(path.into())),
        }
    }
}

impl TryFrom<String> for PolicySpec {
    type Error = NameError;

    fn try_from(s: String) -> std::result::Result<Self, NameError> {
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
            Self::Shipped(s) => f.write_str(s.name()),
            Self::Onnx(p) => write!(f, "{}", p.display()),
        }
    }
}

/// The placement policy `spec` names (a shipped policy from [`PolicySpec::DEFAULT_MODELS_DIR`]
/// unless resolved before). An ONNX model is loaded as a [`CandidatePolicy`] when its
/// inputs are the candidate contract's and as an [`OnnxPolicy`] (the observation contract)
/// otherwise; either refuses a model that breaks its contract.
pub fn load_policy(spec: &PolicySpec, catalog: &herb_core::Catalog) -> Result<Box<dyn Policy>> {
    let resolved = spec.resolved(std::path::Path::new(PolicySpec::DEFAULT_MODELS_DIR));
    let path = match &resolved {
        PolicySpec::Blbf => return Ok(Box::new(Blbf::new())),
        PolicySpec::Onnx(p) => p.as_path(),
        PolicySpec::Shipped(_) => unreachable!("resolved above"),
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
