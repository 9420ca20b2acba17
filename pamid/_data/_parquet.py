"""Reading bench and decay tables from Parquet files (``.parquet``, ``.pq``) with pyarrow."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .._errors import BenchDataError
from ._cells import QUANTITY_UNITS
from ._streams import _read_bytes
from ._table import _check_duplicates, _Column, _Table

#: Extensions read as Parquet.
PARQUET_SUFFIXES: tuple[str, ...] = (".parquet", ".pq")


def _read_parquet(path: Path, shown: str, data: bytes | None = None,
                  columns: dict[str, str] | None = None) -> _Table:
    """Read a Parquet file with pyarrow, column by column (from ``data``, its bytes, where a
    stream was read already). ``columns``, the user's mapping, is the loader's to apply."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = _read_bytes(path, shown, data)  # existence, directory and empty-file checks
    source = pa.py_buffer(data)
    names = _schema_names(pa.BufferReader(source), shown)
    try:
        table = pq.ParquetFile(pa.BufferReader(source)).read()
    except Exception as exc:
        raise BenchDataError(shown, f"cannot read the Parquet data ({exc})") from exc

    return _arrow_table(table, names, shown)


def _schema_names(source, shown: str) -> list[str]:
    """The data columns' names of a Parquet file (pandas' index columns left out); errors
    for a file that is not Parquet, a column without a name and a name given twice."""
    import pyarrow.parquet as pq

    try:
        schema = pq.read_schema(source)
    except Exception as exc:  # pyarrow raises several types for a corrupt file
        raise BenchDataError(shown, f"not a table: cannot read it as Parquet ({exc})") from exc
    names = [n for n in schema.names if not n.startswith("__index_level_")]
    for j, name in enumerate(names):
        if not name.strip():
            raise BenchDataError(shown, f"column {j + 1} has no name")
    _check_duplicates(shown, names)
    return names


def parquet_chunks(path: Path, shown: str, rows: int,
                   columns: dict[str, str] | None = None,
                   share: tuple[int, int] | None = None) -> Iterator[_Table]:
    """A Parquet file as tables of whole muscles, in file order, about ``rows`` rows each:
    read one record batch at a time, so that memory holds one chunk, never the file.

    A chunk ends where a muscle ends (the ``muscle`` column, found by pamid's names and the
    user's mapping ``columns``): the rows of the last muscle of a batch wait for the next
    batch, so a muscle of more than ``rows`` rows comes whole in a larger chunk. A last
    chunk of less than half ``rows`` joins the one before it (a chunk of a few muscles
    would compile programs of its own shape for them). A file without a muscle column is
    one muscle, read whole. Each table's ``row_offset`` keeps the file's row numbers in
    messages. A muscle's rows must be together; that a muscle does not come back in a
    later chunk is the loader's check (:func:`pamid._data._bench.load_bench_chunks`).

    ``share`` = (index, count): only the muscles of process ``index`` of ``count``
    (:func:`parquet_share`): each process reads its own rows, none twice."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from ._names import NameProblem, canonical_names
    from ._streams import _stream_key

    if _stream_key(path, shown) is not None:  # errors for a missing path or a directory
        raise BenchDataError(shown, "a pipe or stream cannot be read in chunks (--stream): "
                                    "give a Parquet file on disk")
    names = _schema_names(path, shown)
    try:
        canonical = canonical_names([n.strip() for n in names], QUANTITY_UNITS, columns)
    except NameProblem as problem:
        raise BenchDataError(shown, problem.message, column=problem.column) from None
    muscle = names[canonical.index("muscle")] if "muscle" in canonical else None
    labels = tuple(names[canonical.index(c)] for c in ("muscle", "trial") if c in canonical)
    pending, held = None, None
    try:
        # pre_buffer off: with it, pyarrow's reader kept ~14 MB of every row group it had
        # read (a file of 1,000,000 muscles grew the process by 2.7 GB)
        reader = pq.ParquetFile(path, pre_buffer=False)
        total = reader.metadata.num_rows
        start, stop = (0, total) if share is None else parquet_share(reader, muscle, *share)
        if start >= stop and share is not None:
            return  # a process with no muscle of its own
        if muscle is None:  # one muscle: the whole file
            pending = reader.read()
        group_rows = _group_starts(reader)
        first = int(np.searchsorted(group_rows, start, side="right")) - 1
        position, offset = int(group_rows[max(first, 0)]), start
        batches = () if muscle is None or start >= stop else reader.iter_batches(
            batch_size=max(1, int(rows)), row_groups=range(first, reader.num_row_groups))
        for batch in batches:
            lo, hi = max(start - position, 0), min(stop - position, batch.num_rows)
            position += batch.num_rows
            if hi > lo:
                part = pa.Table.from_batches([batch]).slice(lo, hi - lo)
                pending = part if pending is None else pa.concat_tables([pending, part])
            if position >= stop:
                break
            if pending is None or pending.num_rows < rows:
                continue
            ids = pending.column(muscle)
            last = ids[len(ids) - 1]
            same = np.asarray(pc.fill_null(pc.equal(ids, last), False))
            cut = len(same) - int(np.argmin(same[::-1])) if not same.all() else 0
            if cut == 0:  # one muscle so far: it goes on in the next batch
                continue
            if held is not None:
                yield _arrow_table(held, names, shown, offset, labels)
                offset += held.num_rows
            held, pending = pending.slice(0, cut), pending.slice(cut)
    except BenchDataError:
        raise
    except Exception as exc:  # a corrupt row group, an unreadable page
        raise BenchDataError(shown, f"cannot read the Parquet data ({exc})") from exc
    if pending is None:  # no rows at all: the loader says so, as for a whole file
        pending = pq.read_schema(path).empty_table()
    if held is not None and pending.num_rows < rows / 2:
        pending, held = pa.concat_tables([held, pending]), None
    if held is not None:
        yield _arrow_table(held, names, shown, offset, labels)
        offset += held.num_rows
    if pending.num_rows or offset == start:
        yield _arrow_table(pending, names, shown, offset, labels)


def parquet_share(reader, muscle: str | None, index: int, count: int) -> tuple[int, int]:
    """The rows [start, stop) of process ``index`` of ``count``: the rows are split evenly,
    and each split moves forward to the next start of a muscle, so that every muscle is read
    whole by the one process where its first row lies. Reads the muscle column of the row
    groups at a split only. A file without a muscle column is one muscle: process 0's."""
    total = reader.metadata.num_rows
    if muscle is None:
        return (0, total) if index == 0 else (total, total)
    return _split(reader, muscle, index, count), _split(reader, muscle, index + 1, count)


