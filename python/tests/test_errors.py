"""Bad input raises robocal.BadInput (the CLI's exit 2) and failed work robocal.RuntimeFailure (exit
1), with the message the command line prints for the same file or flag; tables in memory get the
messages of a file with the same columns, naming the column, the row (1-based, as in a file) and the
value; nothing aborts the interpreter."""

from __future__ import annotations

import numpy as np
import pandas as pd
import polars as pl
import pytest

import robocal

from conftest import REPO


@pytest.fixture(scope="module")
def frame(generated) -> pd.DataFrame:
    return robocal.read_table(generated / "measurements.parquet")


def test_the_hierarchy():
    assert issubclass(robocal.BadInput, robocal.Error) and issubclass(robocal.BadInput, ValueError)
    assert issubclass(robocal.RuntimeFailure, robocal.Error) and issubclass(robocal.RuntimeFailure, RuntimeError)
    assert issubclass(robocal.DataWarning, UserWarning)


@pytest.mark.parametrize(
    "options, flags",
    [
        ({"robust": "tukey"}, ["--robust", "tukey"]),
        ({"test_fraction": 1.5}, ["--test-fraction", "1.5"]),
        ({"folds": 3, "test_fraction": 0.2}, ["--folds", "3", "--test-fraction", "0.2"]),
        ({"model": "kinematic+gravity_wells"}, ["--model", "kinematic+gravity_wells"]),
    ],
)
def test_bad_options_have_the_cli_message(cli, generated, tmp_path, options, flags):
    data = generated / "measurements.parquet"
    code, message = cli.error("calibrate", "--data", data, "--out", tmp_path / "m.json", *flags)
    assert code == 2
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(data), **options)
    assert str(e.value) == message


def test_unparsable_values_have_the_first_line_of_the_cli_message(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    out = cli.run("calibrate", "--data", data, "--out", tmp_path / "m.json", "--seed=-1", check=False)
    assert out.returncode == 2
    message = out.stderr.splitlines()[0].removeprefix("error: ")
    assert message == "invalid value '-1' for '--seed <N>': invalid digit found in string"
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(data), seed=-1)
    assert str(e.value) == message


def test_bad_diagnose_and_generate_options(cli, generated, tmp_path):
    data = generated / "measurements.parquet"
    code, message = cli.error("diagnose", "--data", data, "--noise-floor", "0.5")
    with pytest.raises(robocal.BadInput) as e:
        robocal.diagnose(str(data), noise_floor=0.5)
    assert (code, str(e.value)) == (2, message)
    scenario = REPO / "scenarios" / "iiwa7_all.toml"
    code, message = cli.error("generate", "--scenario", scenario, "--out", tmp_path / "g", "--poses", "0")
    with pytest.raises(robocal.BadInput) as e:
        robocal.generate(scenario, poses=0)
    assert (code, str(e.value)) == (2, message)


def test_unknown_options_are_type_errors(generated):
    with pytest.raises(TypeError, match="unexpected keyword argument 'alpha'.*folds, test_fraction"):
        robocal.calibrate(str(generated / "measurements.parquet"), alpha=0.01)
    with pytest.raises(TypeError, match="unexpected keyword argument 'robust'"):
        robocal.diagnose(str(generated / "measurements.parquet"), robust="huber")


def test_bad_files_have_the_cli_message(cli, tmp_path, frame):
    bad = frame.head(40).copy()
    csv = tmp_path / "bad.csv"
    bad.to_csv(csv, index=False, float_format="%.17g")
    text = csv.read_text().splitlines()
    cells = text[5].split(",")
    cells[3] = "abc"  # q3 of data row 5
    text[5] = ",".join(cells)
    csv.write_text("\n".join(text) + "\n")
    code, message = cli.error("calibrate", "--data", csv, "--out", tmp_path / "m.json")
    assert code == 2 and "row 5 (line 6), column q3: 'abc' is not a number" in message
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(csv))
    assert str(e.value) == message
    code, message = cli.error("calibrate", "--data", tmp_path / "missing.parquet", "--out", tmp_path / "m.json")
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(tmp_path / "missing.parquet"))
    assert str(e.value) == message
    code, message = cli.error("calibrate", "--robot", "kuka9", "--data", csv, "--out", tmp_path / "m.json")
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(csv), robot="kuka9")
    assert str(e.value) == message
    (tmp_path / "model.json").write_text('{"format": "something else"}')
    code, message = cli.error("predict", "--model", tmp_path / "model.json", "--data", csv, "--out", tmp_path / "p.csv")
    with pytest.raises(robocal.BadInput) as e:
        robocal.load_model(tmp_path / "model.json")
    assert str(e.value) == message


