"""rclpy controllers that misbehave, for twin's external-controller tests.

    bad_controller.py MODE [--after SECS]

Behaves as scenarios/controllers/hold_pose.py until simulation time reaches --after, then:
  crash   exits with status 3;
  hang    stops answering (keeps running, sends nothing more);
  ignore  (never joins) sleeps without ever creating a node;
  sigint  ignores SIGINT and SIGTERM, so that only SIGKILL stops it (it behaves otherwise);
  flood   publishes commands in a loop on wall time, as fast as it can (or at --rate HZ),
          whatever the simulation time, from within its timer callback (which never returns).
"""

import signal
import sys
import time


def main():
    mode = sys.argv[1]
    after = float(sys.argv[sys.argv.index("--after") + 1]) if "--after" in sys.argv else 0.1
    rate = float(sys.argv[sys.argv.index("--rate") + 1]) if "--rate" in sys.argv else 0.0
    if mode == "ignore":
        while True:
            time.sleep(1.0)
    if mode == "sigint":
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    import rclpy
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    class Bad(Node):
        def __init__(self):
            super().__init__("bad_controller", parameter_overrides=[Parameter("use_sim_time", value=True)])
            self.hold = None
            self.create_subscription(JointState, "/joint_states", self.on_joints, 10)
            self.pub = self.create_publisher(Float64MultiArray, "/humanoid/joint_commands", 10)
            self.create_timer(0.01, self.tick)
            self.flooding = False

        def flood(self):
            msg = Float64MultiArray(data=self.hold)
            period = 1.0 / rate if rate > 0.0 else 0.0
            sent, start = 0, time.monotonic()
            while rclpy.ok():
                try:
                    self.pub.publish(msg)
                except Exception:  # the context shut down (SIGINT): stop
                    return
                sent += 1
                if period > 0.0:
                    time.sleep(max(0.0, start + sent * period - time.monotonic()))

        def on_joints(self, msg):
            if self.hold is None:
                self.hold = list(msg.position)

        def tick(self):
            t = self.get_clock().now().nanoseconds * 1e-9
            if t >= after and mode == "crash":
                print(f"crashing at t = {t:.3f} s", flush=True)
                sys.stdout.flush()
                import os
                os._exit(3)
            if t >= after and mode == "hang":
                return
            if t >= after and mode == "flood" and not self.flooding and self.hold is not None:
                self.flooding = True
                print(f"flooding from t = {t:.3f} s", flush=True)
                self.flood()
            if self.hold is not None:
                self.pub.publish(Float64MultiArray(data=self.hold))

    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO if mode == "sigint" else None)
    rclpy.spin(Bad())


if __name__ == "__main__":
    main()