def _group_starts(reader) -> np.ndarray:
    """The first row of every row group, and the number of rows after the last one."""
    return np.cumsum([0] + [reader.metadata.row_group(g).num_rows
                            for g in range(reader.num_row_groups)])


def _split(reader, muscle: str, k: int, count: int) -> int:
    """The first row of share ``k``: the first muscle that starts at or after row
    ``k·rows // count``."""
    import pyarrow.compute as pc

    total = reader.metadata.num_rows
    target = total * k // count
    if target <= 0 or target >= total:
        return max(0, min(target, total))
    starts = _group_starts(reader)
    g = int(np.searchsorted(starts, target, side="right")) - 1
    ids = reader.read_row_group(g, columns=[muscle]).column(0)
    at = target - int(starts[g])
    if at > 0:
        before = ids[at - 1]
    else:
        previous = reader.read_row_group(g - 1, columns=[muscle]).column(0)
        before = previous[len(previous) - 1]
    while True:
        tail = ids.slice(at)
        differs = np.asarray(pc.fill_null(pc.not_equal(tail, before), True)) \
            if before.is_valid else np.ones(len(tail), bool)
        if differs.any():
            return int(starts[g]) + at + int(np.argmax(differs))
        g, at = g + 1, 0
        if g >= reader.num_row_groups:
            return total
        ids = reader.read_row_group(g, columns=[muscle]).column(0)


def _arrow_table(table, names: list[str], shown: str, row_offset: int = 0,
                 labels: tuple[str, ...] = ()) -> _Table:
    """A pyarrow table as pamid's :class:`_Table`, column by column (numbers as float64
    with their nulls, anything else as text); ``row_offset``: the file's data rows before
    its first (a chunk of the file). ``labels``: the file's names of its label columns
    (muscle, trial): one of strings is read as its distinct stripped cells and a code per
    row, as the fast CSV reader reads labels, not as a Python string per row."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from ._csv import _factorize_text

    columns = {}
    for j, name in enumerate(table.column_names):
        if name.startswith("__index_level_"):
            continue
        chunked = table.column(j)
        kind = chunked.type
        numeric = pa.types.is_integer(kind) or pa.types.is_floating(kind)
        numeric = numeric or pa.types.is_decimal(kind)
        if name in labels and (pa.types.is_string(kind) or pa.types.is_large_string(kind)):
            codes, uniques = _factorize_text(pc.fill_null(chunked, ""))
            columns[name.strip()] = _Column(name.strip(), codes=codes, uniques=uniques)
        elif numeric:
            null = np.asarray(chunked.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            floats = pc.fill_null(pc.cast(chunked, pa.float64()), float("nan"))
            values = np.asarray(floats.to_numpy(), dtype=np.float64)
            columns[name.strip()] = _Column(
                name.strip(), values=values, null=null, original=chunked.to_pandas()
            )
        else:
            cells = ["" if v is None else str(v).strip() for v in chunked.to_pylist()]
            columns[name.strip()] = _Column(name.strip(), text=cells, original=chunked.to_pandas())
    return _Table(shown, [n.strip() for n in names], columns, table.num_rows, None, False,
                  row_offset=row_offset)


def parquet_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The column names of a Parquet file (its schema alone; ``data``: a stream's bytes)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    return pq.read_schema(path if data is None else pa.BufferReader(pa.py_buffer(data))).names
