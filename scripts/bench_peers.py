#!/usr/bin/env python3
"""Run one synthetic kinematic-calibration problem through robocal and through FIGAROH; print times and
held-out errors side by side.

The problem (made here, independently of both tools, with Pinocchio's forward kinematics): the iiwa 7 of
sim/robots/iiwa7.urdf with every joint placement moved by a random rigid motion (0.1-1 mm, 0.1-1 mrad per
axis, random directions), a tracker 2.7 m away (base at (2.5, 1.0, -0.2) m, yaw 2.5 rad in the tracker
frame), a reflector 5 cm in front of the flange; 200 random training poses and 100 held-out poses within
the joint limits, positions with 10 um isotropic Gaussian noise. Errors are |predicted - true| on the
held-out poses against the noise-free truth.

Setup (nothing here is needed by the Rust test suite):
    python3 -m venv /tmp/figaroh-venv && /tmp/figaroh-venv/bin/pip install figaroh pandas pyyaml
    cargo build --release -p robocal
    /tmp/figaroh-venv/bin/python scripts/bench_peers.py [--seed 1] [--poses 200]

FIGAROH (https://github.com/thanhndv212/figaroh, `pip install figaroh`) calibrates the same data with its
`BaseCalibration` ("full_params": 6 placement errors per joint, plus base and marker), configured by the
unified YAML written below. If it cannot be imported or its calibration fails, the script says so and
prints robocal's numbers alone.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
URDF = ROOT / "sim" / "robots" / "iiwa7.urdf"


def make_problem(seed, n_train, n_test, noise):
    import pinocchio as pin

    rng = np.random.default_rng(seed)
    model = pin.buildModelFromUrdf(str(URDF))
    real = model.copy()

    def random_twist(lo, hi):
        def vec():
            d = rng.normal(size=3)
            return d / np.linalg.norm(d) * rng.uniform(lo, hi)

        return vec(), vec()

    for j in range(1, model.njoints):
        w, v = random_twist(1e-4, 1e-3)
        real.jointPlacements[j] = real.jointPlacements[j] * pin.exp6(pin.Motion(v, w))
    tool = model.getFrameId("iiwa7_flange")
    marker = np.array([0.0, 0.0, 0.05]) + rng.normal(scale=1e-3, size=3)
    rot = pin.rpy.rpyToMatrix(0.0, 0.0, 2.5)
    t_tracker_base = pin.SE3(rot, np.array([2.5, 1.0, -0.2]))
    data = real.createData()
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit

    def sample(n):
        q = lo + (hi - lo) * rng.random((n, model.nq))
        p = np.empty((n, 3))
        for k in range(n):
            pin.framesForwardKinematics(real, data, q[k])
            p[k] = t_tracker_base.act(data.oMf[tool].act(marker))
        return q, p

    q_train, p_train = sample(n_train)
    q_test, p_test = sample(n_test)
    measured = p_train + rng.normal(scale=noise, size=p_train.shape)
    return model, q_train, measured, q_test, p_test


def write_contract(path, q, p, sigma=None):
    n = q.shape[1]
    cols = ["pose"] + [f"q{j + 1}" for j in range(n)] + ["x", "y", "z"] + (["sigma"] if sigma else [])
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for k in range(len(q)):
            row = [str(k)] + [repr(float(v)) for v in q[k]] + [repr(float(v)) for v in p[k]]
            if sigma:
                row.append(repr(sigma))
            f.write(",".join(row) + "\n")


def run_robocal(work, q_train, p_train, q_test, p_test, noise):
    exe = ROOT / "target" / "release" / "robocal"
    if not exe.exists():
        return None, "robocal is not built: cargo build --release -p robocal"
    train = work / "train.csv"
    test = work / "test.csv"
    write_contract(train, q_train, p_train, sigma=noise)
    write_contract(test, q_test, np.zeros_like(p_test))
    model = work / "model.json"
    t0 = time.perf_counter()
    r = subprocess.run(
        [str(exe), "calibrate", "--robot", str(URDF), "--data", str(train), "--out", str(model),
         "--test-fraction", "0", "--json"],
        capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if r.returncode != 0:
        return None, f"robocal calibrate failed: {r.stderr.strip()}"
    report = json.loads(r.stdout)["report"]
    pred = work / "pred.csv"
    r = subprocess.run([str(exe), "predict", "--model", str(model), "--data", str(test), "--out", str(pred)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        return None, f"robocal predict failed: {r.stderr.strip()}"
    p = np.loadtxt(pred, delimiter=",", skiprows=1)[:, 1:4]
    err = np.linalg.norm(p - p_test, axis=1)
    return {"time_s": elapsed, "iterations": report["after"]["solver"]["iterations"],
            "train_rms_m": report["after"]["train"]["rms_m"], "err": err,
            "note": "wall time of the whole `robocal calibrate` process (start-up, file I/O, report)"}, None


FIGAROH_CONFIG = """\
robot:
  name: iiwa7
