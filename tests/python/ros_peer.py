#!/usr/bin/env python3
"""A ROS 2 peer built on Cyclone DDS (PyPI `cyclonedds`), independent of twin's DDS stack.

It joins the domain given by --domain on loopback only (the caller sets CYCLONEDDS_URI to a
loopback-only, multicast-free configuration), subscribes to twin's topics with the ROS 2 DDS
names and types, and (lockstep modes) answers every /clock with one command on --command-topic. At the end it
writes one JSON object to --out: every message it received, decoded, per topic.

Modes (--mode):
  lockstep   one Float64MultiArray (--command, a JSON list) per /clock received
  bad        one command per /clock: a too-short, a NaN and a too-long one, then good ones
  flood      --flood-count good commands at up to --flood-hz, no matter the clock
  quit       answer --quit-after clocks, then leave (a peer that disconnects mid-run)
  services   no commands; calls twin's simulation_interfaces services (pause, step, resume,
             reset, quit) and records each reply with the latest /clock after it ("calls")

In every mode it also records twin's ROS 2 graph announcement (ros_discovery_info), each GID
resolved to its DDS topic through Cyclone's built-in discovery topics ("graph").

Exit status 3 when cyclonedds is missing is NOT used: the Rust test must fail without it.
"""

import argparse
import json
import math
import random
import sys
import time
import types
from dataclasses import dataclass

from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.internal import InvalidSample
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
from cyclonedds.idl.types import array, float64, int32, int64, sequence, uint8, uint32, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


def ros_type(full, fields):
    """An IDL struct for ROS 2 type `pkg/msg/Name` with DDS type name `pkg::msg::dds_::Name_`."""
    pkg, kind, name = full.split("/")
    body = {"__annotations__": dict(fields)}
    cls = types.new_class(name, (IdlStruct,), {"typename": f"{pkg}::{kind}::dds_::{name}_"},
                          lambda ns: ns.update(body))
    return dataclass(cls)


XYZ = [("x", float64), ("y", float64), ("z", float64)]
Time = ros_type("builtin_interfaces/msg/Time", [("sec", int32), ("nanosec", uint32)])
Header = ros_type("std_msgs/msg/Header", [("stamp", Time), ("frame_id", str)])
Clock = ros_type("rosgraph_msgs/msg/Clock", [("clock", Time)])
JointState = ros_type("sensor_msgs/msg/JointState", [
    ("header", Header), ("name", sequence[str]), ("position", sequence[float64]),
    ("velocity", sequence[float64]), ("effort", sequence[float64])])
Vector3 = ros_type("geometry_msgs/msg/Vector3", XYZ)
Point = ros_type("geometry_msgs/msg/Point", XYZ)
Quaternion = ros_type("geometry_msgs/msg/Quaternion", XYZ + [("w", float64)])
Imu = ros_type("sensor_msgs/msg/Imu", [
    ("header", Header), ("orientation", Quaternion), ("orientation_covariance", array[float64, 9]),
    ("angular_velocity", Vector3), ("angular_velocity_covariance", array[float64, 9]),
    ("linear_acceleration", Vector3), ("linear_acceleration_covariance", array[float64, 9])])
Pose = ros_type("geometry_msgs/msg/Pose", [("position", Point), ("orientation", Quaternion)])
PoseWithCovariance = ros_type("geometry_msgs/msg/PoseWithCovariance",
                              [("pose", Pose), ("covariance", array[float64, 36])])
Twist = ros_type("geometry_msgs/msg/Twist", [("linear", Vector3), ("angular", Vector3)])
TwistWithCovariance = ros_type("geometry_msgs/msg/TwistWithCovariance",
                               [("twist", Twist), ("covariance", array[float64, 36])])
Odometry = ros_type("nav_msgs/msg/Odometry", [
    ("header", Header), ("child_frame_id", str), ("pose", PoseWithCovariance), ("twist", TwistWithCovariance)])
Transform = ros_type("geometry_msgs/msg/Transform", [("translation", Vector3), ("rotation", Quaternion)])
TransformStamped = ros_type("geometry_msgs/msg/TransformStamped",
                            [("header", Header), ("child_frame_id", str), ("transform", Transform)])
