"""Branches that load the chain from Python (issue 25): a DataFrame with the branch joints'
`q_<joint>` columns is diagnosed as the command line diagnoses its file, and without those columns
the fit is worse (the columns are read, not dropped on the way in)."""

from __future__ import annotations

import pandas as pd
import robocal

from conftest import REPO

URDF = REPO / "sim" / "tests" / "data" / "torso_two_arms.urdf"
BRANCH_COLUMNS = ["q_neck_yaw", "q_neck_pitch", "q_right_shoulder_pitch", "q_right_elbow"]


def held_out_rms(doc):
    return doc["steps"][-1]["test_rms_m"]


def test_branch_columns_of_a_dataframe_diagnose_as_the_cli(cli, tmp_path):
    cli.run("generate", "--scenario", REPO / "scenarios" / "torso_branches_compliance.toml",
            "--out", tmp_path / "gen", "--poses", "150")
    data = tmp_path / "gen" / "measurements.parquet"
    frame = pd.read_parquet(data)
    assert [c for c in frame.columns if c.startswith("q_")] == BRANCH_COLUMNS
    robot = robocal.Robot.load(str(URDF), tip_link="left_flange")
    expected = cli.json("diagnose", "--robot", URDF, "--tip-link", "left_flange", "--data", data)
    got = robocal.diagnose(frame, robot=robot)
    assert got["findings"] == expected["findings"] and got["steps"] == expected["steps"]
    assert "joint_compliance" in [f["cause"] for f in got["findings"]]
    bare = robocal.diagnose(frame.drop(columns=BRANCH_COLUMNS), robot=robot)
    assert held_out_rms(bare) > 5 * held_out_rms(got)
