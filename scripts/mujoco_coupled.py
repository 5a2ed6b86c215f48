"""Static equilibrium of a robot with a coupled (passive) joint and elastic drives, computed by MuJoCo:
the reference for robocal's simulator of coupled chains (issue 25).

The robot is sim/tests/data/coupled_torso.urdf, chain base -> left_flange (CHAIN). Its passive joint
torso_pitch_3 follows theta3 = -(theta1 + theta2) (the URDF's robocal:coupling, which MuJoCo ignores):
here a fixed tendon theta1 + theta2 + theta3 held at length 0 by a tendon equality. Each drive is a
MuJoCo joint spring (stiffness [k, 0, 0], springref = its motor angle q); the passive joint has none.
The branch joints (BRANCH) are deleted in MjSpec: their links stay welded at the joint's zero and load
the chain. At seeded q the arm is settled by mj_step (damped, MuJoCo's soft equality), then polished by
Newton on MuJoCo's forces with the coupling exact (a multiplier lambda on the tendon): qfrc_passive -
qfrc_bias + ten_J' lambda = 0, ten_length = 0. Every rest state is checked against virtual work:
K (q - theta_d) = A' tau_g(theta), theta = A theta_d (+ b = 0), tau_g = qfrc_bias at rest.

Usage:
  python scripts/mujoco_coupled.py [--out DIR] [--compare-to DIR]

Writes DIR/coupled_torso_statics.csv (default DIR: <repo>/golden): comment lines, then `q1..q7` (rad,
the drives' motor angles), `theta1..theta8` (rad, the chain's link-side angles at rest) and `x,y,z` (m,
the origin of left_flange in the base frame). With --compare-to, the new values are compared with the
file of the same name there (q exactly, theta and xyz within 1e-9; exit 1 otherwise).
Requirements: scripts/requirements.txt (mujoco==4.0.0, numpy).
"""

import argparse
import copy
import os
import sys

import mujoco
import numpy as np

from mujoco_branches import read  # the golden CSV's numbers, as the branches' script reads them
from mujoco_reference import write_atomic

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
URDF_REL = "sim/tests/data/coupled_torso.urdf"
FILE = "coupled_torso_statics.csv"
CHAIN = ["torso_yaw", "torso_pitch_1", "torso_pitch_2", "torso_pitch_3", "left_shoulder_pitch",
         "left_shoulder_roll", "left_elbow", "left_wrist"]
PASSIVE = "torso_pitch_3"
SOURCES = ["torso_pitch_1", "torso_pitch_2"]  # theta(PASSIVE) = -(theta1 + theta2) + 0
DRIVES = [j for j in CHAIN if j != PASSIVE]
BRANCH = ["neck_yaw", "neck_pitch", "right_shoulder_pitch", "right_elbow"]
STIFFNESS = [20000.0, 3000.0, 4000.0, 2500.0, 2000.0, 1500.0, 800.0]  # N m/rad, drives in order
TIP, GRAVITY = "left_flange", [0.0, 0.0, -9.81]
N_CONFIGS, SEED = 24, 25
PASSIVE_LIMIT = 1.1  # rad; a configuration whose passive angle at rest leaves it is drawn again
DYN_ARMATURE, DYN_DT, DYN_VEL_TOL, DYN_MAX_STEPS = 0.1, 1e-3, 1e-9, 400000  # the dynamic settle
EQ_SOLREF, EQ_SOLIMP = [0.002, 1.0], [0.99999, 0.99999, 0.001, 0.5, 2.0]  # the coupling equality
DYN_TOL = 1e-7  # rad: the dynamic settle (soft equality) against the Newton root (coupling exact)
FD_STEP, STEP_TOL, MAX_NEWTON = 1e-6, 1e-14, 30  # the Newton polish
CHECK_TOL, COMPARE_TOL = 1e-9, 1e-9  # rad and N m (violation, residuals); rad and m (--compare-to)
HEADER = """\
# Static equilibrium of {urdf}, chain base -> {tip}, with elastic drives and the passive joint {passive}
# coupled: theta({passive}) = -(theta({s1}) + theta({s2})).
# q1..q{nd}: the drives' motor angles (rad): {drives}.
# theta1..theta{nc}: the chain's link-side angles at rest (rad): {chain}.
# x,y,z: the origin of {tip} in the base frame (m). Branch joints {branch} held at zero (deleted).
# Drive stiffness (N m/rad, drive order): {k}; the passive joint has none. Gravity {g} m/s^2.
# Rest state: K (q - theta_d) = A' tau_g(theta), theta = A theta_d, tau_g = MuJoCo qfrc_bias at rest.
# Written by scripts/mujoco_coupled.py (mujoco {mj}, numpy {np}), seed {seed} (np.random.RandomState, each q
# uniform within its URDF limits; a configuration with |theta({passive})| > {lim} at rest drawn again: {redraws} were).
# Verified over all rows: max coupling violation {violation:.1e} rad, max force residual {residual:.1e} N m,
# max virtual-work residual {virtual:.1e} N m; dynamic settle (coupling equality solref {solref}, solimp
# {solimp}) within {dynamic:.1e} rad of the rest state; max sag |q - theta_d| {sag:.4f} rad.
"""