TFMessage = ros_type("tf2_msgs/msg/TFMessage", [("transforms", sequence[TransformStamped])])
Wrench = ros_type("geometry_msgs/msg/Wrench", [("force", Vector3), ("torque", Vector3)])
WrenchStamped = ros_type("geometry_msgs/msg/WrenchStamped", [("header", Header), ("wrench", Wrench)])
String = ros_type("std_msgs/msg/String", [("data", str)])
MultiArrayDimension = ros_type("std_msgs/msg/MultiArrayDimension",
                               [("label", str), ("size", uint32), ("stride", uint32)])
MultiArrayLayout = ros_type("std_msgs/msg/MultiArrayLayout",
                            [("dim", sequence[MultiArrayDimension]), ("data_offset", uint32)])
Float64MultiArray = ros_type("std_msgs/msg/Float64MultiArray",
                             [("layout", MultiArrayLayout), ("data", sequence[float64])])

# The ROS 2 graph announcement (rmw_dds_common, Iron and later: 16-byte GIDs).
Gid = ros_type("rmw_dds_common/msg/Gid", [("data", array[uint8, 16])])
NodeEntitiesInfo = ros_type("rmw_dds_common/msg/NodeEntitiesInfo", [
    ("node_namespace", str), ("node_name", str),
    ("reader_gid_seq", sequence[Gid]), ("writer_gid_seq", sequence[Gid])])
ParticipantEntitiesInfo = ros_type("rmw_dds_common/msg/ParticipantEntitiesInfo",
                                   [("gid", Gid), ("node_entities_info_seq", sequence[NodeEntitiesInfo])])

# simulation_interfaces services, the rmw_cyclonedds way: each request and reply starts with
# the request header (client id, sequence number).
RMW_HEADER = [("client_guid", uint64), ("sequence_number", int64)]
SimulationState = ros_type("simulation_interfaces/msg/SimulationState", [("state", uint8)])
SimResult = ros_type("simulation_interfaces/msg/Result", [("result", uint8), ("error_message", str)])
SERVICES = {
    # service: (srv type, request fields, response fields)
    "get_simulation_state": ("GetSimulationState", [("structure_needs_at_least_one_member", uint8)],
                             [("state", SimulationState), ("result", SimResult)]),
    "set_simulation_state": ("SetSimulationState", [("state", SimulationState)], [("result", SimResult)]),
    "step_simulation": ("StepSimulation", [("steps", uint64)], [("result", SimResult)]),
    "reset_simulation": ("ResetSimulation", [("scope", uint8)], [("result", SimResult)]),
}


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


