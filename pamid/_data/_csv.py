"""Reading bench and decay tables from CSV files (comma-, semicolon- or tab-separated text).

The delimiter (comma, semicolon or tab: the one the header holds most of) and the decimal
mark (a comma in a semicolon- or tab-separated file whose numbers are written ``499,911``,
as Excel writes them in most of Europe) are detected; ``sep=`` and ``decimal=`` override
them. Two readers, which give the same table, to the bit:

* :func:`_read_csv`, the reference: cell by cell with Python's csv module, keeping the file
  line of every row; it reads every file pamid reads as CSV and words every problem;
* :func:`_read_csv_fast`, for a plain file (header on line 1, no quotes, no blank lines, no
  ragged rows, numbers written plainly): column by column with pyarrow, or None for any
  file in doubt, which the reference reader then reads.
"""

from __future__ import annotations

import codecs
import csv
import io
import os
import re
from pathlib import Path

import numpy as np

from .._arrow import from_numpy, null_strings, to_numpy
from .._errors import BenchDataError
from .._units import pressure_text_to_kPa
from ._cells import (
    _LABELS,
    FLAG_COLUMNS,
    PRESSURE_COLUMNS,
    QUANTITY_UNITS,
    _all_numbers,
    _blank_ok,
    _number_problem,
    _parsed_as_float,
    _point,
    _quantity_of,
)
from ._columns import Coded, factorize
from ._names import NameProblem, canonical_names
from ._streams import _looks_binary, _read_bytes, head_bytes
from ._table import _check_duplicates, _Column, _Table

#: Extensions read as CSV (so is any extension no reader claims, and a stream without one).
CSV_SUFFIXES: tuple[str, ...] = (".csv", ".tsv", ".txt")

#: Delimiters detected in a CSV header, in order of preference when it holds as many of each.
CSV_DELIMITERS: tuple[str, ...] = (",", ";", "\t")

# A cell written with a decimal comma, e.g. 499,911 or -1,5E-03.
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")


def _csv_dialect(data: bytes, sep: str | None, decimal: str | None) -> tuple[str, str]:
    """The delimiter and the decimal mark of a CSV file: those given, else detected.

    Delimiter: the one of :data:`CSV_DELIMITERS` (other than a given decimal mark) the
    header (first non-blank line) holds most of; the first of them when it holds none.
    Decimal mark: a comma when the delimiter is not and a cell of the first 200 data lines
    is written like ``499,911``; else a point. Both readers detect from the same bytes, so
    they agree."""
    if sep is not None and decimal is not None:
        return sep, decimal
    size = 1 << 16
    head = data[:size].decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = [line for line in head.splitlines() if line.strip()]
    if len(data) > size and len(lines) > 1:
        lines.pop()  # possibly cut short
    if sep is None:
        header = lines[0] if lines else ""
        candidates = [d for d in CSV_DELIMITERS if d != decimal]  # a decimal comma: not ","
        counts = [header.count(d) for d in candidates]
        sep = candidates[counts.index(max(counts))] if max(counts) else candidates[0]
    if decimal is None:
        decimal = "."
        if sep != ",":
            for line in lines[1:201]:
                cells = (cell.strip().strip('"') for cell in line.split(sep))
                if any(_DECIMAL_COMMA.fullmatch(cell) for cell in cells):
                    decimal = ","
                    break
    return sep, decimal


def _read_csv_bytes(path: Path, shown: str, data: bytes | None = None) -> bytes:
    """The bytes of a file to be read as CSV (``data`` where a stream was read already),
    after the checks that it is text at all."""
    data = _read_bytes(path, shown, data)
    if data[:4] == b"PAR1":
        raise BenchDataError(
            shown, "this is a Parquet file, not CSV; give it the extension .parquet"
        )
    if _looks_binary(data):
        raise BenchDataError(
            shown, "not a table: the file holds binary data, expected CSV text or Parquet"
        )
    return data


