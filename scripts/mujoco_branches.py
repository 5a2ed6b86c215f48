"""Gravity torques of a chain with branches hanging off it, computed by MuJoCo: the reference for
robocal's statics of a chain taken from a tree (issue 25).

The robot is sim/tests/data/torso_two_arms.urdf: a torso with a left arm (the measured chain, tip
link left_flange), a right arm and a head on movable joints off the torso, and a camera welded to it.
MuJoCo compiles the URDF as it is (every body kept, no static fusion, inertials as written) and
evaluates the generalized force that holds the robot still against gravity (qfrc_bias with zero
velocity) at seeded configurations. Those are the holding torques of the chain's joints, branches
included.

Usage:
  python scripts/mujoco_branches.py [--out DIR] [--compare-to DIR]

Writes two files in DIR (default DIR: <repo>/golden), each comment lines (starting with `#`), a
header line, then one row per configuration:
  gravity_torso_two_arms.csv        the branch joints at zero; seed 25, 24 rows:
                                    `q1..q4` (rad, the chain's joints from the base), `tau1..tau4` (N m).
  gravity_torso_two_arms_posed.csv  the branch joints posed (robocal reads them from the measurement
                                    table's `q_<joint name>` columns); seed 2501, 24 rows:
                                    `q1..q4`, `q_neck_yaw, q_neck_pitch, q_right_shoulder_pitch,
                                    q_right_elbow` (rad), `tau1..tau4` (N m).
Every joint value is drawn uniformly within the joint's limits (MuJoCo jnt_range), each file from its
own random stream. The posed file is checked not to be blind to the branch pose: in most rows its
torso torque differs from the one with the branches at zero (same chain configuration) by more than
1 N m (exit 1 otherwise). With --compare-to, both files are compared with the files of the same
name there: the same configurations exactly and the torques within 1e-9 N m, one OK/MISMATCH line
per file, exit 1 on any mismatch. Files are written atomically.
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
FILE_POSED = "gravity_torso_two_arms_posed.csv"
CHAIN = ["torso_pitch", "left_shoulder_pitch", "left_elbow", "left_wrist"]
BRANCH = ["neck_yaw", "neck_pitch", "right_shoulder_pitch", "right_elbow"]
GRAVITY = [0.0, 0.0, -9.81]
N_CONFIGS = 24
SEED = 25
N_CONFIGS_POSED = 24
SEED_POSED = 2501  # a stream of its own: the file with the branches at zero keeps its draws
COMPARE_TOL = 1e-9
# The posed file must see the branch pose: the torso joint's torque moves by more than this (N m)
# from the one with the branches at zero in more than half of its rows.
POSE_EFFECT_NM = 1.0


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


def holding_torques(model, data, values):
    """The chain's holding torques (N m) with the joints of `values` (name -> rad) set, all others zero."""
    data.qpos[:] = 0.0
    data.qvel[:] = 0.0
    for name, v in values.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = v
    mujoco.mj_forward(model, data)
    return [float(data.qfrc_bias[model.jnt_dofadr[model.joint(n).id]]) for n in CHAIN]


def draw(model, rng, names):
    """One configuration of the joints `names`, each uniform within its limits, drawn in that order."""
    return [rng.uniform(*model.jnt_range[model.joint(n).id]) for n in names]


def compute(model, data):
    """The file with the branch joints at zero: (text, rows of q1..q4, tau1..tau4)."""
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
        q = draw(model, rng, CHAIN)
        tau = holding_torques(model, data, dict(zip(CHAIN, q)))
        rows.append(q + tau)
        lines.append(",".join(repr(float(x)) for x in q + tau))
    return "\n".join(lines) + "\n", np.array(rows)


