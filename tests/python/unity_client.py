"""A client framed like Unity's ROS-TCP-Connector, for twin's tests.

Written from the protocol (length-prefixed destination + payload frames; system commands as
JSON followed by one byte; ROS 2 CDR payloads); messages are (de)serialized by rclpy, as the
real ROS-TCP-Endpoint does. Prints one JSON line on stdout.

python unity_client.py HOST PORT COMMAND_TOPIC JOINT TARGET
"""

import json
import socket
import struct
import sys
import time

from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

host, port, command_topic, joint, target = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], float(sys.argv[5])
out = {"frames": [], "handshake": None, "topic_list": None, "joint_states": 0, "errors": []}
sock = socket.create_connection((host, port), timeout=30)


def recv_exact(n):
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise IOError("closed")
        buf += chunk
    return buf


def read_frame():
    (dlen,) = struct.unpack("<I", recv_exact(4))
    dest = recv_exact(dlen).decode("utf-8")
    (plen,) = struct.unpack("<I", recv_exact(4))
    return dest, recv_exact(plen)


def send_frame(dest, payload):
    d = dest.encode("utf-8")
    sock.sendall(struct.pack("<I", len(d)) + d + struct.pack("<I", len(payload)) + payload)


def send_command(name, params):
    # As the connector does: the JSON, then one trailing byte the endpoint strips.
    send_frame(name, json.dumps(params).encode("utf-8") + b"\0")


deadline = time.time() + float(__import__("os").environ.get("UNITY_CLIENT_SECS", "60"))
first = None
moved = None
sent_command = False
send_command("__topic_list", {})
send_command("__subscribe", {"topic": "/joint_states", "message_name": "sensor_msgs/JointState"})
send_command("__publish", {"topic": command_topic, "message_name": "std_msgs/Float64MultiArray", "queue_size": 10, "latch": False})
while time.time() < deadline:
    dest, payload = read_frame()
    if len(out["frames"]) < 6:
        out["frames"].append(dest)
    if dest == "__handshake":
        out["handshake"] = json.loads(payload.decode("utf-8"))
    elif dest == "__topic_list":
        out["topic_list"] = json.loads(payload.decode("utf-8"))
    elif dest == "__error":
        out["errors"].append(json.loads(payload.decode("utf-8")))
    elif dest == "/joint_states":
        msg = deserialize_message(payload, JointState)
        out["joint_states"] += 1
        i = list(msg.name).index(joint)
        if first is None:
            first = {"names": list(msg.name), "position": list(msg.position), "stamp": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9}
        if out["joint_states"] >= 20 and not sent_command:
            cmd = Float64MultiArray()
            data = list(msg.position)
            data[i] = target
            cmd.data = data
            send_frame(command_topic, serialize_message(cmd))
            sent_command = True
            send_frame("", b"")  # a keepalive, as Unity sends when idle
        if sent_command and out["joint_states"] % 100 == 0:
            out.setdefault("trace", []).append([round(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, 3), round(msg.position[i], 4)])
        if sent_command and abs(msg.position[i] - target) < 0.05:
            moved = {"position": msg.position[i], "stamp": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9}
            break
out["first"] = first
out["moved"] = moved
print(json.dumps(out))
