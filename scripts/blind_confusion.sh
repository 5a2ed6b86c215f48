#!/usr/bin/env bash
# The blind diagnose study behind the confusion matrix of docs/diagnose.md: N cases (default 1,000)
# drawn like tests/diagnose_blind.rs draws its CI cases (every kind in turn, effect, joints and
# magnitude from the seed), each generated and diagnosed with `robocal diagnose --json` as a user
# would. Writes the matrix and every failed case to target/blind-study/confusion.md.
#   scripts/blind_confusion.sh [N] [SEED]
# About 1 s of CPU per case on the project's 2-core machine (two cases run at a time); the programs
# are copied first, so rebuilding while it runs does not change what is studied.
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-1000}"
seed="${2:-1592635677}"
out="target/blind-study"
mkdir -p "$out"
cargo build --release --quiet
test_bin=$(cargo test --release --test diagnose_blind --no-run --message-format=json 2>/dev/null \
  | sed -n 's/.*"executable":"\([^"]*diagnose_blind[^"]*\)".*/\1/p' | tail -1)
cp target/release/robocal "$out/robocal"
cp "$test_bin" "$out/diagnose_blind"
ROBOCAL_BIN="$PWD/$out/robocal" ROBOCAL_BLIND_CASES="$n" ROBOCAL_BLIND_SEED="$seed" \
  ROBOCAL_CONFUSION_OUT="$PWD/$out/confusion.md" \
  "$out/diagnose_blind" --ignored confusion_matrix --nocapture
echo "wrote $out/confusion.md" >&2