def _read_csv(
    path: Path, shown: str, *, sep: str | None = None, decimal: str | None = None,
    data: bytes | None = None, columns: dict[str, str] | None = None,
) -> _Table:
    """Read a CSV file cell by cell, keeping the file line of every data row.

    This is the reference reader: it reads every file pamid reads as CSV and words every
    problem. ``sep`` and ``decimal`` default to those detected (:func:`_csv_dialect`).
    ``data``: the file's bytes where they were read already (a stream is read only once).
    ``columns`` (the user's mapping) is not needed here: the header is the first line, and
    the loader maps the names.
    """
    data = _read_csv_bytes(path, shown, data)
    sep, decimal = _csv_dialect(data, sep, decimal)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")  # legacy single-byte files; never fails

    reader = csv.reader(io.StringIO(text, newline=""), delimiter=sep)
    header: list[str] | None = None
    header_line = 0
    records: list[list[str]] = []
    lines: list[int] = []
    last_line = 0
    try:
        for record in reader:
            start, last_line = last_line + 1, reader.line_num
            cells = [cell.strip() for cell in record]
            if not any(cells):
                continue  # blank line, or a row of empty cells
            if header is None:
                while cells and not cells[-1]:
                    cells.pop()  # trailing delimiters after the last name
                header, header_line = cells, start
                continue
            if len(cells) != len(header):
                if len(cells) > len(header) and not any(cells[len(header) :]):
                    cells = cells[: len(header)]
                else:
                    raise BenchDataError(
                        shown,
                        f"this row has {len(cells)} cells but the header (line {header_line}) "
                        f"names {len(header)} columns",
                        row=len(records) + 1,
                        line=start,
                    )
            records.append(cells)
            lines.append(start)
    except csv.Error as exc:
        raise BenchDataError(
            shown, f"not a readable CSV table near line {reader.line_num}: {exc}"
        ) from exc
    if header is None:
        raise BenchDataError(shown, "the file holds only blank lines; expected a table")

    for j, name in enumerate(header):
        if not name:
            raise BenchDataError(shown, f"header column {j + 1} (line {header_line}) has no name")
    _check_duplicates(shown, header)
    columns = {}
    for j, name in enumerate(header):
        cells = [record[j] for record in records]
        columns[name] = _Column(name, text=cells, original=cells, decimal=decimal)
    return _Table(shown, list(header), columns, len(records), lines, is_csv=True)


