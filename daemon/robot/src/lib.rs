//! The robot side of HERB: the Baxter left arm's kinematics, the cell's geometry (where the box
//! and the pick station are, the waypoints of one pick-and-place) and time-optimal joint motion
//! (Ruckig). Used by `herbd` and by the hardware adapters (the loopback today); it knows nothing
//! of placement policies, and of IPC only the joint count the wire carries.

#![warn(missing_docs)]

/// Cell calibration by touch: the box pose for `[cell]` from touched corners.
pub mod calibrate;
pub mod cell;
pub mod kinematics;
pub mod model;
pub mod motion;
