#!/usr/bin/env python3
"""Independent numeric check of sim/robots/{ur5,ur10,wam}.urdf against their published sources.

The URDFs were written from published standard Denavit-Hartenberg tables and published inertial
data (see each file's header). This script does not share any code or numbers with whatever wrote
them: it types the published tables in again, reads each URDF with xml.etree, and checks

  1. kinematics: for 1000 random configurations (numpy default_rng(1) for each robot, q uniform in [-pi, pi]) the
     flange pose from chaining the URDF joint origins and joint rotations equals the standard DH
     product T = prod_i Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i) (so the URDF's joint zero is the DH zero
     and theta_i = q_i);
  2. centres of mass: at the same configurations, every moving link's centre of mass in the base
     frame, from the URDF, equals the published centre of mass (given in DH frame k) mapped through
     the DH chain;
  3. inertia tensors: likewise in the base frame, against the published tensor in its published
     frame (with the WAM document's product-of-inertia sign convention applied, see WAM below);
  4. masses, joint names, joint limits, and that every tensor is positive definite and satisfies the
     triangle inequality (as MuJoCo requires).

Prints the largest errors and exits non-zero if any exceeds its tolerance or any check fails.
Needs Python 3 and numpy only. Run from anywhere: python3 scripts/check_dh_urdfs.py
"""

import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "sim" / "robots"

#: Tolerance on positions (m) and centres of mass (m).
POS_TOL = 1e-12
#: Tolerance on rotation angles (rad).
ROT_TOL = 1e-12
#: Tolerance on inertia tensor entries in the base frame (kg m^2).
INERTIA_TOL = 1e-12
#: Tolerance on masses (kg) and limits (rad, rad/s, N m).
VALUE_TOL = 1e-12
#: Number of random configurations and the seed.
N_CONFIGS = 1000
SEED = 1

PI = math.pi

# ---------------------------------------------------------------------------------------------
# Published data, typed in from the sources (metres, radians, kilograms, kg m^2).
# ---------------------------------------------------------------------------------------------


def sym(ixx, ixy, ixz, iyy, iyz, izz):
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)


