//! The vendored messages hash to the MD5 sums the robot's nodes use: a publisher or subscriber
//! with another sum is refused by every ROS 1 peer, so these are the wire contract.

use herb_ros1::{RosMessageType, baxter_core_msgs, sensor_msgs, std_msgs};

fn md5<T: RosMessageType>() -> (&'static str, &'static str) {
    (T::DESCRIPTION.ros_type_name, T::DESCRIPTION.md5sum)
}

#[test]
fn baxter_messages_hash_as_the_robot_publishes_them() {
    // Baxter robot software 1.2 (RethinkRobotics/baxter_common 6c4b0f3).
    assert_eq!(
        [
            md5::<baxter_core_msgs::JointCommand>(),
            md5::<baxter_core_msgs::AssemblyState>(),
            md5::<baxter_core_msgs::EndEffectorCommand>(),
            md5::<baxter_core_msgs::EndEffectorState>(),
        ],
        [
            (
                "baxter_core_msgs/JointCommand",
                "19bfec8434dd568ab3c633d187c36f2e"
            ),
            (
                "baxter_core_msgs/AssemblyState",
                "356d9dd237ce73b2667da9235f541933"
            ),
            (
                "baxter_core_msgs/EndEffectorCommand",
                "c003234e90416f2ca02ac7837c42cbb7"
            ),
            (
                "baxter_core_msgs/EndEffectorState",
                "ade777f069d738595bc19e246b8ec7a0"
            ),
        ]
    );
}

#[test]
fn common_messages_hash_as_ros_noetic_defines_them() {
    // The sums genmsg computes for Debian's ros-std-msgs 0.5.13 and ros-sensor-msgs 1.13.1
    // (the same as the installed rospy modules' `_md5sum`).
    assert_eq!(
        [
            md5::<sensor_msgs::JointState>(),
            md5::<sensor_msgs::Image>(),
            md5::<sensor_msgs::CameraInfo>(),
            md5::<std_msgs::Bool>(),
            md5::<std_msgs::Header>(),
        ],
        [
            ("sensor_msgs/JointState", "3066dcd76a6cfaef579bd0f34173e9fd"),
            ("sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743"),
            ("sensor_msgs/CameraInfo", "c9a58c1b0b154e0e6da7578cb991d214"),
            ("std_msgs/Bool", "8b94c1b53db61fb6aed406028ad6332a"),
            ("std_msgs/Header", "2176decaecbce78abc3b96ef049fabed"),
        ]
    );
}
