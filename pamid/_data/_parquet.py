"""Reading bench and decay tables from Parquet files (``.parquet``, ``.pq``) with pyarrow."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import BenchDataError
from ._streams import _read_bytes
from ._table import _check_duplicates, _Column, _Table

#: Extensions read as Parquet.
PARQUET_SUFFIXES: tuple[str, ...] = (".parquet", ".pq")


def _read_parquet(path: Path, shown: str, data: bytes | None = None,
                  columns: dict[str, str] | None = None) -> _Table:
    """Read a Parquet file with pyarrow, column by column (from ``data``, its bytes, where a
    stream was read already). ``columns``, the user's mapping, is the loader's to apply."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    data = _read_bytes(path, shown, data)  # existence, directory and empty-file checks
    source = pa.py_buffer(data)
    try:
        schema = pq.read_schema(pa.BufferReader(source))
    except Exception as exc:  # pyarrow raises several types for a corrupt file
        raise BenchDataError(shown, f"not a table: cannot read it as Parquet ({exc})") from exc
    names = [n for n in schema.names if not n.startswith("__index_level_")]
    for j, name in enumerate(names):
        if not name.strip():
            raise BenchDataError(shown, f"column {j + 1} has no name")
    _check_duplicates(shown, names)
    try:
        table = pq.ParquetFile(pa.BufferReader(source)).read()
    except Exception as exc:
        raise BenchDataError(shown, f"cannot read the Parquet data ({exc})") from exc

    columns = {}
    for j, name in enumerate(table.column_names):
        if name.startswith("__index_level_"):
            continue
        chunked = table.column(j)
        kind = chunked.type
        numeric = pa.types.is_integer(kind) or pa.types.is_floating(kind)
        numeric = numeric or pa.types.is_decimal(kind)
        if numeric:
            null = np.asarray(chunked.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            floats = pc.fill_null(pc.cast(chunked, pa.float64()), float("nan"))
            values = np.asarray(floats.to_numpy(), dtype=np.float64)
            columns[name.strip()] = _Column(
                name.strip(), values=values, null=null, original=chunked.to_pandas()
            )
        else:
            cells = ["" if v is None else str(v).strip() for v in chunked.to_pylist()]
            columns[name.strip()] = _Column(name.strip(), text=cells, original=chunked.to_pandas())
    return _Table(shown, [n.strip() for n in names], columns, table.num_rows, None, False)


def parquet_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The column names of a Parquet file (its schema alone; ``data``: a stream's bytes)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    return pq.read_schema(path if data is None else pa.BufferReader(pa.py_buffer(data))).names
