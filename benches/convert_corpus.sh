#!/usr/bin/env bash
# Times `twin convert` on every URDF of example-robot-data 6.0.0 (meshes included: package://
# resolution and Collada/ASCII STL → OBJ conversion, written next to each output), one file at
# a time, and prints the total and the slowest file.
# Usage: benches/convert_corpus.sh [path/to/twin]   (default: target/release/twin)
set -euo pipefail
twin="${1:-target/release/twin}"
cache="${TWIN_URDF_CACHE:-$HOME/.cache/twin/urdf-cache}"
python3 "$(dirname "$0")/../twin-core/tests/python/fetch_example_robot_data.py" "$cache"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
total=0
worst=0
worst_file=""
while IFS= read -r urdf; do
  name=$(basename "$urdf" .urdf)
  start=$(date +%s%N)
  "$twin" convert "$urdf" -o "$out/$name.xml" >/dev/null 2>&1 || echo "refused: $urdf"
  ms=$(( ($(date +%s%N) - start) / 1000000 ))
  total=$((total + ms))
  if (( ms > worst )); then worst=$ms; worst_file=$name; fi
done < <(find "$cache/cmeel.prefix/share/example-robot-data/robots" -name '*.urdf' | sort)
echo "total ${total} ms, slowest ${worst_file} ${worst} ms"
