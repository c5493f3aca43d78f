"""A controller on Cyclone DDS (PyPI `cyclonedds`), not rclpy, for `controller = "ros"`: it
joins $ROS_DOMAIN_ID with the loopback-only $CYCLONEDDS_URI twin gives it, and once it has seen
a /clock it answers each /joint_states with one Float64MultiArray on /<robot>/joint_commands:
every joint at the first pose it saw minus 0.02 s times the answered state's velocity. Runs until
SIGINT or SIGTERM.

Usage: python cyclone_controller.py [--robot humanoid] [--tag TAG]
"""
import argparse
import os
import signal
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from cyclonedds.core import Policy, Qos, ReadCondition, SampleState, ViewState, InstanceState, WaitSet  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.internal import InvalidSample  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from ros_peer import Clock, Float64MultiArray, JointState, MultiArrayLayout  # noqa: E402


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--robot", default="humanoid")
    p.add_argument("--tag", default="", help="ignored: marks the process for the tests")
    a = p.parse_args()
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
    xcdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)
    reliable = Policy.Reliability.Reliable(duration(seconds=1))
    qos = Qos(reliable, Policy.History.KeepLast(100), xcdr1)
    clock = DataReader(dp, Topic(dp, "rt/clock", Clock, qos=qos), qos=qos)
    states = DataReader(dp, Topic(dp, "rt/joint_states", JointState, qos=qos), qos=qos)
    topic = Topic(dp, f"rt/{a.robot}/joint_commands", Float64MultiArray, qos=qos)
    writer = DataWriter(dp, topic, qos=qos)
    waitset = WaitSet(dp)
    for r in (clock, states):
        waitset.attach(ReadCondition(r, SampleState.Any | ViewState.Any | InstanceState.Any))
    seen_clock = False
    hold = None
    while not stop:
        waitset.wait(duration(milliseconds=50))
        # /clock first: a state and the /clock that followed it may both be waiting.
        if any(not isinstance(m, InvalidSample) for m in clock.take(N=100)):
            seen_clock = True
        for m in states.take(N=100):
            if isinstance(m, InvalidSample) or not seen_clock:
                continue
            if hold is None:
                hold = list(m.position)
            v = list(m.velocity) or [0.0] * len(hold)
            data = [q - 0.02 * w for q, w in zip(hold, v)]
            writer.write(Float64MultiArray(layout=MultiArrayLayout(dim=[], data_offset=0), data=data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
