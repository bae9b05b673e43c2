//! herb-camera: the adapter from a depth camera on ROS 1 to herbd's heightmap service.
//!
//! - [`project`]: depth image to heightmap (deprojection with the intrinsics, the calibrated
//!   camera pose in the box frame, the interior, the highest point per cell, the floor
//!   threshold, conservative filling of unseen cells, an optional median over frames).
//! - [`config`]: the adapter's file.

#![warn(missing_docs)]

pub mod config;
pub mod project;
