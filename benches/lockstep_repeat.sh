#!/bin/bash
# Repeatability of lockstep with an external controller (issue 40): N runs (default 20) of
# `twin randomize --scenario S --episodes E --seed 4` into OUT/r<k> under a busy loop per core
# (every run at 1 thread but the last, at 2), each run's episodes.csv compared with run 0's, and
# what twin's repeat check (the first episode run again) said of each run.
# Usage: benches/lockstep_repeat.sh SCENARIO EPISODES [RUNS] OUT   (TWIN: the binary to run)
set -u
S=$1; E=$2; N=${3:-20}; OUT=$4
mkdir -p "$OUT"
busy=()
for _ in $(seq "$(nproc)"); do (while :; do :; done) & busy+=($!); done
start=$(date +%s.%N)
for k in $(seq 0 $((N-1))); do
  th=1; [ $k -eq $((N-1)) ] && th=2
  ${TWIN:-target/release/twin} randomize --scenario $S --episodes $E --threads $th --seed 4 --out $OUT/r$k > $OUT/r$k.log 2>&1
  pass=$(grep -c "controller=PASS" $OUT/r$k/episodes.csv)
  if cmp -s $OUT/r0/episodes.csv $OUT/r$k/episodes.csv; then same=identical; else same=DIFFERS; fi
  if grep -q "warning: episode 0 run again" $OUT/r$k.log; then rep="repeat check: DIFFERS"; else rep="repeat check: same"; fi
  echo "run $k threads $th: $pass/$E controller=PASS, $same, $rep, $(date +%s.%N)"
done
kill "${busy[@]}"
end=$(date +%s.%N)
echo "wall $(echo "$end - $start" | bc) s"
