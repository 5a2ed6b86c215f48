"""Campaigns from Python (issue 13): a DataFrame with a `campaign` column calibrates one tracker
registration per campaign, `folds=` validates by k-fold cross-validation, predict puts each row in
its campaign's tracker frame, and `register` adds a moved tracker from 20 poses. Expected values: the
CLI on the same files and flags (same bytes), and the measured positions (a row predicted in the
wrong tracker frame is off by metres, the right one by the tracker noise)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import robocal

from conftest import REPO

#: Tracker placements (m, rad): the scenario's own, and one moved across the cell.
PLACEMENTS = {0: ("[2.5, 1.0, -0.2]", "[0.0, 0.0, 2.5]"), 1: ("[-1.8, 2.2, 0.3]", "[0.05, -0.03, -1.2]")}


def campaign(tmp_path, cid: int, poses: int) -> pd.DataFrame:
    """iiwa7_kinematic.toml with the tracker at placement `cid`; seed 5 draws the same robot errors
    wherever the tracker stands."""
    xyz, rpy = PLACEMENTS[cid]
    text = (REPO / "scenarios" / "iiwa7_kinematic.toml").read_text()
    moved = text.replace("xyz_m = [2.5, 1.0, -0.2]", f"xyz_m = {xyz}").replace(
        "rpy_rad = [0.0, 0.0, 2.5]", f"rpy_rad = {rpy}"
    )
    assert moved != text or cid == 0
    scenario = tmp_path / f"c{cid}.toml"
    scenario.write_text(moved)
    return robocal.generate(scenario, seed=5, poses=poses).measurements


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    d = tmp_path_factory.mktemp("campaigns")
    a, b = campaign(d, 0, 60), campaign(d, 1, 80)
    return a, b


def rms(pred: pd.DataFrame, data: pd.DataFrame) -> float:
    e = pred[["x", "y", "z"]].to_numpy() - data[["x", "y", "z"]].to_numpy()
    return float(np.sqrt((e**2).sum(axis=1).mean()))


def test_a_campaign_column_and_folds_match_the_cli(cli, two, tmp_path):
    a, b = two
    both = pd.concat([a.assign(campaign=0), b.assign(campaign=1)], ignore_index=True)
    assert both["campaign"].dtype == np.int64
    data = tmp_path / "both.parquet"
    both.to_parquet(data, index=False)
    out = tmp_path / "cli.json"
    expected = cli.json("calibrate", "--data", data, "--out", out, "--folds", "3", "--seed", "4")
    model = robocal.calibrate(both, robot="iiwa7", folds=3, seed=4)
    assert model.report["split"] == {"kind": "cross_validation", "folds": 3, "seed": 4, "regions": 5}
    for key in ("report", "validation", "split", "model"):
        assert model.report[key] == expected[key], key
    assert model.to_json() == out.read_text()
    saved = json.loads(out.read_text())
    assert [c["id"] for c in saved["parameters"]["campaigns"]] == [1]
    # Each row in its own campaign's frame: the tracker noise (tens of µm), not the metres between
    # the two placements.
    pred = model.predict(both)
    assert rms(pred, both) < 1e-4
    # The same rows declared in the other campaign land metres away.
    swapped = model.predict(both.assign(campaign=1 - both["campaign"]))
    assert rms(swapped, both) > 0.5
    # An id the model does not know: the CLI's one-line error.
    with pytest.raises(robocal.BadInput, match="campaign"):
        model.predict(both.assign(campaign=7))


def test_register_a_moved_tracker_matches_the_cli(cli, two, tmp_path):
    a, b = two
    first = robocal.calibrate(a, robot="iiwa7", folds=0)
    first.save(tmp_path / "a.json")
    few, rest = b.iloc[:20], b.iloc[20:]
    few.to_csv(tmp_path / "few.csv", index=False, float_format="%.17g")
    expected = cli.json("register", "--model", tmp_path / "a.json", "--data", tmp_path / "few.csv",
                        "--out", tmp_path / "cli2.json")
    moved = first.register(few)
    assert moved.to_json() == (tmp_path / "cli2.json").read_text()
    assert moved.report["report"] == expected["report"]
    assert moved.report["model"] is None and moved.report["out"] is None
    assert robocal.register(first, few).to_json() == moved.to_json()
    # Rows without a campaign column go to the new registration: the rest of series b predicted to
    # the tracker noise; the first model (no registration of b) misses them by metres.
    assert rms(moved.predict(rest), rest) < 1e-4
    assert rms(first.predict(rest), rest) > 0.5
    # Every robot parameter and the model's own campaign are kept as they were (the file's numbers);
    # its rows predict as before, up to the rounding of a chain evaluated per campaign (1e-17 m).
    p0, p1 = json.loads(first.to_json())["parameters"], json.loads(moved.to_json())["parameters"]
    for key in ("joint_error_twists", "zero_offsets", "t_tracker_base", "p_flange_target_m"):
        assert p1[key] == p0[key], key
    assert [c["id"] for c in p1["campaigns"]] == [1] and p1["default_campaign"] == 1
    np.testing.assert_allclose(
        moved.predict(a.assign(campaign=0))[["x", "y", "z"]].to_numpy(),
        first.predict(a)[["x", "y", "z"]].to_numpy(),
        rtol=0, atol=1e-12,
    )


def test_register_options_are_the_cli_flags(two):
    a, _ = two
    assert robocal.options("register") == ["target", "campaign"]
    model = robocal.calibrate(a, robot="iiwa7", folds=0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'folds'"):
        model.register(a, folds=3)
    with pytest.raises(robocal.BadInput, match="campaign"):
        model.register(a, campaign=9)
