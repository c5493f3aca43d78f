#!/usr/bin/env bash
# What streaming to Foxglove costs the simulation: the same `twin sim` (the shipped humanoid,
# the model-based walker, DURATION simulated seconds, seed 1, `--rtf max`, the default topic
# rates) run three ways, interleaved a, b, c, a, b, c ... REPEAT times:
#   a  no viewer
#   b  --foxglove 0, no client
#   c  --foxglove 0 --wait-for-subscriber 60, with benches/foxglove_subscribe_all.js (npm
#      @foxglove/ws-protocol) subscribed to every channel before the first step, decoding every
#      message with @foxglove/rosmsg2-serialization
# Per row: the medians of the loop's wall µs per step and of the simulation thread's CPU µs per
# step, as `twin sim` reports them, of the whole twin process's CPU (all threads, user + sys,
# GNU time) per step, and the wall overhead against a and b; for c the client's own CPU per
# step, the messages it received and decoded, per topic (last repetition), and those the server
# dropped. On a machine with fewer free cores than the run has busy threads, c's wall time also
# pays for the client's CPU (the scheduler shares the cores): the process CPU column separates
# what the server costs from that.
#   benches/foxglove_stream.sh [DURATION=10] [REPEAT=5]
# PIN=1: twin (all its threads) on CPU 0 and the client on CPU 1 (`taskset`), so that the client's
# decoding does not share the simulation's core; a, b and c alike. Unset: the scheduler places them.
# TWIN: binary (default target/release/twin); FOXGLOVE_NODE_MODULES: node_modules with the
# client's packages (default: the test's, target/tmp/foxglove-node/node_modules; installed there
# with npm when missing).
set -euo pipefail
duration=${1:-10}
repeat=${2:-5}
source "$(dirname "$0")/common.sh"
modules=${FOXGLOVE_NODE_MODULES:-target/tmp/foxglove-node/node_modules}
if [[ ! -f "$modules/@foxglove/rosmsg2-serialization/package.json" ]]; then
  prefix=$(dirname "$modules")
  mkdir -p "$prefix"
  npm install --no-audit --no-fund --prefix "$prefix" @foxglove/ws-protocol@0.8.0 ws@8 @foxglove/rosmsg@5.0.5 \
    @foxglove/rosmsg2-serialization@3.1.0 >/dev/null
fi
modules=$(cd "$modules" && pwd)
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT
pin_twin=() pin_client=()
if [[ "${PIN:-}" == 1 ]]; then pin_twin=(taskset -c 0) pin_client=(taskset -c 1); fi
args=(sim models/humanoid.urdf --controller walk --duration "$duration" --seed 1 --rtf max)

# µs per step (wall, CPU) from twin sim's report.
per_step() {
  awk '/^simulated .* steps of/ { for (i = 1; i <= NF; i++) { if ($i == "steps") n = substr($(i - 1), 2); if ($(i + 1) == "s" && $(i + 2) == "wall:") w = $i } }
       /^simulation thread CPU:/ { c = $4 }
       END { if (!n || !w) exit 1; printf "%.3f %.3f\n", w * 1e6 / n, c * 1e6 / n }' "$1"
}

run_c() {
  local out=$1 client=$2
  /usr/bin/time -f '%U %S' -o "$out.cpu" "${pin_twin[@]}" "$twin" "${args[@]}" --foxglove 0 --wait-for-subscriber 60 >"$out" 2>"$out.err" &
  local sim=$!
  pids+=("$sim")
  local url="" i
  for i in $(seq 600); do
    url=$(sed -n 's|^foxglove: \(ws://[^ ]*\).*|\1|p' "$out" | head -1)
    [[ -n "$url" ]] && break
    kill -0 "$sim" 2>/dev/null || break
    sleep 0.1
  done
  [[ -n "$url" ]] || { echo "twin sim never said where the Foxglove server listens:" >&2; cat "$out" "$out.err" >&2; exit 1; }
  NODE_PATH="$modules" /usr/bin/time -f '%U %S' -o "$client.cpu" "${pin_client[@]}" node benches/foxglove_subscribe_all.js "$url" >"$client" &
  local node=$!
  pids+=("$node")
  wait "$sim" || { echo "twin sim failed:" >&2; cat "$out.err" >&2; exit 1; }
  wait "$node"
}

