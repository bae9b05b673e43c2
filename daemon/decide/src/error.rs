//! Errors of the decision core.

use std::path::PathBuf;

/// Result with [`DecideError`].
pub type Result<T, E = DecideError> = std::result::Result<T, E>;

/// What went wrong, naming the input at fault.
#[derive(Debug, thiserror::Error)]
pub enum DecideError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A sequence model that does not parse or does not fit the catalog.
    #[error("sequence model {origin}: {message}")]
    SequenceModel {
        /// Where it came from (a path or a description).
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A policy model that cannot be used, with the reason.
    #[error("policy model {path}: {message}")]
    Model {
        /// The model file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An empty object list was given to the planner.
    #[error("no objects to order")]
    EmptyObjectList,
    /// An object type index outside the catalog.
    #[error("unknown object type index {0}")]
    UnknownType(u16),
    /// A decision refused, with the reason (bad input or a bad action).
    #[error("{policy} rejected the decision: {reason}")]
    Rejected {
        /// The policy.
        policy: String,
        /// Why.
        reason: String,
    },
    /// The placement lattice holds no feasible placement for the object: nothing fits
    /// between the walls below the height limit.
    #[error("no feasible placement")]
    NoFeasiblePlacement,
    /// A method that cannot be built as asked (a missing policy, a replay asked to decide).
    #[error("{method}: {message}")]
    Method {
        /// The method's name.
        method: &'static str,
        /// What is wrong.
        message: String,
    },
    /// An error from the packing world.
    #[error(transparent)]
    Sim(#[from] herb_core::SimError),
}

/// A name that names nothing: an unknown method or order, an empty policy.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// A name that is none of the known ones.
    #[error("{what} {name:?}: expected one of {}", .expected.join(", "))]
    Unknown {
        /// What was named (`method`, `order`).
        what: &'static str,
        /// The name given.
        name: String,
        /// The known names.
        expected: Vec<&'static str>,
    },
    /// An empty policy.
    #[error("policy: empty (give blbf or the path of an ONNX model)")]
    EmptyPolicy,
}

/// Why the inputs of an ONNX file could not be listed ([`crate::candidate::input_names`]).
#[derive(Debug, thiserror::Error)]
pub enum ModelReadError {
    /// tract's ONNX parser panicked on the file.
    #[error("the ONNX parser failed on this file")]
    ParserFailed,
    /// The file is not an ONNX model tract can read.
    #[error("not a readable ONNX model: {0:#}")]
    Unreadable(tract_onnx::prelude::TractError),
    /// The model's inputs could not be listed.
    #[error("{0}")]
    Inputs(tract_onnx::prelude::TractError),
}
