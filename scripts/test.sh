#!/usr/bin/env bash
# The whole robocal test suite: the Rust tests plus the independent Python references they are checked
# against. Sets up a Python venv (.venv, pinned by scripts/requirements.txt) on first use.
#   ./scripts/test.sh            run everything
#   ROBOCAL_SKIP_LINT=1 ...      skip cargo fmt/clippy
#   ROBOCAL_SKIP_SLURM=1 ...     skip the sweep on a one-node Slurm cluster (it installs slurm-wlm and
#                                munge with apt-get when missing, which needs root)
set -euo pipefail
cd "$(dirname "$0")/.."

# Creates the venv $1. Python's ensurepip fails now and then on a busy machine (once in a CI run,
# the same command succeeding right after), so a failed attempt is removed and tried again.
make_venv() {
  local attempt
  for attempt in 1 2 3; do
    if python3 -m venv "$1"; then
      return 0
    fi
    echo "python3 -m venv $1 failed (attempt $attempt of 3)" >&2
    rm -rf "$1"
    sleep 2
  done
  return 1
}

venv=".venv"
if [ ! -x "$venv/bin/python" ] || ! cmp -s scripts/requirements.txt "$venv/.requirements"; then
  echo "== setting up the Python venv ($venv) from scripts/requirements.txt" >&2
  make_venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r scripts/requirements.txt
  cp scripts/requirements.txt "$venv/.requirements"
fi
py="$venv/bin/python"

echo "== shipped DH robots against their published tables" >&2
"$py" scripts/check_dh_urdfs.py

echo "== no import cycles between source files, no import up a floor of calib" >&2
"$py" scripts/check_import_cycles.py
"$py" scripts/check_floors.py

echo "== MuJoCo reference, re-run live and compared with the stored golden files" >&2
live="target/golden-live"
mkdir -p "$live"
"$py" scripts/mujoco_reference.py --out "$live" --compare-to golden
"$py" scripts/mujoco_branches.py --out "$live" --compare-to golden
"$py" scripts/mujoco_coupled.py --out "$live" --compare-to golden
export ROBOCAL_GOLDEN_LIVE="$PWD/$live"

echo "== Parquet as pandas, polars and DuckDB write it (read back by the Rust tests)" >&2
variants="target/reader-variants"
"$py" scripts/write_reader_variants.py ../shared/data/real/ur5_jacobi2025_grid.csv "$variants"
export ROBOCAL_READER_VARIANTS="$PWD/$variants"

if [ -z "${ROBOCAL_SKIP_LINT:-}" ]; then
  echo "== cargo fmt --check and clippy" >&2
  cargo fmt --all -- --check
  cargo clippy --workspace --all-targets --quiet -- -D warnings
fi

echo "== cargo test" >&2
cargo test --workspace --no-fail-fast

echo "== the Python package (python/): built on the test build's dependencies, checked against the CLI" >&2
pyvenv="target/python-venv"
if [ ! -x "$pyvenv/bin/python" ] || ! cmp -s python/requirements-test.txt "$pyvenv/.requirements"; then
  rm -rf "$pyvenv"
  make_venv "$pyvenv"
  "$pyvenv/bin/pip" install --quiet --disable-pip-version-check -r python/requirements-test.txt
  # numpy, pandas and polars come from the main venv (a .pth line), which stays as it is.
  site=$("$pyvenv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  "$py" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])' > "$site/robocal_main_venv.pth"
  cp python/requirements-test.txt "$pyvenv/.requirements"
fi
pkg=$(./scripts/python_package.sh)
PYTHONPATH="$pkg" ROBOCAL_BIN="$PWD/target/debug/robocal" "$pyvenv/bin/python" -m pytest -q python/tests

echo "== pandas, polars and DuckDB read robocal's own tables identically" >&2
cargo test --workspace --quiet --test measurement_table -- --ignored write_files_for_check_readers
tmp="${TMPDIR:-/tmp}"
"$py" scripts/check_readers.py "$tmp/robocal_table.parquet" "$tmp/robocal_table.csv"
"$py" scripts/check_readers.py "$tmp/robocal_ur5.parquet" "$tmp/robocal_ur5.csv"

# The binary the integration tests ran (cargo test builds it; the line prints its path).
robocal=$(cargo test --workspace --quiet --no-run --message-format=json 2>/dev/null \
  | "$py" -c 'import json, sys
found = []
for line in sys.stdin:
    m = json.loads(line)
    t = m.get("target", {})
    if m.get("reason") == "compiler-artifact" and t.get("name") == "robocal" and "bin" in t.get("kind", []) \
            and not m["profile"]["test"]:
        found.append(m["executable"])
print(found[0] if found else "")')
[ -x "$robocal" ] || { echo "no robocal binary from cargo test" >&2; exit 1; }

echo "== the calibrated URDF: XML diff and MuJoCo forward kinematics against robocal predict" >&2
"$py" scripts/check_urdf_out.py "$robocal"

echo "== UR's kinematics file (--ur-kinematics): ur_description's ur.urdf.xacro expanded with it, against robocal predict" >&2
"$py" scripts/check_ur_kinematics.py "$robocal"

echo "== the worked stiffness study (scripts/study_stiffness.py), a seeded subset: it runs and writes its table" >&2
study=target/study-smoke
rm -rf "$study"
"$py" scripts/study_stiffness.py --robocal "$robocal" --payloads 0,7 --poses 25,50 --reps 2 --out "$study" > /dev/null
# Header and 2 payload sets × 2 pose counts × 7 joints.
[ "$(wc -l < "$study/stiffness_study.csv")" -eq 29 ] && grep -q "<svg" "$study/stiffness_study.svg" \
  || { echo "study_stiffness.py wrote no complete table" >&2; exit 1; }

echo "== planned against random poses for compliance (scripts/study_planning.py), a seeded subset" >&2
planning=target/planning-smoke
rm -rf "$planning"
"$py" scripts/study_planning.py --robocal "$robocal" --poses 40 --reps 2 --out "$planning" > /dev/null
# Header and, for both selections, the determined stiffnesses (joints 2 to 6 of the iiwa 7).
[ "$(grep -c '^planned,40,' "$planning/planned_vs_random.csv")" -eq 5 ] \
  && [ "$(grep -c '^random,40,' "$planning/planned_vs_random.csv")" -eq 5 ] \
  && grep -q "<svg" "$planning/planned_vs_random.svg" \
  || { echo "study_planning.py wrote no complete table" >&2; exit 1; }

echo "== the growth figure of the streamed commands (scripts/streaming_growth.py), on small tables" >&2
growth=target/growth-smoke
rm -rf "$growth"
TMPDIR="$growth/tmp" "$py" scripts/streaming_growth.py --robocal "$robocal" --rows 2000,4000 --out "$growth" > /dev/null
# Header and 2 commands × 2 sizes.
[ "$(wc -l < "$growth/streaming_growth.csv")" -eq 5 ] && grep -q "<svg" "$growth/streaming_growth.svg" \
  || { echo "streaming_growth.py wrote no complete table" >&2; exit 1; }

if [ -z "${ROBOCAL_SKIP_SLURM:-}" ]; then
  echo "== a sweep as a Slurm job array on a one-node cluster, merged: the bytes of one machine" >&2
  ROBOCAL="$robocal" ./scripts/slurm_check.sh
fi
