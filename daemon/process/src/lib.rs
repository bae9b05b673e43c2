//! The plumbing every HERB process shares (herbd, the loopback, the Baxter and camera
//! adapters): configuration files ([`config_file`]: TOML, every value checked before anything
//! acts on it) and real-time timing ([`rt`]). Apart from the arm's kinematics and motion
//! (`herb-robot`), so that a process that needs no arm (the camera adapter) links neither.

#![warn(missing_docs)]

pub mod config_file;
pub mod rt;