def csv_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The column names on the first line of a CSV file, split at commas, semicolons and
    tabs alike and stripped of blanks and quotes (``data``: a stream's bytes)."""
    head = head_bytes(path) if data is None else data[:65536]
    first = head.split(b"\n", 1)[0].decode("utf-8-sig", "replace")
    return [c.strip().strip('"') for c in first.replace(";", ",").replace("\t", ",").split(",")]


# --------------------------------------------------------------------------------------
# Fast CSV reader, for large, plain files
# --------------------------------------------------------------------------------------


#: Whether :func:`load_bench` tries the fast, column-wise CSV reader first. Switched off, every
#: CSV file goes through the cell-by-cell reader (tests and benchmarks compare the two); so
#: does the environment variable ``PAMID_FAST_CSV=0`` (the public switch,
#: ``benchmarks/load_bench.py``), read at every call.
_FAST_CSV = True

#: Bytes a plain decimal number is written with, for each decimal mark.
_NUMBER_BYTES = np.zeros(256, dtype=bool)
_NUMBER_BYTES[np.frombuffer(b"0123456789+-.eE", dtype=np.uint8)] = True
_NUMBER_BYTES_COMMA = np.zeros(256, dtype=bool)
_NUMBER_BYTES_COMMA[np.frombuffer(b"0123456789+-,eE", dtype=np.uint8)] = True


def read_csv_fast(
    path: Path, shown: str, *, data: bytes | None = None, sep: str | None = None,
    decimal: str | None = None, columns: dict[str, str] | None = None,
) -> _Table | None:
    """:func:`_read_csv_fast` (the table with pamid's names, or None), unless the fast reader is
    switched off (:data:`_FAST_CSV`, or ``PAMID_FAST_CSV=0``): then None, and the reference
    reader reads every file."""
    if not _FAST_CSV or os.environ.get("PAMID_FAST_CSV", "").strip() == "0":
        return None
    return _read_csv_fast(path, shown, sep=sep, decimal=decimal, columns=columns, data=data)


def _plain_numbers(chunked, decimal: str = ".", blanks: bool = False) -> np.ndarray | None:
    """Float64 values of a pyarrow string column whose every cell is a plain decimal number.

    A cell qualifies if it is written with the characters ``0-9 + - . e E`` only (a comma
    for the point when ``decimal`` is ``","``) and pyarrow parses it as a finite number.
    Such a cell is in the syntax of Python's ``float()`` (what the cell-by-cell reader uses,
    once the decimal comma is made a point), and both round the decimal value to the
    nearest float64, so the two readers give the same number. With ``blanks``, an empty
    cell qualifies too and gives NaN (no other cell can). None if any cell does not
    qualify (an empty cell, blanks, an underscore, 'nan', '1e', text, ...).
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    allowed = _NUMBER_BYTES if decimal == "." else _NUMBER_BYTES_COMMA
    step = 1 << 20
    ok = None  # reused, so that the check allocates nothing big
    values = np.empty(len(chunked), dtype=np.float64)
    blank = np.zeros(len(chunked), dtype=bool) if blanks else None
    at = 0
    for chunk in chunked.chunks:
        if chunk.null_count or chunk.type != pa.string():
            return None
        _, offsets, data = chunk.buffers()
        offsets = np.frombuffer(offsets, dtype=np.int32)
        start, stop = offsets[chunk.offset], offsets[chunk.offset + len(chunk)]
        text = np.frombuffer(data, dtype=np.uint8) if stop > start else None
        if ok is None or len(ok) < min(step, stop - start):
            ok = np.empty(min(step, stop - start), dtype=bool)
        for k in range(start, stop, step):
            part = text[k : min(k + step, stop)]
            if not np.take(allowed, part, out=ok[: len(part)]).all():
                return None
        empty = None
        if blanks:
            empty = np.diff(offsets[chunk.offset : chunk.offset + len(chunk) + 1]) == 0
            blank[at : at + len(chunk)] = empty
        if decimal != ".":
            chunk = pc.replace_substring(chunk, ",", ".")
        if empty is not None and empty.any():
            chunk = pc.if_else(from_numpy(empty), null_strings(len(chunk)), chunk)
        try:
            floats = pc.cast(chunk, pa.float64())
        except (pa.ArrowException, ValueError):
            return None
        values[at : at + len(chunk)] = to_numpy(floats)
        at += len(chunk)
    finite = np.isfinite(values)
    if not (finite.all() if blank is None else (finite | blank).all()):
        return None
    return values


def _factorize_text(chunked) -> tuple[np.ndarray, np.ndarray]:
    """The stripped cells of a pyarrow string column (or dictionary of strings) as
    ``uniques[codes]``.

    ``uniques`` (an object array of str) are distinct and in order of first appearance, so
    code k first appears after code k - 1 does. Python strips each distinct cell once.
    """
    import pyarrow as pa

    if pa.types.is_dictionary(chunked.type):  # parsed as such (labels, _read_csv_fast)
        encoded = chunked.unify_dictionaries().combine_chunks()
    else:
        encoded = chunked.combine_chunks().dictionary_encode()
    raw_codes = to_numpy(encoded.indices)
    stripped = np.array([cell.strip() for cell in encoded.dictionary.to_pylist()], dtype=object)
    text_ids, texts = factorize(stripped)  # cells that differ only in blanks merge here
    ids = text_ids[raw_codes]
    if _in_order_of_appearance(ids, len(texts)):  # pyarrow's dictionary usually is
        return ids, texts
    codes, order = factorize(ids)
    return codes, texts[order]


def _in_order_of_appearance(codes: np.ndarray, n_codes: int) -> bool:
    """Whether every code 0 … ``n_codes`` − 1 appears in ``codes``, code k first after code
    k − 1 does (as :func:`~pamid._data._columns.factorize` numbers them): the largest code
    so far starts at 0 and grows by steps of 1 up to ``n_codes`` − 1."""
    if len(codes) == 0:
        return n_codes == 0
    step = np.diff(codes)
    if (step >= 0).all():  # each code in one block: the largest so far is the code itself
        return bool(codes[0] == 0 and codes[-1] == n_codes - 1
                    and ((step == 0) | (step == 1)).all())
    del step
    largest = np.maximum.accumulate(codes)
    return bool(codes[0] == 0 and largest[-1] == n_codes - 1
                and (np.diff(largest) <= 1).all())


def _is_utf8(data: bytes) -> bool:
    """Whether ``data`` is valid UTF-8, as the cell-by-cell reader decodes it then."""
    if data.isascii():
        return True
    decoder = codecs.getincrementaldecoder("utf-8")()
    view = memoryview(data)
    step = 1 << 24  # in pieces, so that no copy of the whole file is made
    try:
        for k in range(0, len(data), step):
            decoder.decode(view[k : k + step])
        decoder.decode(b"", final=True)
    except UnicodeDecodeError:
        return False
    return True


def _float_column(name: str, chunked) -> _Column | None:
    """A column pyarrow parsed as float64 (a blank cell is a null), or None if the
    cell-by-cell reader must read the file: a blank cell where a number is required, or a
    cell that is not a finite number (NaN or inf written as such, or 1e999)."""
    if chunked.null_count and not _blank_ok(name):
        return None
    values = to_numpy(chunked)  # NaN where a cell is blank (null)
    if not values.flags.writeable:  # one chunk: a view of pyarrow's buffer
        values = values.copy()
    finite = np.isfinite(values)
    if chunked.null_count:
        null = ~finite  # every null is NaN; no other cell may be NaN or infinite ...
        if int(np.count_nonzero(null)) != chunked.null_count:  # ... and one is
            return None
    else:
        if not finite.all():
            return None
        null = np.broadcast_to(False, values.shape)
    return _Column(name, values=values, null=null, parsed=values)


def _fast_column(
    name: str, chunked, n: int, decimal: str = ".", values: np.ndarray | None = None
) -> _Column | None:
    """One column for the fast reader, or None if the cell-by-cell reader must read the file.

    ``values``: the column's cells as :func:`_plain_numbers` with ``blanks=True`` reads
    them, where they were read already (with other columns, :func:`_fast_columns`)."""
    if name in _LABELS:
        codes, uniques = _factorize_text(chunked)
        return _Column(name, codes=codes, uniques=uniques)
    blanks = _blank_ok(name)
    known = name in FLAG_COLUMNS or _quantity_of(name) is not None
    if values is None:
        values = _plain_numbers(chunked, decimal, blanks)
    elif not blanks and np.isnan(values).any():
        values = None  # a blank cell where a number is required
    if values is not None:
        null = np.isnan(values) if blanks else np.broadcast_to(False, (n,))
        if known or not null.all():  # an extra column with no number is text
            column = _Column(name, values=values, null=null, parsed=values)
            if name in PRESSURE_COLUMNS and PRESSURE_COLUMNS[name] != "kPa":
                codes, uniques = _factorize_text(chunked)
                kpa = pressure_text_to_kPa(_point(uniques, decimal), PRESSURE_COLUMNS[name])
                column.kpa = kpa[codes]
            return column
    if known:
        return None  # a quantity that is not all plain numbers
    codes, uniques = _factorize_text(chunked)
    numbers = _point(uniques, decimal)
    if not _all_numbers(numbers):  # text, kept as it is
        column = _Column(name, codes=codes, uniques=uniques, numeric=False)
        column.original = Coded(codes, uniques)
        return column
    if any(_number_problem(cell) is not None for cell in numbers if cell or not blanks):
        return None  # a numeric covariate with a problem
    parsed = np.array([float(cell) if cell else np.nan for cell in numbers])[codes]
    null = (uniques == "")[codes]
    return _Column(name, values=parsed, null=null, parsed=parsed)


def _read_csv_fast(
    path: Path,
    shown: str,
    *,
    sep: str | None = None,
    decimal: str | None = None,
    columns: dict[str, str] | None = None,
    data: bytes | None = None,
) -> _Table | None:
    """Read a plain CSV file column by column with pyarrow, or return None.

    Plain: the header on line 1, its names distinct and non-empty and free of problems (see
    :meth:`_Table.rename`, which ``columns`` feeds); no quote characters, NUL bytes, lone
    carriage returns or blank lines (blank lines at the end aside); every row with exactly
    as many cells as the header has names; every cell of a numeric column a plain decimal
    number (see :func:`_plain_numbers`), or blank where a blank means "not recorded". The
    delimiter and decimal mark are those of :func:`_csv_dialect`. Data row i is then on
    line i + 1 and every cell reads as the cell-by-cell reader reads it. For any other file
    (not UTF-8, say), or any cell in doubt, the answer is None and the cell-by-cell reader
    takes over; it also words every problem, so messages do not depend on which reader ran.
    The columns have pamid's names (the file's headers in ``file_names``). ``data``: the
    file's bytes where they were read already (a stream is read only once).
    """
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    data = _read_csv_bytes(path, shown, data)
    if b'"' in data or b"\0" in data or not _is_utf8(data):
        return None
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        return None  # a lone carriage return
    sep, decimal = _csv_dialect(data, sep, decimal)
    header_end = data.find(b"\n")
    if header_end < 0:
        return None
    end = len(data)
    while end > header_end and data[end - 1] in b" \t\r\n":
        end -= 1  # blank lines at the end of the file (and blanks the slow reader strips)
    if end <= header_end:
        return None  # no data rows
    try:
        header = data[:header_end].rstrip(b"\r").decode("utf-8-sig")
    except UnicodeDecodeError:
        return None
    if sep not in header or not header.replace("\t", " ").isprintable():
        return None
    names = [name.strip() for name in header.split(sep)]
    if not all(names) or len(set(names)) != len(names):
        return None
    try:
        canonical = canonical_names(names, QUANTITY_UNITS, columns)
    except NameProblem:
        return None

    keys = [f"c{j}" for j in range(len(names))]
    # With two columns or more, pyarrow refuses a line without the header's cell count (an
    # empty line among them), so every row is one line; one column's empty line would be a
    # row of one blank cell, and there the lines are counted (56 ms for 139 MB).
    n_lines = data.count(b"\n", header_end + 1, end) + 1 if len(names) == 1 else None
    # Numbers pamid knows by name are parsed by pyarrow as float64 where no cell can hold a
    # blank or a tab (pyarrow would read " 1" as 1; such files take the text way below).
    # pyarrow's float64 takes [+-]digits[.digits][e[+-]digits] (the decimal mark
    # ``decimal``), a subset of what float() reads, rounded the same way, and nan, inf and
    # infinity, which _float_column refuses (tests/test_bench_data.py holds them to
    # float()). Labels are parsed as dictionaries; every other column as text.
    typed = data.find(b" ", header_end + 1, end) < 0 and (
        sep == "\t" or data.find(b"\t", header_end + 1, end) < 0)
    types = {}
    for key, name in zip(keys, canonical, strict=True):
        if name in _LABELS:
            types[key] = pa.dictionary(pa.int32(), pa.string())
        elif typed and _parsed_as_float(name):
            types[key] = pa.float64()
        else:
            types[key] = pa.string()
    body = pa.py_buffer(data).slice(header_end + 1, end - header_end - 1)
    del data  # memory: ``body`` holds the bytes as long as they are needed
    try:
        arrow = pa_csv.read_csv(
            pa.BufferReader(body),
            read_options=pa_csv.ReadOptions(column_names=keys, block_size=1 << 24),
            parse_options=pa_csv.ParseOptions(
                delimiter=sep,
                quote_char=False,
                double_quote=False,
                escape_char=False,
                newlines_in_values=False,
                ignore_empty_lines=False,
            ),
            convert_options=pa_csv.ConvertOptions(
                column_types=types,
                null_values=[""],  # a blank number is a null; text keeps its ''
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
                check_utf8=True,
                decimal_point=decimal,
            ),
        )
    except (pa.ArrowException, ValueError):  # a cell that is not a number, a ragged row, ...
        return None
    del body
    n = arrow.num_rows
    if n_lines is not None and n != n_lines:
        return None

    parsed = arrow.columns
    del arrow
    try:
        table_columns = _fast_columns(canonical, parsed, n, decimal)
    except pa.ArrowException:  # e.g. a text column too large to combine into one array
        return None
    if table_columns is None:
        return None
    file_names = {new: old for new, old in zip(canonical, names, strict=True) if new != old}
    return _Table(shown, canonical, table_columns, n, None, is_csv=True, first_line=2,
                  canonical=True, file_names=file_names)


#: Cells, and columns, the fast reader checks and converts in one go (columns of a wide file
#: together; a text column sends only its own block to the column-by-column way).
_BLOCK_CELLS = 1 << 20
_BLOCK_COLUMNS = 256


def _fast_columns(names: list[str], parsed: list, n: int, decimal: str
                  ) -> dict[str, _Column] | None:
    """The fast reader's columns (see :func:`_fast_column`) from pyarrow columns ``parsed``
    (emptied as they are converted), or None if the cell-by-cell reader must read the file.

    Columns pyarrow parsed as float64 go to :func:`_float_column`. Other columns of text
    are checked and converted in blocks of adjacent columns of
    up to :data:`_BLOCK_CELLS` cells (and :data:`_BLOCK_COLUMNS` columns), with one
    :func:`_plain_numbers` for the whole block: a file 10 rows by 20,000 columns costs a
    hundred pyarrow calls rather than 20,000 of each. A block with a cell that is not a plain
    number (a text column, say) is read column by column."""
    import pyarrow as pa

    def text(k):  # a column of text cells, neither a label nor parsed as numbers
        return names[k] not in _LABELS and parsed[k].type == pa.string()

    columns: dict[str, _Column] = {}
    per_block = min(_BLOCK_COLUMNS, max(1, _BLOCK_CELLS // max(n, 1)))
    j = 0
    while j < len(names):
        if parsed[j].type == pa.float64():
            chunked, parsed[j] = parsed[j], None
            column = _float_column(names[j], chunked)
            if column is None:
                return None
            columns[names[j]] = column
            j += 1
            continue
        block = [j]  # a label column alone; else adjacent columns of text
        if text(j):
            while j + len(block) < len(names) and len(block) < per_block and text(j + len(block)):
                block.append(j + len(block))
        values = None
        if len(block) > 1:
            joined = pa.chunked_array(
                [pa.concat_arrays([c for k in block for c in parsed[k].chunks])], pa.string())
            values = _plain_numbers(joined, decimal, blanks=True)
            del joined
            if values is not None:
                values = values.reshape(len(block), n)
        for i, k in enumerate(block):
            chunked, parsed[k] = parsed[k], None  # memory: the column goes once converted
            column = _fast_column(names[k], chunked, n, decimal,
                                  None if values is None else values[i])
            if column is None:
                return None
            columns[names[k]] = column
        j += len(block)
    return columns
