#!/usr/bin/env bash
# Benchmark of `robocal sweep` (issue 7): 3 noise levels × 5 pose counts × 100 repetitions of the iiwa 7
# kinematic scenario = 1,500 generate-calibrate-score runs, in release mode, on all cores (rayon; set
# RAYON_NUM_THREADS to choose). Target: under 30 s on the project's 2-core machine.
# Usage: scripts/bench_sweep.sh [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-${TMPDIR:-/tmp}/robocal_bench_sweep}"
mkdir -p "$out"
cargo build --release --quiet
bin="${CARGO_TARGET_DIR:-target}/release/robocal"
start=$(date +%s.%N)
"$bin" sweep --scenario scenarios/iiwa7_kinematic.toml \
    --noise 0.5,1,2 --poses 25,50,100,200,400 --reps 100 --seed 1 \
    --out "$out/bench.parquet"
end=$(date +%s.%N)
echo "bench_sweep: 1500 runs in $(echo "$end - $start" | bc) s wall (nproc $(nproc))"