def compile_model(path):
    with open(path) as f:
        spec = mujoco.MjSpec.from_string(f.read())
    for key, value in dict(fusestatic=False, balanceinertia=False, boundmass=0.0, boundinertia=0.0, settotalmass=-1.0,
                           inertiafromgeom=mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE).items():
        setattr(spec.compiler, key, value)
    spec.option.gravity = GRAVITY
    # Limits off: a drive may sag a hair past its limit (the passive one is kept inside by redrawing).
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_LIMIT
    for name in BRANCH:
        spec.delete(spec.joint(name))  # the body is welded to its parent at the joint's zero
    for name in CHAIN:
        js = spec.joint(name)
        js.stiffness = [STIFFNESS[DRIVES.index(name)] if name in DRIVES else 0.0, 0.0, 0.0]
        js.springref = 0.0  # the motor angle, set per configuration through mjModel.qpos_spring
        js.springyield = 0.0
        js.damping, js.frictionloss, js.armature = np.zeros_like(np.asarray(js.damping)), 0.0, 0.0
    ten = spec.add_tendon(name="coupling")
    for name in SOURCES + [PASSIVE]:
        ten.wrap_joint(name, 1.0)
    eq = spec.add_equality(name="coupling", type=mujoco.mjtEq.mjEQ_TENDON, objtype=mujoco.mjtObj.mjOBJ_TENDON,
                           name1="coupling")
    eq.data = np.zeros_like(np.asarray(eq.data))  # one tendon: length - length(qpos0) = data[0] = 0
    eq.solref, eq.solimp = EQ_SOLREF, EQ_SOLIMP  # stiff, so that the dynamic settle lands near the root
    model = spec.compile()
    names = [model.joint(j).name for j in range(model.njnt)]
    k = [STIFFNESS[DRIVES.index(n)] if n in DRIVES else 0.0 for n in CHAIN]
    if names != CHAIN or model.nv != len(CHAIN) or np.any(model.jnt_stiffness != k) \
            or np.any(model.jnt_stiffnesspoly != 0) or np.any(model.dof_damping != 0) \
            or np.any(model.dof_armature != 0) or model.neq != 1 or model.tendon_length0[0] != 0.0:
        raise SystemExit("model not as built: joints %s, stiffness %s" % (names, model.jnt_stiffness))
    return model


def forces(model, data, theta):
    """qfrc_passive - qfrc_bias at rest at theta (N m), the coupling tendon's length and Jacobian."""
    data.qpos[:], data.qvel[:] = theta, 0.0
    mujoco.mj_forward(model, data)
    J = np.zeros((model.ntendon, model.nv))  # MuJoCo 4.0 stores ten_J sparse (rows in mjModel.ten_J_*)
    mujoco.mju_sparse2dense(J, data.ten_J, model.ten_J_rownnz, model.ten_J_rowadr, model.ten_J_colind)
    return data.qfrc_passive - data.qfrc_bias, float(data.ten_length[0]), J[0]


def settle_dynamic(model, data, q_motor):
    """mj_step with armature and critical joint damping, MuJoCo's soft equality holding the coupling."""
    n, dyn = model.nv, copy.copy(model)  # damping and armature change the motion, not the rest state
    forces(model, data, q_motor)
    M = np.zeros((n, n))
    mujoco.mj_fullM(model, data, M)
    inertia = 1.0 / np.diag(np.linalg.inv(M + DYN_ARMATURE * np.eye(n)))
    k = np.maximum(model.jnt_stiffness, min(STIFFNESS))  # the passive joint damped like the softest drive
    dyn.dof_damping[:], dyn.dof_armature[:] = 2.0 * np.sqrt(k * inertia), DYN_ARMATURE
    dyn.opt.timestep, dyn.opt.integrator = DYN_DT, mujoco.mjtIntegrator.mjINT_EULER
    for _ in range(0, DYN_MAX_STEPS, 100):
        mujoco.mj_step(dyn, data, nstep=100)
        if np.max(np.abs(data.qvel)) < DYN_VEL_TOL:
            return data.qpos.copy()
    raise SystemExit("the dynamic settle did not come to rest in %d steps" % DYN_MAX_STEPS)


def settle(model, data, q_motor):
    """The rest state: dynamic settle, then Newton on [r + J' lam, length] = 0 (r, length, J from MuJoCo)."""
    model.qpos_spring[:] = q_motor
    theta0 = settle_dynamic(model, data, q_motor)
    theta, n = theta0.copy(), len(theta0)
    r, length, J = forces(model, data, theta)
    lam = -float(J @ r) / float(J @ J)
    H, E = np.zeros((n + 1, n + 1)), FD_STEP * np.eye(n)
    for _ in range(MAX_NEWTON):  # the Jacobian by central differences: it sets the rate, never the root
        H[:n, :n] = np.array([forces(model, data, theta + e)[0] - forces(model, data, theta - e)[0] for e in E]).T
        H[:n, :n] /= 2 * FD_STEP
        H[:n, n], H[n, :n] = J, J
        step = np.linalg.solve(H, -np.append(r + J * lam, length))
        theta, lam = theta + step[:n], lam + step[n]
        r, length, J = forces(model, data, theta)
        if np.max(np.abs(step[:n])) < STEP_TOL:
            return theta, lam, theta0
    raise SystemExit("Newton did not converge at q = %r" % list(q_motor))


