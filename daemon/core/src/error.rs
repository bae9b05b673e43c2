//! The one error type of the packing world.

use std::path::PathBuf;

/// Everything that can go wrong in the packing world. Every variant names what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The object catalog is malformed or inconsistent.
    #[error("object catalog {origin}: {message}")]
    Catalog {
        /// Where the catalog came from (path or "built-in").
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A mesh file does not parse or gives no usable hull.
    #[error("mesh {path}: {message}")]
    Mesh {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An object id that the catalog does not know.
    #[error("unknown object id {0:?} (not in the catalog)")]
    UnknownObject(String),
    /// An episode with no objects.
    #[error("empty object sequence: an episode needs at least one object")]
    EmptySequence,
    /// An action with NaN or infinite components.
    #[error("invalid action {0:?}: every component must be finite")]
    InvalidAction([f32; 3]),
    /// A placement request with a non-finite pose.
    #[error("invalid placement (x={x}, y={y}, theta={theta}): must be finite")]
    InvalidPlacement {
        /// x (m).
        x: f32,
        /// y (m).
        y: f32,
        /// theta (rad).
        theta: f32,
    },
    /// `step` was called on an episode that has ended, or before `reset`.
    #[error("episode is not running (call reset first; it ended after {placed} placements)")]
    EpisodeOver {
        /// Placements made in the ended episode.
        placed: usize,
    },
    /// A BoxED session file is missing or malformed.
    #[error("BoxED session {session}: {message}")]
    Session {
        /// Session folder name.
        session: String,
        /// What is wrong.
        message: String,
    },
    /// A heightmap whose size or values do not fit.
    #[error("heightmap: {0}")]
    Heightmap(String),
    /// Invalid configuration value.
    #[error("config: {0}")]
    Config(String),
    /// Writing an output file failed.
    #[error("cannot write {path}: {message}")]
    Output {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Result alias of the packing world.
pub type Result<T> = std::result::Result<T, SimError>;
