#!/usr/bin/env python3
"""`calibrate --ur-kinematics FILE.yaml`, checked with UR's own macros (issue 26).

For the built-in UR5 and UR10 (campaigns generated with drawn kinematic errors) and the real UR5
(Jacobi 2025) and UR10 (Landgraf 2021, series B, with its 6-DoF orientation) data in ../shared/data/real/,
this script runs robocal as a user would:

  1. `robocal calibrate --robot urX --data D --out M.json --ur-kinematics K.yaml`;
  2. expands ../shared/data/robots/ur_description/urdf/ur.urdf.xacro with PyPI's `xacro` and
     `kinematics_params:=K.yaml` (ROS' `$(find ur_description)` is replaced by the folder's path in a
     copy, since no ROS is installed);
  3. computes the forward kinematics of the expanded URDF from `base_link_inertia` to `tool0` at 200
     random configurations (robocal fk, i.e. sim's URDF reader: the file's joint origins as URDF
     defines them, independent of the writer in calib) and carries the target into it by the file's
     `robocal: target_in_tool0_m`;
  4. compares with `robocal predict` of the same configurations, turned into the base frame by the
     model file's `T_tracker_base`: every target within 1e-9 m.

Usage: python scripts/check_ur_kinematics.py ROBOCAL_BINARY [--shared DIR] [--keep DIR]
Exit status: 0 all checks passed; 1 a check failed (the message says which); 2 bad usage or setup.
"""

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile

import yaml
import xacro

TOLERANCE_M = 1e-9
CONFIGURATIONS = 200


def run(cmd, **kw):
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if p.returncode != 0:
        sys.exit(f"check_ur_kinematics: {' '.join(map(str, cmd))} failed ({p.returncode}): {p.stderr.strip()}")
    return p.stdout


def expand(ur_description, ur_type, kinematics, out):
    """ur.urdf.xacro expanded with `kinematics` as kinematics_params, into `out`."""
    doc = xacro.process_file(
        os.path.join(ur_description, "urdf", "ur.urdf.xacro"),
        mappings={"ur_type": ur_type, "name": "ur", "kinematics_params": kinematics},
    )
    with open(out, "w") as f:
        f.write(doc.toprettyxml(indent="  "))


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def check(robocal, work, ur_description, name, ur_type, data, rng):
    model = os.path.join(work, f"{name}.json")
    kin = os.path.join(work, f"{name}.yaml")
    run([robocal, "calibrate", "--robot", ur_type, "--data", data, "--out", model, "--folds", "0",
         "--ur-kinematics", kin])
    urdf = os.path.join(work, f"{name}.urdf")
    expand(ur_description, ur_type, kin, urdf)
    with open(kin) as f:
        k = yaml.safe_load(f)
    target = k["robocal"]["target_in_tool0_m"]
    with open(model) as f:
        m = json.load(f)
    tb = m["parameters"]["t_tracker_base"]
    rot, trans = tb["rotation"], tb["translation_m"]
    limits = [(-2 * math.pi, 2 * math.pi)] * 6
    limits[2] = (-math.pi, math.pi)
    configs = [[rng.uniform(lo, hi) for lo, hi in limits] for _ in range(CONFIGURATIONS)]
    table = os.path.join(work, f"{name}_q.csv")
    with open(table, "w") as f:
        f.write("pose," + ",".join(f"q{j}" for j in range(1, 7)) + "\n")
        for i, q in enumerate(configs):
            f.write(f"{i}," + ",".join(repr(v) for v in q) + "\n")
    pred = os.path.join(work, f"{name}_pred.csv")
    run([robocal, "predict", "--model", model, "--data", table, "--out", pred])
    with open(pred) as f:
        rows = [list(map(float, line.split(",")[1:4])) for line in f.read().splitlines()[1:]]
    worst = 0.0
    for q, p in zip(configs, rows):
        # Tracker frame to base frame: p_base = Rᵀ (p − t).
        d = [p[i] - trans[i] for i in range(3)]
        p_base = [sum(rot[j][i] * d[j] for j in range(3)) for i in range(3)]
        fk = json.loads(run([robocal, "fk", "--robot", urdf, "--base-link", "base_link_inertia",
                             "--tip-link", "tool0", "--q", ",".join(repr(v) for v in q), "--json"]))
        r, t = fk["rotation"], fk["position_m"]
        x = [t[i] + sum(r[i][j] * target[j] for j in range(3)) for i in range(3)]
        worst = max(worst, math.dist(x, p_base))
    print(f"{name}: expanded ur.urdf.xacro against robocal predict, {CONFIGURATIONS} configurations: "
          f"largest difference {worst:.2e} m")
    return worst <= TOLERANCE_M


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("robocal")
    ap.add_argument("--shared", default=os.path.join(os.path.dirname(__file__), "..", "..", "shared"))
    ap.add_argument("--keep", default=None, help="keep the files in this folder")
    a = ap.parse_args()
    shared = os.path.abspath(a.shared)
    work = a.keep or tempfile.mkdtemp(prefix="robocal_ur_kinematics_")
    os.makedirs(work, exist_ok=True)
    # ur_description with ROS' $(find ur_description) replaced by its path.
    urd = os.path.join(work, "ur_description")
    shutil.rmtree(urd, ignore_errors=True)
    shutil.copytree(os.path.join(shared, "data", "robots", "ur_description"), urd)
    for root, _, files in os.walk(os.path.join(urd, "urdf")):
        for fn in files:
            path = os.path.join(root, fn)
            with open(path) as f:
                text = f.read()
            with open(path, "w") as f:
                f.write(text.replace("$(find ur_description)", urd))
    repo = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    cases = []
    for ur_type in ["ur5", "ur10"]:
        scenario = os.path.join(work, f"{ur_type}_kinematic.toml")
        with open(os.path.join(repo, "scenarios", "ur5_kinematic.toml")) as f:
            text = f.read()
        with open(scenario, "w") as f:
            f.write(text.replace('name = "ur5"', f'name = "{ur_type}"'))
        out = os.path.join(work, f"gen_{ur_type}")
        run([a.robocal, "generate", "--scenario", scenario, "--out", out, "--seed", "3"])
        cases.append((f"builtin_{ur_type}", ur_type, os.path.join(out, "measurements.parquet")))
    real = os.path.join(shared, "data", "real")
    cases.append(("real_ur5_jacobi2025", "ur5", os.path.join(real, "ur5_jacobi2025_grid.csv")))
    cases.append(("real_ur10_landgraf2021B", "ur10", os.path.join(real, "ur10_landgraf2021_seriesB.csv")))
    rng = random.Random(26)
    ok = True
    for name, ur_type, data in cases:
        ok &= check(a.robocal, work, urd, name, ur_type, data, rng)
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    if not ok:
        sys.exit(f"check_ur_kinematics: a difference above {TOLERANCE_M} m")
    print("check_ur_kinematics: every UR kinematics file reproduces the calibrated model")


if __name__ == "__main__":
    main()
