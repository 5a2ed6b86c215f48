#!/usr/bin/env bash
# Time and peak memory of the commands that read large measurement files (issue 28): `predict`
# (streams in pieces of --chunk-rows) and `calibrate --folds 0` (in memory, without the kept
# Jacobian above 2^24 entries), on POSES poses of iiwa7_clean (default 1,000,000; 10,000,000 needs
# about 4 GB of disk for the generated files). The model predicted with is calibrated on 2,000 other
# poses. Prints one line per command: wall seconds and peak resident memory (GNU time's %M).
# With `calibrate` (or `register`, or `validate`, or a comma-separated list of them) as the second
# argument, also `calibrate --folds 0`, `register` of the file as a new campaign of the model, and
# `calibrate` with its default validation (5 folds, 5 regions) (all streamed above 262,144 rows).
# With `diagnose`: `diagnose` (streamed: a sample of 100,000 rows diagnosed, the rest predicted) on
# POSES poses of iiwa7_all, generated beside the others.
# Usage: [ROBOCAL_BIN=…] scripts/bench_streaming.sh [POSES] [calibrate|register|validate|diagnose|…,…]
set -euo pipefail
cd "$(dirname "$0")/.."
poses="${1:-1000000}"
with_calibrate="${2:-}"
out="${TMPDIR:-/tmp}/robocal_bench_streaming_$poses"
if [ -n "${ROBOCAL_BIN:-}" ]; then
  bin="$ROBOCAL_BIN"
else
  cargo build --release --quiet --bin robocal
  bin="${CARGO_TARGET_DIR:-target}/release/robocal"
fi
mkdir -p "$out"
if [ ! -f "$out/big/measurements.parquet" ]; then
  "$bin" generate --scenario scenarios/iiwa7_clean.toml --out "$out/big" --seed 1 --poses "$poses" >/dev/null 2>&1
fi
if [ ! -f "$out/model.json" ]; then
  "$bin" generate --scenario scenarios/iiwa7_clean.toml --out "$out/small" --seed 2 --poses 2000 >/dev/null 2>&1
  "$bin" calibrate --data "$out/small/measurements.parquet" --out "$out/model.json" >/dev/null 2>&1
fi
measure() { # label, args...
  local label="$1"; shift
  /usr/bin/time -o "$out/time.txt" -f "%e %M" "$bin" "$@" >/dev/null 2>&1
  local t; t=$(tail -1 "$out/time.txt")
  echo "bench_streaming: $label, $poses rows: wall ${t%% *} s, peak $(( ${t##* } / 1024 )) MB"
}
measure predict predict --model "$out/model.json" --data "$out/big/measurements.parquet" --out "$out/predicted.csv"
if [[ ",$with_calibrate," == *",calibrate,"* ]]; then
  measure "calibrate --folds 0" calibrate --data "$out/big/measurements.parquet" --out "$out/m.json" --folds 0
fi
if [[ ",$with_calibrate," == *",register,"* ]]; then
  measure "register" register --model "$out/model.json" --data "$out/big/measurements.parquet" --out "$out/r.json"
fi
if [[ ",$with_calibrate," == *",validate,"* ]]; then
  measure "calibrate (5 folds, 5 regions)" calibrate --data "$out/big/measurements.parquet" --out "$out/m.json"
fi
if [[ ",$with_calibrate," == *",diagnose,"* ]]; then
  if [ ! -f "$out/all/measurements.parquet" ]; then
    "$bin" generate --scenario scenarios/iiwa7_all.toml --out "$out/all" --seed 1 --poses "$poses" >/dev/null 2>&1
  fi
  measure "diagnose (iiwa7_all)" diagnose --data "$out/all/measurements.parquet"
fi
rm -f "$out/predicted.csv" "$out/m.json" "$out/r.json"
