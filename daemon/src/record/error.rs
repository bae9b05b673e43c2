//! The run log's errors: writing one ([`RecordError`]) and reading one back ([`LogError`]).

use crate::job::JobRecordError;
use std::path::PathBuf;

/// A run log that cannot be started or written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A model file the header digests cannot be read.
    #[error("{path}: {source}")]
    Model {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The configuration cannot be written into the header.
    #[error("configuration: {0}")]
    Config(#[from] toml::ser::Error),
    /// The folder cannot be created.
    #[error("run log folder {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A segment file cannot be created or written.
    #[error("run log {path}: {source}")]
    Segment {
        /// The segment file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The writer thread cannot be started.
    #[error("cannot start the run-log writer: {0}")]
    Thread(std::io::Error),
}

/// A segment file that cannot be read back: which file, and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct LogError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub problem: LogProblem,
}

/// What is wrong with a segment file. A torn or corrupt tail is not one of these: the records
/// before it are read, and the log says where it ends.
#[derive(Debug, thiserror::Error)]
pub enum LogProblem {
    /// The file cannot be read.
    #[error("{0}")]
    Io(std::io::Error),
    /// It does not start as a run log.
    #[error("not a HERB run log")]
    NotALog,
    /// A run log of another format version.
    #[error(
        "run log format {found}, this herbd reads format {reads} (replay it with the herbd \
         that wrote it)"
    )]
    Format {
        /// The file's format version.
        found: u32,
        /// The version this herbd reads ([`FORMAT`](super::FORMAT)).
        reads: u32,
    },
    /// No header record.
    #[error("no header")]
    NoHeader,
    /// A header record that does not decode.
    #[error("bad header")]
    Header,
    /// A snapshot record that does not decode.
    #[error("bad snapshot: {0}")]
    Snapshot(#[from] SnapshotError),
    /// A record of the planner's frames that does not decode.
    #[error("bad plan frame")]
    PlanFrame,
    /// A frame's cells that do not decode.
    #[error("bad frame")]
    Frame,
    /// A loop record that does not decode.
    #[error("malformed record of kind {0}")]
    Malformed(u8),
    /// A record of a kind this format does not have.
    #[error("unknown record kind {0}")]
    UnknownKind(u8),
}

/// Why a snapshot record does not decode.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// The job's record.
    #[error("the job's record: {0}")]
    Job(#[from] JobRecordError),
    /// The rest is too short or too long, or holds a code that names nothing.
    #[error("truncated, or an unknown code")]
    Malformed,
}
