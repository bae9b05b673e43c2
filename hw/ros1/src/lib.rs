//! The ROS 1 side shared by HERB's ROS adapters (`herb-baxter`, `herb-camera`).
//!
//! - **Messages**: the vendored definitions under `msgs/` (Baxter's `baxter_core_msgs` exactly
//!   as Rethink Robotics published them, and the `std_msgs` and `sensor_msgs` types used),
//!   compiled to Rust types at build time by roslibrust's generator: no ROS installation is
//!   needed to build or run. Each type carries its ROS MD5 sum (`RosMessageType::DESCRIPTION.md5sum`);
//!   a test checks them against the robot's.

#![warn(missing_docs)]

/// The generated message types, one module per package (`baxter_core_msgs`, `std_msgs`,
/// `sensor_msgs`), re-exported at the crate root.
#[allow(missing_docs, unused_imports, clippy::all)]
mod generated {
    include!(concat!(env!("OUT_DIR"), "/messages.rs"));
}
pub use generated::*;
pub use roslibrust::RosMessageType;

pub mod node;
pub mod time;
