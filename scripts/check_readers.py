#!/usr/bin/env python3
"""Checks that common data tools read robocal's measurement tables identically.

Given a Parquet file and a CSV file written by robocal (the same table, see
shared/spec/measurements.md), reads each with pandas (pyarrow engine), polars and DuckDB, and checks:

  1. within each file, all three readers give the same column names in the same order, the same
     dtypes, and bit-identical values (floats compared by their 64-bit patterns, so -0.0 differs
     from 0.0 and subnormals must survive);
  2. the contract's types: in the Parquet file `pose` and `campaign` are int64, `dir*` int8 and every
     other column float64; in the CSV file `pose`, `campaign` and `dir*` are integers and every other column float64 (the
     writer puts a '.' or an exponent in every float so that readers infer floats);
  3. across the two files, the same columns in the same order and exactly the same values (integers
     as int64, floats bit for bit).

Writes nothing. Prints a one-line summary and exits 0 when everything agrees; otherwise prints
what differs (file, reader, column, row, values) and exits 1; exits 2 on bad arguments.

    python3 scripts/check_readers.py TABLE.parquet TABLE.csv

Needs pandas, pyarrow, polars and duckdb (versions pinned in scripts/requirements.txt). Files to
try it on: `cargo test -p sim --test measurement_table -- --ignored` writes
$TMPDIR/robocal_table.{parquet,csv} (all optional columns, extreme values) and
$TMPDIR/robocal_ur5.{parquet,csv} (the real UR5 data).
"""

import sys
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import polars as pl

#: How many differing cells to show per comparison.
MAX_SHOWN = 5


class Mismatch(Exception):
    """Readers disagree; the message says where."""


def canonical_dtype(name):
    """A reader's dtype name as a numpy-style name ('int64', 'int8', 'float64', ...)."""
    table = {
        # polars
        "Int8": "int8", "Int16": "int16", "Int32": "int32", "Int64": "int64",
        "UInt8": "uint8", "UInt16": "uint16", "UInt32": "uint32", "UInt64": "uint64",
        "Float32": "float32", "Float64": "float64", "String": "string", "Utf8": "string",
        "Boolean": "bool",
        # DuckDB
        "TINYINT": "int8", "SMALLINT": "int16", "INTEGER": "int32", "BIGINT": "int64",
        "UTINYINT": "uint8", "USMALLINT": "uint16", "UINTEGER": "uint32", "UBIGINT": "uint64",
        "FLOAT": "float32", "DOUBLE": "float64", "VARCHAR": "string", "BOOLEAN": "bool",
    }
    return table.get(name, name)


def with_pandas(path, fmt):
    if fmt == "parquet":
        df = pd.read_parquet(path, engine="pyarrow")
    else:
        df = pd.read_csv(path, engine="pyarrow")
    return {c: (str(df[c].dtype), df[c].to_numpy()) for c in df.columns}


def with_polars(path, fmt):
    if fmt == "parquet":
        df = pl.read_parquet(path)
    else:
        df = pl.read_csv(path, infer_schema_length=None)
    return {c: (canonical_dtype(str(df[c].dtype)), df[c].to_numpy()) for c in df.columns}


def with_duckdb(path, fmt):
    con = duckdb.connect()
    if fmt == "parquet":
        rel = con.read_parquet(str(path))
    else:
        rel = con.read_csv(str(path), header=True, sample_size=-1)
    types = [canonical_dtype(str(t)) for t in rel.types]
    data = rel.fetchnumpy()
    out = {}
    for name, dtype in zip(rel.columns, types):
        values = data[name]
        if isinstance(values, np.ma.MaskedArray):
            if values.mask.any():
                raise Mismatch(f"{path}: duckdb: column {name} has missing values")
            values = values.data
        out[name] = (dtype, np.asarray(values))
    con.close()
    return out


READERS = {"pandas(pyarrow)": with_pandas, "polars": with_polars, "duckdb": with_duckdb}


def as_bits(values):
    """Values as int64 (integers) or their float64 bit patterns, for exact comparison."""
    values = np.asarray(values)
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    if values.dtype.kind == "f":
        return values.astype(np.float64).view(np.uint64)
    raise Mismatch(f"unexpected dtype {values.dtype}")


def kind(dtype):
    """'int' or 'float' for a canonical dtype name, else the name."""
    if dtype.startswith(("int", "uint")):
        return "int"
    if dtype.startswith("float"):
        return "float"
    return dtype


