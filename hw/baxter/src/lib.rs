//! herb-baxter: the adapter between herbd (iceoryx2) and a Rethink Baxter's left arm and
//! electric gripper (ROS 1, Baxter SDK 1.2 topics), through roslibrust's native ROS 1 client.
//!
//! - **iceoryx2 side** (`herb_adapter::ArmPorts`, the loopback's ports and validation): joint
//!   and gripper commands from herbd in, joint and gripper states out.
//! - **ROS side** ([`ros`]): sends the latest fresh herbd command at `arm.command_rate_hz`
//!   (never extrapolated: when herbd goes quiet nothing is sent and the robot holds after the
//!   latched `command_timeout_s`); maps `/robot/joint_states` by name and stamps each on
//!   receipt with the monotonic clock; withholds joint state while the robot is disabled,
//!   stopped or in error, or the master is lost (herbd then faults, brakes and reports);
//!   calibrates the gripper once and resends each gripper command until acknowledged; enables
//!   the robot only with `--enable`.

#![warn(missing_docs)]

pub mod bridge;
pub mod config;
pub mod ros;
