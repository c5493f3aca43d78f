#!/usr/bin/env python3
"""A ROS 2 peer built on Cyclone DDS (PyPI `cyclonedds`), independent of twin's DDS stack.

It joins the domain given by --domain on loopback only (the caller sets CYCLONEDDS_URI to a
loopback-only, multicast-free configuration), subscribes to twin's topics with the ROS 2 DDS
names and types, and answers every /clock with one command on --command-topic. At the end it
writes one JSON object to --out: every message it received, decoded, per topic.

Modes (--mode):
  lockstep   one Float64MultiArray (--command, a JSON list) per /clock received
  bad        a wrong-length, a NaN and an undecodable-length command, then good ones per /clock
  flood      --flood-count good commands at up to --flood-hz, no matter the clock
  quit       answer --quit-after clocks, then leave (a peer that disconnects mid-run)

Exit status 3 when cyclonedds is missing is NOT used: the Rust test must fail without it.
"""

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.internal import InvalidSample
from cyclonedds.idl.types import array, float64, int32, sequence, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Imu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header
    orientation: Quaternion
    orientation_covariance: array[float64, 9]
    angular_velocity: Vector3
    angular_velocity_covariance: array[float64, 9]
    linear_acceleration: Vector3
    linear_acceleration_covariance: array[float64, 9]


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    force: Vector3
    torque: Vector3


@dataclass
class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    header: Header
    wrench: Wrench


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    label: str
    size: uint32
    stride: uint32


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension]
    data_offset: uint32


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    layout: MultiArrayLayout
    data: sequence[float64]


def nanos(t):
    return t.sec * 1_000_000_000 + t.nanosec


def vec(v):
    return [v.x, v.y, v.z]


def quat(q):
    return [q.x, q.y, q.z, q.w]


def header(h):
    return {"stamp": nanos(h.stamp), "frame_id": h.frame_id}


