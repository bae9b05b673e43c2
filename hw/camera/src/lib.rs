//! herb-camera: the adapter from a depth camera on ROS 1 to herbd's heightmap service.
//!
//! - [`project`]: depth image to heightmap (deprojection with the intrinsics, the calibrated
//!   camera pose in the box frame, the interior, the highest point per cell, the floor
//!   threshold, conservative filling of unseen cells, an optional median over frames).
//! - [`calibrate`]: the camera's pose fitted from a depth image of the empty box.
//! - [`config`]: the adapter's file.

#![warn(missing_docs)]

pub mod calibrate;
pub mod config;
pub mod project;