def rot_x(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Universal Robots, "DH Parameters for calculations of kinematics and dynamics" (UR5 table).
UR5 = dict(
    a=[0.0, -0.425, -0.39225, 0.0, 0.0, 0.0],
    d=[0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823],
    alpha=[PI / 2, 0.0, 0.0, PI / 2, -PI / 2, 0.0],
    mass=[3.7, 8.393, 2.33, 1.219, 1.219, 0.1879],
    com=[
        [0.0, -0.02561, 0.00193],
        [0.2125, 0.0, 0.11336],
        [0.15, 0.0, 0.0265],
        [0.0, -0.0018, 0.01634],
        [0.0, 0.0018, 0.01634],
        [0.0, 0.0, -0.001159],
    ],
    # ur_description config/ur5/physical_parameters.yaml: cylinder tensors, expressed in that
    # package's link k frame turned by the listed rpy. Its link k frame is DH frame k turned by
    # Rx(-alpha_k) (origin moved), so R_DHk_published = Rx(-alpha_k) R_rpy.
    inertia=[
        sym(0.014972358333333331, 0, 0, 0.014972358333333331, 0, 0.01040625),
        sym(0.13388583541666665, 0, 0, 0.13388583541666665, 0, 0.0151074),
        sym(0.031216803515624995, 0, 0, 0.031216803515624995, 0, 0.004095),
        sym(0.002013889583333333, 0, 0, 0.002013889583333333, 0, 0.0021942),
        sym(0.0018310395833333333, 0, 0, 0.0018310395833333333, 0, 0.0021942),
        sym(8.062475833333332e-05, 0, 0, 8.062475833333332e-05, 0, 0.0001321171875),
    ],
    inertia_rpy=[(0, 0, 0), (0, PI / 2, 0), (0, PI / 2, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)],
    inertia_frame="ur_description_link",
    # UR5 user manual (CB3): +-360 deg, 180 deg/s; UR "Max. joint torques".
    limits=[(-2 * PI, 2 * PI, PI, e) for e in (150, 150, 150, 28, 28, 28)],
)

# Universal Robots, same article (UR10 table); tensors from ur_description
# config/ur10/physical_parameters.yaml ("extracted from URSim"), whose inertial rpy (alpha_k, 0, 0)
# puts them in DH frame k orientation.
UR10 = dict(
    a=[0.0, -0.612, -0.5723, 0.0, 0.0, 0.0],
    d=[0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922],
    alpha=[PI / 2, 0.0, 0.0, PI / 2, -PI / 2, 0.0],
    mass=[7.1, 12.7, 4.27, 2.0, 2.0, 0.365],
    com=[
        [0.021, 0.0, 0.027],
        [0.38, 0.0, 0.158],
        [0.24, 0.0, 0.068],
        [0.0, 0.007, 0.018],
        [0.0, 0.007, 0.018],
        [0.0, 0.0, -0.026],
    ],
    inertia=[
        sym(0.03408, 0.00002, -0.00425, 0.03529, 0.00008, 0.02156),
        sym(0.02814, 0.00005, -0.01561, 0.77068, 0.00002, 0.76943),
        sym(0.01014, 0.00008, 0.00916, 0.30928, 0.0, 0.30646),
        sym(0.00296, -0.00001, 0.0, 0.00222, -0.00024, 0.00258),
        sym(0.00296, -0.00001, 0.0, 0.00222, -0.00024, 0.00258),
        sym(0.00040, 0.0, 0.0, 0.00041, 0.0, 0.00034),
    ],
    inertia_frame="dh",
    # UR10 user manual (CB3): +-360 deg; 120/120/180/180/180/180 deg/s; UR "Max. joint torques".
    limits=[
        (-2 * PI, 2 * PI, math.radians(v), e)
        for v, e in zip((120, 120, 180, 180, 180, 180), (330, 330, 150, 56, 56, 56))
    ],
)


def solidworks_l(lxx, lxy, lxz, lyy, lyz, lzz):
    """Barrett's L matrix is SolidWorks output: Lxy = +integral(x y dm). Tensor negates products."""
    return sym(lxx, -lxy, -lxz, lyy, -lyz, lzz)


# Barrett WAM: User's Manual D1001 AH.00 (DH table; Table 6 joint limits) and
# "WAM Arm Inertial Specifications" AC-02 (mass, CoM in DH frame k, L at CoM aligned with frame k).
WAM = dict(
    a=[0.0, 0.0, 0.045, -0.045, 0.0, 0.0, 0.0],
    d=[0.0, 0.0, 0.55, 0.0, 0.3, 0.0, 0.06],
    alpha=[-PI / 2, PI / 2, -PI / 2, PI / 2, -PI / 2, PI / 2, 0.0],
    mass=[10.76768767, 3.87493756, 1.80228141, 2.40016804, 0.12376019, 0.41797364, 0.06864753],
    com=[
        [-0.00443422, 0.12189039, -0.00066489],
        [-0.00236983, 0.03105614, 0.01542114],
        [-0.03825858, 0.20750770, 0.00003309],
        [0.00498512, -0.00022942, 0.13271662],
        [0.00008921, 0.00511217, 0.00435824],
        [-0.00012262, -0.01703194, 0.02468336],
        [-0.00007974, 0.00016313, -0.00323552],
    ],
    inertia=[
        solidworks_l(0.13488033, -0.00213041, -0.00012485, 0.11328369, 0.00068555, 0.09046330),
        solidworks_l(0.02140958, 0.00027172, 0.00002461, 0.01377875, -0.00181920, 0.01558906),
        solidworks_l(0.05911077, -0.00249612, 0.00000738, 0.00324550, -0.00001767, 0.05927043),
        solidworks_l(0.01491672, 0.00001741, -0.00150604, 0.01482922, -0.00002109, 0.00294463),
        solidworks_l(0.00005029, 0.00000020, -0.00000005, 0.00007582, -0.00000359, 0.00006270),
        solidworks_l(0.00055516, 0.00000061, -0.00000074, 0.00024367, -0.00004590, 0.00045358),
        solidworks_l(0.00003773, -0.00000019, 0.0, 0.00003806, 0.0, 0.00007408),
    ],
    inertia_frame="dh",
    # Position limits from the manual's Table 6; effort and velocity are derived bounds (see the
    # URDF header): continuous torque = sum |drive ratio| x motor continuous torque, velocity =
    # motor no-load speed / drive ratio.
    limits=[
        (-2.6, 2.6, 100.218 / 42, 42 * 1.490),
        (-2.0, 2.0, 100.218 / 28.25, 2 * 28.25 * 1.490),
        (-2.8, 2.8, 100.218 / 16.8155, 2 * 16.8155 * 1.490),
        (-0.9, 3.1, 100.218 / 18, 18 * 1.490),
        (-4.76, 1.24, 192.309 / 9.7, 2 * 9.7 * 0.356),
        (-1.6, 1.6, 192.309 / 9.7, 2 * 9.7 * 0.356),
        (-3.0, 3.0, 569.022 / 14.93, 14.93 * 0.091),
    ],
    # the URDF rounds the derived velocity bound to 4 decimals
    velocity_tol=5e-5,
)

PUBLISHED = {"ur5": UR5, "ur10": UR10, "wam": WAM}

# ---------------------------------------------------------------------------------------------
# Transforms
# ---------------------------------------------------------------------------------------------


def hom(r, p):
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = p
    return t


def dh_step(theta, d, a, alpha):
    """Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_frames(pub, q):
    """[T_0_1, ..., T_0_N] from the published table."""
    t = np.eye(4)
    out = []
    for qi, a, d, al in zip(q, pub["a"], pub["d"], pub["alpha"]):
        t = t @ dh_step(qi, d, a, al)
        out.append(t)
    return out


def rpy_matrix(r, p, y):
    """URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def axis_angle(axis, angle):
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def rotation_angle(r_a, r_b):
    """Angle of r_a^T r_b, accurate for small angles."""
    e = r_a.T @ r_b
    v = np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]])
    return math.atan2(np.linalg.norm(v) / 2.0, (np.trace(e) - 1.0) / 2.0)