class ServiceClient:
    """A ROS 2 service client as rmw_cyclonedds makes one: requests on rq/<name>Request, replies
    on rr/<name>Reply, matched by the request header."""

    def __init__(self, dp, name, qos):
        srv, request_fields, response_fields = SERVICES[name]
        self.name = name
        self.request = ros_type(f"simulation_interfaces/srv/{srv}_Request", RMW_HEADER + request_fields)
        self.response = ros_type(f"simulation_interfaces/srv/{srv}_Response", RMW_HEADER + response_fields)
        self.writer = DataWriter(dp, Topic(dp, f"rq/twin/{name}Request", self.request, qos=qos), qos=qos)
        self.reader = DataReader(dp, Topic(dp, f"rr/twin/{name}Reply", self.response, qos=qos), qos=qos)
        self.client_guid = random.getrandbits(64)
        self.sequence_number = 0

    def ready(self):
        return bool(self.writer.get_matched_subscriptions()) and bool(self.reader.get_matched_publications())

    def call(self, timeout, **fields):
        """The response, or None after `timeout` s."""
        self.sequence_number += 1
        self.writer.write(self.request(client_guid=self.client_guid, sequence_number=self.sequence_number, **fields))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for m in self.reader.take(N=100):
                if (not isinstance(m, InvalidSample) and m.client_guid == self.client_guid
                        and m.sequence_number == self.sequence_number):
                    return m
            time.sleep(0.005)
        return None


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--mode", default="lockstep", choices=["lockstep", "bad", "flood", "quit", "services"])
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
    p.add_argument("--clock-only", action="store_true",
                   help="subscribe to /clock alone (round-trip figures without decoding the state in Python)")
    a = p.parse_args()
    command = json.loads(a.command)

    dp = DomainParticipant(a.domain)
    # XCDR1 (what ROS 2 and rustdds speak), reliable, keep last 100: matches twin's writers.
    xcdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)
    reliable = Policy.Reliability.Reliable(duration(seconds=1))
    reader_qos = Qos(reliable, Policy.History.KeepLast(1000), xcdr1)
    latched_qos = Qos(reliable, Policy.Durability.TransientLocal, Policy.History.KeepLast(1), xcdr1)
    writer_qos = Qos(reliable, Policy.History.KeepLast(10000), xcdr1)
    service_qos = Qos(reliable, Policy.History.KeepLast(10), xcdr1)

    subs = [("/clock", Clock, reader_qos), ("/joint_states", JointState, reader_qos),
            (a.imu_topic, Imu, reader_qos), ("/odom", Odometry, reader_qos), ("/tf", TFMessage, reader_qos),
            ("/tf_static", TFMessage, latched_qos), ("/robot_description", String, latched_qos)]
    subs += [(t, WrenchStamped, reader_qos) for t in a.contact_topics.split(",") if t]
    if a.clock_only:
        subs = subs[:1]
    readers = []
    for name, ty, qos in subs:
        topic = Topic(dp, "rt/" + name.lstrip("/"), ty, qos=qos)
        readers.append((name, DataReader(dp, topic, qos=qos)))
    clock_reader = readers[0][1]
    cmd_topic = Topic(dp, "rt/" + a.command_topic.lstrip("/"), Float64MultiArray, qos=writer_qos)
    writer = DataWriter(dp, cmd_topic, qos=writer_qos)
    graph = DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo, qos=latched_qos), qos=latched_qos)
    endpoints = [BuiltinDataReader(dp, BuiltinTopicDcpsPublication), BuiltinDataReader(dp, BuiltinTopicDcpsSubscription)]
    clients = {name: ServiceClient(dp, name, service_qos) for name in SERVICES} if a.mode == "services" else {}

    def send(data):
        writer.write(Float64MultiArray(layout=MultiArrayLayout(dim=[], data_offset=0), data=data))

    waitset = WaitSet(dp)
    waitset.attach(ReadCondition(clock_reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    received = {name: [] for name, _, _ in subs}
    topic_of_guid = {}
    graph_info = []
    calls = []
    sent = 0
    started = time.monotonic()
    last_clock = -1.0
    bad_left = None  # mode bad: the bad commands still to send, one per /clock
    finished = False
    flood_rate = None

    def take_clocks():
        nonlocal last_clock
        clocks = []
        for m in clock_reader.take(N=1000):
            if isinstance(m, InvalidSample):  # a writer went away (twin exited)
                continue
            received["/clock"].append(to_json("/clock", m))
            clocks.append(nanos(m.clock) * 1e-9)
            last_clock = max(last_clock, clocks[-1])
        return clocks

    def drain(clock=True):
        """Takes everything that arrived (but /clock when `clock` is false); returns the /clock
        values among it."""
        clocks = take_clocks() if clock else []
        for name, r in readers[1:]:
            for m in r.take(N=1000):
                if not isinstance(m, InvalidSample):
                    received[name].append(to_json(name, m))
        for r in endpoints:
            for e in r.take(N=1000):
                if getattr(e, "topic_name", None):  # (a disposed endpoint has only its key)
                    topic_of_guid[e.key.bytes.hex()] = e.topic_name
        for m in graph.take(N=100):
            if not isinstance(m, InvalidSample):
                graph_info.append(m)
        return clocks

    def settle(secs):
        """Takes what arrives during `secs` s; returns the latest /clock, s."""
        end = time.monotonic() + secs
        while time.monotonic() < end:
            drain()
            time.sleep(0.01)
        return last_clock

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
                drain()
        flood_rate = sent / (time.monotonic() - t0)
        while time.monotonic() - started < a.timeout and last_clock < a.until_clock:
            drain()
            time.sleep(0.01)
        finished = last_clock >= a.until_clock
    elif a.mode == "services":
        # The script of calls: each entry records the reply and the latest /clock after it.
        deadline = started + a.timeout
        while (not all(c.ready() for c in clients.values()) or last_clock < 0) and time.monotonic() < deadline:
            drain()
            time.sleep(0.05)
        script = [
            ("get_simulation_state", {"structure_needs_at_least_one_member": 0}, 0.0),
            ("set_simulation_state", {"state": SimulationState(2)}, 0.3),   # pause
            ("get_simulation_state", {"structure_needs_at_least_one_member": 0}, 0.7),  # still paused?
            ("step_simulation", {"steps": 7}, 0.3),
            ("step_simulation", {"steps": 1}, 0.3),                          # a single step
            ("set_simulation_state", {"state": SimulationState(2)}, 0.0),   # already paused
            ("set_simulation_state", {"state": SimulationState(1)}, 0.6),   # resume
            ("step_simulation", {"steps": 3}, 0.0),                          # not paused: refused
            ("reset_simulation", {"scope": 1}, 0.0),                         # time: unsupported
            ("reset_simulation", {"scope": 2}, 0.5),                         # state
            ("set_simulation_state", {"state": SimulationState(3)}, 0.3),   # quit
        ]
        for name, fields, wait in script:
            if time.monotonic() > deadline:
                break
            drain()
            clock_before = last_clock
            reply = clients[name].call(max(1.0, deadline - time.monotonic()), **fields)
            clock_after = settle(wait)
            call = {"service": name, "request": {k: getattr(v, "state", v) for k, v in fields.items()},
                    "clock_before": clock_before, "clock_after": clock_after, "answered": reply is not None}
            if reply is not None:
                call["result"] = reply.result.result
                call["message"] = reply.result.error_message
                if name == "get_simulation_state":
                    call["state"] = reply.state.state
            calls.append(call)
        finished = len(calls) == len(script) and all(c["answered"] for c in calls)
        settle(0.5)
    else:
        answered = -1.0  # the latest /clock answered (twin says a time again while it waits)
        while time.monotonic() - started < a.timeout:
            clocks = take_clocks()
            for c in clocks:
                if c <= answered:
                    continue
                answered = c
                if a.mode == "quit" and sent >= a.quit_after:
                    break
                if a.mode == "bad" and bad_left is None:
                    bad_left = [command[:-1], [math.nan] + command[1:], command + [0.0]]
                if bad_left:
                    # Each takes its period's slot in lockstep and is rejected (one per period:
                    # twin drops commands beyond one per period as a flood's surplus).
                    send(bad_left.pop(0))
                    sent += 1
                    continue
                send(command)
                sent += 1
            drain(clock=False)
            if a.mode == "quit" and sent >= a.quit_after:
                finished = True
                break
            if last_clock >= a.until_clock:
                finished = True
                break
            if not clocks:
                waitset.wait(duration(milliseconds=50))
        # Collect what is still in flight.
        settle(0.5)

    # The graph as twin announced it (the latest announcement), with each GID's DDS topic.
    graph_json = []
    if graph_info:
        g = graph_info[-1]
        graph_json = [{"participant": bytes(g.gid.data).hex(), "nodes": [{
            "namespace": n.node_namespace, "name": n.node_name,
            "readers": [topic_of_guid.get(bytes(x.data).hex(), bytes(x.data).hex()) for x in n.reader_gid_seq],
            "writers": [topic_of_guid.get(bytes(x.data).hex(), bytes(x.data).hex()) for x in n.writer_gid_seq],
        } for n in g.node_entities_info_seq]}]
    with open(a.out, "w") as f:
        json.dump({"finished": finished, "sent": sent, "flood_rate_hz": flood_rate, "last_clock": last_clock,
                   "received": received, "calls": calls, "graph": graph_json}, f)
    print(f"peer: sent {sent} commands, last /clock {last_clock} s, finished {finished}")
    return 0 if finished else 1


if __name__ == "__main__":
    sys.exit(main())
