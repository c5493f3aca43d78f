#!/usr/bin/env bash
# Sourced by the benches' shell scripts (after `set -euo pipefail` and their arguments): moves to
# the repository root, sets `twin` to the binary (TWIN, default target/release/twin, built when
# missing) and gives the timing helpers every script uses:
#   now              wall-clock seconds (date +%s.%N)
#   since T          seconds elapsed since `now` printed T, 3 decimals
#   median           the median of the numbers on stdin (blank-separated or one per line)
cd "$(dirname "${BASH_SOURCE[0]}")/.."
twin=${TWIN:-target/release/twin}
[[ -x "$twin" ]] || cargo build --release --locked --bin twin
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.3f", b - a }'; }
median() { tr ' ' '\n' | grep . | sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
