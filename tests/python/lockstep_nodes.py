"""rclpy controllers written the common way, for twin's lockstep tests (`controller = "ros"`):
ROS 2 Kilted from PyPI on Fast DDS, started by twin with `use_sim_time:=true`.

Every mode is a balance node of the usual shape: `/joint_states` (depth 10) and the IMU
(`qos_profile_sensor_data`, best effort) subscribed, a 100 Hz timer on simulation time, and no
command until the first `/joint_states` has arrived (the node holds that first pose). Its
command depends on the latest state it read, so a run that read another period's state ends
elsewhere: every joint at the first pose minus 0.02 s times its latest velocity, the hips
also leaning against the latest IMU pitch rate (0.05 s).

Modes (--mode):
  first-state  as above (single-threaded executor)
  late         subscribes to /joint_states and the IMU only --delay wall seconds after start
               (its readers match late: twin's join must wait for them)
  callback     subscribes to /joint_states and the IMU in its first /clock callback (a reader
               twin can never see before time starts: twin must send the first state again)
  multi        first-state on a MultiThreadedExecutor (4 threads), every callback in one
               ReentrantCallbackGroup: callbacks of one node may run at the same time
  subscription no timer: answers each /joint_states in its callback
  imu          no timer: answers each IMU sample in its callback, from the latest /joint_states
  wall-clock   first-state, its command also a little function of the wall clock
               (time.monotonic()): a node twin can never make reproducible
"""
import argparse
import signal
import time

import rclpy
import rclpy.callback_groups
import rclpy.executors
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64MultiArray

HIPS = ("left_hip_pitch_joint", "right_hip_pitch_joint")


class Balance(Node):
    def __init__(self, robot, imu_topic, mode, delay):
        super().__init__("balance")
        self.imu_topic = imu_topic
        self.imu = None
        self.trace = None
        self.hold = None
        self.latest = None
        self.rate = 0.0
        self.pub = self.create_publisher(Float64MultiArray, f"/{robot}/joint_commands", 10)
        self.group = rclpy.callback_groups.ReentrantCallbackGroup() if mode == "multi" else None
        self.mode = mode
        if mode not in ("subscription", "imu"):
            self.create_timer(0.01, self.tick, callback_group=self.group)
        self.subscribed = False
        if mode in ("first-state", "multi", "subscription", "imu", "wall-clock"):
            self.subscribe()
        elif mode == "late":
            self.later = self.create_timer(delay, self.subscribe_once, clock=rclpy.clock.Clock())
        else:
            self.clock_sub = self.create_subscription(Clock, "/clock", self.on_clock, qos_profile_sensor_data)

    def subscribe(self):
        g = self.group
        self.create_subscription(JointState, "/joint_states", self.on_joints, 10, callback_group=g)
        self.create_subscription(Imu, self.imu_topic, self.on_imu, qos_profile_sensor_data, callback_group=g)
        self.subscribed = True

    def subscribe_once(self):
        self.later.cancel()
        if not self.subscribed:
            self.subscribe()

    def on_clock(self, _msg):
        if not self.subscribed:
            self.subscribe()

    def on_joints(self, msg):
        if self.hold is None:
            self.hold = list(msg.position)
            self.names = list(msg.name)
        self.latest = msg
        if self.mode == "subscription":
            self.tick()

    def on_imu(self, msg):
        self.rate = msg.angular_velocity.y
        self.imu = msg
        if self.mode == "imu":
            self.tick()

    def tick(self):
        if self.trace is not None:
            stamp = lambda m: None if m is None else m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            now = self.get_clock().now().nanoseconds * 1e-9
            self.trace.write(f"{now:.3f} {stamp(self.latest)} {stamp(self.imu)}\n")
            self.trace.flush()
        if self.hold is None:
            return  # no command until the first /joint_states
        v = list(self.latest.velocity) or [0.0] * len(self.hold)
        target = [q - 0.02 * w for q, w in zip(self.hold, v)]
        for k, name in enumerate(self.names):
            if name in HIPS:
                target[k] -= 0.05 * self.rate
        if self.mode == "wall-clock":
            target = [q + 1e-3 * (time.monotonic() % 1.0) for q in target]
        self.pub.publish(Float64MultiArray(data=target))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--mode", choices=["first-state", "late", "callback", "multi", "subscription", "imu", "wall-clock"], default="first-state")
    p.add_argument("--delay", type=float, default=2.0)
    p.add_argument("--robot", default="humanoid")
    p.add_argument("--imu-topic", default="/humanoid/imu/data")
    p.add_argument("--tag", default="", help="ignored: marks the process for the tests")
    p.add_argument("--trace", help="append, per tick: the sim time, the stamps of the latest state and IMU read")
    a, ros_args = p.parse_known_args()
    rclpy.init(args=ros_args)
    node = Balance(a.robot, a.imu_topic, a.mode, a.delay)
    if a.trace:
        node.trace = open(a.trace, "a")
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    executor = rclpy.executors.MultiThreadedExecutor(4) if a.mode == "multi" else None
    try:
        rclpy.spin(node, executor=executor)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