def test_tables_in_memory_name_column_row_and_value(frame):
    bad = frame.copy()
    bad.loc[3, "q2"] = np.nan
    with pytest.raises(robocal.BadInput, match=r"^<pandas DataFrame>: row 4, column q2: NaN is not finite$"):
        robocal.calibrate(bad)
    with pytest.raises(robocal.BadInput, match=r"^<pandas DataFrame>: column q3: has type (str|object); an integer or floating-point type is required$"):
        robocal.calibrate(frame.assign(q3=frame["q3"].astype(str)))
    with pytest.raises(robocal.BadInput, match=r"^<dict>: column z: missing required column 'z'"):
        robocal.calibrate({c: frame[c].to_numpy() for c in frame.columns if c != "z"})
    nulls = pl.from_pandas(frame).with_columns(pl.when(pl.int_range(pl.len()) == 6).then(None).otherwise(pl.col("x")).alias("x"))
    with pytest.raises(robocal.BadInput, match=r"^<polars DataFrame>: row 7, column x: missing value \(null\): a number is required$"):
        robocal.calibrate(nulls)
    with pytest.raises(robocal.BadInput, match=r"^<pandas DataFrame>: row 2, column pose: 0.5 is not an integer$"):
        robocal.calibrate(frame.assign(pose=frame["pose"].astype(float).where(frame.index != 1, 0.5)))
    with pytest.raises(robocal.BadInput, match=r"column q1: 3 values, but column pose has"):
        robocal.calibrate({**{c: frame[c].to_numpy() for c in frame.columns}, "q1": np.zeros(3)})
    with pytest.raises(TypeError, match="expected a pandas or polars DataFrame"):
        robocal.calibrate([1, 2, 3])


def test_too_few_poses_names_the_split(cli, tmp_path, frame):
    small = tmp_path / "small.csv"
    frame.head(12).to_csv(small, index=False, float_format="%.17g")
    code, message = cli.error("calibrate", "--data", small, "--out", tmp_path / "m.json")
    assert code == 2 and "--folds 5 fits each fold on 4/5 of the poses" in message
    with pytest.raises(robocal.BadInput) as e:
        robocal.calibrate(str(small))
    assert str(e.value) == message


def test_data_warnings_are_the_cli_warnings(cli, tmp_path, frame):
    odd = frame.copy()
    odd.loc[0, "q1"] = 2.97  # beyond the iiwa's 2.9671 rad limit, by less than 0.1 rad
    csv = tmp_path / "odd.csv"
    odd.to_csv(csv, index=False, float_format="%.17g")
    out = cli.run("calibrate", "--data", csv, "--out", tmp_path / "m.json")
    expected = [l.removeprefix("warning: ") for l in out.stderr.splitlines() if l.startswith("warning: ") and "limit" in l]
    assert expected
    with pytest.warns(robocal.DataWarning) as caught:
        robocal.calibrate(str(csv))
    assert [str(w.message) for w in caught if "limit" in str(w.message)] == expected


def test_prediction_needs_the_model_joints(cli, tmp_path, frame, generated):
    data = generated / "measurements.parquet"
    cli.run("calibrate", "--data", data, "--out", tmp_path / "m.json")
    six = tmp_path / "six.csv"
    frame.drop(columns=["q7", "dir7"]).to_csv(six, index=False, float_format="%.17g")
    code, message = cli.error("predict", "--model", tmp_path / "m.json", "--data", six, "--out", tmp_path / "p.csv")
    with pytest.raises(robocal.BadInput) as e:
        robocal.load_model(tmp_path / "m.json").predict(str(six))
    assert (code, str(e.value)) == (2, message)
