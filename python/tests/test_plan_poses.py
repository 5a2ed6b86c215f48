"""Pose planning from Python (issue 27): `robocal.plan_poses` gives the CLI's poses, payloads and
plan (the same flags, the same bytes of the pose file), takes the robot's own candidates as a
DataFrame, and refuses what the CLI refuses, as `BadInput`."""

from __future__ import annotations

import pandas as pd
import pytest

import robocal


def test_a_compliance_plan_is_the_clis(cli, tmp_path) -> None:
    out = tmp_path / "plan.csv"
    flags = ["--model", "kinematic+joint_compliance", "--payloads", "0,7", "--candidates", "150",
             "--select", "25", "--seed", "4", "--tracker", "2,1,0.3", "--tracker-range", "1,3"]
    doc = cli.json("plan-poses", "--robot", "iiwa7", *flags, "--out", out)
    frame = robocal.plan_poses(
        "iiwa7", select=25, model="kinematic+joint_compliance", payloads=[0, 7], candidates_count=150,
        seed=4, tracker=(2, 1, 0.3), tracker_range=(1, 3),
    )
    assert list(frame.columns) == ["pose"] + [f"q{j}" for j in range(1, 8)] + ["payload"]
    assert frame.equals(pd.read_csv(out))
    plan = frame.attrs["plan"]
    assert plan["candidate_indices"] == doc["plan"]["candidate_indices"]
    assert plan["rejected"] == doc["plan"]["rejected"]
    sigma = {p["name"]: p["sigma"] for p in plan["parameters"]}
    assert sigma["joint 2 compliance"] == pytest.approx(
        next(p["sigma"] for p in doc["plan"]["parameters"] if p["name"] == "joint 2 compliance"),
        rel=0, abs=0,
    )
    assert "plan_poses" in robocal.__all__ and "payloads" in robocal.options("plan_poses")


def test_own_candidates_as_a_dataframe(cli, tmp_path) -> None:
    drawn = robocal.plan_poses("ur5", select=40, candidates_count=300, seed=2)
    own = drawn.drop(columns=["pose"]).assign(pose=range(100, 140))
    chosen = robocal.plan_poses("ur5", select=30, candidates=own)
    assert len(chosen) == 30
    assert set(chosen.attrs["plan"]["source_poses"]) <= set(range(100, 140))
    path = tmp_path / "own.csv"
    own.to_csv(path, index=False)
    again = robocal.plan_poses("ur5", select=30, candidates=path)
    assert again.equals(chosen)


def test_bad_options_are_bad_input() -> None:
    with pytest.raises(robocal.BadInput, match="--criterion x: not one of d, a, e"):
        robocal.plan_poses("iiwa7", select=20, criterion="x")
    with pytest.raises(robocal.BadInput, match="needs --tracker"):
        robocal.plan_poses("iiwa7", select=20, tracker_range=(1, 3))
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        robocal.plan_poses("iiwa7", select=20, colour="red")
