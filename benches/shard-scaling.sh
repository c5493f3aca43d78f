#!/usr/bin/env bash
# Threads or shards on one machine? Episodes/s of the same batch run as
#   - one process, one thread         (--threads 1: one shard's worth of CPU)
#   - two concurrent shard processes   (--shard 1/2 and 2/2, --threads 1 each, started together)
#   - one process, two threads        (--threads 2)
# wall-clock, whole processes (model load/conversion included), interleaved REPEAT times so all
# rows see the same load; prints the best and the median of each row, then checks that the two
# shards merge into the 2-thread run's summary.
#   benches/shard-scaling.sh [EPISODES=96] [REPEAT=3]   (TWIN: binary, default target/release/twin)
set -euo pipefail
episodes=${1:-96}
repeat=${2:-3}
source "$(dirname "$0")/common.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
args=(randomize --episodes "$episodes" --seed 3)
declare -A secs=()
for r in $(seq "$repeat"); do
  t=$(now); "$twin" "${args[@]}" --threads 1 --out "$work/t1" >/dev/null 2>&1; secs[t1]+="$(since "$t") "
  t=$(now)
  "$twin" "${args[@]}" --threads 1 --shard 1/2 --out "$work/s1" >/dev/null 2>&1 &
  a=$!
  "$twin" "${args[@]}" --threads 1 --shard 2/2 --out "$work/s2" >/dev/null 2>&1 &
  b=$!
  wait "$a" "$b"
  secs[s2]+="$(since "$t") "
  t=$(now); "$twin" "${args[@]}" --threads 2 --out "$work/t2" >/dev/null 2>&1; secs[t2]+="$(since "$t") "
  # Shards leave shard.json: a rerun of a finished shard would be a no-op, not a measurement.
  ((r == repeat)) || rm -rf "$work/s1" "$work/s2"
done
"$twin" randomize merge "$work/s1" "$work/s2" --out "$work/merged" >/dev/null
cmp -s "$work/merged/episodes.csv" "$work/t2/episodes.csv" || { echo "merged shards differ from the 2-thread run" >&2; exit 1; }
echo "$episodes episodes (models/humanoid.urdf, default spec, 5 s), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg), $repeat runs each"
printf '| %-42s | %9s | %9s | %12s |\n' run "best s" "median s" "episodes/s"
row() {
  local times sorted best median
  read -ra times <<<"${secs[$1]}"
  mapfile -t sorted < <(printf '%s\n' "${times[@]}" | sort -g)
  best=${sorted[0]}; median=${sorted[$(( ${#sorted[@]} / 2 ))]}
  printf '| %-42s | %9.2f | %9.2f | %12.1f |\n' "$2" "$best" "$median" "$(awk -v n="$episodes" -v t="$median" 'BEGIN { print n / t }')"
}
row t1 "1 process, --threads 1"
row s2 "2 concurrent shards (1/2, 2/2), --threads 1"
row t2 "1 process, --threads 2"