def compute_posed(model, data):
    """The file with the branch joints posed: (text, rows of q1..q4, q_<branch>..., tau1..tau4, and
    the torques at the same chain configuration with the branches at zero)."""
    rng = np.random.RandomState(SEED_POSED)
    n = len(CHAIN)
    lines = [
        "# Holding torques against gravity of the chain base -> left_flange of %s, with the branch joints"
        % URDF_REL,
        "# (%s) posed: each row draws the chain's joints, then the branch joints, uniformly within their"
        % ", ".join(BRANCH),
        "# limits (MuJoCo jnt_range). MuJoCo qfrc_bias at zero velocity, gravity %s m/s^2. Columns: q1..q%d"
        % (GRAVITY, n),
        "# (rad, the chain's joints from the base), q_<branch joint> (rad, named as robocal's measurement"
        " table names them), tau1..tau%d (N m)." % n,
        "# Written by scripts/mujoco_branches.py (mujoco %s, numpy %s), seed %d."
        % (mujoco.__version__, np.__version__, SEED_POSED),
        ",".join(["q%d" % (k + 1) for k in range(n)] + ["q_" + b for b in BRANCH]
                 + ["tau%d" % (k + 1) for k in range(n)]),
    ]
    rows, at_zero = [], []
    for _ in range(N_CONFIGS_POSED):
        q = draw(model, rng, CHAIN)
        qb = draw(model, rng, BRANCH)
        tau = holding_torques(model, data, dict(zip(CHAIN + BRANCH, q + qb)))
        at_zero.append(holding_torques(model, data, dict(zip(CHAIN, q))))
        rows.append(q + qb + tau)
        lines.append(",".join(repr(float(x)) for x in q + qb + tau))
    return "\n".join(lines) + "\n", np.array(rows), np.array(at_zero)


def check_pose_effect(rows, at_zero):
    """Exit 1 unless the branch pose moves the torso joint's torque by more than POSE_EFFECT_NM in most
    rows; prints the largest difference (and that of the arm's joints, which carry no branch)."""
    n = len(CHAIN)
    tau = rows[:, -n:]
    d = np.abs(tau - at_zero)
    seen = int(np.sum(d[:, 0] > POSE_EFFECT_NM))
    print("%s: branch pose against branches at zero: torso |tau1 diff| max %.3f N m, > %g N m in %d of %d rows;"
          " arm joints max %.1e N m" % (FILE_POSED, float(d[:, 0].max()), POSE_EFFECT_NM, seen, len(rows),
                                        float(d[:, 1:].max())))
    if 2 * seen <= len(rows):
        print("FAIL %s is nearly blind to the branch pose" % FILE_POSED, file=sys.stderr)
        return 1
    return 0


def read(path):
    with open(path) as f:
        return np.array([[float(x) for x in l.split(",")] for l in f if l[0] not in "#q"])


def compare(name, old_dir, rows):
    """Compares `rows` with DIR/name: the configurations exactly, the torques within COMPARE_TOL.
    Prints one OK/MISMATCH line; returns 0 or 1."""
    n = len(CHAIN)
    path = os.path.join(old_dir, name)
    if not os.path.isfile(path):
        print("MISMATCH %s: no %s" % (name, path), file=sys.stderr)
        return 1
    old = read(path)
    if old.shape != rows.shape or np.any(old[:, :-n] != rows[:, :-n]):
        print("MISMATCH %s: other configurations" % name, file=sys.stderr)
        return 1
    d = float(np.max(np.abs(old[:, -n:] - rows[:, -n:])))
    ok = d <= COMPARE_TOL
    print("%s %s: max |tau diff| %.1e N m" % ("OK" if ok else "MISMATCH", name, d))
    return 0 if ok else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(REPO, "golden"), help="output directory (default <repo>/golden)")
    ap.add_argument("--compare-to", default=None, metavar="DIR",
                    help="compare with %s and %s in DIR; exit 1 on other configurations or a torque difference"
                    " above %g N m" % (FILE, FILE_POSED, COMPARE_TOL))
    args = ap.parse_args(argv)
    path = os.path.join(REPO, URDF_REL)
    model = compile_model(path)
    data = mujoco.MjData(model)
    names = [model.joint(j).name for j in range(model.njnt)]
    if sorted(names) != sorted(CHAIN + BRANCH):
        raise SystemExit("unexpected joints in %s: %s" % (path, names))
    text, rows = compute(model, data)
    text_posed, rows_posed, at_zero = compute_posed(model, data)
    status = check_pose_effect(rows_posed, at_zero)
    if args.compare_to is not None:
        status |= compare(FILE, args.compare_to, rows)
        status |= compare(FILE_POSED, args.compare_to, rows_posed)
    for name, t, k in [(FILE, text, N_CONFIGS), (FILE_POSED, text_posed, N_CONFIGS_POSED)]:
        out = os.path.join(args.out, name)
        write_atomic(out, t)
        print("wrote %s (%d configurations)" % (out, k))
    return status


if __name__ == "__main__":
    sys.exit(main())
