#!/usr/bin/env bash
# An external rclpy controller against the same control law in process, in `twin randomize`:
#   - pd-hold            in process: hold the start pose with the hold gains (--controller pd-hold)
#   - rclpy, restart=episode  scenarios/controllers/hold_pose.py, a fresh process per episode
#   - rclpy, restart=never    the same node, one process per worker, the simulation reset under it
# on the same scenario (scenarios/hold_pose.toml, its duration overridden), EPISODES episodes on
# 2 threads, wall-clock of the whole command, interleaved REPEAT times; prints episodes/s and the
# wall seconds per episode of each row, and, from the rclpy rows, the per-episode cost of a
# process start (restart=episode minus restart=never, per episode per worker).
#   benches/external_controller.sh [EPISODES=8] [DURATION=2] [REPEAT=2]
# TWIN: binary (default target/release/twin); TWIN_PYTHON: a Python with rclpy.
set -euo pipefail
episodes=${1:-8}
duration=${2:-2}
repeat=${3:-2}
source "$(dirname "$0")/common.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
sed 's/^restart = "episode".*/restart = "never"/' scenarios/hold_pose.toml > scenarios/.bench_hold_never.toml
trap 'rm -rf "$work" scenarios/.bench_hold_never.toml' EXIT
args=(randomize --episodes "$episodes" --threads 2 --seed 3 --duration "$duration")
declare -A secs=()
for r in $(seq "$repeat"); do
  t=$(now); "$twin" "${args[@]}" --scenario scenarios/hold_pose.toml --controller pd-hold --out "$work/pd" >/dev/null 2>&1; secs[pd]+="$(since "$t") "
  t=$(now); "$twin" "${args[@]}" --scenario scenarios/hold_pose.toml --out "$work/ep" >/dev/null 2>&1; secs[ep]+="$(since "$t") "
  t=$(now); "$twin" "${args[@]}" --scenario scenarios/.bench_hold_never.toml --out "$work/nv" >/dev/null 2>&1; secs[nv]+="$(since "$t") "
done
printf '%-26s %10s %12s %14s\n' row "wall (s)" "episodes/s" "s per episode"
for row in pd ep nv; do
  m=$(echo "${secs[$row]}" | median)
  name=$(case $row in pd) echo "pd-hold in process";; ep) echo "rclpy, restart=episode";; nv) echo "rclpy, restart=never";; esac)
  printf '%-26s %10.2f %12.2f %14.3f\n' "$name" "$m" "$(awk -v m="$m" -v e="$episodes" 'BEGIN { print e / m }')" "$(awk -v m="$m" -v e="$episodes" 'BEGIN { print m / e }')"
done
ep=$(echo "${secs[ep]}" | median); nv=$(echo "${secs[nv]}" | median)
echo "process start + join + stop, per episode per worker: $(awk -v a="$ep" -v b="$nv" -v e="$episodes" 'BEGIN { printf "%.3f", (a - b) / e * 2 }') s"
for d in pd ep nv; do echo "$d: $(grep -c . "$work/$d/episodes.csv") lines, $(awk -F, 'NR > 1 { s += $2 } END { print s }' "$work/$d/episodes.csv") successes"; done
