"""Coupled joints from Python (issue 25): `Robot.load(..., couplings=FILE)` declares them beside the
URDF, as `--couplings` does, and a diagnosis of a table with one column per driven joint is the
command line's."""

from __future__ import annotations

import robocal

from conftest import REPO

URDF = REPO / "sim" / "tests" / "data" / "coupled_torso.urdf"
COUPLINGS = """[[coupling]]
joint = "torso_pitch_3"
sources = ["torso_pitch_1", "torso_pitch_2"]
multipliers = [-1.0, -1.0]
"""


def test_couplings_beside_the_urdf_diagnose_as_the_cli(cli, tmp_path):
    text = URDF.read_text()
    start = text.index("<robocal:coupling")
    end = text.index("/>", start) + 2
    bare = tmp_path / "bare.urdf"
    bare.write_text(text[:start] + text[end:])
    couplings = tmp_path / "couplings.toml"
    couplings.write_text(COUPLINGS)
    cli.run("generate", "--scenario", REPO / "scenarios" / "coupled_torso_compliance.toml",
            "--out", tmp_path / "gen", "--poses", "120")
    data = tmp_path / "gen" / "measurements.parquet"
    robot = robocal.Robot.load(str(bare), tip_link="left_flange", couplings=str(couplings))
    assert robot.dof == 8 and robot.joint_names[3] == "torso_pitch_3"
    expected = cli.json("diagnose", "--robot", bare, "--tip-link", "left_flange",
                        "--couplings", couplings, "--data", data)
    got = robocal.diagnose(str(data), robot=robot, stream="never")
    assert got == expected
    names = [f["cause"] for f in got["findings"]]
    assert "joint_compliance" in names and "gear_backlash" not in names
    compliance = next(f for f in got["findings"] if f["cause"] == "joint_compliance")
    assert 4 not in compliance["joints"]
