"""Robot.fk and Robot.jacobian against independent computations: MuJoCo's forward kinematics stored in
golden/ (scripts/mujoco_reference.py), the command line's `robocal fk`, and central differences of fk."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import robocal

from conftest import REPO, SHARED

#: MuJoCo's golden flange poses and ours agree to rounding: the README's table gives <= 1e-15 m and
#: 1e-15 rad over 500 configurations per robot. A margin of 100x covers the summation order.
GOLDEN_POSITION_TOL_M = 1e-13
GOLDEN_ROTATION_TOL = 1e-13
#: Central differences with h = 1e-6: truncation O(h^2) and rounding O(eps/h) stay below 1e-8.
FD_STEP = 1e-6
FD_TOL = 1e-8


def golden(name: str):
    """(root link, tip link, urdf, q, p, R) of golden/kinematics_<name>.csv."""
    path = REPO / "golden" / f"kinematics_{name}.csv"
    header = [l for l in path.read_text().splitlines() if l.startswith("#")]
    line = next(l for l in header if l.startswith("# urdf:"))
    urdf = (SHARED if "shared directory" in line else REPO) / line.split()[2]
    links = next(l for l in header if l.startswith("# root link:"))
    root = links.split("root link:")[1].split()[0]
    tip = links.split("tip link:")[1].split()[0]
    table = pd.read_csv(path, comment="#")
    q = table[[c for c in table.columns if c.startswith("q")]].to_numpy()
    p = table[["px", "py", "pz"]].to_numpy()
    r = table[[f"r{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]].to_numpy().reshape(-1, 3, 3)
    return root, tip, urdf, q, p, r


ROBOTS = ["iiwa7", "ur5", "ur10", "wam", "iiwa_stack_iiwa7", "lbr_stack_iiwa7"]


@pytest.mark.parametrize("name", ROBOTS)
def test_fk_matches_mujoco_golden_files(name):
    root, tip, urdf, q, p, r = golden(name)
    robot = robocal.Robot.load(str(urdf), base_link=root, tip_link=tip)
    t = robot.fk(q)  # all 500 configurations at once: N x 4 x 4
    assert t.shape == (len(q), 4, 4)
    assert np.abs(t[:, :3, 3] - p).max() < GOLDEN_POSITION_TOL_M
    assert np.abs(t[:, :3, :3] - r).max() < GOLDEN_ROTATION_TOL
    np.testing.assert_array_equal(t[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (len(q), 1)))
    # One configuration at a time gives the same bits as the batch.
    for k in (0, 17, len(q) - 1):
        np.testing.assert_array_equal(robot.fk(q[k]), t[k])


def test_fk_matches_the_cli(cli):
    robot = robocal.Robot.load("ur5")
    rng = np.random.default_rng(3)
    for q in rng.uniform(*robot.limits.T, size=(5, robot.dof)):
        doc = cli.json("fk", "--robot", "ur5", "--q", ",".join(repr(float(v)) for v in q))
        t = robot.fk(q)
        np.testing.assert_array_equal(t[:3, 3], doc["position_m"])
        np.testing.assert_array_equal(t[:3, :3], doc["rotation"])


def test_robot_description():
    robot = robocal.Robot.load("iiwa7")
    assert robot.dof == 7 and len(robot.joint_names) == 7
    assert robot.joint_names[0] == "iiwa7_A1"
    assert (robot.base_link, robot.tip_link) == ("iiwa7_link_0", "iiwa7_flange")
    assert robot.limits.shape == (7, 2)
    assert "<robot" in robot.urdf
    # The flange at q = 0 is 1.266 m above the base (KUKA's data sheet, as in sim's tests).
    np.testing.assert_allclose(robot.fk(np.zeros(7))[:3, 3], [0, 0, 1.266], atol=1e-15)


def skew_vector(m: np.ndarray) -> np.ndarray:
    return np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / 2


@pytest.mark.parametrize("name", ["iiwa7", "wam"])
def test_jacobians_match_central_differences(name):
    robot = robocal.Robot.load(name)
    rng = np.random.default_rng(11)
    lower, upper = robot.limits.T
    for q in rng.uniform(lower + 0.01, upper - 0.01, size=(4, robot.dof)):
        t = robot.fk(q)
        r, p = t[:3, :3], t[:3, 3]
        js, jb, jl = (robot.jacobian(q, frame=f) for f in ("spatial", "body", "local_world_aligned"))
        assert js.shape == (6, robot.dof)
        for i in range(robot.dof):
            dq = np.zeros(robot.dof)
            dq[i] = FD_STEP
            tp, tm = robot.fk(q + dq), robot.fk(q - dq)
            dr = (tp[:3, :3] - tm[:3, :3]) / (2 * FD_STEP)
            dp = (tp[:3, 3] - tm[:3, 3]) / (2 * FD_STEP)
            w = skew_vector(dr @ r.T)           # angular velocity, base frame
            v_spatial = dp - np.cross(w, p)     # velocity of the point at the base origin
            assert np.abs(js[:3, i] - w).max() < FD_TOL
            assert np.abs(js[3:, i] - v_spatial).max() < FD_TOL
            assert np.abs(jl[:3, i] - w).max() < FD_TOL
            assert np.abs(jl[3:, i] - dp).max() < FD_TOL
            assert np.abs(jb[:3, i] - r.T @ w).max() < FD_TOL
            assert np.abs(jb[3:, i] - r.T @ dp).max() < FD_TOL


def test_fk_refuses_a_wrong_joint_count():
    robot = robocal.Robot.load("iiwa7")
    with pytest.raises(robocal.BadInput, match=r"^q: "):
        robot.fk([0.0, 1.0])
    with pytest.raises(robocal.BadInput, match="expected \\(7,\\) or \\(N, 7\\)"):
        robot.fk(np.zeros((3, 6)))
    with pytest.raises(robocal.BadInput, match="not one of spatial, body, local_world_aligned"):
        robot.jacobian(np.zeros(7), frame="world")
    with pytest.warns(robocal.DataWarning, match="outside the limits"):
        robot.fk([3.0, 0, 0, 0, 0, 0, 0])
