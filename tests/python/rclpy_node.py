"""rclpy controllers for twin's live tests (real ROS 2: the PyPI Kilted wheels, Fast DDS).

Modes (each runs until SIGINT/SIGTERM or --timeout, then writes --out as JSON):
  subscription  answers each /joint_states (no timer): every joint held at the first
                /joint_states pose, the left elbow at f(stamp) = -0.5 + 0.2 sin(pi stamp), with
                `stamp` the answered message's header stamp (s): the test reads which state each
                command answered from the command itself.
  by-name       a use_sim_time timer at 100 Hz publishing sensor_msgs/JointState on
                /<robot>/joint_command with the left elbow only, by name (position -0.6 rad,
                velocity 0): the topic_based_ros2_control convention.
"""
import argparse
import json
import math
import signal
import sys
import time

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

ELBOW = "left_elbow_joint"


def elbow_target(stamp_secs):
    return -0.5 + 0.2 * math.sin(math.pi * stamp_secs)


class Subscription(Node):
    def __init__(self, robot):
        super().__init__("subscription_controller")
        self.hold = None
        self.sent = 0
        self.pub = self.create_publisher(Float64MultiArray, f"/{robot}/joint_commands", 10)
        self.create_subscription(JointState, "/joint_states", self.on_joints, 10)

    def on_joints(self, msg):
        if self.hold is None:
            self.names = list(msg.name)
            self.hold = dict(zip(msg.name, msg.position))
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        target = dict(self.hold)
        target[ELBOW] = elbow_target(stamp)
        self.pub.publish(Float64MultiArray(data=[target[j] for j in self.names]))
        self.sent += 1


class ByName(Node):
    def __init__(self, robot):
        super().__init__("by_name_commander")
        self.sent = 0
        self.pub = self.create_publisher(JointState, f"/{robot}/joint_command", 10)
        self.create_timer(0.01, self.tick)

    def tick(self):
        msg = JointState(name=[ELBOW], position=[-0.6], velocity=[0.0])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub.publish(msg)
        self.sent += 1


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--mode", choices=["subscription", "by-name"], required=True)
    p.add_argument("--robot", default="humanoid")
    p.add_argument("--out", required=True)
    p.add_argument("--timeout", type=float, default=120.0, help="wall-clock limit, s")
    a, ros_args = p.parse_known_args()
    rclpy.init(args=[sys.argv[0]] + ros_args)
    node = Subscription(a.robot) if a.mode == "subscription" else ByName(a.robot)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    deadline = time.monotonic() + a.timeout
    while not stop and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    with open(a.out, "w") as f:
        json.dump({"mode": a.mode, "sent": node.sent, "timed_out": not stop}, f)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
