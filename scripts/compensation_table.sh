#!/usr/bin/env bash
# The compensation table of the README (issue 26): runs tests/compensate_truth.rs, which generates a
# campaign per cause with a hidden effect, calibrates with that cause, compensates a nominal program of
# 100 poses the calibration never saw, evaluates the compensated joints on the hidden robot (noise 0)
# and prints ISO 9283 positioning accuracy before and after, as a Markdown table.
#   scripts/compensation_table.sh            # a generator seed drawn for the run (printed)
#   scripts/compensation_table.sh 32670      # that seed
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -ge 1 ]; then export ROBOCAL_COMPENSATE_SEED="$1"; fi
cargo test --release --test compensate_truth -- --nocapture 2>&1 | grep -E '^\||^generator seed'
