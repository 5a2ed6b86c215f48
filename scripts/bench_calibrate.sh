#!/usr/bin/env bash
# Benchmark of `robocal calibrate` on large data (issue 13): 100,000 poses of iiwa7_clean, the model
# fitted on every pose with --folds 0 (no validation) and with the default 5-fold cross-validation
# (folds in parallel), in release mode, on all cores. Prints the wall and CPU time of each run and the
# medians. With ROBOCAL_BASE=path/to/robocal it also times that build's default calibrate (before issue
# 13: 70 % of the poses fitted, 30 % held out) on the same data, interleaved run by run, for the
# side-by-side comparison the targets ask for (the machine's speed varies).
# Targets: --folds 0 no slower than the base build's default; default folds under 4x --folds 0.
# Usage: [ROBOCAL_BIN=…] [ROBOCAL_BASE=…] scripts/bench_calibrate.sh [POSES] [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
poses="${1:-100000}"
runs="${2:-5}"
out="${TMPDIR:-/tmp}/robocal_bench_calibrate_$poses"
if [ -n "${ROBOCAL_BIN:-}" ]; then
  bin="$ROBOCAL_BIN"
else
  cargo build --release --quiet --bin robocal
  bin="${CARGO_TARGET_DIR:-target}/release/robocal"
fi
mkdir -p "$out"
if [ ! -f "$out/clean/measurements.parquet" ]; then
  "$bin" generate --scenario scenarios/iiwa7_clean.toml --out "$out/clean" --seed 1 --poses "$poses" >/dev/null 2>&1
fi
data="$out/clean/measurements.parquet"
declare -A wall cpu
time_one() { # label, binary, args...
  local label="$1" b="$2"; shift 2
  local s e t c
  s=$(date +%s.%N)
  /usr/bin/time -f "%U %S" -o "$out/cpu" "$b" calibrate --data "$data" --out "$out/model_$label.json" "$@" >/dev/null 2>&1
  e=$(date +%s.%N)
  t=$(echo "$e - $s" | bc)
  c=$(awk '{print $1 + $2}' "$out/cpu")
  wall[$label]+="$t "
  cpu[$label]+="$c "
  echo "run $k $label: wall $t s, cpu $c s"
}
for k in $(seq "$runs"); do
  if [ -n "${ROBOCAL_BASE:-}" ]; then time_one base_default "$ROBOCAL_BASE"; fi
  time_one folds0 "$bin" --folds 0
  time_one folds5 "$bin"
done
median() { tr ' ' '\n' | grep -v '^$' | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
for label in base_default folds0 folds5; do
  [ -n "${wall[$label]:-}" ] || continue
  echo "bench_calibrate: $label: median wall $(echo "${wall[$label]}" | median) s, median cpu $(echo "${cpu[$label]}" | median) s over $runs runs ($poses poses, nproc $(nproc))"
done
