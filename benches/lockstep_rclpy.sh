#!/usr/bin/env bash
# Lockstep period round trip with a real rclpy node (ROS 2 Kilted wheels, Fast DDS, loopback
# only): `twin sim --ros --lockstep` against the README's gait_controller.py (taken verbatim from
# README.md), RUNS times; prints twin's round-trip line (/clock out → command in, p50/p99) and
# the wall time of each run, and the same against the in-process pd-hold for scale.
#
#   benches/lockstep_rclpy.sh [DURATION_S=10] [RUNS=3]
#
# Needs: target/release/twin (cargo build --release --bin twin) and TWIN_PYTHON (or python3)
# with .ci/requirements.txt installed (ros-kilted-rclpy, -sensor-msgs, -std-msgs,
# -rmw-fastrtps-cpp, ...). Every run uses a domain of its own (ROS_DOMAIN_ID 150+k), DDS on
# loopback only (UDPv4 on 127.0.0.1, no multicast).
set -euo pipefail
cd "$(dirname "$0")/.."
duration="${1:-10}"
runs="${2:-3}"
py="${TWIN_PYTHON:-python3}"
twin=target/release/twin
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The README's node, verbatim (the python block after its heading line).
awk '/A complete 100 Hz controller \(`gait_controller.py`\)/{f=1} f&&/^```python/{p=1;next} p&&/^```/{exit} p' \
  README.md > "$work/gait_controller.py"
# The loopback-only Fast DDS profile twin ships (twin_bridges::live::loopback::FASTDDS_PROFILE).
sed -n '/^pub const FASTDDS_PROFILE: &str = r#"/,/^"#;/p' bridges/src/live/loopback.rs | sed '1s/.*r#"//;$d' \
  > "$work/fastdds.xml"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST FASTDDS_DEFAULT_PROFILES_FILE="$work/fastdds.xml"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp

echo "machine: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg), $(date -u +%FT%TZ), $(git rev-parse --short HEAD)"
for k in $(seq 1 "$runs"); do
  domain=$((150 + k))
  start=$(date +%s.%N)
  ROS_DOMAIN_ID=$domain "$twin" sim --ros --lockstep --duration "$duration" > "$work/twin.out" 2> "$work/twin.err" &
  twin_pid=$!
  (cd "$work" && ROS_DOMAIN_ID=$domain exec "$py" gait_controller.py --ros-args -p use_sim_time:=true) \
    > "$work/node.out" 2>&1 &
  node_pid=$!
  if ! wait "$twin_pid"; then
    kill -INT "$node_pid" 2>/dev/null || true
    cat "$work/twin.out" "$work/twin.err" >&2
    exit 1
  fi
  kill -INT "$node_pid" 2>/dev/null || true
  wait "$node_pid" 2>/dev/null || true
  end=$(date +%s.%N)
  echo "run $k: $(grep -h 'lockstep round trip' "$work/twin.out"); $(grep -h 'joined after' "$work/twin.out"); \
$(grep -h 'control periods' "$work/twin.out" | cut -d';' -f1); wall $(echo "$end - $start" | bc) s (load $(cut -d' ' -f1 /proc/loadavg))"
done
# For scale: the same robot and duration with the control law in process.
/usr/bin/time -f "in process (pd-hold): %e s wall" "$twin" sim --controller pd-hold --duration "$duration" 2>&1 \
  | grep -E 'real-time factor|in process'