def show(v):
    """A value for a message: integers as such, floats as repr and hex (every bit visible)."""
    if isinstance(v, (np.integer, int)):
        return str(int(v))
    f = float(v)
    return f"{f!r} ({f.hex()})"


def compare_values(what, name, a, b, label_a, label_b):
    """Raises Mismatch if the columns differ in length or any value (exactly)."""
    if len(a) != len(b):
        raise Mismatch(f"{what}: column {name}: {len(a)} rows from {label_a}, {len(b)} from {label_b}")
    ba, bb = as_bits(a), as_bits(b)
    diff = np.nonzero(ba != bb)[0]
    if diff.size:
        shown = ", ".join(
            f"row {r + 1}: {show(a[r])} vs {show(b[r])}" for r in diff[:MAX_SHOWN]
        )
        raise Mismatch(
            f"{what}: column {name}: {diff.size} value(s) differ between {label_a} and {label_b} "
            f"({shown})"
        )


def expected_dtype(name, fmt):
    if name in ("pose", "campaign"):
        return "int64"
    if name.startswith("dir"):
        return "int8" if fmt == "parquet" else "int"
    return "float64"


def check_file(path, fmt):
    """Reads `path` with every reader; returns the agreed columns {name: (dtype, values)}."""
    results = {}
    for label, reader in READERS.items():
        try:
            results[label] = reader(path, fmt)
        except Mismatch:
            raise
        except Exception as e:  # noqa: BLE001 - any reader failure is a finding
            raise Mismatch(f"{path}: {label} cannot read the file: {type(e).__name__}: {e}") from e
    labels = list(results)
    ref_label = labels[0]
    ref = results[ref_label]
    for label in labels[1:]:
        cols = results[label]
        if list(cols) != list(ref):
            raise Mismatch(
                f"{path}: columns differ: {ref_label} {list(ref)} vs {label} {list(cols)}"
            )
        for name in ref:
            if cols[name][0] != ref[name][0]:
                raise Mismatch(
                    f"{path}: column {name}: dtype {ref[name][0]} from {ref_label} but "
                    f"{cols[name][0]} from {label}"
                )
            compare_values(str(path), name, ref[name][1], cols[name][1], ref_label, label)
    for name, (dtype, _) in ref.items():
        want = expected_dtype(name, fmt)
        if dtype != want and not (want == "int" and kind(dtype) == "int"):
            raise Mismatch(f"{path}: column {name}: dtype {dtype}, but the contract means {want}")
    return ref


def main(argv):
    if len(argv) != 3:
        print("usage: check_readers.py TABLE.parquet TABLE.csv", file=sys.stderr)
        return 2
    parquet_path, csv_path = Path(argv[1]), Path(argv[2])
    for path, ext in ((parquet_path, ".parquet"), (csv_path, ".csv")):
        if path.suffix.lower() != ext:
            print(f"{path}: expected a {ext} file (usage: check_readers.py TABLE.parquet TABLE.csv)",
                  file=sys.stderr)
            return 2
        if not path.is_file():
            print(f"{path}: no such file", file=sys.stderr)
            return 2
    try:
        pq_cols = check_file(parquet_path, "parquet")
        csv_cols = check_file(csv_path, "csv")
        if list(pq_cols) != list(csv_cols):
            raise Mismatch(
                f"columns differ between the files: {parquet_path} {list(pq_cols)} vs "
                f"{csv_path} {list(csv_cols)}"
            )
        for name in pq_cols:
            kp, kc = kind(pq_cols[name][0]), kind(csv_cols[name][0])
            if kp != kc:
                raise Mismatch(
                    f"column {name}: {pq_cols[name][0]} in {parquet_path} but {csv_cols[name][0]} "
                    f"in {csv_path}"
                )
            compare_values("Parquet vs CSV", name, pq_cols[name][1], csv_cols[name][1],
                           str(parquet_path), str(csv_path))
    except Mismatch as e:
        print(f"check_readers: MISMATCH: {e}", file=sys.stderr)
        return 1
    rows = len(next(iter(pq_cols.values()))[1]) if pq_cols else 0
    print(
        f"check_readers: OK: {', '.join(READERS)} agree on {parquet_path} and {csv_path}: "
        f"{rows} rows, {len(pq_cols)} columns ({', '.join(pq_cols)}); "
        f"pandas {pd.__version__}, polars {pl.__version__}, duckdb {duckdb.__version__}, "
        f"numpy {np.__version__}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
