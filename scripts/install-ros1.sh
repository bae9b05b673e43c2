#!/usr/bin/env bash
# Installs Debian's ROS 1 pieces that herb-baxter's tests run against (a real rosmaster, rospy
# peers, genpy to generate the Baxter messages' Python modules), unless already present.
# Nothing of it is needed to build or run the adapters themselves.
set -euo pipefail
if command -v rosmaster >/dev/null 2>&1 && /usr/bin/python3 -c 'import rospy, genpy, genmsg, numpy, std_msgs.msg, sensor_msgs.msg' 2>/dev/null; then
  exit 0
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO=sudo
$SUDO apt-get update >/dev/null
$SUDO apt-get install -y --no-install-recommends python3-rospy python3-rosmaster python3-std-msgs \
  python3-sensor-msgs python3-genpy python3-genmsg python3-numpy ros-std-msgs ros-sensor-msgs >/dev/null