def to_json(topic, m):
    """The fields of a received message, named like twin's typed messages."""
    if isinstance(m, Clock):
        return {"clock": nanos(m.clock)}
    if isinstance(m, JointState):
        return {"header": header(m.header), "name": list(m.name), "position": list(m.position),
                "velocity": list(m.velocity), "effort": list(m.effort)}
    if isinstance(m, Imu):
        return {"header": header(m.header), "orientation": quat(m.orientation),
                "angular_velocity": vec(m.angular_velocity),
                "linear_acceleration": vec(m.linear_acceleration),
                "angular_velocity_covariance": list(m.angular_velocity_covariance),
                "linear_acceleration_covariance": list(m.linear_acceleration_covariance)}
    if isinstance(m, Odometry):
        return {"header": header(m.header), "child_frame_id": m.child_frame_id,
                "position": [m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z],
                "orientation": quat(m.pose.pose.orientation),
                "linear": vec(m.twist.twist.linear), "angular": vec(m.twist.twist.angular)}
    if isinstance(m, TFMessage):
        return {"transforms": [{"header": header(t.header), "child_frame_id": t.child_frame_id,
                                "translation": vec(t.transform.translation),
                                "rotation": quat(t.transform.rotation)} for t in m.transforms]}
    if isinstance(m, WrenchStamped):
        return {"header": header(m.header), "force": vec(m.wrench.force), "torque": vec(m.wrench.torque)}
    if isinstance(m, String):
        return {"data_len": len(m.data), "data_head": m.data[:200]}
    raise TypeError(type(m))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--mode", default="lockstep", choices=["lockstep", "bad", "flood", "quit"])
    p.add_argument("--command-topic", required=True)
    p.add_argument("--command", required=True, help="JSON list: the command sent each period")
    p.add_argument("--imu-topic", default="/humanoid/imu/data")
    p.add_argument("--contact-topics", default="", help="comma-separated")
    p.add_argument("--until-clock", type=float, required=True, help="stop after /clock reaches this, s")
    p.add_argument("--timeout", type=float, default=60.0, help="wall-clock limit, s")
    p.add_argument("--flood-hz", type=float, default=10000.0)
    p.add_argument("--flood-count", type=int, default=10000)
    p.add_argument("--quit-after", type=int, default=20)
    p.add_argument("--out", required=True, help="JSON output file")
    a = p.parse_args()
    command = json.loads(a.command)

    dp = DomainParticipant(a.domain)
    # XCDR1 (what ROS 2 and rustdds speak), reliable, keep last 100: matches twin's writers.
    xcdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)
    reader_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000), xcdr1)
    latched_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                      Policy.History.KeepLast(1), xcdr1)
    writer_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10000), xcdr1)

    subs = [("/clock", Clock, reader_qos), ("/joint_states", JointState, reader_qos),
            (a.imu_topic, Imu, reader_qos), ("/odom", Odometry, reader_qos), ("/tf", TFMessage, reader_qos),
            ("/tf_static", TFMessage, latched_qos), ("/robot_description", String, latched_qos)]
    subs += [(t, WrenchStamped, reader_qos) for t in a.contact_topics.split(",") if t]
    readers = []
    for name, ty, qos in subs:
        topic = Topic(dp, "rt/" + name.lstrip("/"), ty, qos=qos)
        readers.append((name, DataReader(dp, topic, qos=qos)))
    clock_reader = readers[0][1]
    cmd_topic = Topic(dp, "rt/" + a.command_topic.lstrip("/"), Float64MultiArray, qos=writer_qos)
    writer = DataWriter(dp, cmd_topic, qos=writer_qos)

    def send(data):
        writer.write(Float64MultiArray(layout=MultiArrayLayout(dim=[], data_offset=0), data=data))

    waitset = WaitSet(dp)
    waitset.attach(ReadCondition(clock_reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    received = {name: [] for name, _, _ in subs}
    sent = 0
    started = time.monotonic()
    last_clock = -1.0
    bad_sent = False
    finished = False
    flood_rate = None

    def drain(skip_clock):
        nonlocal last_clock
        clocks = []
        for name, r in readers:
            if skip_clock and r is clock_reader:
                continue
            for m in r.take(N=1000):
                if isinstance(m, InvalidSample):  # a writer went away (twin exited)
                    continue
                received[name].append(to_json(name, m))
                if isinstance(m, Clock):
                    clocks.append(nanos(m.clock) * 1e-9)
                    last_clock = max(last_clock, clocks[-1])
        return clocks

    if a.mode == "flood":
        # Wait until twin's command reader matched, then flood at flood_hz.
        deadline = time.monotonic() + a.timeout
        while not writer.get_matched_subscriptions() and time.monotonic() < deadline:
            time.sleep(0.05)
        # Bursts of 10 every 1/100 of the rate's second: the average rate without a busy loop.
        burst = 10
        t0 = time.monotonic()
        k = 0
        while sent < a.flood_count:
            for _ in range(burst):
                send(command)
                sent += 1
            k += 1
            wake = t0 + k * burst / a.flood_hz
            pause = wake - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            if k % 100 == 0:
                drain(False)
        flood_rate = sent / (time.monotonic() - t0)
        while time.monotonic() - started < a.timeout and last_clock < a.until_clock:
            drain(False)
            time.sleep(0.01)
        finished = last_clock >= a.until_clock
    else:
        while time.monotonic() - started < a.timeout:
            clocks = []
            for m in clock_reader.take(N=1000):
                if isinstance(m, InvalidSample):
                    continue
                received["/clock"].append(to_json("/clock", m))
                clocks.append(nanos(m.clock) * 1e-9)
            for c in clocks:
                if c <= last_clock:  # the same time said again (twin waiting for us): answered
                    continue
                last_clock = c
                if a.mode == "quit" and sent >= a.quit_after:
                    break
                if a.mode == "bad" and not bad_sent:
                    # Each of these takes a period's slot in lockstep and is rejected.
                    send(command[:-1])
                    send([math.nan] + command[1:])
                    send(command + [0.0])
                    sent += 3
                    bad_sent = True
                    continue
                send(command)
                sent += 1
            drain(True)
            if a.mode == "quit" and sent >= a.quit_after:
                finished = True
                break
            if last_clock >= a.until_clock:
                finished = True
                break
            if not clocks:
                waitset.wait(duration(milliseconds=50))
        # Collect what is still in flight.
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            drain(False)
            time.sleep(0.02)
    with open(a.out, "w") as f:
        json.dump({"finished": finished, "sent": sent, "flood_rate_hz": flood_rate, "last_clock": last_clock, "received": received}, f)
    print(f"peer: sent {sent} commands, last /clock {last_clock} s, finished {finished}")
    return 0 if finished else 1


if __name__ == "__main__":
    sys.exit(main())
