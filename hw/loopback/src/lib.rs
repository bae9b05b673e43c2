//! `herb-loopback`'s library part: its view of the shared configuration file (the binary is
//! `src/main.rs`).

#![warn(missing_docs)]

pub mod config;
