#!/usr/bin/env bash
# Contact cost: the humanoid walking (walk_rough.toml's walker and 18 s) on flat ground (a plane)
# against rough ground (±1 cm heightfield at walk_rough.toml's 0.05-m cells, and at 0.1-m cells).
# Each row is `twin sim`'s simulation-thread CPU time per physics step (walker + mj_step, less
# sensitive to a loaded machine than wall time), as steps/s of one core; REPEAT interleaved runs
# per row, best and median. Also prints how far each walked (the same gait, so the same work).
#   benches/contact_cost.sh [REPEAT=3]   (TWIN: binary, default target/release/twin)
set -euo pipefail
repeat=${1:-3}
source "$(dirname "$0")/common.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
model="$PWD/models/humanoid.urdf"
base=$(sed "s#^model = .*#model = \"$model\"#" scenarios/walk_rough.toml)
# The flat row: the same file with the terrain table replaced by a flat one.
awk '/^\[terrain\]/ { print "[terrain]\nkind = \"flat\"\n"; skip = 1; next } /^\[/ { skip = 0 } !skip' \
  <<<"$base" >"$work/flat.toml"
printf '%s\n' "$base" >"$work/rough.toml"
sed 's/^seed = 0 .*/seed = 0\ncell_m = 0.1/' <<<"$base" >"$work/rough10.toml"
grep -q '^cell_m = 0.1' "$work/rough10.toml" || { echo "contact_cost.sh: could not set cell_m" >&2; exit 1; }
declare -A us=() fwd=()
for r in $(seq "$repeat"); do
  for k in flat rough rough10; do
    out=$("$twin" sim --scenario "$work/$k.toml" 2>&1 || true)
    us[$k]+="$(sed -n 's/.*simulation thread CPU: .* (\([0-9.]*\) µs per step).*/\1/p' <<<"$out") "
    fwd[$k]=$(sed -n 's/.*(forward \([-0-9.]*\) m,.*/\1/p' <<<"$out" | head -1)
  done
done
echo "humanoid, walk_rough.toml's walker, 18 s at 2 ms; $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg); $repeat runs each"
printf '| %-44s | %11s | %13s | %15s | %9s |\n' ground "best µs/step" "median µs/step" "median steps/s" "forward m"
row() {
  local best median
  best=$(tr ' ' '\n' <<<"${us[$1]}" | grep . | sort -g | head -1)
  median=$(median <<<"${us[$1]}")
  printf '| %-44s | %11.1f | %13.1f | %15.0f | %9s |\n' "$2" "$best" "$median" \
    "$(awk -v t="$median" 'BEGIN { print 1e6 / t }')" "${fwd[$1]}"
}
row flat "flat (plane)"
row rough "rough ±1 cm, heightfield 0.05-m cells"
row rough10 "rough ±1 cm, heightfield 0.1-m cells"
