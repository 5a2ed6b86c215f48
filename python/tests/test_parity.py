"""The Python package gives exactly the command line's results for the same inputs and flags: the
same generated data, the same calibration report and model file, the same predictions and the same
diagnosis. Expected values come from the CLI binary (the same engine, driven through files and flags),
so these tests catch any second path in the Python layer: a conversion that changes a value, an
option that maps to another flag, a default that differs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import polars as pl
import pytest

import robocal

from conftest import REPO


def report_without_outputs(doc: dict) -> dict:
    """A `calibrate --json` document without what names the output files (none are written from
    Python until `save`)."""
    return {k: v for k, v in doc.items() if k not in ("out", "urdf_out")}


def test_generate_gives_the_cli_dataset(generated, tmp_path):
    ds = robocal.generate(REPO / "scenarios" / "iiwa7_all.toml", seed=7, poses=150)
    # Independent reader: pandas (pyarrow) on the CLI's file.
    expected = pd.read_parquet(generated / "measurements.parquet")
    assert list(ds.measurements.columns) == list(expected.columns)
    for c in expected.columns:
        assert ds.measurements[c].dtype == expected[c].dtype, c
        np.testing.assert_array_equal(ds.measurements[c].to_numpy(), expected[c].to_numpy(), err_msg=c)
    with open(generated / "truth.json", encoding="utf-8") as f:
        assert ds.truth == json.load(f)
    assert ds.summary["poses"] == 150 and ds.summary["seed"] == 7
    # With out=, the files themselves.
    kept = robocal.generate(REPO / "scenarios" / "iiwa7_all.toml", seed=7, poses=150, out=tmp_path / "d")
    for name in ("measurements.parquet", "truth.json", "truth.parquet"):
        assert (tmp_path / "d" / name).read_bytes() == (generated / name).read_bytes(), name
    assert kept.path == str(tmp_path / "d")


CALIBRATE_FLAGS = [
    {},
    {"test_fraction": 0.2, "seed": 3},
    {"folds": 3, "seed": 2},
    {"folds": 0},
    {"robust": "huber"},
    {"model": "kinematic+joint_compliance+gear_backlash"},
]


def as_flags(options: dict) -> list[str]:
    out = []
    for k, v in options.items():
        out += ["--" + k.replace("_", "-"), str(v)]
    return out


@pytest.mark.parametrize("options", CALIBRATE_FLAGS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "defaults")
def test_calibrate_gives_the_cli_report_and_model_file(cli, generated, tmp_path, options):
    data = generated / "measurements.parquet"
    out = tmp_path / "cli.json"
    expected = cli.json("calibrate", "--data", data, "--out", out, *as_flags(options))
    model = robocal.calibrate(str(data), robot="iiwa7", **options)
    assert report_without_outputs(model.report) == report_without_outputs(expected)
    assert model.report["out"] is None
    model.save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == out.read_bytes()


def test_every_kind_of_data_gives_the_same_calibration(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    # One fit each (no cross-validation): the kinds of data are the subject here.
    expected = cli.json("calibrate", "--data", data, "--out", tmp_path / "m.json", "--folds", "0")["report"]
    frame = robocal.read_table(data)
    csv = tmp_path / "m.csv"
    cli.run("predict", "--model", tmp_path / "m.json", "--data", data, "--out", tmp_path / "p.csv")
    frame.to_csv(csv, index=False, float_format="%.17g")
    kinds = {
        "pandas": frame,
        "polars": pl.from_pandas(frame),
        "dict": {c: frame[c].to_numpy() for c in frame.columns},
        "csv": str(csv),
        "dataset": robocal.Dataset(frame, {}, {}, None),
        # Narrower types that convert exactly: int32 pose, int16 dir, a column the contract ignores.
        "int32 pose": frame.assign(pose=frame["pose"].astype("int32"), note="x",
                                   dir1=frame["dir1"].astype("int16")),
        "nullable pandas dtypes": frame.astype({"pose": "Int64", "q1": "Float64"}),
    }
    for name, data_like in kinds.items():
        got = robocal.calibrate(data_like, robot="iiwa7", folds=0).report["report"]
        assert got == expected, name


def test_predict_gives_the_cli_predictions(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    cli.run("calibrate", "--data", data, "--model", "kinematic+joint_compliance", "--out", tmp_path / "m.json")
    cli.run("predict", "--model", tmp_path / "m.json", "--data", data, "--out", tmp_path / "p.csv")
    expected = pd.read_csv(tmp_path / "p.csv")
    model = robocal.load_model(tmp_path / "m.json")
    assert model.model == "kinematic+joint_compliance" and model.robot == "iiwa7" and model.report is None
    got = model.predict(robocal.read_table(data))
    assert list(got.columns) == list(expected.columns) == ["pose", "x", "y", "z", "sigma_m", "outside_support"]
    for c in expected.columns:
        np.testing.assert_array_equal(got[c].to_numpy(), expected[c].to_numpy(), err_msg=c)
    # From file to file, streamed in pieces: the command's bytes, whatever the piece size.
    for rows in (7, 65_536):
        out = tmp_path / f"streamed_{rows}.csv"
        assert model.predict_file(data, out, chunk_rows=rows) == len(expected)
        assert out.read_bytes() == (tmp_path / "p.csv").read_bytes()
    with pytest.raises(robocal.BadInput, match="chunk_rows=0"):
        model.predict_file(data, tmp_path / "never.csv", chunk_rows=0)
    assert not (tmp_path / "never.csv").exists()
    # Joint configurations alone, as predict reads them: only what the model needs.
    frame = robocal.read_table(data).drop(columns=["x", "y", "z", "sigma", "t", "temp"])
    np.testing.assert_array_equal(model.predict(frame)[["x", "y", "z"]].to_numpy(), expected[["x", "y", "z"]].to_numpy())


def test_compensate_gives_the_cli_joints(cli, generated, tmp_path):
    """`Model.compensate` returns the CLI's `compensate` output, column for column and bit for bit, in
    both modes (x, y, z targets in the tracker frame; a nominal joint program)."""
    data = generated / "measurements.parquet"
    model_path = tmp_path / "m.json"
    cli.run("calibrate", "--data", data, "--model", "kinematic+joint_compliance+gear_backlash", "--out", model_path)
    model = robocal.load_model(model_path)
    frame = robocal.read_table(data).head(40)
    targets = tmp_path / "targets.csv"
    frame.to_csv(targets, index=False, float_format="%.17g")
    program = tmp_path / "program.csv"
    frame.drop(columns=["x", "y", "z", "sigma"]).to_csv(program, index=False, float_format="%.17g")
    for source, options, flags in [(targets, {}, []), (program, {"program": True}, ["--program"])]:
        out = tmp_path / f"q_{source.stem}.csv"
        cli.run("compensate", "--model", model_path, "--targets", source, "--out", out, *flags)
        expected = pd.read_csv(out)
        got = model.compensate(pd.read_csv(source), **options)
        assert list(got.columns) == list(expected.columns)
        assert list(got.columns[:11]) == ["pose"] + [f"q{j}" for j in range(1, 8)] + ["residual_m", "outside_support", "converged"]
        for c in expected.columns:
            np.testing.assert_array_equal(got[c].to_numpy(), expected[c].to_numpy(), err_msg=c)
        assert (got["converged"] == 1).all()
    with pytest.raises(TypeError, match="unexpected keyword argument 'frame_'"):
        model.compensate(str(targets), frame_="base")


DIAGNOSE_FLAGS = [{}, {"test_fraction": 0.25, "seed": 2, "alpha": 0.01}, {"noise_floor": 2e-05}]


@pytest.mark.parametrize("options", DIAGNOSE_FLAGS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "defaults")
def test_diagnose_gives_the_cli_document(cli, generated, options):
    data = generated / "measurements.parquet"
    expected = cli.json("diagnose", "--data", data, *as_flags(options))
    got = robocal.diagnose(str(data), robot="iiwa7", **options)
    assert got == expected
    assert {f["cause"] for f in got["findings"]}  # iiwa7_all hides causes the diagnosis finds


def test_diagnose_of_a_file_streams_as_the_cli(cli, generated):
    """A path streams as `diagnose --stream` (issue 28): the same document, with its `stream` object.
    The sample (at least 1,000 rows) is here the whole file, so the diagnosis is the in-memory one
    and nothing is left to predict."""
    data = generated / "measurements.parquet"
    expected = cli.json(
        "diagnose", "--data", data, "--stream", "always", "--sample-rows", "1000", "--chunk-rows", "40"
    )
    got = robocal.diagnose(str(data), robot="iiwa7", stream="always", sample_rows=1000, chunk_rows=40)
    assert got == expected
    assert got["stream"]["rows"] == 150 and got["stream"]["sample_rows"] == 150
    assert got["stream"]["rest"] is None
    in_memory = robocal.diagnose(str(data), robot="iiwa7", stream="never")
    assert "stream" not in in_memory
    del got["stream"]
    assert got == in_memory
    with pytest.raises(robocal.BadInput, match="data is not a file path"):
        robocal.diagnose(robocal.read_table(data), robot="iiwa7", stream="always")
    with pytest.raises(robocal.BadInput, match="--sample-rows 10"):
        robocal.diagnose(str(data), robot="iiwa7", stream="always", sample_rows=10)


def test_test_data_and_base_tip_links_as_the_cli(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    frame = robocal.read_table(data)
    train, test = frame[frame["pose"] % 3 != 0], frame[frame["pose"] % 3 == 0]
    train.to_csv(tmp_path / "train.csv", index=False, float_format="%.17g")
    test.to_csv(tmp_path / "test.csv", index=False, float_format="%.17g")
    expected = cli.json("calibrate", "--data", tmp_path / "train.csv", "--test-data", tmp_path / "test.csv",
                        "--robot", "iiwa7", "--tip-link", "iiwa7_flange", "--out", tmp_path / "m.json")
    robot = robocal.Robot.load("iiwa7", tip_link="iiwa7_flange")
    got = robocal.calibrate(str(tmp_path / "train.csv"), robot=robot, test_data=str(tmp_path / "test.csv"))
    assert report_without_outputs(got.report) == report_without_outputs(expected)


@pytest.mark.parametrize("folds", [0, 5])
@pytest.mark.parametrize("stream", ["always", "never"])
def test_calibrate_of_a_file_streams_as_the_cli(cli, generated, tmp_path, stream, folds):
    """A path streams as `calibrate --stream` (issue 28), with or without the default validation:
    the same report (with its `stream` object and validation) and the same model file, in pieces of
    40 rows."""
    data = generated / "measurements.parquet"
    out = tmp_path / "cli.json"
    expected = cli.json(
        "calibrate", "--data", data, "--out", out, "--folds", str(folds), "--stream", stream,
        "--chunk-rows", "40"
    )
    model = robocal.calibrate(str(data), robot="iiwa7", folds=folds, stream=stream, chunk_rows=40)
    assert ("validation" in model.report and model.report["validation"] is not None) == (folds > 0)
    assert report_without_outputs(model.report) == report_without_outputs(expected)
    assert ("stream" in model.report) == (stream == "always")
    if stream == "always":
        assert model.report["stream"]["rows"] == 150 and model.report["stream"]["chunk_rows"] == 40
    model.save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == out.read_bytes()


def test_streaming_refuses_what_needs_the_table_in_memory(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    code, message = cli.error(
        "calibrate", "--data", data, "--out", tmp_path / "m.json", "--test-fraction", "0.3", "--stream", "always"
    )
    assert code == 2
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(data), robot="iiwa7", test_fraction=0.3, stream="always")
    assert str(e.value) == message and "--test-fraction" in message
    with pytest.raises(robocal.BadInput, match="reads a .csv or .parquet file in pieces"):
        robocal.calibrate(robocal.read_table(data), robot="iiwa7", folds=0, stream="always")
    with pytest.raises(robocal.BadInput, match="one of 'auto', 'always' or 'never'"):
        robocal.calibrate(str(data), robot="iiwa7", folds=0, stream="sometimes")
