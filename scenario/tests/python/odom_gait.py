"""An independent reading of a walk from its recorded /odom (mcap-ros2-support): prints JSON
{distance_m, forward_m, fall_time_secs}.

distance: horizontal distance between the first and last base positions; forward: along the
direction the robot faced at the start (the base's horizontal axis nearest the direction of
travel, read from the recording alone: the first message's orientation and the whole path);
fall: the first time, from the first message, that the base is below half its first height or
the base axis that pointed up at the start tilts more than 60 degrees (null: none).

Usage: python odom_gait.py WALK.mcap
"""
import json
import math
import sys

from mcap_ros2.reader import read_ros2_messages


def rot(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


msgs = []
for m in read_ros2_messages(sys.argv[1], topics=["/odom"]):
    o = m.ros_msg
    t = o.header.stamp.sec + o.header.stamp.nanosec * 1e-9
    msgs.append((t, o.pose.pose.position, rot(o.pose.pose.orientation)))
if not msgs:
    sys.exit("no /odom in " + sys.argv[1])
t0, p0, r0 = msgs[0]
# The base axis (column of r0) nearest world up at the start.
up_axis = max(range(3), key=lambda j: abs(r0[2][j]))
up_sign = math.copysign(1.0, r0[2][up_axis])
fall = None
for t, p, r in msgs:
    uprightness = up_sign * r[2][up_axis]
    if p.z < 0.5 * p0.z or uprightness < 0.5:
        fall = t - t0
        break
end = msgs[-1] if fall is None else next(m for m in msgs if m[0] - t0 >= fall)
d = (end[1].x - p0.x, end[1].y - p0.y)
# Forward at the start: the base's horizontal axis (other than up) nearest the path's direction.
dist = math.hypot(*d)
best = None
for j in range(3):
    if j == up_axis:
        continue
    a = (r0[0][j], r0[1][j])
    n = math.hypot(*a)
    if n < 1e-9:
        continue
    along = (a[0] * d[0] + a[1] * d[1]) / n
    if best is None or abs(along) > abs(best):
        best = along
print(json.dumps({"distance_m": dist, "forward_m": abs(best) if best is not None else 0.0, "fall_time_secs": fall}))
