#!/usr/bin/python3
"""A fake Baxter for herb-baxter's tests: a rospy node speaking the Baxter SDK 1.2 topics.

A test fixture, not a robot model: the left arm follows position commands at most at the given
joint speeds (a command older than the latched joint_command_timeout is not followed: the arm
holds), joint states of the whole robot are published at 100 Hz with the joint names in a new
random order each time, /robot/state reports enabled unless SIGUSR1 toggled it (or --start-disabled and no enable request
came on /robot/set_super_enable yet), and the
electric gripper calibrates and moves on command, echoing the command's sender and sequence.
Closing grips (an object is always there, unless --miss-grasps), opening releases.

The arm can move only while enabled and not e-stopped. SIGUSR2 toggles an e-stop: pressed, the
robot is stopped and disabled (/robot/state: stopped, estop_button and estop_source 1); released,
it is enabled again (the operator released the button and re-enabled it). While the arm cannot
move it sags: left_s1 drifts at +--sag rad/s and left_e1 at half that (--sag-joints chooses),
within the limits --lower/--upper, which are the robot's own (and
their reported velocities say so). Commands received while it cannot move are counted and not
followed, and when it can move again (SIGUSR1, the e-stop's release, an enable request on
/robot/set_super_enable) every command received before is forgotten: the arm holds until a new
one (an enable request while e-stopped is refused, as by the real robot). Every command followed
is measured against the arm, by its largest joint offset from the current position: the largest
offset is reported, those over --far counted, and the offset of the first command after each
such transition, of the first after a pause of over 0.5 s in the commands (herbd halted, e.g.
on a master loss), and of the very first, listed.

The gripper's calibration takes --calibrate-s seconds with no further calibrate command: one
received while calibrating starts the wait again (a calibrate command to a calibrated gripper
is acknowledged and changes nothing). Each command's sender and sequence are echoed at once.
With --miss-grasps N, the first N grasps (a "go" closing the gripper) close on nothing: the
position goes to 0 with gripping 0 (and missed 1) until the next opening.

With --corrupt-every N, every Nth joint state is made bad (a NaN angle, a misspelt joint name
or a short velocity array, in turn). Every joint command is checked: its names must be the left arm's seven joints and every angle
within the given limits. On SIGTERM the node writes a JSON report (--report) and exits 0.

    fake_baxter.py --report R.json --start q0,..,q6 --lower ... --upper ... --vmax ...
"""

import argparse
import collections
import json
import math
import os
import random
import signal
import sys
import threading
import time

import rospy
from baxter_core_msgs.msg import AssemblyState, EndEffectorCommand, EndEffectorState, JointCommand
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64

LEFT = ["left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2"]
OTHERS = ["head_pan", "right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1",
          "right_w2", "torso_t0"]
GRIPPER_ID = 65664
# The joints that sag while the arm cannot move (indices in LEFT) and their share of --sag.
SAG = {1: 1.0, 3: 0.5}


