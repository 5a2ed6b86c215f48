"""Gravity torques of a chain with branches hanging off it, computed by MuJoCo: the reference for
robocal's statics of a chain taken from a tree (issue 25).

The robot is sim/tests/data/torso_two_arms.urdf: a torso with a left arm (the measured chain, tip
link left_flange), a right arm and a head on movable joints off the torso, and a camera welded to it.
MuJoCo compiles the URDF as it is (every body kept, no static fusion, inertials as written) and
evaluates, at seeded configurations of the chain's joints with every branch joint at zero, the
generalized force that holds the robot still against gravity (qfrc_bias with zero velocity). Those
are the holding torques of the chain's joints, branches included.

Usage:
  python scripts/mujoco_branches.py [--out DIR] [--compare-to DIR]

Writes DIR/gravity_torso_two_arms.csv (default DIR: <repo>/golden): comment lines, then
`q1..q4` (rad, the chain's joints from the base) and `tau1..tau4` (N m). With --compare-to, the new
values are compared with the file of the same name there (exit 1 beyond 1e-9 N m).
Requirements: scripts/requirements.txt (mujoco==4.0.0, numpy).
"""

import argparse
import os
import sys

import mujoco
import numpy as np

from mujoco_reference import write_atomic

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
URDF_REL = "sim/tests/data/torso_two_arms.urdf"
FILE = "gravity_torso_two_arms.csv"
CHAIN = ["torso_pitch", "left_shoulder_pitch", "left_elbow", "left_wrist"]
BRANCH = ["neck_yaw", "neck_pitch", "right_shoulder_pitch", "right_elbow"]
GRAVITY = [0.0, 0.0, -9.81]
N_CONFIGS = 24
SEED = 25
COMPARE_TOL = 1e-9


def compile_model(path):
    with open(path) as f:
        spec = mujoco.MjSpec.from_string(f.read())
    c = spec.compiler
    c.fusestatic = False  # keep every body: the camera stays welded by its own fixed joint
    c.balanceinertia = False
    c.boundmass = 0.0
    c.boundinertia = 0.0
    c.settotalmass = -1.0
    c.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.gravity = GRAVITY
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return spec.compile()


def compute(path):
    model = compile_model(path)
    data = mujoco.MjData(model)
    names = [model.joint(j).name for j in range(model.njnt)]
    if sorted(names) != sorted(CHAIN + BRANCH):
        raise SystemExit("unexpected joints in %s: %s" % (path, names))
    chain = [model.joint(n) for n in CHAIN]
    rng = np.random.RandomState(SEED)
    lines = [
        "# Holding torques against gravity of the chain base -> left_flange of %s, with the branch joints"
        % URDF_REL,
        "# (%s) at zero: MuJoCo qfrc_bias at zero velocity, gravity %s m/s^2." % (", ".join(BRANCH), GRAVITY),
        "# Written by scripts/mujoco_branches.py (mujoco %s, numpy %s), seed %d."
        % (mujoco.__version__, np.__version__, SEED),
        ",".join(["q%d" % (k + 1) for k in range(len(CHAIN))] + ["tau%d" % (k + 1) for k in range(len(CHAIN))]),
    ]
    rows = []
    for _ in range(N_CONFIGS):
        data.qpos[:] = 0.0
        data.qvel[:] = 0.0
        q = [rng.uniform(*model.jnt_range[j.id]) for j in chain]
        for j, v in zip(chain, q):
            data.qpos[model.jnt_qposadr[j.id]] = v
        mujoco.mj_forward(model, data)
        tau = [float(data.qfrc_bias[model.jnt_dofadr[j.id]]) for j in chain]
        rows.append(q + tau)
        lines.append(",".join(repr(float(x)) for x in q + tau))
    return "\n".join(lines) + "\n", np.array(rows)


def read(path):
    with open(path) as f:
        return np.array([[float(x) for x in l.split(",")] for l in f if l[0] not in "#q"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(REPO, "golden"), help="output directory (default <repo>/golden)")
    ap.add_argument("--compare-to", default=None, metavar="DIR",
                    help="compare with %s in DIR; exit 1 on a difference above %g N m" % (FILE, COMPARE_TOL))
    args = ap.parse_args(argv)
    text, rows = compute(os.path.join(REPO, URDF_REL))
    status = 0
    if args.compare_to is not None:
        old = read(os.path.join(args.compare_to, FILE))
        n = len(CHAIN)
        if old.shape != rows.shape or np.any(old[:, :n] != rows[:, :n]):
            print("MISMATCH %s: other configurations" % FILE, file=sys.stderr)
            status = 1
        else:
            d = float(np.max(np.abs(old[:, n:] - rows[:, n:])))
            print("%s %s: max |tau diff| %.1e N m" % ("OK" if d <= COMPARE_TOL else "MISMATCH", FILE, d))
            status = 0 if d <= COMPARE_TOL else 1
    out = os.path.join(args.out, FILE)
    write_atomic(out, text)
    print("wrote %s (%d configurations)" % (out, N_CONFIGS))
    return status


if __name__ == "__main__":
    sys.exit(main())
