"""Measurement tables in and out: pandas or polars DataFrames, dicts of numpy arrays and files.

Columns go to the Rust side as numpy arrays that it reads in place (a pandas or polars column of a
numeric type without missing values is handed over without a copy); the table is checked there exactly
as a file with these columns would be, with the same messages. Tables come back as numpy arrays that
own the memory the Rust side filled.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, Union

import numpy as np

from . import _robocal

#: What robocal accepts as measurement data: a pandas or polars DataFrame, a dict of 1-D arrays
#: (column name -> values), a path to a ``.csv`` or ``.parquet`` file, or a :class:`robocal.Dataset`.
DataLike = Union["pd.DataFrame", "pl.DataFrame", Mapping[str, Any], str, "os.PathLike[str]", Any]

_NUMERIC = set("iuf")


def _column(name: Any, values: Any) -> tuple[str, Any, int | None]:
    """One column as ``(name, contiguous numeric numpy array or type name, first null index)``."""
    name = str(name)
    module = type(values).__module__.split(".")[0]
    if module == "polars":
        nulls = values.null_count()
        first = int(values.is_null().arg_true()[0]) if nulls else None
        if not values.dtype.is_numeric():
            return name, str(values.dtype), first
        if first is not None:
            return name, np.zeros(len(values)), first
        return name, np.ascontiguousarray(values.to_numpy()), None
    if module == "pandas":
        dtype = values.dtype
        if isinstance(dtype, np.dtype):
            # A NaN in a float column is a value (not finite), as in a file.
            if dtype.kind in _NUMERIC:
                return name, _native(values.to_numpy()), None
            return name, str(dtype), None
        # Extension dtypes: nullable integers and floats, pyarrow-backed numbers, categoricals; their
        # missing values (NA) are nulls, as in a Parquet file.
        kind = getattr(dtype, "kind", "O")
        mask = np.asarray(values.isna())
        first = int(np.argmax(mask)) if mask.any() else None
        if first is not None:
            return name, np.zeros(len(values)), first
        numpy_dtype = getattr(dtype, "numpy_dtype", None)
        if numpy_dtype is not None and numpy_dtype.kind in _NUMERIC and kind in _NUMERIC:
            return name, _native(values.to_numpy(dtype=numpy_dtype)), None
        if str(dtype) == "category":
            dense = np.asarray(values)
            if dense.dtype.kind in _NUMERIC:
                return name, _native(dense), None
        return name, str(dtype), None
    array = np.asarray(values)
    if array.ndim != 1:
        raise _robocal_error(f"column {name}: {array.ndim}-D values; one value per row is needed")
    if array.dtype.kind == "f" and array.dtype.itemsize < 4:
        array = array.astype(np.float32)
    if array.dtype.kind not in _NUMERIC:
        return name, str(array.dtype), None
    return name, _native(array), None


def _native(array: np.ndarray) -> np.ndarray:
    """The array contiguous and in native byte order (no copy when it already is)."""
    if not array.dtype.isnative:
        array = array.astype(array.dtype.newbyteorder("="))
    if array.dtype.kind == "f" and array.dtype.itemsize < 4:
        array = array.astype(np.float32)
    return np.ascontiguousarray(array)


def _robocal_error(message: str) -> Exception:
    from ._errors import BadInput

    return BadInput(message)


def to_table(data: Any, *, configurations: bool = False) -> _robocal.Table:
    """The native table of ``data`` (see :data:`DataLike`). With ``configurations`` the positions
    ``x, y, z`` may be absent (joint configurations for a prediction)."""
    from . import Dataset

    if isinstance(data, _robocal.Table):
        return data
    if isinstance(data, Dataset):
        data = data.measurements
    if isinstance(data, (str, os.PathLike)):
        return _robocal.Table.read(os.fspath(data), configurations)
    module = type(data).__module__.split(".")[0]
    if module == "pandas" and hasattr(data, "columns"):
        columns = [_column(c, data[c]) for c in data.columns]
        source = "<pandas DataFrame>"
    elif module == "polars" and hasattr(data, "columns"):
        columns = [_column(c, data.get_column(c)) for c in data.columns]
        source = "<polars DataFrame>"
    elif isinstance(data, Mapping):
        columns = [_column(c, v) for c, v in data.items()]
        source = "<dict>"
    else:
        raise TypeError(
            "data: expected a pandas or polars DataFrame, a dict of arrays, a path to a .csv or "
            f".parquet file, or a robocal.Dataset; got {type(data).__name__}"
        )
    return _robocal.Table.from_columns(columns, source, configurations)


def to_frame(columns: list[tuple[str, np.ndarray]]) -> "pd.DataFrame":
    """A pandas DataFrame of ``(name, array)`` columns, in that order."""
    import pandas as pd

    return pd.DataFrame(dict(columns), copy=False)


def flags(options: Mapping[str, Any]) -> list[str]:
    """Keyword options as the command line's flags: ``test_fraction=0.2`` -> ``--test-fraction=0.2``,
    ``True`` -> the bare flag, ``None`` and ``False`` -> nothing. Floats are written as ``repr`` (the
    shortest text that reads back to the same value)."""
    out = []
    for key, value in options.items():
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        if value is True:
            out.append(flag)
            continue
        if isinstance(value, float):
            text = repr(float(value))
        elif isinstance(value, (list, tuple)):
            text = ",".join(str(v) for v in value)
        else:
            text = str(value)
        out.append(f"{flag}={text}")
    return out


try:  # for the type annotations only
    import pandas as pd  # noqa: F401
except ImportError:  # pragma: no cover
    pass