# ---------------------------------------------------------------------------------------------
# URDF reading
# ---------------------------------------------------------------------------------------------


def floats(text, n):
    vals = [float(x) for x in text.split()]
    if len(vals) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return vals


def origin_of(elem):
    o = elem.find("origin")
    if o is None:
        return np.eye(4)
    xyz = floats(o.get("xyz", "0 0 0"), 3)
    rpy = floats(o.get("rpy", "0 0 0"), 3)
    return hom(rpy_matrix(*rpy), xyz)


class Urdf:
    def __init__(self, path):
        root = ET.parse(path).getroot()
        if root.tag != "robot":
            raise ValueError(f"{path}: root element is <{root.tag}>, not <robot>")
        self.name = root.get("name")
        self.links = {l.get("name"): l for l in root.findall("link")}
        self.joints = root.findall("joint")
        self.by_child = {}
        for j in self.joints:
            child = j.find("child").get("link")
            if child in self.by_child:
                raise ValueError(f"{path}: link {child} has two parent joints")
            self.by_child[child] = j

    def chain(self, base, tip):
        """Joints from base to tip, in order."""
        out = []
        link = tip
        while link != base:
            j = self.by_child.get(link)
            if j is None:
                raise ValueError(f"no path from {base} to {tip}")
            out.append(j)
            link = j.find("parent").get("link")
        return out[::-1]

    def link_poses(self, base, tip, q):
        """Pose of every link on the chain (dict name -> 4x4), and the moving joints in order."""
        poses = {base: np.eye(4)}
        t = np.eye(4)
        moving = []
        qi = 0
        for j in self.chain(base, tip):
            t = t @ origin_of(j)
            jt = j.get("type")
            if jt in ("revolute", "continuous"):
                axis = floats(j.find("axis").get("xyz"), 3) if j.find("axis") is not None else [1, 0, 0]
                t = t @ hom(axis_angle(axis, q[qi]), [0.0, 0.0, 0.0])
                qi += 1
                moving.append(j)
            elif jt != "fixed":
                raise ValueError(f"joint {j.get('name')}: unexpected type {jt}")
            poses[j.find("child").get("link")] = t
        if qi != len(q):
            raise ValueError(f"chain has {qi} moving joints, configuration has {len(q)}")
        return poses, moving