# User + sys seconds of a GNU time -o file, in µs per step of run $2.
cpu_per_step() { awk -v n="$(sed -n 's/^simulated .*(\([0-9]*\) steps of.*/\1/p' "$2")" '{ printf "%.3f\n", ($1 + $2) * 1e6 / n }' "$1"; }
load0=$(cut -d' ' -f1-3 /proc/loadavg)
declare -A wall=() cpu=() proc=()
node_cpu=""
for r in $(seq "$repeat"); do
  /usr/bin/time -f '%U %S' -o "$work/a.$r.cpu" "${pin_twin[@]}" "$twin" "${args[@]}" >"$work/a.$r" 2>&1
  /usr/bin/time -f '%U %S' -o "$work/b.$r.cpu" "${pin_twin[@]}" "$twin" "${args[@]}" --foxglove 0 >"$work/b.$r" 2>&1
  run_c "$work/c.$r" "$work/client.$r"
  for row in a b c; do
    read -r w c < <(per_step "$work/$row.$r")
    wall[$row]+="$w "
    cpu[$row]+="$c "
    proc[$row]+="$(cpu_per_step "$work/$row.$r.cpu" "$work/$row.$r") "
  done
  node_cpu+="$(cpu_per_step "$work/client.$r.cpu" "$work/c.$r") "
done
echo "$(date -u '+%F %H:%M UTC'), $(nproc) CPUs, load before: $load0; after: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "cores: $(if [[ "${PIN:-}" == 1 ]]; then echo 'PIN=1: twin on CPU 0, client on CPU 1 (taskset)'; else echo 'unpinned (scheduler)'; fi)"
echo "twin ${args[*]}  ($repeat repetitions, interleaved; medians)"
grep -m1 '^simulated' "$work/a.1"
printf '%-44s %12s %12s %13s %9s %9s\n' row "wall µs/step" "loop CPU µs" "process CPU µs" "vs a" "vs b"
wa=$(echo "${wall[a]}" | median)
wb=$(echo "${wall[b]}" | median)
for row in a b c; do
  name=$(case $row in a) echo "a: no viewer";; b) echo "b: --foxglove, no client";; c) echo "c: --foxglove, client on every channel";; esac)
  w=$(echo "${wall[$row]}" | median)
  printf '%-44s %12.2f %12.2f %13.2f %+8.1f%% %+8.1f%%\n' "$name" "$w" "$(echo "${cpu[$row]}" | median)" \
    "$(echo "${proc[$row]}" | median)" \
    "$(awk -v x="$w" -v y="$wa" 'BEGIN { print (x / y - 1) * 100 }')" "$(awk -v x="$w" -v y="$wb" 'BEGIN { print (x / y - 1) * 100 }')"
done
echo "each repetition, wall µs/step: a ${wall[a]}| b ${wall[b]}| c ${wall[c]}"
echo "each repetition, process CPU µs/step: a ${proc[a]}| b ${proc[b]}| c ${proc[c]}"
echo "c, the client's own CPU (node), µs per simulated step: median $(echo "$node_cpu" | median) (each: $node_cpu)"
echo "c, the server: $(grep -h '^viewers:' "$work/c.$repeat")"
echo "c, the client (last repetition), messages received and decoded per topic:"
node -e '
const s = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
let n = 0, b = 0;
for (const [t, v] of Object.entries(s.topics)) { n += v.messages; b += v.bytes; console.log(`  ${t}: ${v.messages} messages, ${v.bytes} bytes`); }
console.log(`  total ${n} messages, ${(b / 1e6).toFixed(1)} MB, ${s.times} time updates, ${s.failures} decode failures, end: ${s.end}`);
if (s.failures > 0 || n === 0) process.exit(1);
' "$work/client.$repeat"
