//! Run logs: everything that reaches the job state machine and the decision core, written off
//! the loop, so that `herbd replay` can re-run a run bit for bit and `herbd explain` can
//! say why an object went where it did.
//!
//! # What is recorded
//!
//! - A header: format, herbd's version, the CPU, the effective configuration (TOML) and the
//!   digests of the catalog, the policy and the sequence model.
//! - Per loop cycle, in the order the loop fed them to the machine ([`crate::job`]): the
//!   cycle's time, every joint and gripper state (raw bytes, publisher, receive time), every
//!   heightmap frame's header and grid, every planner response (its digest and measured
//!   decision latency), every job and cancel request, the stop flag, and a digest of the
//!   machine's outputs in that cycle.
//! - From the planner thread: for every request, the heightmap it was served with (the cells
//!   of each distinct frame once per segment).
//!
//! # Format
//!
//! A segment file starts with [`MAGIC`] and the format version, then records of
//! `kind: u8 | len: u32 | payload | crc32: u32` (little-endian; the CRC covers kind, length and
//! payload), so a tail torn by a crash is found and reported. Segments rotate at
//! `segment_mb`, only between jobs: a later segment starts with the machine's
//! [`JobSnapshot`](crate::job::JobSnapshot) and replays on its own; the oldest are deleted
//! beyond `keep_mb`.
//!
//! # Off the loop
//!
//! The loop pushes fixed-size [`LoopRec`]s into a preallocated wait-free ring (no allocation,
//! no I/O; a full ring drops records, counted and marked by a [`LoopRec::Gap`]); a writer
//! thread encodes, writes, flushes every 100 ms and rotates.
//!
//! # Modules
//!
//! The data model and its byte layout are in `format`, the errors in `error`, the run's identity (CPU, digests, the
//! header of a configuration) in `identity`, the loop's end, the writer thread and the
//! segment files in `writer`, and reading a segment back in `reader`; everything public is
//! re-exported here.

mod error;
mod format;
mod identity;
mod reader;
mod writer;

pub use error::{LogError, LogProblem, RecordError, SnapshotError};
pub use format::{
    DecisionRec, Entry, FORMAT, FRAME_META, LoopRec, MAGIC, OutDigest, RespRec, RunHeader, Sent,
};
pub use identity::{catalog_digest, cpu_identity, header_for};
pub use reader::Log;
pub use writer::{RecordOptions, Recorder, Recording, start};

#[cfg(test)]
mod tests;
