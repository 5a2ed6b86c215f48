#!/usr/bin/env bash
# Builds the Python package for the tests without maturin: the extension crate (python/) with cargo in
# the `test` profile, so that it links the dependencies `cargo test --workspace` has already built
# (same profile, same target dir, same features: the crate is a workspace member), then lays it out
# as maturin would (python/robocal/*.py + _robocal.abi3.so) in target/python-pkg. Prints that folder:
#   PYTHONPATH=$(scripts/python_package.sh) python -c 'import robocal'
# (`maturin build --profile test` would build the crate as a test harness; users run
# `pip install ./python`, which builds in release.)
set -euo pipefail
cd "$(dirname "$0")/.."
# As maturin does: do not link libpython (the interpreter that imports the module provides it).
PYO3_BUILD_EXTENSION_MODULE=1 cargo build -p robocal-python --profile test --quiet
pkg="target/python-pkg"
rm -rf "$pkg"
mkdir -p "$pkg"
cp -r python/robocal "$pkg/"
cp target/debug/lib_robocal.so "$pkg/robocal/_robocal.abi3.so"
echo "$PWD/$pkg"