def inertial_of(link):
    """(mass, T_link_com, I_com in inertial frame) or None."""
    i = link.find("inertial")
    if i is None:
        return None
    m = float(i.find("mass").get("value"))
    t = origin_of(i)
    it = i.find("inertia")
    vals = {k: float(it.get(k)) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    tensor = sym(vals["ixx"], vals["ixy"], vals["ixz"], vals["iyy"], vals["iyz"], vals["izz"])
    return m, t, tensor


# ---------------------------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------------------------


def physical_tensor_problem(tensor):
    if np.max(np.abs(tensor - tensor.T)) > 0:
        return "not symmetric"
    w = np.linalg.eigvalsh(tensor)
    if w[0] <= 0:
        return f"not positive definite (eigenvalues {w})"
    if w[0] + w[1] < w[2]:
        return f"violates the triangle inequality (eigenvalues {w})"
    return None


def published_inertia_in_dh(pub, k):
    """Published tensor re-expressed in DH frame k (orientation only)."""
    tensor = pub["inertia"][k]
    if pub["inertia_frame"] == "dh":
        return tensor
    r = rot_x(-pub["alpha"][k]) @ rpy_matrix(*pub["inertia_rpy"][k])
    return r @ tensor @ r.T


def check_robot(robot, pub, rng, failures):
    path = ROBOTS_DIR / f"{robot}.urdf"
    u = Urdf(path)
    n = len(pub["a"])
    base, tip = f"{robot}_base_link", f"{robot}_flange"
    link_names = [f"{robot}_link_{k}" for k in range(1, n + 1)]
    joint_names = [f"{robot}_joint_{k}" for k in range(1, n + 1)]

    def fail(msg):
        failures.append(f"{robot}: {msg}")

    if u.name != robot:
        fail(f"robot name is {u.name!r}")
    for name in [base, tip] + link_names:
        if name not in u.links:
            fail(f"missing link {name}")
    for link in u.links.values():
        if link.find("visual") is not None or link.find("collision") is not None:
            fail(f"link {link.get('name')} has geometry")
    if failures:
        return None

    _, moving = u.link_poses(base, tip, np.zeros(n))
    if [j.get("name") for j in moving] != joint_names:
        fail(f"moving joints are {[j.get('name') for j in moving]}")

    # masses, limits, tensor validity
    for k in range(n):
        inert = inertial_of(u.links[link_names[k]])
        if inert is None:
            fail(f"{link_names[k]} has no inertial")
            continue
        m, _, tensor = inert
        if abs(m - pub["mass"][k]) > VALUE_TOL:
            fail(f"{link_names[k]} mass {m} != published {pub['mass'][k]}")
        problem = physical_tensor_problem(tensor)
        if problem:
            fail(f"{link_names[k]} inertia {problem}")
    for k, j in enumerate(moving):
        if j.get("type") != "revolute":
            fail(f"{j.get('name')} is {j.get('type')}, expected revolute")
        lim = j.find("limit")
        lo, hi, vel, eff = (float(lim.get(x)) for x in ("lower", "upper", "velocity", "effort"))
        plo, phi, pvel, peff = pub["limits"][k]
        vtol = pub.get("velocity_tol", VALUE_TOL)
        if abs(lo - plo) > VALUE_TOL or abs(hi - phi) > VALUE_TOL:
            fail(f"{j.get('name')} range [{lo}, {hi}] != [{plo}, {phi}]")
        if abs(vel - pvel) > vtol:
            fail(f"{j.get('name')} velocity {vel} != {pvel}")
        if abs(eff - peff) > 1e-9:
            fail(f"{j.get('name')} effort {eff} != {peff}")

    # kinematics, centres of mass, inertia tensors over random configurations
    max_pos = max_rot = max_com = max_inertia = 0.0
    for _ in range(N_CONFIGS):
        q = rng.uniform(-PI, PI, size=n)
        poses, _ = u.link_poses(base, tip, q)
        frames = dh_frames(pub, q)
        t_u, t_dh = poses[tip], frames[-1]
        max_pos = max(max_pos, float(np.max(np.abs(t_u[:3, 3] - t_dh[:3, 3]))))
        max_rot = max(max_rot, rotation_angle(t_u[:3, :3], t_dh[:3, :3]))
        for k in range(n):
            m, t_link_com, tensor = inertial_of(u.links[link_names[k]])
            t_com = poses[link_names[k]] @ t_link_com
            com_dh = frames[k] @ np.append(pub["com"][k], 1.0)
            max_com = max(max_com, float(np.max(np.abs(t_com[:3, 3] - com_dh[:3]))))
            r_u = t_com[:3, :3]
            i_base_u = r_u @ tensor @ r_u.T
            r_dh = frames[k][:3, :3]
            i_base_pub = r_dh @ published_inertia_in_dh(pub, k) @ r_dh.T
            max_inertia = max(max_inertia, float(np.max(np.abs(i_base_u - i_base_pub))))

    print(
        f"{robot:5s} {N_CONFIGS} configurations: max flange position error {max_pos:.3e} m, "
        f"max flange rotation error {max_rot:.3e} rad, max CoM error {max_com:.3e} m, "
        f"max inertia error {max_inertia:.3e} kg m^2"
    )
    if max_pos > POS_TOL:
        fail(f"flange position error {max_pos:.3e} m > {POS_TOL}")
    if max_rot > ROT_TOL:
        fail(f"flange rotation error {max_rot:.3e} rad > {ROT_TOL}")
    if max_com > POS_TOL:
        fail(f"centre-of-mass error {max_com:.3e} m > {POS_TOL}")
    if max_inertia > INERTIA_TOL:
        fail(f"inertia error {max_inertia:.3e} kg m^2 > {INERTIA_TOL}")
    return max_pos, max_rot, max_com, max_inertia


def main():
    failures = []
    for robot, pub in PUBLISHED.items():
        rng = np.random.default_rng(SEED)
        try:
            check_robot(robot, pub, rng, failures)
        except (OSError, ValueError, ET.ParseError, AttributeError, TypeError) as e:
            failures.append(f"{robot}: could not be checked: {e}")
    if failures:
        print("FAILED:")
        for f in failures:
            print("  " + f)
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
