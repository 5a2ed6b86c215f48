#!/usr/bin/env python3
"""Benchmark of the Python package against the command line (issue 14): a 100,000-pose DataFrame
through ``robocal.calibrate`` against ``robocal calibrate --data FILE.parquet --out MODEL.json`` on the
same data and flags. Target: Python under 1.2x the CLI's wall time.

Both in release mode: the CLI from ``cargo build --release`` (or $ROBOCAL_BIN), the package as
``pip install ./python`` builds it, imported by the interpreter that runs this script. Runs alternate
(CLI, Python, CLI, …) so that a busy machine slows both alike; prints every run and the medians.
The Python time covers what a notebook user waits for: the DataFrame's conversion to the Rust table,
the calibration and the report as a dict (the CLI's: process start, reading the Parquet file, the
calibration, writing the model file and the JSON report).

    python scripts/bench_python.py [--poses 100000] [--runs 5] [--scenario scenarios/iiwa7_clean.toml]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import pandas as pd

import robocal
from robocal._data import to_table

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--scenario", default=str(REPO / "scenarios" / "iiwa7_clean.toml"))
    ap.add_argument("--model", default="kinematic")
    args = ap.parse_args()
    binary = os.environ.get("ROBOCAL_BIN")
    if not binary:
        subprocess.run(["cargo", "build", "--release", "--quiet", "--bin", "robocal"], cwd=REPO, check=True)
        binary = str(REPO / "target" / "release" / "robocal")
    work = Path(tempfile.gettempdir()) / f"robocal_bench_python_{Path(args.scenario).stem}_{args.poses}"
    data = work / "measurements.parquet"
    if not data.exists():
        subprocess.run([binary, "generate", "--scenario", args.scenario, "--out", str(work), "--seed", "1",
                        "--poses", str(args.poses)], check=True, capture_output=True)
    try:
        frame = pd.read_parquet(data)  # pandas' own reader (pyarrow): the user's DataFrame
    except ImportError:  # no pyarrow: robocal's reader gives the same DataFrame
        frame = robocal.read_table(data)
    print(f"{len(frame)} rows x {len(frame.columns)} columns, model {args.model}; robocal {robocal.__version__}")

    cli_times, py_times, convert_times = [], [], []
    for run in range(args.runs):
        start = time.perf_counter()
        subprocess.run([binary, "calibrate", "--data", str(data), "--model", args.model,
                        "--out", str(work / "cli.json"), "--json"], check=True, capture_output=True)
        cli_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        model = robocal.calibrate(frame, robot="iiwa7", model=args.model)
        py_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        to_table(frame)  # the conversion alone, for the record
        convert_times.append(time.perf_counter() - start)
        print(f"run {run + 1}: CLI {cli_times[-1]:.3f} s, Python {py_times[-1]:.3f} s "
              f"(DataFrame -> table {convert_times[-1] * 1e3:.1f} ms)")
    cli, py = statistics.median(cli_times), statistics.median(py_times)
    rms = model.report["report"]["after"]["train"]["rms_m"]
    print(f"median: CLI {cli:.3f} s, Python {py:.3f} s, ratio {py / cli:.2f} (target < 1.2); "
          f"conversion {statistics.median(convert_times) * 1e3:.1f} ms; train RMS {rms * 1e6:.2f} µm")


if __name__ == "__main__":
    main()
