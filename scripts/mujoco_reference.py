#!/usr/bin/env python3
"""Golden reference data for the `sim` crate, computed with MuJoCo.

For every robot this script loads the URDF into MuJoCo, draws 500 joint configurations uniformly within
the URDF joint limits (numpy.random.default_rng(20261123), one `rng.uniform(lower, upper, size=(500, n))`
call, joints ordered from root to tip, continuous joints in [-pi, pi]) and writes
`golden/kinematics_<robot>.csv` with, per configuration:

  * q1..qN            joint positions (rad for revolute / continuous joints, m for prismatic joints);
  * px, py, pz        position of the tip link's URDF frame in the root link's URDF frame (m);
  * r11 .. r33        rotation matrix of that frame, row-major (dimensionless);
  * tau1..tauN        gravity torques: MuJoCo `qfrc_bias` with qvel = 0 and gravity (0, 0, -9.81) m/s^2
                      along the root link's -z axis, i.e. the torque (N m; N for prismatic joints) each
                      joint must supply to hold the pose.

MuJoCo URDF importer details handled here:

  * the importer fuses static (fixed-joint) bodies by default (`compiler.fusestatic` is switched on by
    the URDF parser); it is switched off so the tip link (behind a fixed joint) and the root link stay
    bodies of their own, and the pose is taken as (root body pose)^-1 * (tip body pose);
  * a URDF link called `world` becomes MuJoCo's world body (iiwa_stack's root);
  * `<dynamics damping/friction>` are imported as joint damping / frictionloss; they do not enter
    `qfrc_bias` (checked: zeroing them changes no bit of the output);
  * third-party ROS exports carry `package://` meshes, Gazebo, transmission and ros2_control tags (the
    latter two with `<joint>` children of their own): every `<visual>`, `<collision>`, `<gazebo>`,
    `<transmission>` and `<ros2_control>` element is removed in memory before MuJoCo sees the file;
  * a massless link behind a movable joint (legal URDF) makes MuJoCo refuse the model; it gets a tiny
    mass and the torques are extrapolated linearly to zero mass (exact: qfrc_bias is linear in masses);
  * `<mimic>` joints would be silently ignored by MuJoCo: they are refused (exit 2);
  * MuJoCo stores inertia diagonalised (principal axes); masses and centres of mass are checked
    against the URDF, and the full inertia tensor rebuilt from MuJoCo's principal axes is checked against
    the URDF tensor (balanceinertia / boundmass / boundinertia / settotalmass are kept off).

Independent cross-checks done on every run (the script fails with exit status 3 if one fails):
a plain numpy forward kinematics / gravity-torque computation straight from the URDF text, which must
agree with MuJoCo to 1e-12 m and 1e-10 N m (absolute); the fixed reference points of the iiwa7
variants (flange at (0, 0, 1.266) m at q = 0; an independent Pinocchio 4.1 value for the two ROS exports);
and, for ur5 / ur10 / wam, the published Denavit-Hartenberg tables (tip pose at every configuration,
1e-12).

Settle experiment (robots in SETTLE_ROBOTS, i.e. iiwa7): `golden/settle_<robot>.csv` holds the compliant
arm at rest under gravity for 200 configurations (numpy.random.default_rng(20261124), within the URDF
limits) x two joint-stiffness sets x payload 0 and 3 kg (a point mass at a stated point of the tip link
frame): joint i is a MuJoCo 4.0 joint spring (`stiffness` = [k_i, 0, 0], `springref` = q_i), and the link-side
angles theta solve qfrc_passive = qfrc_bias at qvel = 0, i.e. K (q - theta) = tau_g(theta), by Newton on
MuJoCo's own forces. See the comment above SETTLE_ROBOTS for why Newton rather than stepping, and for the
checks done on every run (residual, the numpy torque balance, a dynamic mj_step settle of a few poses).

Deflection experiment (same robots): `golden/settle_deflection_<robot>.csv` holds the arm with link
deflection (sim::effects::link_deflection: the child side of a joint tilts about two axes u, v across the
joint axis under the moment it carries) at rest under gravity, for 200 configurations
(numpy.random.default_rng(20261125)) x two compliance sets (deflection across every axis with rigid joints;
deflection at joints 2, 4, 6 together with the stiff joint springs) x payload 0 and 3 kg: each deflecting
joint's child body gets two more MuJoCo hinges about u and v with stiffness [1/c, 0, 0] and springref 0, and
joints and hinges settle together (Newton on MuJoCo's forces). Checked on every run against the numpy URDF
reference of the same chain written as URDF with the hinges as revolute joints. See the comment above
DEFLECTION_SEED.

Usage:
  python scripts/mujoco_reference.py [--out DIR] [--shared DIR] [--robots a,b,...] [--compare-to DIR]
                                     [--experiment all|kinematics|settle|deflection]

`--experiment` (default all) selects kinematics_<robot>.csv, the settle files (settle_<robot>.csv and
settle_deflection_<robot>.csv), the deflection file alone, or all of them; each file is the same bytes
whichever is chosen.

Exit status: 0 OK; 1 a --compare-to mismatch; 2 a URDF that was asked for is missing or unparsable (or
an unknown robot name); 3 an internal consistency check failed.
Requirements: scripts/requirements.txt (mujoco==4.0.0, numpy).
"""

import argparse
import hashlib
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT_REL = "scripts/mujoco_reference.py"

SEED = 20261123
N_CONFIGS = 500
GRAVITY = (0.0, 0.0, -9.81)

# name -> (base, path relative to base, tip link); base "repo" = repository root, "shared" = shared dir.
ROBOTS = {
    "iiwa7": ("repo", "sim/robots/iiwa7.urdf", "iiwa7_flange"),
    "ur5": ("repo", "sim/robots/ur5.urdf", "ur5_flange"),
    "ur10": ("repo", "sim/robots/ur10.urdf", "ur10_flange"),
    "wam": ("repo", "sim/robots/wam.urdf", "wam_flange"),
    "iiwa_stack_iiwa7": ("shared", "data/robots/iiwa_stack_iiwa7.urdf", "iiwa_link_ee"),
    "lbr_stack_iiwa7": ("shared", "data/robots/lbr_stack_iiwa7.urdf", "lbr_link_ee"),
}

STRIP_TAGS = ("visual", "collision", "gazebo", "transmission", "ros2_control")
MOVABLE = ("revolute", "continuous", "prismatic")

COMPARE_TOL = 1e-12
MASSLESS_EPS = 1e-6  # kg, see compute_robot
SELF_POS_TOL = 1e-12
SELF_ROT_TOL = 1e-12
SELF_TAU_TOL = 1e-10
SELF_INERTIA_TOL = 1e-12

# Fixed reference points: robot -> list of (label, q, expected tip position, tolerance in m).
Q_PIN = (0.1, 0.2, -0.3, -1.2, 0.4, 0.5, -0.6)
P_PIN = (0.586678450550, -0.065874910531, 0.766998508288)  # Pinocchio 4.1, ../shared/data/robots/README.md
CHECKS = {
    "iiwa7": [("q = 0", (0.0,) * 7, (0.0, 0.0, 1.266), 1e-12)],
    "iiwa_stack_iiwa7": [
        ("q = 0", (0.0,) * 7, (0.0, 0.0, 1.266), 1e-12),
        ("Pinocchio q = " + str(Q_PIN), Q_PIN, P_PIN, 1e-11),
    ],
    "lbr_stack_iiwa7": [
        ("q = 0", (0.0,) * 7, (0.0, 0.0, 1.266), 1e-12),
        ("Pinocchio q = " + str(Q_PIN), Q_PIN, P_PIN, 1e-11),
    ],
}


# Published standard Denavit-Hartenberg tables (a, d, alpha; theta_i = q_i), independent of the URDF text:
# Universal Robots "DH Parameters for calculations of kinematics and dynamics" (UR5, UR10 tables) and
# Barrett "WAM Arm User's Manual" D1001 (7-DoF WAM). The URDFs of this project place the base link at DH
# frame 0 and the flange at the last DH frame, so MuJoCo's tip pose must equal the DH product.
HALF_PI = math.pi / 2
DH = {
    "ur5": ([0, -0.425, -0.39225, 0, 0, 0], [0.089159, 0, 0, 0.10915, 0.09465, 0.0823],
            [HALF_PI, 0, 0, HALF_PI, -HALF_PI, 0]),
    "ur10": ([0, -0.612, -0.5723, 0, 0, 0], [0.1273, 0, 0, 0.163941, 0.1157, 0.0922],
             [HALF_PI, 0, 0, HALF_PI, -HALF_PI, 0]),
    "wam": ([0, 0, 0.045, -0.045, 0, 0, 0], [0, 0, 0.55, 0, 0.3, 0, 0.06],
            [-HALF_PI, HALF_PI, -HALF_PI, HALF_PI, -HALF_PI, HALF_PI, 0]),
}