def floats(text, n=7):
    v = [float(x) for x in text.split(",")]
    if len(v) != n:
        raise SystemExit(f"expected {n} comma-separated numbers, got {text!r}")
    return v


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--report", required=True)
    ap.add_argument("--start", required=True)
    ap.add_argument("--lower", required=True)
    ap.add_argument("--upper", required=True)
    ap.add_argument("--vmax", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--start-disabled", action="store_true",
                    help="start disabled: enabled by /robot/set_super_enable (or SIGUSR1)")
    ap.add_argument("--corrupt-every", type=int, default=0,
                    help="make every Nth joint state bad, in turn: a NaN angle, a misspelt "
                         "joint name, a short velocity array (0: never)")
    ap.add_argument("--sag", type=float, default=0.05,
                    help="while disabled or e-stopped the arm sags: left_s1 at +SAG rad/s, "
                         "left_e1 at +SAG/2 rad/s, within the limits (default 0.05)")
    ap.add_argument("--sag-joints", default="1,3",
                    help="which joints sag (indices in s0..w2, of 1 (s1) and 3 (e1); default 1,3)")
    ap.add_argument("--far", type=float, default=0.2,
                    help="a command whose largest joint offset from the arm exceeds FAR rad is "
                         "counted in commands_far (default 0.2)")
    ap.add_argument("--calibrate-s", type=float, default=0.5,
                    help="the gripper is calibrated CALIBRATE_S s after the last calibrate "
                         "command; one received while calibrating restarts the wait (default 0.5)")
    ap.add_argument("--miss-grasps", type=int, default=0,
                    help="the first N closings of the calibrated gripper close on nothing: "
                         "position 0, gripping 0 (default 0)")
    a = ap.parse_args()
    q = floats(a.start)
    lower, upper, vmax = floats(a.lower), floats(a.upper), floats(a.vmax)
    sagging = {int(j): SAG[int(j)] for j in a.sag_joints.split(",") if j.strip()}
    rng = random.Random(a.seed)
    lock = threading.Lock()
    st = {
        "enabled": not a.start_disabled, "stopped": False, "enable_requests": 0,
        "enable_requests_after_toggle": 0, "target": list(q), "target_at": 0.0, "timeout": 0.2,
        "commands": 0, "out_of_limits": 0, "bad_names": 0, "modes": [],
        "timeouts_latched": [], "speed_ratios": [],
        "grip": {"calibrated": 0, "position": 100.0, "target": 100.0, "gripping": 0,
                 "sender": "", "sequence": 0, "command": "", "calibrating_since": None,
                 "miss": False},
        "grip_events": [], "calibrations": 0, "enable_toggles": 0, "corrupted": 0, "published": 0,
        "estop_toggles": 0, "commands_while_disabled": 0, "max_command_offset": 0.0,
        "first_command_offsets": [], "commands_far": 0, "calibrate_commands": 0,
        "missed_grasps": 0,
        # The next command followed is the first since the arm could move again (or ever).
        "first_pending": True,
    }

    def can_move():
        return st["enabled"] and not st["stopped"]

    def changed(could):
        """After a change of enabled/stopped (lock held): when the arm can move again, every
        command received before is forgotten."""
        if not could and can_move():
            st["target_at"] = 0.0
            st["first_pending"] = True

    def on_command(m):
        with lock:
            st["commands"] += 1
            able = can_move()
            if not able:
                st["commands_while_disabled"] += 1
            if sorted(m.names) != sorted(LEFT) or len(m.names) != len(m.command):
                st["bad_names"] += 1
                return
            if m.mode not in st["modes"]:
                st["modes"].append(m.mode)
            byname = dict(zip(m.names, m.command))
            cmd = [byname[j] for j in LEFT]
            if any(not (lower[i] <= c <= upper[i]) or not math.isfinite(c) for i, c in enumerate(cmd)):
                st["out_of_limits"] += 1
                return
            if not able:
                return
            offset = max(abs(cmd[i] - q[i]) for i in range(7))
            st["max_command_offset"] = max(st["max_command_offset"], offset)
            if offset > a.far:
                st["commands_far"] += 1
            now = time.monotonic()
            # A command after a pause of over 0.5 s (herbd halted: a master loss, a fault) is a
            # first command too.
            if st["first_pending"] or now - st["target_at"] > 0.5:
                st["first_command_offsets"].append(round(offset, 6))
                st["first_pending"] = False
            st["target"], st["target_at"] = cmd, now

    def on_timeout(m):
        with lock:
            st["timeout"] = m.data
            st["timeouts_latched"].append(m.data)

    def on_ratio(m):
        with lock:
            st["speed_ratios"].append(m.data)

    def on_gripper(m):
        with lock:
            g = st["grip"]
            if m.id != GRIPPER_ID:
                return
            g["sender"], g["sequence"], g["command"] = m.sender, m.sequence, m.command
            if m.command == "calibrate":
                st["calibrate_commands"] += 1
                if not g["calibrated"]:
                    g["calibrating_since"] = time.monotonic()
            elif m.command == "go" and g["calibrated"]:
                target = float(json.loads(m.args)["position"])
                if target != g["target"]:
                    closing = target < 50
                    st["grip_events"].append("close" if closing else "open")
                    g["miss"] = closing and st["missed_grasps"] < a.miss_grasps
                    if g["miss"]:
                        st["missed_grasps"] += 1
                g["target"] = target

    def on_enable(m):
        with lock:
            st["enable_requests"] += 1
            if st["enable_toggles"]:
                st["enable_requests_after_toggle"] += 1
            if m.data and not st["stopped"]:
                could = can_move()
                st["enabled"] = True
                changed(could)

    # The signals are only queued by their handlers (which run in the main thread, maybe while
    # it holds the lock) and applied by the loop.
    signals = collections.deque()

    def toggle_enabled():
        could = can_move()
        st["enabled"] = not st["enabled"]
        st["enable_toggles"] += 1
        changed(could)

    def toggle_estop():
        could = can_move()
        st["estop_toggles"] += 1
        if st["stopped"]:
            st["stopped"], st["enabled"] = False, True
        else:
            st["stopped"], st["enabled"] = True, False
        changed(could)

    stop = threading.Event()
    signal.signal(signal.SIGUSR1, lambda *_: signals.append(toggle_enabled))
    signal.signal(signal.SIGUSR2, lambda *_: signals.append(toggle_estop))
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    rospy.init_node("fake_baxter", anonymous=False, disable_signals=True)
    js_pub = rospy.Publisher("/robot/joint_states", JointState, queue_size=10)
    as_pub = rospy.Publisher("/robot/state", AssemblyState, queue_size=10)
    gs_pub = rospy.Publisher("/robot/end_effector/left_gripper/state", EndEffectorState, queue_size=10)
    rospy.Subscriber("/robot/limb/left/joint_command", JointCommand, on_command)
    rospy.Subscriber("/robot/limb/left/joint_command_timeout", Float64, on_timeout)
    rospy.Subscriber("/robot/limb/left/set_speed_ratio", Float64, on_ratio)
    rospy.Subscriber("/robot/end_effector/left_gripper/command", EndEffectorCommand, on_gripper)
    rospy.Subscriber("/robot/set_super_enable", Bool, on_enable)
    dt = 0.01
    seq = 0
    others = {n: 0.0 for n in OTHERS}
    next_t = time.monotonic()
    # Replaced by a node of the same name, rospy shuts down: stop too (and report).
    while not stop.is_set() and not rospy.is_shutdown():
        next_t += dt
        with lock:
            while signals:
                signals.popleft()()
            now = time.monotonic()
            qd = [0.0] * 7
            fresh = now - st["target_at"] <= st["timeout"]
            if can_move():
                if fresh:
                    for i in range(7):
                        step = max(-vmax[i] * dt, min(vmax[i] * dt, st["target"][i] - q[i]))
                        q[i] += step
                        qd[i] = step / dt
            else:
                for i, share in sagging.items():
                    new = max(lower[i], min(upper[i], q[i] + a.sag * share * dt))
                    qd[i] = (new - q[i]) / dt
                    q[i] = new
            g = st["grip"]
            since = g["calibrating_since"]
            if since is not None and now - since >= a.calibrate_s:
                g["calibrating_since"] = None
                g["calibrated"] = 1
                st["calibrations"] += 1
            if g["target"] < 50 and g["miss"]:
                g["position"], g["gripping"] = 0.0, 0
            elif g["target"] < 50:
                g["position"], g["gripping"] = 40.0, 1
            else:
                g["position"], g["gripping"] = g["target"], 0
            names = LEFT + OTHERS
            pos = q + [others[n] for n in OTHERS]
            vel = qd + [0.0] * len(OTHERS)
            order = list(range(len(names)))
            rng.shuffle(order)
            seq += 1
            js = JointState()
            js.header.seq = seq
            js.header.stamp = rospy.Time.now()
            js.name = [names[i] for i in order]
            js.position = [pos[i] for i in order]
            js.velocity = [vel[i] for i in order]
            js.effort = [0.0] * len(order)
            if a.corrupt_every and seq % a.corrupt_every == 0:
                kind = (seq // a.corrupt_every) % 3
                k = js.name.index("left_e0")
                if kind == 0:
                    js.position[k] = float("nan")
                elif kind == 1:
                    js.name[k] = "left_eO"
                else:
                    js.velocity = js.velocity[:3]
                st["corrupted"] += 1
            stopped = st["stopped"]
            asm = AssemblyState(ready=can_move(), enabled=st["enabled"], stopped=stopped,
                                error=False,
                                estop_button=(AssemblyState.ESTOP_BUTTON_PRESSED if stopped
                                              else AssemblyState.ESTOP_BUTTON_UNPRESSED),
                                estop_source=(AssemblyState.ESTOP_SOURCE_USER if stopped
                                              else AssemblyState.ESTOP_SOURCE_NONE))
            es = EndEffectorState(id=GRIPPER_ID, enabled=1, calibrated=g["calibrated"], ready=1,
                                  moving=0, gripping=g["gripping"], missed=int(g["miss"]),
                                  error=0, reverse=0,
                                  position=g["position"], force=0.0, state="{}",
                                  command=g["command"], command_sender=g["sender"],
                                  command_sequence=g["sequence"])
            es.timestamp = rospy.Time.now()
        js_pub.publish(js)
        st["published"] += 1
        as_pub.publish(asm)
        gs_pub.publish(es)
        time.sleep(max(0.0, next_t - time.monotonic()))
    with lock:
        report = {k: st[k] for k in ("commands", "out_of_limits", "bad_names", "modes",
                                     "timeouts_latched", "speed_ratios", "grip_events",
                                     "calibrations", "enable_toggles", "corrupted", "published",
                                     "enable_requests", "enable_requests_after_toggle",
                                     "estop_toggles", "commands_while_disabled",
                                     "max_command_offset", "first_command_offsets",
                                     "commands_far", "calibrate_commands", "missed_grasps")}
    tmp = a.report + ".tmp"
    with open(tmp, "w") as f:
        json.dump(report, f)
    os.replace(tmp, a.report)
    rospy.signal_shutdown("done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
