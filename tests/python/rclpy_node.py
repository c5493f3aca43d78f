"""rclpy controllers for twin's live tests (real ROS 2: the PyPI Kilted wheels, Fast DDS).

Modes (each runs until SIGINT/SIGTERM or --timeout, then writes --out as JSON):
  subscription  answers each /joint_states (no timer): every joint held at the first
                /joint_states pose, the left elbow at f(stamp) = -0.5 + 0.2 sin(pi stamp), with
                `stamp` the answered message's header stamp (s): the test reads which state each
                command answered from the command itself.
  by-name       a use_sim_time timer at 100 Hz publishing sensor_msgs/JointState on
                /<robot>/joint_command with the left elbow only, by name (position -0.6 rad,
                velocity 0): the topic_based_ros2_control convention.
  services      a Gazebo-Classic-style client of twin's std_srvs/srv/Empty services, against
                `twin sim --ros` in real time: moves the left elbow (by name) to -0.6 rad, then
                /pause_physics (records /clock over 1 s wall), /unpause_physics (over 0.5 s),
                /reset_simulation (the elbow back at its first /joint_states position), moves it
                again and /reset_world; writes what it saw. Exits by itself when done.
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

try:  # the services mode only
    from std_srvs.srv import Empty
except ImportError:
    Empty = None

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


class Services(Node):
    """Calls twin's Gazebo-style services in turn (see the module docs)."""

    def __init__(self, robot):
        super().__init__("gazebo_services_client")
        self.sent = 0
        self.clock_secs = None  # the latest /clock
        self.clocks = 0  # /clock messages received
        self.elbow = None  # the latest elbow position
        self.elbow_start = None
        self.commanding = False
        from rosgraph_msgs.msg import Clock

        self.create_subscription(Clock, "/clock", self.on_clock, 10)
        self.create_subscription(JointState, "/joint_states", self.on_joints, 10)
        self.pub = self.create_publisher(JointState, f"/{robot}/joint_command", 10)
        self.clients_ = {n: self.create_client(Empty, n) for n in
                         ["/pause_physics", "/unpause_physics", "/reset_simulation", "/reset_world"]}
        self.create_timer(0.02, self.command)  # wall time: 50 Hz while commanding

    def on_clock(self, msg):
        self.clock_secs = msg.clock.sec + msg.clock.nanosec * 1e-9
        self.clocks += 1

    def on_joints(self, msg):
        e = list(msg.name).index(ELBOW)
        self.elbow = msg.position[e]
        if self.elbow_start is None:
            self.elbow_start = self.elbow

    def command(self):
        if self.commanding:
            self.pub.publish(JointState(name=[ELBOW], position=[-0.6], velocity=[0.0]))
            self.sent += 1

    def spin_for(self, secs):
        end = time.monotonic() + secs
        while time.monotonic() < end:
            rclpy.spin_once(self, timeout_sec=0.01)

    def spin_until(self, what, cond, secs):
        end = time.monotonic() + secs
        while not cond():
            if time.monotonic() > end:
                raise TimeoutError(f"waited {secs} s for {what}")
            rclpy.spin_once(self, timeout_sec=0.01)

    def call(self, name, secs=10.0):
        future = self.clients_[name].call_async(Empty.Request())
        self.spin_until(f"the reply of {name}", future.done, secs)
        return future.result()

    def run(self):
        out = {}
        for name, c in self.clients_.items():
            if not c.wait_for_service(timeout_sec=30.0):
                raise TimeoutError(f"waited 30 s for the service {name}")
        self.spin_until("/joint_states and /clock", lambda: self.elbow_start is not None and self.clock_secs, 30.0)
        out["elbow_start"] = self.elbow_start
        self.commanding = True
        self.spin_until("the elbow at -0.6 rad", lambda: abs(self.elbow + 0.6) < 0.02, 20.0)
        self.call("/pause_physics")
        self.spin_for(0.2)  # what was in flight
        paused_at, clocks = self.clock_secs, self.clocks
        self.spin_for(1.0)
        out["paused"] = {"clock_before": paused_at, "clock_after": self.clock_secs, "clocks": self.clocks - clocks}
        self.call("/unpause_physics")
        before = self.clock_secs
        self.spin_for(0.5)
        out["unpaused"] = {"clock_before": before, "clock_after": self.clock_secs}
        for name in ["/reset_simulation", "/reset_world"]:
            self.commanding = True
            self.spin_until("the elbow at -0.6 rad", lambda: abs(self.elbow + 0.6) < 0.02, 20.0)
            self.commanding = False
            self.spin_for(0.1)  # the last command in flight
            before = (self.clock_secs, self.elbow)
            self.call(name)
            self.spin_for(0.5)
            out[name] = {"clock_before": before[0], "elbow_before": before[1],
                         "clock_after": self.clock_secs, "elbow_after": self.elbow}
        return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--mode", choices=["subscription", "by-name", "services"], required=True)
    p.add_argument("--robot", default="humanoid")
    p.add_argument("--out", required=True)
    p.add_argument("--timeout", type=float, default=120.0, help="wall-clock limit, s")
    a, ros_args = p.parse_known_args()
    rclpy.init(args=[sys.argv[0]] + ros_args)
    if a.mode == "services":
        node = Services(a.robot)
        out = node.run()
        out["sent"] = node.sent
        with open(a.out, "w") as f:
            json.dump(out, f)
        node.destroy_node()
        rclpy.try_shutdown()
        return 0
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
