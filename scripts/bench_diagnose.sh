#!/usr/bin/env bash
# Benchmark of `robocal diagnose` on large data (issues 11 and 12): 100,000 poses of a scenario, every
# candidate cause, the probes for unexplained structure and the learned models, in release mode, on all
# cores. Prints the wall time of each run, the median, and the peak resident memory.
# Targets: iiwa7_clean under 6 s (issue 11); iiwa7_all under 15 s with peak memory under 1 GB (issue 12).
# Usage: [ROBOCAL_BIN=…] scripts/bench_diagnose.sh [SCENARIO.toml] [POSES] [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
scenario="${1:-scenarios/iiwa7_clean.toml}"
poses="${2:-100000}"
runs="${3:-3}"
out="${TMPDIR:-/tmp}/robocal_bench_diagnose_$(basename "$scenario" .toml)_$poses"
# ROBOCAL_BIN=path/to/robocal compares another build (e.g. an earlier commit's) on the same data.
if [ -n "${ROBOCAL_BIN:-}" ]; then
  bin="$ROBOCAL_BIN"
else
  cargo build --release --quiet --bin robocal
  bin="${CARGO_TARGET_DIR:-target}/release/robocal"
fi
if [ ! -f "$out/measurements.parquet" ]; then
  "$bin" generate --scenario "$scenario" --out "$out" --seed 1 --poses "$poses" >/dev/null 2>&1
fi
times=()
for k in $(seq "$runs"); do
  start=$(date +%s.%N)
  if [ -x /usr/bin/time ]; then
    /usr/bin/time -f "%M" -o "$out/rss_kb" "$bin" diagnose --data "$out/measurements.parquet" --json > "$out/diagnosis.json"
  else
    "$bin" diagnose --data "$out/measurements.parquet" --json > "$out/diagnosis.json"
  fi
  end=$(date +%s.%N)
  t=$(echo "$end - $start" | bc)
  times+=("$t")
  rss=$( [ -f "$out/rss_kb" ] && echo "$(( $(cat "$out/rss_kb") / 1024 )) MB" || echo "n/a")
  echo "run $k: $t s, peak RSS $rss"
done
median=$(printf '%s\n' "${times[@]}" | sort -n | sed -n "$(( (runs + 1) / 2 ))p")
echo "bench_diagnose: $(basename "$scenario") $poses poses: median $median s over $runs runs (nproc $(nproc)); model $(grep -o '"model": "[^"]*"' "$out/diagnosis.json" | tail -1)"