def dh_pose(table, q):
    T = np.eye(4)
    for a, d, al, th in zip(*table, q):
        ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                          [0, sa, ca, d], [0, 0, 0, 1]])
    return T[:3, 3], T[:3, :3]


class UrdfError(Exception):
    pass


class CheckError(Exception):
    pass


# ----------------------------------------------------------------------------------------------------
# URDF reading (also used for the independent numpy cross-check)


def _floats(text, n, default):
    if text is None:
        return np.array(default, dtype=float)
    vals = [float(v) for v in text.split()]
    if len(vals) != n:
        raise UrdfError("expected %d numbers, got %r" % (n, text))
    return np.array(vals, dtype=float)


def rpy_matrix(rpy):
    """URDF rpy: fixed-axis roll about x, then pitch about y, then yaw about z: R = Rz(y) Ry(p) Rx(r)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def axis_angle_matrix(axis, angle):
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


def _origin(elem):
    o = elem.find("origin") if elem is not None else None
    if o is None:
        return np.zeros(3), np.eye(3)
    return _floats(o.get("xyz"), 3, [0, 0, 0]), rpy_matrix(_floats(o.get("rpy"), 3, [0, 0, 0]))


def load_urdf(path, tip):
    """Parse and clean a URDF. Returns (cleaned xml text, description dict)."""
    try:
        tree = ET.parse(path)
    except (OSError, ET.ParseError) as e:
        raise UrdfError("cannot parse %s: %s" % (path, e))
    root = tree.getroot()
    if root.tag != "robot":
        raise UrdfError("%s: root element is <%s>, not <robot>" % (path, root.tag))
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag in STRIP_TAGS:
                parent.remove(child)

    links = {}
    for l in root.findall("link"):
        inertial = l.find("inertial")
        if inertial is None:
            links[l.get("name")] = None
        else:
            c, R = _origin(inertial)
            m = float(inertial.find("mass").get("value"))
            ie = inertial.find("inertia")
            g = lambda k: float(ie.get(k, "0")) if ie is not None else 0.0
            I = np.array(
                [
                    [g("ixx"), g("ixy"), g("ixz")],
                    [g("ixy"), g("iyy"), g("iyz")],
                    [g("ixz"), g("iyz"), g("izz")],
                ]
            )
            links[l.get("name")] = (m, c, R @ I @ R.T)
    joints = {}  # child link -> joint description
    for j in root.findall("joint"):  # direct children of <robot> only
        jt = j.get("type")
        if j.find("mimic") is not None:
            raise UrdfError("%s: joint %s is a mimic joint (MuJoCo would ignore the coupling)" % (path, j.get("name")))
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        xyz, R = _origin(j)
        axis = _floats(j.find("axis").get("xyz") if j.find("axis") is not None else None, 3, [1, 0, 0])
        if jt in MOVABLE:
            axis = axis / np.linalg.norm(axis)
        lim = j.find("limit")
        if jt == "continuous":
            lo, hi = -math.pi, math.pi
        elif jt in ("revolute", "prismatic"):
            if lim is None:
                raise UrdfError("%s: joint %s has no <limit>" % (path, j.get("name")))
            lo, hi = float(lim.get("lower", "0")), float(lim.get("upper", "0"))
        elif jt == "fixed":
            lo = hi = None
        else:
            raise UrdfError("%s: joint %s of type %s is not supported" % (path, j.get("name"), jt))
        if child in joints:
            raise UrdfError("%s: link %s has two parent joints" % (path, child))
        joints[child] = dict(name=j.get("name"), type=jt, parent=parent, child=child, xyz=xyz, R=R,
                             axis=axis, lower=lo, upper=hi)
    roots = [l for l in links if l not in joints]
    if len(roots) != 1:
        raise UrdfError("%s: expected one root link, found %r" % (path, roots))
    if tip not in links:
        raise UrdfError("%s: tip link %s not found" % (path, tip))
    chain = []
    l = tip
    while l != roots[0]:
        chain.append(joints[l])
        l = joints[l]["parent"]
    chain.reverse()
    movable = [j for j in chain if j["type"] in MOVABLE]
    others = [j["name"] for j in joints.values() if j["type"] in MOVABLE and j not in movable]
    if others:
        raise UrdfError("%s: movable joints off the root-tip chain are not supported: %r" % (path, others))
    desc = dict(root=roots[0], tip=tip, links=links, joints=joints, chain=chain, movable=movable)
    return ET.tostring(root, encoding="unicode"), desc


def numpy_reference(desc, q):
    """Tip pose in the root frame and gravity torques, straight from the URDF (independent of MuJoCo)."""
    g = np.array(GRAVITY)
    frames = {desc["root"]: (np.zeros(3), np.eye(3))}
    axes = []  # (joint position, joint axis in the root frame, type, child link, joint name)
    # every link of the tree (all off-chain joints are fixed, so their links hang on at fixed offsets)
    order = [desc["root"]]
    children = {}
    for j in desc["joints"].values():
        children.setdefault(j["parent"], []).append(j)
    i = 0
    qmap = {j["name"]: q[n] for n, j in enumerate(desc["movable"])}
    while i < len(order):
        p, R = frames[order[i]]
        for j in children.get(order[i], []):
            pj, Rj = p + R @ j["xyz"], R @ j["R"]
            if j["type"] in ("revolute", "continuous"):
                axes.append((pj, Rj @ j["axis"], j["type"], j["child"], j["name"]))
                Rj = Rj @ axis_angle_matrix(j["axis"], qmap[j["name"]])
            elif j["type"] == "prismatic":
                axes.append((pj, Rj @ j["axis"], j["type"], j["child"], j["name"]))
                pj = pj + Rj @ j["axis"] * qmap[j["name"]]
            frames[j["child"]] = (pj, Rj)
            order.append(j["child"])
        i += 1

    def subtree(link):
        out = [link]
        for j in children.get(link, []):
            out += subtree(j["child"])
        return out

    tau = []
    by_name = {a[4]: a for a in axes}
    for j in desc["movable"]:
        pj, a, jt, child, _ = by_name[j["name"]]
        t = 0.0
        for l in subtree(child):
            if desc["links"][l] is None:
                continue
            m, c, _I = desc["links"][l]
            pl, Rl = frames[l]
            f = m * g
            if jt == "prismatic":
                t -= a @ f
            else:
                t -= a @ np.cross(pl + Rl @ c - pj, f)
        tau.append(t)
    p, R = frames[desc["tip"]]
    return p, R, np.array(tau)


# ----------------------------------------------------------------------------------------------------
# MuJoCo


def massless_moving_links(desc):
    """Links without mass behind a movable joint: MuJoCo refuses them ("mass and inertia of moving
    bodies must be larger than mjMINVAL")."""
    return [l for l, j in desc["joints"].items()
            if j["type"] in MOVABLE and (desc["links"][l] is None or desc["links"][l][0] == 0.0)]


def build_model(xml, desc, keep_joint_dynamics=False, eps=0.0):
    """Compile the cleaned URDF; massless moving links get mass `eps` (kg) at their origin."""
    spec = mujoco.MjSpec.from_string(xml)
    for link in massless_moving_links(desc):
        b = spec.body(link)
        b.explicitinertial = True
        b.mass = eps
        b.ipos = [0.0, 0.0, 0.0]
        b.iquat = [1.0, 0.0, 0.0, 0.0]
        b.inertia = [eps, eps, eps]
        b.fullinertia = [float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0]
    c = spec.compiler
    c.fusestatic = False  # the URDF parser switches it on; keep root and tip links as bodies
    c.discardvisual = False
    c.balanceinertia = False
    c.boundmass = 0.0
    c.boundinertia = 0.0
    c.settotalmass = -1.0
    c.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.gravity = GRAVITY
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    if not keep_joint_dynamics:
        for j in spec.joints:
            j.damping = np.zeros_like(np.asarray(j.damping))
            j.frictionloss = 0.0
            j.armature = 0.0
            j.stiffness = np.zeros_like(np.asarray(j.stiffness))
    model = spec.compile()
    return model


def check_model(model, desc, robot, eps):
    """MuJoCo must have kept the URDF structure and inertials exactly."""
    massless = massless_moving_links(desc)
    if model.ngeom != 0:
        raise CheckError("%s: MuJoCo model has %d geoms (expected none)" % (robot, model.ngeom))
    if model.nq != len(desc["movable"]) or model.nv != len(desc["movable"]):
        raise CheckError("%s: nq=%d nv=%d, URDF chain has %d movable joints"
                         % (robot, model.nq, model.nv, len(desc["movable"])))
    for n, j in enumerate(desc["movable"]):
        mj = model.joint(j["name"])
        if int(mj.qposadr[0]) != n or int(mj.dofadr[0]) != n:
            raise CheckError("%s: joint %s is not at qpos index %d" % (robot, j["name"], n))
        if model.dof_armature[n] != 0.0:
            raise CheckError("%s: joint %s has armature" % (robot, j["name"]))
    root = model.body(desc["root"])
    for link, inert in desc["links"].items():
        if link == desc["root"] and root.id == 0:
            continue  # became MuJoCo's world body; a fixed body's inertia never matters
        b = model.body(link)
        m, c, I = inert if inert is not None else (0.0, np.zeros(3), np.zeros((3, 3)))
        if link in massless:
            m, c, I = eps, np.zeros(3), eps * np.eye(3)
        if abs(model.body_mass[b.id] - m) > 1e-15 * max(1.0, m):
            raise CheckError("%s: mass of %s changed: %r -> %r" % (robot, link, m, model.body_mass[b.id]))
        if m == 0.0:
            continue
        if np.max(np.abs(model.body_ipos[b.id] - c)) > 1e-15:
            raise CheckError("%s: centre of mass of %s changed" % (robot, link))
        Rq = np.zeros(9)
        mujoco.mju_quat2Mat(Rq, model.body_iquat[b.id])
        Rq = Rq.reshape(3, 3)
        I_mj = Rq @ np.diag(model.body_inertia[b.id]) @ Rq.T
        if np.max(np.abs(I_mj - I)) > SELF_INERTIA_TOL:
            raise CheckError("%s: inertia of %s changed by %g" % (robot, link, np.max(np.abs(I_mj - I))))


def mujoco_eval(model, data, root_id, tip_id, q):
    data.qpos[:] = q
    data.qvel[:] = 0.0
    data.qacc[:] = 0.0
    data.ctrl[:] = 0.0
    mujoco.mj_forward(model, data)
    Rr = data.xmat[root_id].reshape(3, 3)
    Rt = data.xmat[tip_id].reshape(3, 3)
    p = Rr.T @ (data.xpos[tip_id] - data.xpos[root_id])
    R = Rr.T @ Rt
    return p, R, data.qfrc_bias.copy()


# ----------------------------------------------------------------------------------------------------


def fmt(x):
    return repr(float(x))


def show(x):
    """12 decimals for the printed checks, without '-0.000000000000'."""
    return "%.12f" % (round(float(x), 12) + 0.0)


def compute_robot(robot, path, rel_label, tip):
    xml, desc = load_urdf(path, tip)
    with open(path, "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()
    n = len(desc["movable"])
    lower = np.array([j["lower"] for j in desc["movable"]])
    upper = np.array([j["upper"] for j in desc["movable"]])
    rng = np.random.default_rng(SEED)
    Q = rng.uniform(lower, upper, size=(N_CONFIGS, n))

    # Massless links behind a movable joint (legal in URDF) are refused by MuJoCo. They get a tiny mass
    # eps, and since qfrc_bias at qvel = 0 is linear in every mass, the torques are extrapolated to
    # eps = 0 exactly (up to rounding): tau = 2 tau(eps) - tau(2 eps).
    eps_list = [MASSLESS_EPS, 2 * MASSLESS_EPS] if massless_moving_links(desc) else [0.0]
    try:
        models = [build_model(xml, desc, eps=e) for e in eps_list]
        model_dyn = build_model(xml, desc, keep_joint_dynamics=True, eps=eps_list[0])
    except Exception as e:  # mujoco raises ValueError on compile errors
        raise UrdfError("%s: MuJoCo cannot load it: %s" % (path, str(e).strip().splitlines()[0]))
    for m_, e in zip(models, eps_list):
        check_model(m_, desc, robot, e)
    model = models[0]
    datas = [mujoco.MjData(m_) for m_ in models]
    data, data_dyn = datas[0], mujoco.MjData(model_dyn)
    root_id, tip_id = model.body(desc["root"]).id, model.body(tip).id

    def evaluate(q):
        res = [mujoco_eval(m_, d_, root_id, tip_id, q) for m_, d_ in zip(models, datas)]
        p, R, tau = res[0]
        if len(res) == 2:
            if not (np.array_equal(p, res[1][0]) and np.array_equal(R, res[1][1])):
                raise CheckError("%s: the pose depends on the massless-link mass" % robot)
            tau = 2.0 * res[0][2] - res[1][2]
        return p, R, tau

    if tip_id == root_id:
        raise UrdfError("%s: tip link is the root link" % path)

    # the root link must sit at the world origin, unrotated, so gravity is -z of the root frame
    mujoco.mj_kinematics(model, data)
    if np.any(data.xpos[root_id] != 0.0) or np.any(data.xmat[root_id] != np.eye(3).ravel()):
        raise CheckError("%s: root body is not at the MuJoCo world origin" % robot)

    rows = []
    worst = {"pos": 0.0, "rot": 0.0, "tau": 0.0}
    for k in range(N_CONFIGS):
        p, R, tau = evaluate(Q[k])
        p1, R1, tau1 = mujoco_eval(model, data, root_id, tip_id, Q[k])  # (data is reused, evaluate is done)
        p2, R2, tau2 = mujoco_eval(model_dyn, data_dyn, root_id, tip_id, Q[k])
        if not (np.array_equal(p1, p2) and np.array_equal(R1, R2) and np.array_equal(tau1, tau2)):
            raise CheckError("%s: URDF joint damping/friction changed MuJoCo's output (row %d)" % (robot, k))
        pn, Rn, taun = numpy_reference(desc, Q[k])
        worst["pos"] = max(worst["pos"], float(np.max(np.abs(p - pn))))
        worst["rot"] = max(worst["rot"], float(np.max(np.abs(R - Rn))))
        worst["tau"] = max(worst["tau"], float(np.max(np.abs(tau - taun))))
        rows.append(list(Q[k]) + list(p) + list(R.ravel()) + list(tau))
    if worst["pos"] > SELF_POS_TOL or worst["rot"] > SELF_ROT_TOL or worst["tau"] > SELF_TAU_TOL:
        raise CheckError("%s: MuJoCo and the numpy URDF cross-check disagree: %r" % (robot, worst))

    checks = []
    for label, q, expected, tol in CHECKS.get(robot, []):
        p, _R, _tau = evaluate(np.array(q, dtype=float))
        err = float(np.max(np.abs(p - np.array(expected))))
        checks.append("%s: %s tip at (%s, %s, %s) m, expected (%s, %s, %s), max |err| %.1e"
                      % ((robot, label) + tuple(show(x) for x in list(p) + list(expected)) + (err,)))
        if err > tol:
            raise CheckError(checks[-1] + " > %g" % tol)
    if robot in DH:
        for label, q in (("q = 0", np.zeros(n)), ("q = (0.1, 0.2, -0.3, -1.2, 0.4, 0.5, -0.6)[:n]", np.array(Q_PIN[:n])),
                         ("all %d configurations" % N_CONFIGS, None)):
            qs = [q] if q is not None else list(Q)
            err = 0.0
            for qq in qs:
                p, R, _tau = evaluate(qq)
                pd, Rd = dh_pose(DH[robot], qq)
                err = max(err, float(np.max(np.abs(p - pd))), float(np.max(np.abs(R - Rd))))
            if q is not None:
                msg = "%s: %s tip at (%s, %s, %s) m, published DH table gives (%s, %s, %s)" % (
                    (robot, label) + tuple(show(x) for x in list(p) + list(pd)))
            else:
                msg = "%s: %s against the published DH table" % (robot, label)
            checks.append(msg + ", max |err| (position, rotation) %.1e" % err)
            if err > 1e-12:
                raise CheckError(checks[-1] + " > 1e-12")

    header = (["q%d" % (i + 1) for i in range(n)] + ["px", "py", "pz"]
              + ["r%d%d" % (i, j) for i in (1, 2, 3) for j in (1, 2, 3)]
              + ["tau%d" % (i + 1) for i in range(n)])
    kinds = sorted({j["type"] for j in desc["movable"]})
    qunit = "rad" if "prismatic" not in kinds else "rad (revolute/continuous) or m (prismatic)"
    tunit = "N m" if "prismatic" not in kinds else "N m (revolute/continuous) or N (prismatic)"
    comments = [
        "generated by %s -- do not edit; regenerate with: python %s" % (SCRIPT_REL, SCRIPT_REL),
        "mujoco %s, numpy %s" % (mujoco.__version__, np.__version__),
        "urdf: %s" % rel_label,
        "urdf sha256: %s" % sha,
        "root link: %s (frame of px..r33); tip link: %s" % (desc["root"], tip),
        "joints (root to tip): %s" % " ".join("%s(%s)" % (j["name"], j["type"]) for j in desc["movable"]),
        "configurations: %d, numpy.random.default_rng(%d).uniform(lower, upper, size=(%d, %d)) within the "
        "URDF limits (continuous joints in [-pi, pi])" % (N_CONFIGS, SEED, N_CONFIGS, n),
        "gravity: (%r, %r, %r) m/s^2 in the root link frame; qvel = 0; contacts disabled" % GRAVITY,
        "columns: q1..q%d joint positions [%s]; px,py,pz tip position in the root frame [m]; "
        "r11..r33 tip rotation matrix, row-major [1]; tau1..tau%d gravity torques = MuJoCo qfrc_bias, "
        "the torque each joint must supply to hold the pose [%s]" % (n, qunit, n, tunit),
        "numbers are Python repr() of float64 (round-trip exact)",
    ]
    text = "".join("# " + c + "\n" for c in comments)
    text += ",".join(header) + "\n"
    text += "".join(",".join(fmt(x) for x in r) + "\n" for r in rows)
    return text, checks, worst


# ----------------------------------------------------------------------------------------------------
# Settle experiment: the compliant arm at rest under gravity (golden/settle_<robot>.csv)
#
# Each joint is a linear torsional spring between the commanded (motor-side) angle q and the link-side
# angle theta: MuJoCo 4.0 joint `stiffness` (a 3-vector [k, k2, k3]: linear plus two higher-order
# coefficients, here [k, 0, 0]; springyield = 0, i.e. elastic) with the spring reference qpos_spring = q
# (`springref`). The arm settles where the passive spring force balances gravity:
#
#     qfrc_passive(theta) - qfrc_bias(theta) = 0,   qvel = 0,   i.e.   K (q - theta) = tau_g(theta).
#
# This is solved by Newton's method on MuJoCo's own forces (mj_forward at qvel = 0; the 7x7 Jacobian by
# central differences of the same residual, which only affects the convergence rate, never the root).
# Why not step the simulation until it stops: a dynamic settle stops on a velocity threshold, so its
# result carries a settle error that depends on damping, time step and integrator (MuJoCo's springs are
# explicit: a stiff spring on the light wrist needs a small step), while the rest state itself is
# exactly the root above. Newton finds that root to rounding. As evidence that the two agree, the first
# SETTLE_DYN_CHECK configurations of every case are also settled dynamically (mj_step, Euler with
# implicit joint damping 2 sqrt(k I), armature SETTLE_DYN_ARMATURE to slow the wrist down, 1 ms steps,
# until max |qvel| < 1e-11 rad/s) and must reach the Newton root within SETTLE_DYN_TOL rad. Armature and
# damping change the motion, never the rest state. Joint limits are disabled (mjDSBL_LIMIT): neither
# the analytic model nor rapier has them, and the sag may carry a joint a hair past its limit.

SETTLE_ROBOTS = {"iiwa7"}
SETTLE_SEED = 20261124
N_SETTLE = 200
# Joint stiffness sets (N m/rad), root to tip: an iiwa-like order of magnitude (1e4 N m/rad at the base
# joints, less at the wrist) and a soft arm about five times more compliant.
SETTLE_STIFFNESS = (
    ("stiff", (15000.0, 15000.0, 10000.0, 10000.0, 6000.0, 4000.0, 4000.0)),
    ("soft", (2500.0, 2500.0, 2000.0, 2000.0, 1500.0, 1000.0, 1000.0)),
)
SETTLE_PAYLOAD_KG = (0.0, 3.0)
SETTLE_PAYLOAD_COM = (0.02, -0.01, 0.08)  # point mass position in the flange (tip link) frame, m
SETTLE_FD_STEP = 1e-6  # rad, central differences for the Newton Jacobian
SETTLE_STEP_TOL = 1e-14  # rad, Newton stops when max |step| is below this
SETTLE_MAX_NEWTON = 30
SETTLE_RESIDUAL_TOL = 1e-9  # N m, max |qfrc_passive - qfrc_bias| at the root (self-check)
SETTLE_NUMPY_TOL = 1e-9  # N m, max |K (q - theta) - tau_numpy(theta)| (independent self-check)
SETTLE_DYN_CHECK = 3
SETTLE_DYN_ARMATURE = 0.1  # kg m^2
SETTLE_DYN_DT = 1e-3  # s
SETTLE_DYN_TOL = 1e-9  # rad
SETTLE_DYN_MAX_STEPS = 200000
SETTLE_COMPARE_TOL = 1e-12  # rad and m; the residual column is compared to SETTLE_RESIDUAL_TOL


def build_settle_model(xml, desc, stiffness, payload_kg):
    """The URDF as in build_model (no geoms, inertials kept exactly, gravity -z, contacts off), plus joint
    springs [k, 0, 0] and, for payload_kg > 0, a point mass welded to the tip link at
    SETTLE_PAYLOAD_COM. Joint damping, friction and armature are zero; joint limits are disabled."""
    spec = mujoco.MjSpec.from_string(xml)
    c = spec.compiler
    c.fusestatic = False
    c.discardvisual = False
    c.balanceinertia = False
    c.boundmass = 0.0
    c.boundinertia = 0.0
    c.settotalmass = -1.0
    c.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.gravity = GRAVITY
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_LIMIT
    for j, k in zip(desc["movable"], stiffness):
        js = spec.joint(j["name"])
        js.damping = np.zeros_like(np.asarray(js.damping))
        js.frictionloss = 0.0
        js.armature = 0.0
        js.stiffness = [k, 0.0, 0.0]
        js.springref = 0.0  # set per configuration through mjModel.qpos_spring
        js.springyield = 0.0
    if payload_kg > 0.0:
        b = spec.body(desc["tip"]).add_body(name="robocal_payload", pos=list(SETTLE_PAYLOAD_COM))
        b.explicitinertial = True
        b.mass = payload_kg
        b.ipos = [0.0, 0.0, 0.0]
        b.iquat = [1.0, 0.0, 0.0, 0.0]
        b.inertia = [0.0, 0.0, 0.0]  # a point mass; inertia never enters a static balance
    model = spec.compile()
    n = len(desc["movable"])
    if model.nq != n or np.any(model.jnt_stiffness != np.array(stiffness)) or np.any(model.jnt_stiffnesspoly != 0):
        raise CheckError("settle model: joint stiffness not as set: %r %r" % (model.jnt_stiffness, model.jnt_stiffnesspoly))
    if np.any(model.dof_damping != 0.0) or np.any(model.dof_armature != 0.0):
        raise CheckError("settle model: joint damping or armature left on")
    return model


def settle_residual(model, data, theta):
    """qfrc_passive - qfrc_bias at rest at theta: the net joint torque (N m); zero at equilibrium."""
    data.qpos[:] = theta
    data.qvel[:] = 0.0
    data.qacc[:] = 0.0
    data.ctrl[:] = 0.0
    mujoco.mj_forward(model, data)
    return data.qfrc_passive - data.qfrc_bias


def settle_newton(model, data, q):
    """Newton on settle_residual from theta = q; returns (theta, residual, iterations)."""
    model.qpos_spring[:] = q
    theta = np.array(q, dtype=float)
    n = len(theta)
    J = np.empty((n, n))
    for it in range(1, SETTLE_MAX_NEWTON + 1):
        r = settle_residual(model, data, theta)
        for j in range(n):
            tp, tm = theta.copy(), theta.copy()
            tp[j] += SETTLE_FD_STEP
            tm[j] -= SETTLE_FD_STEP
            J[:, j] = (settle_residual(model, data, tp) - settle_residual(model, data, tm)) / (2 * SETTLE_FD_STEP)
        step = np.linalg.solve(J, -r)
        theta = theta + step
        if np.max(np.abs(step)) < SETTLE_STEP_TOL:
            r = settle_residual(model, data, theta)
            return theta, float(np.max(np.abs(r))), it
    raise CheckError("settle: Newton did not converge in %d iterations at q = %r" % (SETTLE_MAX_NEWTON, list(q)))


def settle_dynamic(model, data, q, stiffness):
    """Settles by simulation (see the section comment); returns theta at rest."""
    n = len(q)
    model.qpos_spring[:] = q
    data.qpos[:] = q
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    inertia = 1.0 / np.diag(np.linalg.inv(M + SETTLE_DYN_ARMATURE * np.eye(n)))
    saved = (model.dof_damping.copy(), model.dof_armature.copy(), model.opt.timestep, model.opt.integrator)
    model.dof_damping[:] = 2.0 * np.sqrt(np.array(stiffness) * inertia)
    model.dof_armature[:] = SETTLE_DYN_ARMATURE
    model.opt.timestep = SETTLE_DYN_DT
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    try:
        steps = 0
        while steps < SETTLE_DYN_MAX_STEPS:
            mujoco.mj_step(model, data, nstep=100)
            steps += 100
            if np.max(np.abs(data.qvel)) < 1e-11:
                return data.qpos.copy(), steps
        raise CheckError("settle: the dynamic check did not come to rest in %d steps" % SETTLE_DYN_MAX_STEPS)
    finally:
        model.dof_damping[:], model.dof_armature[:], model.opt.timestep, model.opt.integrator = saved


def payload_desc(desc, payload_kg):
    """desc with the payload as one more link behind a fixed joint at the tip, for numpy_reference."""
    if payload_kg == 0.0:
        return desc
    d = dict(desc)
    d["links"] = dict(desc["links"])
    d["joints"] = dict(desc["joints"])
    d["links"]["robocal_payload"] = (payload_kg, np.zeros(3), np.zeros((3, 3)))
    d["joints"]["robocal_payload"] = dict(name="robocal_payload_joint", type="fixed", parent=desc["tip"],
                                          child="robocal_payload", xyz=np.array(SETTLE_PAYLOAD_COM), R=np.eye(3),
                                          axis=np.array([1.0, 0.0, 0.0]), lower=None, upper=None)
    return d


def compute_settle(robot, path, rel_label, tip):
    xml, desc = load_urdf(path, tip)
    with open(path, "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()
    n = len(desc["movable"])
    if massless_moving_links(desc):
        raise UrdfError("%s: the settle experiment needs a mass on every moving link" % path)
    lower = np.array([j["lower"] for j in desc["movable"]])
    upper = np.array([j["upper"] for j in desc["movable"]])
    Q = np.random.default_rng(SETTLE_SEED).uniform(lower, upper, size=(N_SETTLE, n))
    rows = []
    worst = {"residual": 0.0, "numpy": 0.0, "numpy_pos": 0.0, "dynamic": 0.0, "newton": 0, "sag": 0.0}
    for name, stiffness in SETTLE_STIFFNESS:
        if len(stiffness) != n:
            raise CheckError("%s: stiffness set %s has %d entries for %d joints" % (robot, name, len(stiffness), n))
        K = np.array(stiffness)
        for payload_kg in SETTLE_PAYLOAD_KG:
            model = build_settle_model(xml, desc, stiffness, payload_kg)
            data = mujoco.MjData(model)
            root_id, tip_id = model.body(desc["root"]).id, model.body(tip).id
            pdesc = payload_desc(desc, payload_kg)
            for k in range(N_SETTLE):
                q = Q[k]
                theta, res, its = settle_newton(model, data, q)
                p, R, _tau = mujoco_eval(model, data, root_id, tip_id, theta)
                pn, Rn, taun = numpy_reference(pdesc, theta)
                worst["residual"] = max(worst["residual"], res)
                worst["numpy"] = max(worst["numpy"], float(np.max(np.abs(K * (q - theta) - taun))))
                worst["numpy_pos"] = max(worst["numpy_pos"], float(np.max(np.abs(p - pn))), float(np.max(np.abs(R - Rn))))
                worst["newton"] = max(worst["newton"], its)
                worst["sag"] = max(worst["sag"], float(np.max(np.abs(q - theta))))
                if k < SETTLE_DYN_CHECK:
                    theta_dyn, _steps = settle_dynamic(model, data, q, stiffness)
                    worst["dynamic"] = max(worst["dynamic"], float(np.max(np.abs(theta_dyn - theta))))
                rows.append([float(k)] + list(K) + [payload_kg] + list(SETTLE_PAYLOAD_COM) + list(q) + list(theta)
                            + list(p) + list(R.ravel()) + [res])
    if worst["residual"] > SETTLE_RESIDUAL_TOL:
        raise CheckError("%s: settle residual %.3g N m > %g" % (robot, worst["residual"], SETTLE_RESIDUAL_TOL))
    if worst["numpy"] > SETTLE_NUMPY_TOL or worst["numpy_pos"] > SELF_POS_TOL:
        raise CheckError("%s: settled poses fail the numpy URDF cross-check: torque %.3g N m, pose %.3g"
                         % (robot, worst["numpy"], worst["numpy_pos"]))
    if worst["dynamic"] > SETTLE_DYN_TOL:
        raise CheckError("%s: dynamic settle and Newton root differ by %.3g rad > %g"
                         % (robot, worst["dynamic"], SETTLE_DYN_TOL))

    header = (["config"] + ["k%d" % (i + 1) for i in range(n)] + ["payload_kg", "payload_x", "payload_y", "payload_z"]
              + ["q%d" % (i + 1) for i in range(n)] + ["theta%d" % (i + 1) for i in range(n)] + ["px", "py", "pz"]
              + ["r%d%d" % (i, j) for i in (1, 2, 3) for j in (1, 2, 3)] + ["residual"])
    comments = [
        "generated by %s -- do not edit; regenerate with: python %s" % (SCRIPT_REL, SCRIPT_REL),
        "mujoco %s, numpy %s" % (mujoco.__version__, np.__version__),
        "urdf: %s" % rel_label,
        "urdf sha256: %s" % sha,
        "root link: %s (frame of px..r33); tip link: %s" % (desc["root"], tip),
        "joints (root to tip): %s" % " ".join("%s(%s)" % (j["name"], j["type"]) for j in desc["movable"]),
        "experiment: compliant joints at rest under gravity; joint i is a linear spring of stiffness k_i between the "
        "commanded angle q_i and the link-side angle theta_i (MuJoCo joint stiffness [k_i, 0, 0], springref = q_i); "
        "theta solves K (q - theta) = tau_g(theta), i.e. qfrc_passive = qfrc_bias at qvel = 0, by Newton on "
        "MuJoCo's forces to |step| < %g rad" % SETTLE_STEP_TOL,
        "configurations: %d, numpy.random.default_rng(%d).uniform(lower, upper, size=(%d, %d)) within the URDF "
        "limits; every configuration for every stiffness set and payload, in the order stiffness set, payload, "
        "configuration" % (N_SETTLE, SETTLE_SEED, N_SETTLE, n),
        "stiffness sets [N m/rad]: %s" % "; ".join("%s = %s" % (nm, ", ".join(repr(v) for v in ks))
                                                   for nm, ks in SETTLE_STIFFNESS),
        "payload: point mass of payload_kg at (payload_x, payload_y, payload_z) in the tip link frame, welded to it "
        "(masses %s kg)" % ", ".join(repr(m) for m in SETTLE_PAYLOAD_KG),
        "gravity: (%r, %r, %r) m/s^2 in the root link frame; contacts and joint limits disabled; no joint damping, "
        "friction or armature" % GRAVITY,
        "self-checks: max |qfrc_passive - qfrc_bias| %.1e N m; numpy URDF torque balance %.1e N m, pose %.1e; "
        "Newton iterations <= %d; largest sag %.4f rad; dynamic settle (mj_step) of the first %d configurations "
        "per case agrees to %.1e rad"
        % (worst["residual"], worst["numpy"], worst["numpy_pos"], worst["newton"], worst["sag"], SETTLE_DYN_CHECK,
           worst["dynamic"]),
        "columns: config 0-based index of the configuration; k1..k%d joint stiffness [N m/rad]; payload_kg [kg], "
        "payload_x..z [m]; q1..q%d commanded joint angles [rad]; theta1..theta%d settled link-side angles [rad]; "
        "px,py,pz settled tip position in the root frame [m]; r11..r33 settled tip rotation, row-major [1]; "
        "residual max |qfrc_passive - qfrc_bias| at theta [N m]" % (n, n, n),
        "numbers are Python repr() of float64 (round-trip exact)",
    ]
    text = "".join("# " + c + "\n" for c in comments)
    text += ",".join(header) + "\n"
    text += "".join(",".join(fmt(x) for x in r) + "\n" for r in rows)
    return text, worst


def compare_settle(robot, text, other_path):
    """Returns (ok, worst difference, message). Inputs (config, k, payload, q) must match exactly; theta,
    pose within SETTLE_COMPARE_TOL; the residual column only has to stay below SETTLE_RESIDUAL_TOL."""
    try:
        with open(other_path) as f:
            h2, r2 = parse_csv(f.read())
    except (OSError, ValueError, IndexError) as e:
        return False, math.inf, "%s: cannot read %s: %s" % (robot, other_path, e)
    h1, r1 = parse_csv(text)
    if h1 != h2:
        return False, math.inf, "%s: header differs from %s" % (robot, other_path)
    if len(r1) != len(r2):
        return False, math.inf, "%s: %d rows here, %d in %s" % (robot, len(r1), len(r2), other_path)
    exact = {c for c, h in enumerate(h1) if h == "config" or h.startswith(("k", "payload", "q"))}
    res_col = h1.index("residual")
    worst = (0.0, 1, h1[0])
    for i, (a, b) in enumerate(zip(r1, r2)):
        for c, (x, y) in enumerate(zip(a, b)):
            if c in exact and x != y:
                return False, math.inf, "%s: row %d column %s: input differs (%r vs %r)" % (robot, i + 1, h1[c], x, y)
            if c == res_col:
                if not (y <= SETTLE_RESIDUAL_TOL):
                    return False, math.inf, "%s: row %d: residual %r in %s" % (robot, i + 1, y, other_path)
                continue
            d = abs(x - y)
            if math.isnan(d):
                d = math.inf
            if d > worst[0]:
                worst = (d, i + 1, h1[c])
    msg = "%s settle: worst |difference| %.3g at row %d column %s (vs %s)" % (robot, worst[0], worst[1], worst[2],
                                                                            other_path)
    return worst[0] <= SETTLE_COMPARE_TOL, worst[0], msg


# ----------------------------------------------------------------------------------------------------
# Deflection experiment: joint springs plus bearing/link compliance across the joint axes, at rest under
# gravity (golden/settle_deflection_<robot>.csv)
#
# Link deflection (sim::effects::link_deflection): the child side of joint i tilts by alpha_i about u_i,
# then beta_i about v_i, two axes across the joint axis a_i through the joint origin, in the joint's
# (child link's) frame: u = the coordinate axis least aligned with a (first of x, y, z on ties) made
# orthogonal to a, v = a x u. In MuJoCo each deflecting joint's child body gets two more hinge joints
# after the URDF joint (joints of one body apply in order, each about its axis in the body frame as
# turned by the joints before it, at the body origin where the URDF importer puts the joint), with
# stiffness [1/c, 0, 0] and springref 0; a hinge of compliance 0 is left out. Joint springs are as in
# the settle experiment ([k, 0, 0], springref = q); a joint without a spring is held rigidly at q (its
# degree of freedom is not an unknown). The rest state solves qfrc_passive = qfrc_bias on every
# unknown (compliant joints and hinges) at qvel = 0, by Newton on MuJoCo's own forces as above.
#
# Independent self-check on every row: the same URDF text with two massless links and revolute joints
# inserted after each deflecting joint (the hinged chain written out as URDF), evaluated by the numpy
# URDF reference: its tip pose at the settled angles must equal MuJoCo's (1e-12) and its torques must
# balance every spring (DEFLECTION_NUMPY_TOL). No dynamic (mj_step) check: the bearing springs
# (1e5-1e6 N m/rad on light bodies) would need steps of ~1e-5 s with MuJoCo's explicit springs, and the
# settle experiment already shows that the Newton root is the dynamic rest state.

DEFLECTION_SEED = 20261125
N_DEFLECTION = 200
INF = float("inf")
# (name, joint stiffness in N m/rad (inf = rigid), [(c_u, c_v)] in rad/(N m) per joint, root to tip).
# "bearing": every joint rigid, deflection across every axis; "bearing_and_joints": the stiff joint set
# of the settle experiment plus deflection at the shoulder, elbow and wrist (joints 2, 4, 6) only.
DEFLECTION_SETS = (
    ("bearing", (INF,) * 7,
     ((2e-6, 3e-6), (3e-6, 3e-6), (2e-6, 2e-6), (4e-6, 4e-6), (3e-6, 3e-6), (5e-6, 5e-6), (6e-6, 6e-6))),
    ("bearing_and_joints", SETTLE_STIFFNESS[0][1],
     ((0.0, 0.0), (4e-6, 6e-6), (0.0, 0.0), (5e-6, 5e-6), (0.0, 0.0), (8e-6, 4e-6), (0.0, 0.0))),
)
DEFLECTION_NUMPY_TOL = 1e-9  # N m, max |spring torque - numpy holding torque| per unknown
DEFLECTION_COMPARE_TOL = 1e-12  # rad and m


def deflection_axes(a):
    """(u, v) across the unit joint axis a (see the section comment)."""
    a = np.asarray(a, dtype=float) / np.linalg.norm(a)
    k = 0
    for j in (1, 2):
        if abs(a[j]) < abs(a[k]):
            k = j
    e = np.zeros(3)
    e[k] = 1.0
    u = e - a * (a @ e)
    u = u / np.linalg.norm(u)
    return u, np.cross(a, u)


def hinged_urdf(xml, desc, compliance):
    """The cleaned URDF text with, after every joint with a nonzero compliance, massless links and
    revolute joints about u then v (those with nonzero compliance) at the joint's child frame origin.
    Returns (text, names of the unknowns' joints in chain order, compliance per hinge joint name)."""
    root = ET.fromstring(xml)
    by_name = {j.get("name"): j for j in root.findall("joint")}
    hinge_c = {}
    for j, (cu, cv) in zip(desc["movable"], compliance):
        hinges = [(nm, ax, c) for nm, ax, c in zip(("u", "v"), deflection_axes(j["axis"]), (cu, cv)) if c > 0.0]
        if not hinges:
            continue
        child = j["child"]
        parent = child + "_robocal_d0"
        by_name[j["name"]].find("child").set("link", parent)
        for k, (nm, ax, c) in enumerate(hinges):
            ET.SubElement(root, "link", name=parent)
            to = child if k + 1 == len(hinges) else "%s_robocal_d%d" % (child, k + 1)
            name = "%s_robocal_%s" % (j["name"], nm)
            je = ET.SubElement(root, "joint", name=name, type="revolute")
            ET.SubElement(je, "parent", link=parent)
            ET.SubElement(je, "child", link=to)
            ET.SubElement(je, "axis", xyz=" ".join(repr(float(x)) for x in ax))
            ET.SubElement(je, "limit", lower="-1", upper="1", effort="1", velocity="1")
            hinge_c[name] = c
            parent = to
    return ET.tostring(root, encoding="unicode"), hinge_c


def build_deflection_model(xml, desc, stiffness, compliance, payload_kg):
    """The settle model (joint springs where the stiffness is finite) plus the deflection hinges in the
    child bodies. Returns (model, unknowns: qpos indices of the compliant joints and hinges, in chain
    order; hinge joint names in the same order as the hinged URDF's)."""
    spec = mujoco.MjSpec.from_string(xml)
    c = spec.compiler
    c.fusestatic = False
    c.discardvisual = False
    c.balanceinertia = False
    c.boundmass = 0.0
    c.boundinertia = 0.0
    c.settotalmass = -1.0
    c.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.gravity = GRAVITY
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_LIMIT
    for j, k, (cu, cv) in zip(desc["movable"], stiffness, compliance):
        js = spec.joint(j["name"])
        js.damping = np.zeros_like(np.asarray(js.damping))
        js.frictionloss = 0.0
        js.armature = 0.0
        js.stiffness = [k if math.isfinite(k) else 0.0, 0.0, 0.0]
        js.springref = 0.0
        js.springyield = 0.0
        body = spec.body(j["child"])
        for nm, ax, cc in zip(("u", "v"), deflection_axes(j["axis"]), (cu, cv)):
            if cc > 0.0:
                body.add_joint(name="%s_robocal_%s" % (j["name"], nm), type=mujoco.mjtJoint.mjJNT_HINGE,
                               axis=list(ax), pos=[0.0, 0.0, 0.0], stiffness=[1.0 / cc, 0.0, 0.0], springref=0.0)
    if payload_kg > 0.0:
        b = spec.body(desc["tip"]).add_body(name="robocal_payload", pos=list(SETTLE_PAYLOAD_COM))
        b.explicitinertial = True
        b.mass = payload_kg
        b.ipos = [0.0, 0.0, 0.0]
        b.iquat = [1.0, 0.0, 0.0, 0.0]
        b.inertia = [0.0, 0.0, 0.0]
    model = spec.compile()
    names = [model.joint(i).name for i in range(model.njnt)]
    if model.nq != model.njnt or list(model.jnt_qposadr) != list(range(model.njnt)):
        raise CheckError("deflection model: one qpos per hinge expected")
    if np.any(model.jnt_pos != 0.0) or np.any(model.jnt_stiffnesspoly != 0) or np.any(model.dof_damping != 0.0):
        raise CheckError("deflection model: a joint off its body origin, or higher-order stiffness or damping left on")
    unknowns = [i for i, nm in enumerate(names) if model.jnt_stiffness[i] > 0.0]
    return model, names, unknowns


def settle_subset(model, data, x0, unknowns):
    """Newton on qfrc_passive - qfrc_bias over the unknowns (the others held at x0); model.qpos_spring
    must be set. Returns (x, residual on the unknowns, iterations)."""
    x = np.array(x0, dtype=float)
    u = np.array(unknowns)
    m = len(u)
    J = np.empty((m, m))
    for it in range(1, SETTLE_MAX_NEWTON + 1):
        r = settle_residual(model, data, x)[u]
        for jj in range(m):
            xp, xm = x.copy(), x.copy()
            xp[u[jj]] += SETTLE_FD_STEP
            xm[u[jj]] -= SETTLE_FD_STEP
            J[:, jj] = (settle_residual(model, data, xp)[u] - settle_residual(model, data, xm)[u]) / (2 * SETTLE_FD_STEP)
        step = np.linalg.solve(J, -r)
        x[u] += step
        if np.max(np.abs(step)) < SETTLE_STEP_TOL:
            r = settle_residual(model, data, x)[u]
            return x, float(np.max(np.abs(r))), it
    raise CheckError("deflection: Newton did not converge in %d iterations" % SETTLE_MAX_NEWTON)


def compute_deflection(robot, path, rel_label, tip):
    xml, desc = load_urdf(path, tip)
    with open(path, "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()
    n = len(desc["movable"])
    lower = np.array([j["lower"] for j in desc["movable"]])
    upper = np.array([j["upper"] for j in desc["movable"]])
    Q = np.random.default_rng(DEFLECTION_SEED).uniform(lower, upper, size=(N_DEFLECTION, n))
    rows = []
    worst = {"residual": 0.0, "numpy": 0.0, "numpy_pos": 0.0, "newton": 0, "tilt": 0.0}
    joint_names = [j["name"] for j in desc["movable"]]
    for name, stiffness, compliance in DEFLECTION_SETS:
        if len(stiffness) != n or len(compliance) != n:
            raise CheckError("%s: deflection set %s does not have %d joints" % (robot, name, n))
        htext, hinge_c = hinged_urdf(xml, desc, compliance)
        with tempfile.TemporaryDirectory() as d:
            hp = os.path.join(d, "hinged.urdf")
            with open(hp, "w") as f:
                f.write(htext)
            _, hdesc = load_urdf(hp, tip)
        for payload_kg in SETTLE_PAYLOAD_KG:
            model, names, unknowns = build_deflection_model(xml, desc, stiffness, compliance, payload_kg)
            if names != [j["name"] for j in hdesc["movable"]]:
                raise CheckError("%s: MuJoCo joint order %r differs from the hinged URDF's" % (robot, names))
            data = mujoco.MjData(model)
            root_id, tip_id = model.body(desc["root"]).id, model.body(tip).id
            pdesc = payload_desc(hdesc, payload_kg)
            jidx = [names.index(nm) for nm in joint_names]
            for k in range(N_DEFLECTION):
                q = Q[k]
                x0 = np.zeros(model.nq)
                x0[jidx] = q
                model.qpos_spring[:] = x0
                x, res, its = settle_subset(model, data, x0, unknowns)
                p, R, _tau = mujoco_eval(model, data, root_id, tip_id, x)
                pn, Rn, taun = numpy_reference(pdesc, x)
                spring = -model.jnt_stiffness * (x - x0)  # torque of each spring on the link side
                bal = np.abs(spring - taun)[unknowns]
                worst["residual"] = max(worst["residual"], res)
                worst["numpy"] = max(worst["numpy"], float(np.max(bal)))
                worst["numpy_pos"] = max(worst["numpy_pos"], float(np.max(np.abs(p - pn))), float(np.max(np.abs(R - Rn))))
                worst["newton"] = max(worst["newton"], its)
                alpha, beta = np.zeros(n), np.zeros(n)
                for i, jn in enumerate(joint_names):
                    for arr, nm in ((alpha, "u"), (beta, "v")):
                        hn = "%s_robocal_%s" % (jn, nm)
                        if hn in names:
                            arr[i] = x[names.index(hn)]
                worst["tilt"] = max(worst["tilt"], float(np.max(np.abs(alpha))), float(np.max(np.abs(beta))))
                rows.append([float(k)] + list(stiffness) + [c[0] for c in compliance] + [c[1] for c in compliance]
                            + [payload_kg] + list(SETTLE_PAYLOAD_COM) + list(q) + list(x[jidx]) + list(alpha)
                            + list(beta) + list(p) + list(R.ravel()) + [res])
    if worst["residual"] > SETTLE_RESIDUAL_TOL:
        raise CheckError("%s: deflection residual %.3g N m > %g" % (robot, worst["residual"], SETTLE_RESIDUAL_TOL))
    if worst["numpy"] > DEFLECTION_NUMPY_TOL or worst["numpy_pos"] > SELF_POS_TOL:
        raise CheckError("%s: settled poses fail the numpy hinged-URDF cross-check: torque %.3g N m, pose %.3g"
                         % (robot, worst["numpy"], worst["numpy_pos"]))

    header = (["config"] + ["k%d" % (i + 1) for i in range(n)] + ["cu%d" % (i + 1) for i in range(n)]
              + ["cv%d" % (i + 1) for i in range(n)] + ["payload_kg", "payload_x", "payload_y", "payload_z"]
              + ["q%d" % (i + 1) for i in range(n)] + ["theta%d" % (i + 1) for i in range(n)]
              + ["alpha%d" % (i + 1) for i in range(n)] + ["beta%d" % (i + 1) for i in range(n)] + ["px", "py", "pz"]
              + ["r%d%d" % (i, j) for i in (1, 2, 3) for j in (1, 2, 3)] + ["residual"])
    short = lambda v: "%g" % (round(float(v), 12) + 0.0)
    axes = "; ".join("%s: u = (%s), v = (%s)" % ((j["name"],) + tuple(" ".join(short(v) for v in w)
                                                                         for w in deflection_axes(j["axis"])))
                     for j in desc["movable"])
    comments = [
        "generated by %s -- do not edit; regenerate with: python %s" % (SCRIPT_REL, SCRIPT_REL),
        "mujoco %s, numpy %s" % (mujoco.__version__, np.__version__),
        "urdf: %s" % rel_label,
        "urdf sha256: %s" % sha,
        "root link: %s (frame of px..r33); tip link: %s" % (desc["root"], tip),
        "joints (root to tip): %s" % " ".join("%s(%s)" % (j["name"], j["type"]) for j in desc["movable"]),
        "experiment: joint springs and link deflection at rest under gravity. Joint i: a linear spring k_i between the "
        "commanded angle q_i and the link-side angle theta_i (MuJoCo joint stiffness [k_i, 0, 0], springref = q_i; "
        "k_i = inf: rigid, theta_i = q_i). Deflection: the child side of joint i turns by alpha_i about u_i, then "
        "beta_i about v_i (axes across the joint axis a_i, in the joint's child frame, through its origin: u = the "
        "frame axis least aligned with a, first of x, y, z on ties, made orthogonal to a; v = a x u), two MuJoCo "
        "hinges after the joint in its child body with stiffness [1/c, 0, 0] and springref 0 (c = 0: no hinge, "
        "angle 0). The rest state solves qfrc_passive = qfrc_bias on every compliant joint and hinge at qvel = 0, "
        "by Newton on MuJoCo's forces to |step| < %g rad" % SETTLE_STEP_TOL,
        "deflection axes: %s" % axes,
        "configurations: %d, numpy.random.default_rng(%d).uniform(lower, upper, size=(%d, %d)) within the URDF "
        "limits; every configuration for every set and payload, in the order set, payload, configuration"
        % (N_DEFLECTION, DEFLECTION_SEED, N_DEFLECTION, n),
        "sets: %s" % "; ".join("%s: k [N m/rad] = %s, (c_u, c_v) [rad/(N m)] = %s"
                               % (nm, ", ".join(repr(v) for v in ks), ", ".join("(%r, %r)" % c for c in cs))
                               for nm, ks, cs in DEFLECTION_SETS),
        "payload: point mass of payload_kg at (payload_x, payload_y, payload_z) in the tip link frame, welded to it "
        "(masses %s kg)" % ", ".join(repr(m) for m in SETTLE_PAYLOAD_KG),
        "gravity: (%r, %r, %r) m/s^2 in the root link frame; contacts and joint limits disabled; no joint damping, "
        "friction or armature" % GRAVITY,
        "self-checks: max |qfrc_passive - qfrc_bias| on the unknowns %.1e N m; the hinged chain written as URDF "
        "(massless links between the hinges) in the numpy reference: spring balance %.1e N m, pose %.1e; Newton "
        "iterations <= %d; largest deflection angle %.2e rad"
        % (worst["residual"], worst["numpy"], worst["numpy_pos"], worst["newton"], worst["tilt"]),
        "columns: config 0-based index of the configuration; k1..k%d joint stiffness [N m/rad] (inf = rigid); "
        "cu1..cu%d, cv1..cv%d deflection compliance about u and v [rad/(N m)] (0 = rigid); payload_kg [kg], "
        "payload_x..z [m]; q1..q%d commanded joint angles [rad]; theta1..theta%d settled joint angles [rad]; "
        "alpha1..alpha%d, beta1..beta%d settled deflection angles about u and v [rad]; px,py,pz settled tip "
        "position in the root frame [m]; r11..r33 settled tip rotation, row-major [1]; residual max "
        "|qfrc_passive - qfrc_bias| over the compliant joints and hinges [N m]" % ((n,) * 7),
        "numbers are Python repr() of float64 (round-trip exact)",
    ]
    text = "".join("# " + c + "\n" for c in comments)
    text += ",".join(header) + "\n"
    text += "".join(",".join(fmt(x) for x in r) + "\n" for r in rows)
    return text, worst


def compare_deflection(robot, text, other_path):
    """As compare_settle for settle_deflection_<robot>.csv: inputs (config, k, cu, cv, payload, q) exact;
    angles and pose within DEFLECTION_COMPARE_TOL; the residual only below SETTLE_RESIDUAL_TOL."""
    try:
        with open(other_path) as f:
            h2, r2 = parse_csv(f.read())
    except (OSError, ValueError, IndexError) as e:
        return False, math.inf, "%s: cannot read %s: %s" % (robot, other_path, e)
    h1, r1 = parse_csv(text)
    if h1 != h2:
        return False, math.inf, "%s: header differs from %s" % (robot, other_path)
    if len(r1) != len(r2):
        return False, math.inf, "%s: %d rows here, %d in %s" % (robot, len(r1), len(r2), other_path)
    exact = {c for c, h in enumerate(h1) if h == "config" or h.startswith(("k", "cu", "cv", "payload", "q"))}
    res_col = h1.index("residual")
    worst = (0.0, 1, h1[0])
    for i, (a, b) in enumerate(zip(r1, r2)):
        for c, (x, y) in enumerate(zip(a, b)):
            if c in exact:
                if x != y:
                    return False, math.inf, "%s: row %d column %s: input differs (%r vs %r)" % (robot, i + 1, h1[c],
                                                                                              x, y)
                continue  # (inf - inf is nan: rigid joints are exact inputs, not compared values)
            if c == res_col:
                if not (y <= SETTLE_RESIDUAL_TOL):
                    return False, math.inf, "%s: row %d: residual %r in %s" % (robot, i + 1, y, other_path)
                continue
            d = abs(x - y)
            if math.isnan(d):
                d = math.inf
            if d > worst[0]:
                worst = (d, i + 1, h1[c])
    msg = "%s deflection: worst |difference| %.3g at row %d column %s (vs %s)" % (robot, worst[0], worst[1],
                                                                                worst[2], other_path)
    return worst[0] <= DEFLECTION_COMPARE_TOL, worst[0], msg


def write_atomic(path, text):
    d = os.path.dirname(path)
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=d)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file ordinary permissions
        with os.fdopen(fd, "w", newline="\n") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def parse_csv(text):
    lines = [l for l in text.splitlines() if l and not l.startswith("#")]
    header = lines[0].split(",")
    rows = [[float(x) for x in l.split(",")] for l in lines[1:]]
    if any(len(r) != len(header) for r in rows):
        raise ValueError("ragged rows")
    return header, rows


def compare(robot, text, other_path):
    """Returns (ok, worst difference, message); row numbers count data rows from 1."""
    try:
        with open(other_path) as f:
            h2, r2 = parse_csv(f.read())
    except (OSError, ValueError, IndexError) as e:
        return False, math.inf, "%s: cannot read %s: %s" % (robot, other_path, e)
    h1, r1 = parse_csv(text)
    if h1 != h2:
        return False, math.inf, "%s: header differs from %s" % (robot, other_path)
    if len(r1) != len(r2):
        return False, math.inf, "%s: %d rows here, %d in %s" % (robot, len(r1), len(r2), other_path)
    nq = sum(1 for h in h1 if h.startswith("q"))
    worst = (0.0, 1, h1[0])
    for i, (a, b) in enumerate(zip(r1, r2)):
        for c, (x, y) in enumerate(zip(a, b)):
            if c < nq and x != y:
                return False, math.inf, "%s: row %d column %s: q differs (%r vs %r, |difference| %.3g)" % (
                    robot, i + 1, h1[c], x, y, abs(x - y))
            d = abs(x - y)
            if math.isnan(d):
                d = math.inf
            if d > worst[0]:
                worst = (d, i + 1, h1[c])
    msg = "%s: worst |difference| %.3g at row %d column %s (vs %s)" % (robot, worst[0], worst[1], worst[2],
                                                                      other_path)
    return worst[0] <= COMPARE_TOL, worst[0], msg


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(REPO, "golden"), help="output directory (default <repo>/golden)")
    ap.add_argument("--shared", default=os.path.join(os.path.dirname(REPO), "shared"),
                    help="shared data directory (default <repo>/../shared)")
    ap.add_argument("--robots", default=None, help="comma-separated robot names (default: all that exist)")
    ap.add_argument("--compare-to", default=None, metavar="DIR",
                    help="compare with the files of the same name in DIR; exit 1 on a difference > %g" % COMPARE_TOL)
    ap.add_argument("--experiment", choices=("all", "kinematics", "settle", "deflection"), default="all",
                    help="which golden files to compute: kinematics_<robot>.csv; settle: settle_<robot>.csv and "
                         "settle_deflection_<robot>.csv (robots %s only); deflection: settle_deflection_<robot>.csv "
                         "only; all (default)" % ", ".join(sorted(SETTLE_ROBOTS)))
    args = ap.parse_args(argv)
    do_kin = args.experiment in ("all", "kinematics")
    do_settle = args.experiment in ("all", "settle")
    do_deflection = args.experiment in ("all", "settle", "deflection")

    explicit = args.robots is not None
    names = [r.strip() for r in args.robots.split(",") if r.strip()] if explicit else list(ROBOTS)
    for r in names:
        if r not in ROBOTS:
            print("error: unknown robot %r (known: %s)" % (r, ", ".join(ROBOTS)), file=sys.stderr)
            return 2

    results = []
    settle_results = []
    deflection_results = []
    for r in names:
        base, rel, tip = ROBOTS[r]
        base_dir = REPO if base == "repo" else args.shared
        path = os.path.join(base_dir, rel)
        label = "%s (relative to the %s)" % (rel, "repository root" if base == "repo" else "shared directory")
        if not os.path.isfile(path):
            if explicit:
                print("error: %s: URDF %s not found" % (r, path), file=sys.stderr)
                return 2
            print("skip %s: %s not found" % (r, path))
            continue
        if do_kin:
            try:
                text, checks, worst = compute_robot(r, path, label, tip)
            except UrdfError as e:
                print("error: %s: %s" % (r, e), file=sys.stderr)
                return 2
            except CheckError as e:
                print("check failed: %s" % e, file=sys.stderr)
                return 3
            for c in checks:
                print("check " + c)
            print("%s: %d configurations; numpy cross-check max |diff| pos %.1e m, rot %.1e, tau %.1e N m"
                  % (r, N_CONFIGS, worst["pos"], worst["rot"], worst["tau"]))
            results.append((r, text))
        if do_settle and r in SETTLE_ROBOTS:
            try:
                text, worst = compute_settle(r, path, label, tip)
            except UrdfError as e:
                print("error: %s: %s" % (r, e), file=sys.stderr)
                return 2
            except CheckError as e:
                print("check failed: %s" % e, file=sys.stderr)
                return 3
            print("%s settle: %d rows; residual %.1e N m; numpy torque balance %.1e N m; dynamic settle vs Newton "
                  "%.1e rad; largest sag %.4f rad" % (r, N_SETTLE * len(SETTLE_STIFFNESS) * len(SETTLE_PAYLOAD_KG),
                                                      worst["residual"], worst["numpy"], worst["dynamic"], worst["sag"]))
            settle_results.append((r, text))
        if do_deflection and r in SETTLE_ROBOTS:
            try:
                text, worst = compute_deflection(r, path, label, tip)
            except UrdfError as e:
                print("error: %s: %s" % (r, e), file=sys.stderr)
                return 2
            except CheckError as e:
                print("check failed: %s" % e, file=sys.stderr)
                return 3
            print("%s deflection: %d rows; residual %.1e N m; numpy hinged-URDF spring balance %.1e N m, pose %.1e; "
                  "largest deflection %.2e rad" % (r, N_DEFLECTION * len(DEFLECTION_SETS) * len(SETTLE_PAYLOAD_KG),
                                                   worst["residual"], worst["numpy"], worst["numpy_pos"], worst["tilt"]))
            deflection_results.append((r, text))

    # compare before writing, so that --out and --compare-to may name the same directory
    status = 0
    if args.compare_to is not None:
        failed = []
        for r, text in results:
            ok, d, msg = compare(r, text, os.path.join(args.compare_to, "kinematics_%s.csv" % r))
            print(("OK " if ok else "MISMATCH ") + msg)
            if not ok:
                failed.append((d, msg))
        for r, text in settle_results:
            ok, d, msg = compare_settle(r, text, os.path.join(args.compare_to, "settle_%s.csv" % r))
            print(("OK " if ok else "MISMATCH ") + msg)
            if not ok:
                failed.append((d, msg))
        for r, text in deflection_results:
            ok, d, msg = compare_deflection(r, text, os.path.join(args.compare_to, "settle_deflection_%s.csv" % r))
            print(("OK " if ok else "MISMATCH ") + msg)
            if not ok:
                failed.append((d, msg))
        if failed:
            print("compare failed (tolerance %g, q exact); worst: %s" % (COMPARE_TOL, max(failed)[1]),
                  file=sys.stderr)
            status = 1

    for r, text in results:
        out = os.path.join(args.out, "kinematics_%s.csv" % r)
        write_atomic(out, text)
        print("wrote %s" % out)
    for r, text in settle_results:
        out = os.path.join(args.out, "settle_%s.csv" % r)
        write_atomic(out, text)
        print("wrote %s" % out)
    for r, text in deflection_results:
        out = os.path.join(args.out, "settle_deflection_%s.csv" % r)
        write_atomic(out, text)
        print("wrote %s" % out)
    return status


if __name__ == "__main__":
    sys.exit(main())