def compute(path):
    model = compile_model(path)
    data = mujoco.MjData(model)
    d_idx = [CHAIN.index(j) for j in DRIVES]
    A = np.zeros((len(CHAIN), len(DRIVES)))  # theta = A theta_d + b, b = 0
    A[d_idx, range(len(DRIVES))] = 1.0
    A[CHAIN.index(PASSIVE), [DRIVES.index(s) for s in SOURCES]] = -1.0
    K, (lo, hi), rng = np.array(STIFFNESS), model.jnt_range[d_idx].T, np.random.RandomState(SEED)
    tip, rows, redraws = model.body(TIP).id, [], 0
    worst = dict(violation=0.0, residual=0.0, virtual=0.0, dynamic=0.0, sag=0.0)
    while len(rows) < N_CONFIGS:
        qd = np.array([rng.uniform(a, b) for a, b in zip(lo, hi)])
        q_motor = A @ qd  # springref of the passive joint is unused (no stiffness)
        theta, lam, theta_dyn = settle(model, data, q_motor)
        if abs(theta[CHAIN.index(PASSIVE)]) > PASSIVE_LIMIT:
            redraws += 1
            continue
        r, length, J = forces(model, data, theta)
        th_d = theta[d_idx]
        worst["violation"] = max(worst["violation"], abs(length), float(np.max(np.abs(theta - A @ th_d))))
        worst["residual"] = max(worst["residual"], float(np.max(np.abs(r + J * lam))))
        worst["virtual"] = max(worst["virtual"], float(np.max(np.abs(K * (qd - th_d) - A.T @ data.qfrc_bias))))
        worst["dynamic"] = max(worst["dynamic"], float(np.max(np.abs(theta_dyn - theta))))
        worst["sag"] = max(worst["sag"], float(np.max(np.abs(qd - th_d))))
        rows.append(list(qd) + list(theta) + list(data.xpos[tip]))
    bad = [k for k in worst if worst[k] > {"dynamic": DYN_TOL, "sag": np.inf}.get(k, CHECK_TOL)]
    if bad:
        raise SystemExit("rest state checks failed: %s" % {k: worst[k] for k in bad})
    nd, nc = len(DRIVES), len(CHAIN)
    head = HEADER.format(urdf=URDF_REL, tip=TIP, passive=PASSIVE, s1=SOURCES[0], s2=SOURCES[1], nd=nd, nc=nc,
                         drives=", ".join(DRIVES), chain=", ".join(CHAIN), k=", ".join("%g" % k for k in STIFFNESS),
                         branch=", ".join(BRANCH), g=GRAVITY, mj=mujoco.__version__, np=np.__version__, seed=SEED,
                         lim=PASSIVE_LIMIT, redraws=redraws, solref=EQ_SOLREF, solimp=EQ_SOLIMP, **worst)
    print("".join(l[2:] + "\n" for l in head.splitlines()[-3:]), end="")
    cols = ["q%d" % (k + 1) for k in range(nd)] + ["theta%d" % (k + 1) for k in range(nc)] + list("xyz")
    lines = [",".join(cols)] + [",".join(repr(float(x)) for x in row) for row in rows]
    return head + "\n".join(lines) + "\n", np.array(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(REPO, "golden"), help="output directory (default <repo>/golden)")
    ap.add_argument("--compare-to", default=None, metavar="DIR",
                    help="compare with %s in DIR; exit 1 on a difference above %g rad or m" % (FILE, COMPARE_TOL))
    args = ap.parse_args(argv)
    text, rows = compute(os.path.join(REPO, URDF_REL))
    status = 0
    if args.compare_to is not None:
        old = read(os.path.join(args.compare_to, FILE))
        nd, nc = len(DRIVES), len(CHAIN)  # columns: q, theta, xyz
        if old.shape != rows.shape or np.any(old[:, :nd] != rows[:, :nd]):
            print("MISMATCH %s: other configurations" % FILE, file=sys.stderr)
            status = 1
        else:
            dt, dx = (float(np.max(np.abs(old[:, a:b] - rows[:, a:b]))) for a, b in ((nd, nd + nc), (nd + nc, None)))
            ok = dt <= COMPARE_TOL and dx <= COMPARE_TOL
            print("%s %s: max |theta diff| %.1e rad, max |xyz diff| %.1e m" % ("OK" if ok else "MISMATCH", FILE, dt, dx))
            status = 0 if ok else 1
    out = os.path.join(args.out, FILE)
    write_atomic(out, text)
    print("wrote %s (%d configurations)" % (out, N_CONFIGS))
    return status


if __name__ == "__main__":
    sys.exit(main())
