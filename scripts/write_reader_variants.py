#!/usr/bin/env python3
"""Writes one measurement table the way common tools write Parquet, for robocal to read back.

Reads a measurement table (CSV, shared/spec/measurements.md) and writes it into OUT_DIR as:

  pandas.parquet           pandas.DataFrame.to_parquet defaults (pyarrow engine: snappy, dictionary
                           encoding, pandas metadata)
  pandas_categorical.parquet
                           `pose` as a pandas categorical (an Arrow dictionary-typed column)
  pandas_nullable.parquet  pandas nullable dtypes (Int64, Float64): nullable columns without nulls
  polars.parquet           polars.DataFrame.write_parquet defaults (zstd)
  duckdb.parquet           DuckDB `COPY ... TO ... (FORMAT parquet)` defaults (snappy)
  pyarrow_<codec>.parquet  pyarrow with gzip, lz4, brotli, zstd, snappy and none
  int32_pose.parquet       `pose` as int32
  float32.parquet          every value column as float32

and `variants.json`, which lists each file and whether its values were rounded to float32. The test
`parquet_written_by_pandas_polars_and_duckdb_reads_back` (sim/tests/measurement_table.rs) reads every
file with robocal when `ROBOCAL_READER_VARIANTS` names OUT_DIR, as `scripts/test.sh` does, and
compares it with the CSV.

    python3 scripts/write_reader_variants.py TABLE.csv OUT_DIR

Needs pandas, pyarrow, polars and duckdb (versions pinned in scripts/requirements.txt). Exits 2 on
bad arguments.
"""

import json
import sys
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq


def main(argv):
    if len(argv) != 3:
        print("usage: write_reader_variants.py TABLE.csv OUT_DIR", file=sys.stderr)
        return 2
    source, out = Path(argv[1]), Path(argv[2])
    if not source.is_file():
        print(f"error: {source}: no such file", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    df = pd.read_csv(source, engine="pyarrow")
    values = [c for c in df.columns if c != "pose" and not c.startswith("dir")]
    written = {}

    def record(name, float32=False):
        written[name] = {"float32": float32}

    df.to_parquet(out / "pandas.parquet")
    record("pandas.parquet")

    cat = df.copy()
    cat["pose"] = cat["pose"].astype("category")
    cat.to_parquet(out / "pandas_categorical.parquet")
    record("pandas_categorical.parquet")

    nullable = df.convert_dtypes(dtype_backend="numpy_nullable")
    for c in values:
        nullable[c] = nullable[c].astype("Float64")
    nullable.to_parquet(out / "pandas_nullable.parquet")
    record("pandas_nullable.parquet")

    pl.from_pandas(df).write_parquet(out / "polars.parquet")
    record("polars.parquet")

    con = duckdb.connect()
    con.register("measurements", df)
    con.execute(f"COPY measurements TO '{out / 'duckdb.parquet'}' (FORMAT parquet)")
    record("duckdb.parquet")

    table = pa.Table.from_pandas(df, preserve_index=False)
    for codec in ["gzip", "lz4", "brotli", "zstd", "snappy", "none"]:
        name = f"pyarrow_{codec}.parquet"
        pq.write_table(table, out / name, compression=codec)
        record(name)

    small = df.copy()
    small["pose"] = small["pose"].astype(np.int32)
    small.to_parquet(out / "int32_pose.parquet")
    record("int32_pose.parquet")

    single = df.copy()
    for c in values:
        single[c] = single[c].astype(np.float32)
    single.to_parquet(out / "float32.parquet")
    record("float32.parquet", float32=True)

    (out / "variants.json").write_text(
        json.dumps({"source": str(source.resolve()), "files": written}, indent=1) + "\n"
    )
    print(f"wrote {len(written)} Parquet variants of {source.name} into {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