tasks:
  calibration:
    enabled: true
    type: kinematic_calibration
    parameters:
      calibration_level: full_params
      include_non_geometric: false
      regularization_coefficient: 0.0
      outlier_threshold: 0.05
    kinematics:
      base_frame: universe
      tool_frame: iiwa7_flange
      free_flying_base: false
    measurements:
      markers:
        - reference_joint: iiwa7_A7
          measurable_dof: [true, true, true, false, false, false]
      poses:
        base_pose: null
        tool_pose: null
    data:
      source_file: {data}
      number_of_samples: {n}
"""


def run_figaroh(work, model, q_train, p_train, q_test, p_test):
    try:
        import pinocchio as pin
        from figaroh.calibration.base_calibration import BaseCalibration
        from figaroh.calibration.calibration_tools import calc_updated_fkm
    except Exception as e:  # noqa: BLE001 - report whatever stops the import
        return None, f"FIGAROH cannot be imported: {type(e).__name__}: {e}"
    names = [model.names[j] for j in range(1, model.njoints)]
    data_file = work / "figaroh_train.csv"
    with open(data_file, "w") as f:
        f.write(",".join(["x1", "y1", "z1"] + names) + "\n")
        for k in range(len(q_train)):
            f.write(",".join(repr(float(v)) for v in list(p_train[k]) + list(q_train[k])) + "\n")
    config = work / "figaroh.yaml"
    config.write_text(FIGAROH_CONFIG.format(data=data_file, n=len(q_train)))

    class Robot:
        def __init__(self):
            self.model = pin.buildModelFromUrdf(str(URDF))
            self.data = self.model.createData()
            self.q0 = pin.neutral(self.model)

    class Calib(BaseCalibration):
        def cost_function(self, var):
            pee = calc_updated_fkm(self.model, self.data, var, self.q_measured, self.calib_config)
            return self.apply_measurement_weighting(self.PEE_measured - pee)

    try:
        t0 = time.perf_counter()
        cal = Calib(Robot(), str(config))
        # FIGAROH 1.0.2's unified-config reader never sets these two (legacy) keys, which parameter
        # creation reads: the base (tracker) frame and the marker position are unknown.
        cal.calib_config.setdefault("known_baseframe", False)
        cal.calib_config.setdefault("known_tipframe", False)
        cal.initialize()
        cal.solve(enable_logging=False, plotting=False, save_results=False)
        elapsed = time.perf_counter() - t0
        cfg = dict(cal.calib_config, NbSample=len(q_test))
        # calc_updated_fkm returns x of every sample, then y, then z.
        pred = np.asarray(calc_updated_fkm(cal.model, cal.data, cal.var_, q_test, cfg)).reshape(3, -1).T
        err = np.linalg.norm(pred - p_test, axis=1)
    except Exception as e:  # noqa: BLE001
        return None, f"FIGAROH's calibration failed on this problem: {type(e).__name__}: {e}"
    return {"time_s": elapsed, "iterations": None, "train_rms_m": None, "err": err,
            "note": "initialize() + solve() inside Python (no start-up)"}, None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--poses", type=int, default=200)
    ap.add_argument("--test-poses", type=int, default=100)
    ap.add_argument("--noise", type=float, default=1e-5)
    args = ap.parse_args()
    try:
        model, q_train, p_train, q_test, p_test = make_problem(args.seed, args.poses, args.test_poses, args.noise)
    except ImportError as e:
        sys.exit(f"Pinocchio is needed to make the problem (pip install figaroh brings it): {e}")
    print(f"problem: iiwa 7, {args.poses} training / {args.test_poses} held-out poses, "
          f"{args.noise * 1e6:.1f} um noise, seed {args.seed}")
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        results = {"robocal": run_robocal(work, q_train, p_train, q_test, p_test, args.noise),
                   "FIGAROH": run_figaroh(work, model, q_train, p_train, q_test, p_test)}
    print(f"{'tool':<9} {'time':>10} {'held-out RMS':>14} {'mean':>10} {'max':>10}  notes")
    for name, (res, why) in results.items():
        if res is None:
            print(f"{name:<9} {'-':>10} {'-':>14} {'-':>10} {'-':>10}  {why}")
            continue
        e = res["err"]
        print(f"{name:<9} {res['time_s'] * 1e3:>8.1f}ms {np.sqrt(np.mean(e ** 2)) * 1e6:>11.2f} um "
              f"{np.mean(e) * 1e6:>7.2f} um {np.max(e) * 1e6:>7.2f} um  {res['note']}")


if __name__ == "__main__":
    main()
