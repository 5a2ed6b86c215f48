"""`Model.register` of a file read in pieces (issue 28): the same registration as the table held in
memory, within the solver's tolerance, and `report["stream"]` says how it streamed; a DataFrame with
`stream="always"` is `BadInput`."""

from __future__ import annotations

import pytest

import robocal

from conftest import REPO


def test_a_registration_streamed_from_a_file_is_the_in_memory_one(tmp_path) -> None:
    scenario = REPO / "scenarios" / "iiwa7_kinematic.toml"
    first = robocal.generate(scenario, seed=5, poses=200)
    model = robocal.calibrate(first.measurements, folds=0)
    moved = tmp_path / "moved.toml"
    text = scenario.read_text()
    moved.write_text(text.replace("xyz_m = [2.5, 1.0, -0.2]", "xyz_m = [-1.8, 2.2, 0.3]"))
    ds = robocal.generate(moved, seed=5, poses=5000, out=tmp_path / "b")
    path = tmp_path / "b" / "measurements.parquet"
    streamed = model.register(path, stream="always", chunk_rows=700)
    memory = model.register(path, stream="never")
    assert streamed.report["stream"]["rows"] == 5000
    assert streamed.report["stream"]["chunk_rows"] == 700
    assert "stream" not in memory.report
    a, b = memory.report["report"], streamed.report["report"]
    assert a["n_rows"] == b["n_rows"] == 5000
    assert b["translation_m"] == pytest.approx(a["translation_m"], abs=1e-10)
    assert b["residual"]["rms_m"] == pytest.approx(a["residual"]["rms_m"], rel=1e-6)
    with pytest.raises(robocal.BadInput, match="stream='always'"):
        model.register(ds.measurements, stream="always")
