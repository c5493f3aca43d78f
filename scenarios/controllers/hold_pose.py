"""A minimal ROS 2 controller for twin (rclpy): holds the first /joint_states pose.

twin starts it for `scenarios/hold_pose.toml` (twin sim / randomize / test --scenario). By hand,
against a twin you started yourself:

    ROS_DOMAIN_ID=7 twin sim --ros --lockstep --duration 10
    ROS_DOMAIN_ID=7 python3 hold_pose.py --ros-args -p use_sim_time:=true

Its timer runs on simulation time (/clock, use_sim_time): one position command per 10 ms
control period, in /joint_states order (twin's command order). When time jumps back (twin reset
the simulation under it: `restart = "never"`) the held pose is stale: ticks wait for the new
episode's first /joint_states, as at the start.
"""

import rclpy
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray


class HoldPose(Node):
    def __init__(self):
        super().__init__("hold_pose")
        robot = self.declare_parameter("robot", "humanoid").value
        self.hold = None
        self.stamp = None
        self.owed = False  # a tick came before the first /joint_states
        self.create_subscription(JointState, "/joint_states", self.on_joints, 10)
        self.pub = self.create_publisher(Float64MultiArray, f"/{robot}/joint_commands", 10)
        self.create_timer(0.01, self.tick)  # 100 Hz of simulation time
        self.stale = False  # time jumped back: the held pose is the last episode's
        back = JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=False)
        self.jumps = self.get_clock().create_jump_callback(back, post_callback=self.on_jump_back)

    def on_jump_back(self, _jump):
        # Stale unless the new episode's first state already came (stamped at the new time).
        self.stale = self.stamp is not None and self.stamp > self.get_clock().now().nanoseconds

    def on_joints(self, msg):
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        # The first pose, again after the simulation was reset under us (its stamps start
        # again: states of the last episode still queued come first and don't count).
        if self.hold is None or stamp < self.stamp:
            self.hold = list(msg.position)
            self.stale = False
        self.stamp = stamp
        # Discovery may deliver the first state after the first /clock tick: answer that tick
        # now (in lockstep twin waits for exactly one command per period).
        if self.owed and not self.stale:
            self.owed = False
            self.pub.publish(Float64MultiArray(data=self.hold))

    def tick(self):
        if self.hold is None or self.stale:
            self.owed = True
        else:
            self.pub.publish(Float64MultiArray(data=self.hold))


def main():
    rclpy.init()
    node = HoldPose()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
