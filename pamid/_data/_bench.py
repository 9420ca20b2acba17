"""Loading bench measurements of pneumatic artificial muscles (PAMs): CSV, Parquet, Excel.

A bench file is a table with one row per sample and the unit of each quantity in the column
name, e.g. ``pressure_kPa``, ``force_N``, ``contraction_pct``. :func:`load_bench` checks the
file thoroughly, converts it to pamid's units (kPa, %, N, mm, s) and returns a
:class:`BenchData`. Every problem with the file raises :class:`~pamid._errors.BenchDataError`,
whose message names the file and, where it applies, the column and the data row (1-based,
header not counted) and, for CSV, the line in the file (for a spreadsheet, the sheet and
the cell).

Columns
-------
Required:
    * gauge pressure, as exactly one of ``pressure_kPa``, ``pressure_bar``, ``pressure_Pa``,
      ``pressure_psi`` (converted to kPa);
    * ``force_N``, the axial pulling force in N;
    * ``contraction_pct``, 100 (l0 - length) / l0 in percent, or ``contraction_mm`` (the
      contraction as a length, l0 - length), or else ``length_mm`` together
      with the nominal length l0 in mm, from an ``l0_mm`` column (constant within a muscle)
      or from the ``l0_mm=`` argument.
Optional:
    ``muscle`` (identifier, read as text), ``trial`` (also named ``test`` or ``run``; a
    label read as text, even where it is a number: time restarts in each trial),
    ``time_s``, ``direction`` (+1 contracting, -1 extending), ``temperature_C``, ``cycle``
    (whole numbers).
Others:
    Any further column whose cells are all numbers is kept as a covariate; any further
    column holding text (a ``note``, say) is kept unchanged but is not a covariate.

Headers as labs write them (``Pressure [kPa]``, ``force (N)``, ``p / bar``, ``Force_N``,
``Temperature [°C]``, ``T_C``, ...) are mapped to these names (see :mod:`._names`), and
``columns={"Druck": "pressure_bar"}`` maps any other naming. A column named after a known
quantity (``pressure``, ``force``, ``length``, ``l0``, ``contraction``, ``time``,
``temperature``, ``velocity``) must carry one of that quantity's accepted units;
``force_kN`` or ``Time [ms]`` are errors rather than silently ignored columns.

Blank cells
-----------
A blank cell (a null in Parquet, an empty cell in a spreadsheet) of ``time_s``,
``direction``, ``temperature_C``, ``cycle`` or a numeric covariate means "not recorded": it
becomes NaN in the frame (``direction`` and ``cycle`` are then float64), and one
:class:`MissingValuesWarning` says how many cells of which columns were blank. Blank cells
of the required columns, and NaN written as such, are errors.

Reading CSV
-----------
The delimiter (comma, semicolon or tab: the one the header holds most of) and the decimal
mark (a comma in a semicolon- or tab-separated file whose numbers are written ``499,911``,
as Excel writes them in most of Europe) are detected; ``sep=`` and ``decimal=`` override
them. A plain file (header on line 1, no quotes, no blank lines, no ragged rows, numbers
written plainly) is read column by column with pyarrow; every other file, and every file
with a problem, is read cell by cell with Python's csv module, which reports the problem.
Both give the same result, to the bit.

Pipes
-----
A file that is not a regular one (``pamid fit <(cat f.csv)``, ``/dev/stdin``, a FIFO) is
read once, whole, and its bytes go to every reader; one that has no extension is read as
Parquet or a spreadsheet when its first bytes say so, else as CSV. The first byte must
arrive within :data:`STREAM_TIMEOUT_S` (10 s): a FIFO nobody writes to is an error, not a
wait for ever.

Reading spreadsheets
--------------------
``.xlsx`` (and ``.xlsm``, ``.xlsb``, ``.xls``, ``.ods``) are read with python-calamine
(:mod:`._spreadsheet`), the first sheet unless ``sheet=`` names one. Number cells are
numbers and text cells text; a date or time cell in a numeric column is an error (write
times as seconds), in a label or text column it is kept as ISO text.

Censoring
---------
Published force maps mark the lengths a muscle cannot reach at a given pressure with a
force of exactly 0 N. Such rows are dropped (with a :class:`CensoredRowsWarning`) unless
``keep_censored=True``.
"""

from __future__ import annotations

import codecs
import csv
import functools
import io
import math
import os
import re
import select
import stat
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .._errors import BenchDataError
from .._units import ATMOSPHERE_KPA, PRESSURE_UNITS, pressure_text_to_kPa, pressure_to_kPa
from ._names import NameProblem, canonical_names

__all__ = ["BenchData", "CensoredRowsWarning", "MissingValuesWarning", "load_bench"]

#: Accepted units for each quantity that bench-file column names may start with.
QUANTITY_UNITS: dict[str, tuple[str, ...]] = {
    "pressure": PRESSURE_UNITS,
    "force": ("N",),
    "length": ("mm",),
    "l0": ("mm",),
    "contraction": ("pct", "mm"),
    "time": ("s",),
    "temperature": ("C",),
    "velocity": ("mm_s",),
}
#: Pressure column names and the unit each one carries.
PRESSURE_COLUMNS: dict[str, str] = {f"pressure_{unit}": unit for unit in PRESSURE_UNITS}
#: Physical range of the contraction, in percent of the nominal length.
CONTRACTION_RANGE_PCT: tuple[float, float] = (-10.0, 50.0)
#: Extensions read as Parquet; spreadsheets are listed in ``_spreadsheet``; every other
#: extension is read as CSV.
PARQUET_SUFFIXES: tuple[str, ...] = (".parquet", ".pq")
#: Delimiters detected in a CSV header, in order of preference when it holds as many of each.
CSV_DELIMITERS: tuple[str, ...] = (",", ";", "\t")
#: Decimal marks a CSV file may use.
DECIMAL_MARKS: tuple[str, ...] = (".", ",")

# Canonical optional columns, in the order they appear in BenchData.frame.
_OPTIONAL_NUMERIC = ("time_s", "direction", "temperature_C", "cycle", "length_mm", "l0_mm")
# Quantities whose cells must all be numbers; a blank cell of any other numeric column
# (time, temperature, direction, cycle, covariates) means "not recorded".
_STRICT_QUANTITIES = ("pressure", "force", "contraction", "length", "l0")
# Columns read as labels (text), never as numbers.
_LABELS = ("muscle", "trial")
_RESERVED = ("source_row",)
# A cell written with a decimal comma, e.g. 499,911 or -1,5E-03.
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
# Swaps the decimal comma and the point: a decimal-comma cell then reads as Python reads
# numbers, and one written with a point does not read at all (it would be ambiguous).
_SWAP_MARKS = str.maketrans({",": ".", ".": ","})


class CensoredRowsWarning(UserWarning):
    """Rows with a force of exactly 0 N (censored points of a force map) were dropped."""


class MissingValuesWarning(UserWarning):
    """Blank cells of optional numeric columns were read as "not recorded" (NaN).

    ``counts`` maps each such column, as the file names it, to its number of blank cells."""

    def __init__(self, message: str, counts: dict[str, int] | None = None):
        super().__init__(message)
        self.counts = dict(counts or {})


@dataclass(frozen=True, eq=False)
class BenchData:
    """Bench measurements, checked and converted to pamid's units.

    Attributes
    ----------
    frame:
        One row per kept sample, in file order. Columns: ``muscle`` (str), ``trial`` (str,
        where the file gives one), ``pressure_kPa`` (gauge pressure, kPa),
        ``contraction_pct`` (%, positive when shorter than l0) and ``contraction_mm``
        (the contraction as a length, Cullinan's y) where each is given or derivable with
        l0, ``force_N`` (N), all float64 apart from the labels; then those of ``time_s``
        (s), ``direction`` (int, +1 or -1), ``temperature_C`` (deg C), ``cycle`` (int),
        ``length_mm`` (mm) and ``l0_mm`` (mm) that are known; then the covariates and any
        text columns as given; last ``source_row``, the 1-based data row of the sample in the
        file. Blank cells of the optional numeric columns are NaN (``direction`` and
        ``cycle`` are then float64).
    path:
        The file, as given to :func:`load_bench`.
    has_muscle_column:
        False when the file had no ``muscle`` column; every row then has the id ``"muscle"``.
    muscles:
        Muscle ids in order of first appearance (among the kept rows).
    l0_mm:
        Nominal length per muscle in mm, or None where the file does not give it.
    covariates:
        Names of the extra numeric columns, in file order.
    n_censored:
        Number of censored rows (force exactly 0) dropped; 0 when they were kept.
    pressure_unit_in_file:
        The pressure unit of the file's pressure column (``"kPa"``, ``"bar"``, ``"Pa"`` or
        ``"psi"``); ``frame`` always holds kPa.
    """

    frame: pd.DataFrame
    path: str
    has_muscle_column: bool
    muscles: tuple[str, ...]
    l0_mm: dict[str, float | None] = field(default_factory=dict)
    covariates: tuple[str, ...] = ()
    n_censored: int = 0
    pressure_unit_in_file: str = "kPa"

    @functools.cached_property
    def curves(self):
        """The file's curves, direction, trials and repeats (:func:`pamid._data._curves.
        find_curves`), aligned with :attr:`frame`; found once and kept."""
        from ._curves import find_curves

        return find_curves(self.frame)

    def groups(self):
        """(muscle id, its rows with a fresh index) for every muscle, in order, in one pass
        over the table (:meth:`for_muscle` filters the whole table once per call)."""
        for muscle_id, rows in self.frame.groupby("muscle", sort=False):
            yield muscle_id, rows.reset_index(drop=True)

    def for_muscle(self, muscle_id: str) -> pd.DataFrame:
        """The rows of one muscle, as a new DataFrame with a fresh 0-based index.

        Raises KeyError, naming the known ids, if ``muscle_id`` is not among :attr:`muscles`.
        """
        if muscle_id not in self.muscles:
            known = ", ".join(repr(m) for m in self.muscles)
            raise KeyError(f"{self.path}: no muscle {muscle_id!r}; muscles in the file: {known}")
        rows = self.frame[self.frame["muscle"] == muscle_id]
        return rows.reset_index(drop=True)

    def __len__(self) -> int:
        return len(self.frame)


# --------------------------------------------------------------------------------------
# Raw table: the file's cells, before any interpretation
# --------------------------------------------------------------------------------------


@dataclass
class _Column:
    """One column as read: text cells (CSV, Parquet strings) or numbers (Parquet numerics).

    For text, ``text`` holds the stripped cells ('' for an empty cell or a null). For
    numbers, ``values`` holds float64 values and ``null`` marks missing ones. ``original``
    is what goes into the frame if the column ends up kept unchanged.
    """

    name: str
    text: list[str] | None = None
    values: np.ndarray | None = None
    null: np.ndarray | None = None
    original: object = None
    parsed: np.ndarray | None = None  # float64 values of a text column, once checked
    decimal: str = "."  # the decimal mark of numbers written in ``text``
    null_word: str = "missing value (null)"  # what a null is called in messages
    # Spreadsheets: rows whose cell cannot be a number whatever its text (a date), and why.
    problems: dict[int, str] | None = None
    # Set only by the fast CSV reader, which has checked and converted the column already:
    numeric: bool | None = None  # an extra column: numeric covariate (True) or text (False)
    kpa: np.ndarray | None = None  # a pressure column: kPa, converted exactly from the text
    codes: np.ndarray | None = None  # a text column: its stripped cells are uniques[codes],
    uniques: np.ndarray | None = None  # uniques distinct and in order of first appearance

    def raw(self, i: int) -> str:
        """Cell ``i`` as it reads in the file, for messages."""
        if self.text is not None:
            return self.text[i]
        if self.null[i]:
            return "null"
        value = float(self.values[i])
        return str(int(value)) if value.is_integer() and abs(value) < 1e15 else repr(value)

    def number_text(self) -> list[str]:
        """The text cells as Python reads numbers (the decimal mark made a point)."""
        return _point(self.text, self.decimal)

    def blank(self) -> np.ndarray:
        """Which cells are blank (empty text, or null)."""
        if self.text is not None:
            return np.fromiter((cell == "" for cell in self.text), dtype=bool,
                               count=len(self.text))
        return np.asarray(self.null, dtype=bool)


@dataclass
class _Table:
    path: str
    names: list[str]
    columns: dict[str, _Column]
    n_rows: int
    lines: list[int] | None  # file line of each data row (CSV), sheet row (spreadsheets)
    is_csv: bool
    first_line: int | None = None  # fast CSV path: data row i (0-based) is on line i + first_line
    canonical: bool = False  # whether ``names`` are pamid's names already
    file_names: dict[str, str] = field(default_factory=dict)  # name -> header in the file
    sheet: str | None = None  # spreadsheets: the sheet read ...
    letters: dict[str, str] | None = None  # ... and each column's letter(s) there

    def error(self, message: str, *, column: str | None = None, index: int | None = None):
        """A BenchDataError for data row ``index`` (0-based) of ``column``."""
        row = line = cell = None
        if index is not None:
            row = int(index) + 1
            if self.lines is not None:
                line = self.lines[int(index)]
            elif self.first_line is not None:
                line = int(index) + self.first_line
        if self.sheet is not None and line is not None:
            letter = (self.letters or {}).get(column) if column is not None else None
            cell = f"{letter}{line}" if letter else None
            line = None
        if column is not None:
            column = self.file_names.get(column, column)
        return BenchDataError(self.path, message, column=column, row=row, line=line,
                              sheet=self.sheet, cell=cell)

    def rename(self, columns: dict[str, str] | None) -> None:
        """Give the columns pamid's names (see :mod:`._names`), keeping the file's headers
        for messages. Errors for a mapped header the file lacks, or two headers that mean
        the same column."""
        if self.canonical:
            return
        try:
            names = canonical_names(self.names, QUANTITY_UNITS, columns)
        except NameProblem as problem:
            raise self.error(problem.message, column=problem.column) from None
        self.file_names = {new: old for new, old in zip(names, self.names, strict=True)
                           if new != old}
        self.columns = {new: self.columns[old] for new, old in zip(names, self.names,
                                                                   strict=True)}
        if self.letters is not None:
            self.letters = {new: self.letters[old] for new, old in zip(names, self.names,
                                                                       strict=True)}
        self.names = names
        self.canonical = True


def _looks_binary(data: bytes) -> bool:
    """True for bytes that are clearly not a text table (NULs or many control bytes)."""
    head = data[:8192]
    if b"\x00" in head:
        return True
    control = sum(1 for b in head if b < 32 and b not in (9, 10, 12, 13))
    return control > 0.05 * len(head)


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


def _stream_key(path: Path, shown: str) -> tuple[int, int] | None:
    """None for a regular file, else the stream's identity (device, inode): a pipe, a FIFO,
    ``/dev/stdin``, a character device. Errors for a missing path or a directory."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise BenchDataError(shown, "file not found") from None
    except OSError as exc:
        raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}") from exc
    if stat.S_ISDIR(info.st_mode):
        raise BenchDataError(shown, "is a directory, not a data file")
    if stat.S_ISREG(info.st_mode):
        return None
    return info.st_dev, info.st_ino


def _no_data(shown: str, timeout_s: float) -> BenchDataError:
    return BenchDataError(shown, f"no data arrived within {timeout_s:g} s (a pipe or FIFO "
                                 "with no writer?)")


def _read_stream(path: Path, shown: str, timeout_s: float) -> bytes:
    """Every byte of a pipe, FIFO or device, read once.

    The first byte must arrive within ``timeout_s`` seconds (a FIFO nobody writes to would
    otherwise block for ever); after it, the stream is read to its end however slowly it
    comes. A character device stops early once its bytes are plainly not text
    (``/dev/zero`` never ends)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO with no writer opens too
    except OSError as exc:
        raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}") from exc
    device = stat.S_ISCHR(os.fstat(fd).st_mode)
    chunks: list[bytes] = []
    size = 0
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLPRI)
        deadline = time.monotonic() + timeout_s
        while True:
            if chunks:
                wait = None  # data is coming: read it all
            else:
                wait = max(0.0, deadline - time.monotonic()) * 1000.0
            if not poller.poll(wait) and not chunks:
                raise _no_data(shown, timeout_s)
            try:
                chunk = os.read(fd, 1 << 20)
            except BlockingIOError:  # woken without data (a FIFO whose writer is not there)
                if not chunks and time.monotonic() >= deadline:
                    raise _no_data(shown, timeout_s) from None
                continue
            except OSError as exc:
                raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                     ) from exc
            if not chunk:
                break  # the writer closed its end
            chunks.append(chunk)
            size += len(chunk)
            if device and size >= 8192 and _looks_binary(b"".join(chunks[:8])):
                break
    finally:
        os.close(fd)
    return b"".join(chunks)


#: Seconds :func:`load_bench` and :func:`load_decay` wait for the first byte from a pipe, a
#: FIFO or ``/dev/stdin`` before they give up (a FIFO with no writer never sends one).
STREAM_TIMEOUT_S = 10.0
# Streams read ahead by :func:`head_bytes`: their bytes (or the error reading them gave), for
# the next read of the same stream, which takes them.
_READ_AHEAD: dict[tuple[int, int], bytes | BenchDataError] = {}


def _stream_bytes(path: Path, shown: str, timeout_s: float | None = None) -> bytes | None:
    """The bytes of ``path`` if it is a stream (pipe, FIFO, ``/dev/stdin``, device), read once
    (a stream cannot be read twice: every reader of the file is handed these bytes); None for a
    regular file, which each reader reads itself. Errors for a missing path, a directory, an
    empty stream or one that sends nothing within ``timeout_s`` (:data:`STREAM_TIMEOUT_S`)."""
    key = _stream_key(path, shown)
    if key is None:
        return None
    data = _READ_AHEAD.pop(key, None)
    if data is None:
        data = _read_stream(path, shown, STREAM_TIMEOUT_S if timeout_s is None else timeout_s)
    if isinstance(data, BenchDataError):
        raise data
    if not data:
        raise BenchDataError(shown, "no data: the stream ended before its first byte (0 "
                                    "bytes); expected a table with a header")
    return data


def head_bytes(path: str | os.PathLike, size: int = 65536) -> bytes:
    """The first ``size`` bytes of a data file, to tell what it holds (its header) without
    spoiling it for the reader: a stream (pipe, FIFO, ``/dev/stdin``) is read whole, once,
    and its bytes are handed to the next :func:`load_bench` or :func:`load_decay` of it.
    Raises BenchDataError where the file cannot be read."""
    p, shown = Path(path), str(path)
    key = _stream_key(p, shown)
    if key is None:
        try:
            with open(p, "rb") as f:
                return f.read(size)
        except OSError as exc:
            raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                 ) from exc
    if key not in _READ_AHEAD:
        try:
            _READ_AHEAD[key] = _read_stream(p, shown, STREAM_TIMEOUT_S)
        except BenchDataError as exc:
            _READ_AHEAD[key] = exc
            raise
    data = _READ_AHEAD[key]
    if isinstance(data, BenchDataError):
        raise data
    return data[:size]


def _file_kind(path: Path, stream: bytes | None) -> str:
    """How to read a file: ``"parquet"``, ``"spreadsheet"`` or ``"csv"``, by its extension;
    a stream (``/dev/stdin``, a pipe), which has none, by its first bytes."""
    from ._spreadsheet import SPREADSHEET_SUFFIXES

    suffix = path.suffix.lower()
    if suffix in PARQUET_SUFFIXES:
        return "parquet"
    if suffix in SPREADSHEET_SUFFIXES:
        return "spreadsheet"
    if stream is not None and stream[:4] == b"PAR1":
        return "parquet"
    if stream is not None and stream[:4] in (b"PK\x03\x04", b"\xd0\xcf\x11\xe0"):
        return "spreadsheet"  # a zip (xlsx, ods) or an OLE file (xls)
    return "csv"


def _read_bytes(path: Path, shown: str, data: bytes | None = None) -> bytes:
    """The file's bytes: ``data`` where the caller read the stream already, else read now."""
    if data is None:
        data = _stream_bytes(path, shown)
    if data is None:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                 ) from exc
    if not data:
        raise BenchDataError(shown, "the file is empty (0 bytes); expected a table with a header")
    return data


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
    data: bytes | None = None,
) -> _Table:
    """Read a CSV file cell by cell, keeping the file line of every data row.

    This is the reference reader: it reads every file pamid reads as CSV and words every
    problem. ``sep`` and ``decimal`` default to those detected (:func:`_csv_dialect`).
    ``data``: the file's bytes where they were read already (a stream is read only once).
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


def _check_duplicates(shown: str, names: list[str]) -> None:
    seen: dict[str, int] = {}
    for j, name in enumerate(names):
        if name in seen:
            raise BenchDataError(
                shown,
                f"the column name appears twice in the header (columns {seen[name] + 1} and "
                f"{j + 1}); each column name must be unique",
                column=name,
            )
        seen[name] = j


# --------------------------------------------------------------------------------------
# Fast CSV reader, for large, plain files
# --------------------------------------------------------------------------------------

#: Whether :func:`load_bench` tries the fast, column-wise CSV reader first. Switched off, every
#: CSV file goes through the cell-by-cell reader (tests and benchmarks compare the two).
_FAST_CSV = True

#: Bytes a plain decimal number is written with, for each decimal mark.
_NUMBER_BYTES = np.zeros(256, dtype=bool)
_NUMBER_BYTES[np.frombuffer(b"0123456789+-.eE", dtype=np.uint8)] = True
_NUMBER_BYTES_COMMA = np.zeros(256, dtype=bool)
_NUMBER_BYTES_COMMA[np.frombuffer(b"0123456789+-,eE", dtype=np.uint8)] = True


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
            chunk = pc.if_else(pa.array(empty), pa.scalar(None, pa.string()), chunk)
        try:
            floats = pc.cast(chunk, pa.float64())
        except (pa.ArrowException, ValueError):
            return None
        values[at : at + len(chunk)] = floats.to_numpy(zero_copy_only=False)
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
    raw_codes = encoded.indices.to_numpy(zero_copy_only=False)
    stripped = np.array([cell.strip() for cell in encoded.dictionary.to_pylist()], dtype=object)
    text_ids, texts = pd.factorize(stripped)  # cells that differ only in blanks merge here
    ids = text_ids.astype(np.int64)[raw_codes]
    texts = np.asarray(texts, dtype=object)
    if _in_order_of_appearance(ids, len(texts)):  # pyarrow's dictionary usually is
        return ids, texts
    codes, order = pd.factorize(ids)
    return codes.astype(np.int64, copy=False), texts[order]


def _in_order_of_appearance(codes: np.ndarray, n_codes: int) -> bool:
    """Whether every code 0 … ``n_codes`` − 1 appears in ``codes``, code k first after code
    k − 1 does (as ``pd.factorize`` numbers them): the largest code so far starts at 0 and
    grows by steps of 1 up to ``n_codes`` − 1."""
    if len(codes) == 0:
        return n_codes == 0
    largest = np.maximum.accumulate(codes)
    return bool(codes[0] == 0 and largest[-1] == n_codes - 1
                and (np.diff(largest) <= 1).all())


def _text_values(uniques: np.ndarray, codes: np.ndarray):
    """A frame column holding ``uniques[codes]``, of the dtype pandas gives a list of str."""
    return pd.Series(uniques.tolist()).take(codes).array


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


def _point(cells, decimal: str):
    """Cells written with ``decimal`` as Python reads numbers (a decimal comma made a point,
    and a point made a comma, so that a cell with a point does not read as a number)."""
    return cells if decimal == "." else [cell.translate(_SWAP_MARKS) for cell in cells]


def _blank_ok(name: str) -> bool:
    """Whether a blank cell of this numeric column (pamid's name) means "not recorded"."""
    return name not in _LABELS and _quantity_of(name) not in _STRICT_QUANTITIES


def _parsed_as_float(name: str) -> bool:
    """Whether the fast reader has pyarrow parse this column (pamid's name) as float64: a
    number pamid knows by name whose text is not needed (a pressure in kPa, not in bar,
    whose kPa come from the text)."""
    known = name in ("direction", "cycle") or _quantity_of(name) is not None
    return known and name not in _LABELS and PRESSURE_COLUMNS.get(name, "kPa") == "kPa"


def _float_column(name: str, chunked) -> _Column | None:
    """A column pyarrow parsed as float64 (a blank cell is a null), or None if the
    cell-by-cell reader must read the file: a blank cell where a number is required, or a
    cell that is not a finite number (NaN or inf written as such, or 1e999)."""
    if chunked.null_count and not _blank_ok(name):
        return None
    values = chunked.to_numpy()  # NaN where a cell is blank (null)
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
    known = name in ("direction", "cycle") or _quantity_of(name) is not None
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
        column.original = _text_values(uniques, codes)
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
    n_lines = data.count(b"\n", header_end + 1, end) + 1
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
    if n != n_lines:
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


def _read_parquet(path: Path, shown: str, data: bytes | None = None) -> _Table:
    """Read a Parquet file with pyarrow, column by column (from ``data``, its bytes, where a
    stream was read already)."""
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


# --------------------------------------------------------------------------------------
# Interpretation
# --------------------------------------------------------------------------------------


def _quantity_of(name: str, quantities=None) -> str | None:
    """The known quantity a column name starts with (case-insensitive), or None.

    ``quantities`` maps quantity → accepted units (default: the bench-file table; decay
    files pass their own)."""
    quantities = QUANTITY_UNITS if quantities is None else quantities
    # One look-up, not a loop over the quantities (a file may have 40,000 columns): the
    # quantities are lower-case words without an underscore.
    head = name.lower().partition("_")[0]
    return head if head in quantities else None


def _check_units(table: _Table, quantities=None) -> None:
    """Every column named after a known quantity carries one of its accepted units."""
    quantities = QUANTITY_UNITS if quantities is None else quantities
    for name in table.names:
        if name in _RESERVED:
            raise table.error(
                "this column name is reserved for the row numbers pamid adds; rename it",
                column=name,
            )
        quantity = _quantity_of(name, quantities)
        if quantity is None:
            continue
        accepted = [f"{quantity}_{unit}" for unit in quantities[quantity]]
        if name in accepted:
            continue
        units = ", ".join(quantities[quantity])
        spelled = [a for a in accepted if a.lower() == name.lower()]
        if spelled:
            raise table.error(
                f"units are case-sensitive: name the column {spelled[0]} "
                f"(accepted units for {quantity}: {units})",
                column=name,
            )
        given = name[len(quantity) + 1 :] if len(name) > len(quantity) else ""
        what = f"unknown unit '{given}'" if given else "no unit in the column name"
        raise table.error(
            f"{what} for {quantity}; accepted units: {units} "
            f"(name the column {' or '.join(accepted)})",
            column=name,
        )


def _number_problem(cell: str, decimal: str = ".", shown: str | None = None) -> str | None:
    """Why a text cell is not a finite number, or None if it is one.

    ``cell`` is as Python reads numbers (see :func:`_point`); ``shown`` is the cell as the
    file writes it (the same unless the decimal mark is a comma)."""
    shown = cell if shown is None else shown
    if cell == "":
        return "empty cell; a number is required here"
    try:
        if "_" in cell:
            raise ValueError
        value = float(cell)
    except ValueError:
        if decimal != "." and "." in shown:
            return (f"'{shown}' is not a number with the decimal mark ',' this file uses "
                    "(pass decimal='.', --decimal . on the command line, if the point is "
                    "the decimal mark)")
        return f"'{shown}' is not a number"
    if math.isnan(value):
        return f"'{shown}' is NaN; a measured number is required here"
    if math.isinf(value):
        return f"'{shown}' is infinite; a finite number is required here"
    return None


def _first_problem(col: _Column, blank_ok: bool = False) -> tuple[int, str] | None:
    """The first row of ``col`` that is not a finite number, with the reason. With
    ``blank_ok``, blank cells (empty or null) are no problem: they are not recorded."""
    if col.parsed is not None:
        return None  # checked already
    if col.text is not None:
        cells = col.number_text()
        blank = col.blank() if blank_ok else None
        skip = blank is not None and bool(blank.any())
        # Fast path: numpy parses the whole column; the slow loop only finds the bad cell.
        if not col.problems:
            try:
                if "_" not in "".join(cells):
                    parsed = np.array([c or "nan" for c in cells] if skip else cells,
                                      dtype=np.float64)
                    finite = np.isfinite(parsed)
                    if (finite | blank).all() if skip else finite.all():
                        col.parsed = parsed
                        return None
            except ValueError:
                pass
        for i, cell in enumerate(cells):
            if skip and blank[i]:
                continue
            if col.problems and i in col.problems:
                return i, col.problems[i]
            problem = _number_problem(cell, col.decimal, col.text[i])
            if problem is not None:
                return i, problem
        return None
    null = np.asarray(col.null, dtype=bool)
    bad = ~np.isfinite(col.values) & ~null
    if not blank_ok:
        bad |= null
    if not bad.any():
        return None
    i = int(np.argmax(bad))
    if null[i]:
        return i, f"{col.null_word}; a number is required here"
    if np.isnan(col.values[i]):
        return i, "NaN; a measured number is required here"
    return i, f"{col.raw(i)} is infinite; a finite number is required here"


def _as_floats(col: _Column) -> np.ndarray:
    """Float64 values of a column already checked by :func:`_first_problem` (NaN where a
    cell is blank)."""
    if col.parsed is not None:
        return col.parsed  # made for this column by the reader or by _first_problem
    if col.text is not None:
        return np.array([float(cell) if cell else np.nan for cell in col.number_text()],
                        dtype=np.float64)
    return col.values.astype(np.float64, copy=True)


def _is_numeric_extra(col: _Column) -> bool:
    """Whether an extra column is a numeric covariate.

    Parquet: a numeric column type. Text: at least one non-empty cell, and every non-empty
    cell reads as a number (NaN and inf included, so that they are reported as errors).
    """
    if col.numeric is not None:
        return col.numeric
    if col.text is None:
        return True
    if col.problems:
        return False
    return _all_numbers(col.number_text())


def _all_numbers(cells) -> bool:
    """At least one non-empty cell, and every non-empty cell reads as a number."""
    filled = [cell for cell in cells if cell]
    if not filled:
        return False
    for cell in filled:
        try:
            if "_" in cell:
                return False
            float(cell)
        except ValueError:
            return False
    return True


def _check_missing(table: _Table, missing: list[str], n_required: int, kind: str) -> None:
    """Raise for missing required columns (naming them and the columns found), or for a
    table with a header but no rows. ``kind`` names the table ("bench", "decay") in the
    message used when none of the ``n_required`` columns is there."""
    if missing:
        names = [table.file_names.get(name, name) for name in table.names]
        found = ", ".join(names) if names else "none"
        lead = "missing required column" + ("s" if len(missing) > 1 else "")
        if len(missing) == n_required:
            lead = f"not a {kind} table: none of the required columns were found; missing"
        column = missing[0].split(" ")[0] if len(missing) == 1 else None
        raise table.error(f"{lead}: {'; '.join(missing)}. Columns found: {found}", column=column)
    if table.n_rows == 0:
        raise table.error("no data rows: the file has a header but no data below it")


def _check_required(table: _Table, l0_arg: float | None) -> str:
    """Check the required columns are there; return the pressure column's name."""
    names = table.names
    pressures = [name for name in names if name in PRESSURE_COLUMNS]
    if len(pressures) > 1:
        raise table.error(
            f"more than one pressure column ({', '.join(pressures)}); the pressure is "
            "ambiguous, keep exactly one",
            column=pressures[1],
        )
    missing = []
    if not pressures:
        missing.append("pressure_kPa (or pressure_bar, pressure_Pa, pressure_psi)")
    if "force_N" not in names:
        missing.append("force_N")
    if not {"contraction_pct", "contraction_mm", "length_mm"} & set(names):
        missing.append("contraction_pct (or contraction_mm, or length_mm with l0_mm)")
    _check_missing(table, missing, n_required=3, kind="bench")
    if (
        not {"contraction_pct", "contraction_mm"} & set(names)
        and "l0_mm" not in names
        and l0_arg is None
    ):
        raise table.error(
            "length_mm is given without contraction_pct or contraction_mm, so the nominal "
            "length l0 is needed "
            "to compute the contraction: add an l0_mm column or pass l0_mm=... "
            "(--l0-mm on the command line)",
            column="length_mm",
        )
    return pressures[0]


def _labels(table: _Table, name: str, what: str):
    """A label column (muscle, trial) as ``(codes, uniques, ids)``: the label of row i is
    ``uniques[codes[i]]`` (distinct, in order of first appearance), ``ids`` the list of
    every row's label where the reader gave text (else None). Labels are text, even where
    the cells are numbers; an empty one is an error."""
    col = table.columns[name]
    ids: list[str] | None = None
    if col.codes is not None:
        codes, uniques = col.codes, col.uniques
        empty = uniques == ""
        missing = empty[codes] if empty.any() else np.zeros(0, dtype=bool)
    else:
        if col.text is not None:
            ids = list(col.text)
            missing = np.asarray([cell == "" for cell in ids], dtype=bool)
        else:
            ids = [col.raw(i) for i in range(table.n_rows)]
            missing = np.asarray(col.null, dtype=bool)
        codes, uniques = pd.factorize(np.asarray(ids, dtype=object))
        uniques = np.asarray(uniques, dtype=object)
    i = _first_true(missing)
    if i is not None:
        raise table.error(f"empty {what}; every row needs one", column=name, index=i)
    return codes, uniques, ids


def _row_ranges(rows: np.ndarray, most: int = 3) -> str:
    """1-based rows as ranges, e.g. "3-1202, 1500", the first ``most`` ranges only."""
    starts = np.flatnonzero(np.diff(rows, prepend=-2) != 1)
    ends = np.append(starts[1:], len(rows)) - 1
    parts = [f"{rows[a] + 1}" if a == b else f"{rows[a] + 1}-{rows[b] + 1}"
             for a, b in zip(starts[:most], ends[:most], strict=True)]
    return ", ".join(parts) + (", …" if len(starts) > most else "")


def _blank_cells_message(table, blanks: dict, codes, uniques, has_muscle: bool) -> str:
    """The :class:`MissingValuesWarning` text: how many cells of which columns were blank,
    on which rows and of which muscles."""
    parts = []
    for k, (name, mask) in enumerate(blanks.items()):
        rows = np.flatnonzero(mask)
        count = len(rows)
        noun = ("blank cell" if count == 1 else "blank cells") if k == 0 else ""
        where = f"row{'s' if count > 1 else ''} {_row_ranges(rows)}"
        if has_muscle:
            muscles = uniques[pd.unique(codes[rows])].tolist()
            shown = ", ".join(repr(m) for m in muscles[:3])
            more = f" and {len(muscles) - 3} more" if len(muscles) > 3 else ""
            where += f", muscle{'s' if len(muscles) > 1 else ''} {shown}{more}"
        column = table.file_names.get(name, name)
        parts.append(f"{count:,} {noun + ' ' if noun else ''}in {column} ({where})")
    text = f"{table.path}: {' and '.join(parts)}: treated as not recorded"
    if "direction" in blanks:
        text += "; direction is derived from the data there"
    return text


def _first_true(mask: np.ndarray) -> int | None:
    return int(np.argmax(mask)) if mask.any() else None


def _check_time_increases(
    table, time_raw, time, codes, names, group: str, has_group: bool, *, blank=None,
    described: bool = False
) -> None:
    """Time must increase strictly within each group (muscle, trial): error at the first row
    where it does not, naming the earlier row it fails against. ``codes`` are integer group
    codes per row, ``names`` the group name per code, ``group`` the word for a group;
    ``has_group`` False when the file has no group column (one group). Rows marked in
    ``blank`` (time not recorded) are skipped. With ``described``, ``names`` are whole
    descriptions ("muscle 'A', trial 'T2'") rather than bare names."""
    if blank is not None and blank.any():
        kept = np.flatnonzero(~blank)
        previous_kept = _previous_rows(codes[kept])
        previous = np.full(len(codes), -1, dtype=np.int64)
        previous[kept] = np.where(previous_kept >= 0, kept[np.maximum(previous_kept, 0)], -1)
    else:
        previous = _previous_rows(codes)
    i = _first_true((previous >= 0) & (time <= time[np.maximum(previous, 0)]))
    if i is not None:
        j = int(previous[i])
        whose = ""
        if has_group:
            whose = f" of {names[codes[i]]}" if described else f" of {group} '{names[codes[i]]}'"
        raise table.error(
            f"time_s {time_raw(i)} s is not later than {time_raw(j)} s "
            f"on row {j + 1}{whose}; time must increase strictly within a {group}",
            column="time_s",
            index=i,
        )


def _previous_rows(codes: np.ndarray) -> np.ndarray:
    """For every row, the index of the previous row with the same code (-1 if none)."""
    n = len(codes)
    if n and (np.diff(codes) >= 0).all():  # the usual layout: each muscle in one block
        previous = np.arange(-1, n - 1)
        previous[np.diff(codes, prepend=-1) != 0] = -1
        return previous
    order = np.argsort(codes, kind="stable")  # rows grouped by code, in file order within
    previous = np.full(n, -1, dtype=np.int64)
    same = codes[order[1:]] == codes[order[:-1]]
    previous[order[1:][same]] = order[:-1][same]
    return previous


def load_bench(
    path: str | os.PathLike,
    *,
    l0_mm: float | None = None,
    keep_censored: bool = False,
    sep: str | None = None,
    decimal: str | None = None,
    sheet: str | None = None,
    columns: dict[str, str] | None = None,
) -> BenchData:
    """Load a bench file (CSV, Parquet or a spreadsheet) of pneumatic-muscle measurements.

    Parameters
    ----------
    path:
        The file. ``.parquet`` and ``.pq`` are read as Parquet; ``.xlsx``, ``.xlsm``,
        ``.xlsb``, ``.xls`` and ``.ods`` as spreadsheets; anything else as CSV (comma-,
        semicolon- or tab-separated, as the header shows). A pipe or ``/dev/stdin`` is read
        once (see "Pipes" in the module's documentation).
    l0_mm:
        Nominal (unpressurised, uncontracted) muscle length in mm, for files that give
        ``length_mm`` but neither ``contraction_pct`` nor an ``l0_mm`` column. If the file has
        an ``l0_mm`` column too, the two must agree.
    keep_censored:
        Keep rows with a force of exactly 0 N. By default they are dropped with a
        :class:`CensoredRowsWarning`, because force maps use 0 to mark lengths the muscle
        cannot hold.
    sep:
        CSV only: the delimiter (``","``, ``";"``, ``"\\t"`` or ``"tab"``, or any other
        single character); detected from the header by default.
    decimal:
        The decimal mark of numbers written as text, ``"."`` or ``","``; for CSV detected
        by default (a comma in a semicolon- or tab-separated file whose numbers read like
        ``499,911``).
    sheet:
        Spreadsheets only: the name of the sheet to read (default: the first).
    columns:
        Maps headers of the file to pamid's names, e.g. ``{"Druck": "pressure_bar",
        "Kraft": "force_N"}``, for namings pamid does not recognise by itself.

    Returns
    -------
    BenchData
        The checked data with pressures in kPa and the contraction in percent.

    Raises
    ------
    BenchDataError
        For any problem with the file; the message names the file and, where it applies,
        the column and the 1-based data row (and the file line for CSV, the sheet and cell
        for a spreadsheet).

    Warns
    -----
    CensoredRowsWarning, MissingValuesWarning
        Censored rows dropped; blank cells of optional columns read as not recorded.
    """
    from ._spreadsheet import SPREADSHEET_SUFFIXES, read_spreadsheet

    shown = str(path)
    p = Path(path)
    if l0_mm is not None:
        try:
            l0_value = float(l0_mm)
        except (TypeError, ValueError):
            l0_value = math.nan
        if not math.isfinite(l0_value) or l0_value <= 0:
            raise BenchDataError(
                shown, f"the l0_mm argument must be a positive length in mm, got {l0_mm!r}"
            )
    else:
        l0_value = None
    sep = _check_reading_options(shown, sep, decimal, columns)

    # A pipe, FIFO or /dev/stdin is read here, once, and its bytes handed to every reader
    # that looks at the file (None for a regular file).
    stream = _stream_bytes(p, shown)
    kind = _file_kind(p, stream)
    if sheet is not None and kind != "spreadsheet":
        raise BenchDataError(shown, f"sheet={sheet!r} (--sheet) applies to spreadsheets "
                                    f"({', '.join(SPREADSHEET_SUFFIXES)}) only")
    if sep is not None and kind != "csv":
        raise BenchDataError(shown, f"sep={sep!r} (--sep) applies to CSV files only")
    if kind == "parquet":
        if decimal is not None:
            raise BenchDataError(shown, "decimal= (--decimal) applies to CSV files and "
                                        "spreadsheets only")
        table = _read_parquet(p, shown, stream)
    elif kind == "spreadsheet":
        table = read_spreadsheet(p, shown, sheet=sheet, decimal=decimal or ".", data=stream)
    else:
        if _FAST_CSV:
            table = _read_csv_fast(p, shown, sep=sep, decimal=decimal, columns=columns,
                                   data=stream)
            if table is not None:
                try:
                    return _interpret(table, l0_value, keep_censored)
                except BenchDataError:
                    pass  # the cell-by-cell reader finds the problem again and words it exactly
                del table
        table = _read_csv(p, shown, sep=sep, decimal=decimal, data=stream)
    table.rename(columns)
    return _interpret(table, l0_value, keep_censored)


def _check_reading_options(shown: str, sep, decimal, columns) -> str | None:
    """Check ``sep``, ``decimal`` and ``columns`` of :func:`load_bench`; the delimiter
    (``"tab"`` and ``"\\t"`` written out give a tab)."""
    if sep is not None:
        sep = {"tab": "\t", "\\t": "\t", "TAB": "\t"}.get(sep, sep)
        if not isinstance(sep, str) or len(sep) != 1 or sep in "\"\r\n" or sep.isalnum():
            raise BenchDataError(
                shown, f"sep must be one character such as ',', ';' or a tab, got {sep!r}"
            )
    if decimal is not None and decimal not in DECIMAL_MARKS:
        raise BenchDataError(shown, f"decimal must be '.' or ',', got {decimal!r}")
    if sep is not None and sep == decimal:
        raise BenchDataError(shown, f"sep and decimal are both {sep!r}; they must differ")
    if columns is not None:
        if not isinstance(columns, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and k.strip() and v.strip()
            for k, v in columns.items()
        ):
            raise BenchDataError(
                shown, "columns must map headers of the file to pamid's names, e.g. "
                       "{'Druck': 'pressure_bar'}"
            )
    return sep


def _interpret(table: _Table, l0_value: float | None, keep_censored: bool) -> BenchData:
    """Check the table's columns and build the BenchData (the body of :func:`load_bench`)."""
    shown = table.path
    _check_units(table)
    pressure_col = _check_required(table, l0_value)
    pressure_unit = PRESSURE_COLUMNS[pressure_col]
    names = table.names
    cols = table.columns
    n = table.n_rows

    # ---- which columns are numbers, and are they all finite numbers ----
    # (Sets for every membership test: a file may have tens of thousands of columns.)
    quantities = {name: _quantity_of(name) for name in names}
    known_numeric = [
        name for name in names if name in ("direction", "cycle") or quantities[name] is not None
    ]
    known = set(known_numeric)
    extras = [name for name in names if name not in _LABELS and name not in known]
    numeric_extras = {name for name in extras if _is_numeric_extra(cols[name])}
    velocity = {name for name in known_numeric if quantities[name] == "velocity"}
    covariates = [name for name in names if name in numeric_extras or name in velocity]
    is_covariate = set(covariates)
    text_extras = {name for name in extras if name not in is_covariate}

    first: tuple[int, int, str, str] | None = None
    for order, name in enumerate(names):
        if name not in known and name not in is_covariate:
            continue
        problem = _first_problem(cols[name], blank_ok=_blank_ok(name))
        if problem is not None and (first is None or problem[0] < first[0]):
            first = (problem[0], order, name, problem[1])
    if first is not None:
        raise table.error(first[3], column=first[2], index=first[0])
    values = {name: _as_floats(cols[name]) for name in known_numeric}
    values.update({name: _as_floats(cols[name]) for name in covariates})
    # Blank cells ("not recorded") of the optional numeric columns, NaN in ``values``.
    blanks = {name: cols[name].blank() for name in values if _blank_ok(name)}
    blanks = {name: mask for name, mask in blanks.items() if mask.any()}

    # ---- muscle ids and trial labels ----
    # As codes into the distinct ids (in order of first appearance): muscle id of row i is
    # uniques[codes[i]]; ``ids``, the list of every row's id, only where the reader gave it.
    if "muscle" in cols:
        codes, uniques, ids = _labels(table, "muscle", "muscle id")
        has_muscle = True
    else:
        ids = ["muscle"] * n
        codes, uniques = np.zeros(n, dtype=np.int64), np.array(["muscle"], dtype=object)
        has_muscle = False
    trial_labels = None
    if "trial" in cols:
        trial_codes, trial_uniques, trial_labels = _labels(table, "trial", "trial label")
        if trial_labels is None:
            trial_labels = _text_values(trial_uniques, trial_codes)
    # Row where each muscle first appears: code k first appears after code k - 1 does.
    first_row = np.flatnonzero(codes > np.maximum.accumulate(np.concatenate(([-1], codes[:-1]))))

    # ---- pressure ----
    pressure_col_obj = cols[pressure_col]
    if pressure_col_obj.kpa is not None:
        pressure_kpa = pressure_col_obj.kpa
    elif table.is_csv and pressure_unit != "kPa":
        pressure_kpa = pressure_text_to_kPa(pressure_col_obj.number_text(), pressure_unit)
    elif table.sheet is not None and pressure_unit != "kPa":
        # A spreadsheet's numbers: each converted from its shortest decimal text, exactly
        # as the same number written in a CSV file ("2.505" bar is 250.5 kPa).
        if pressure_col_obj.text is not None:
            texts = pressure_col_obj.number_text()
        else:
            texts = [repr(float(v)) for v in pressure_col_obj.values]
        distinct, where = np.unique(np.asarray(texts, dtype=object), return_inverse=True)
        pressure_kpa = pressure_text_to_kPa(distinct, pressure_unit)[where]
    else:
        pressure_kpa = pressure_to_kPa(values[pressure_col], pressure_unit)
    i = _first_true(pressure_kpa < -ATMOSPHERE_KPA)
    if i is not None:
        raise table.error(
            f"gauge pressure {pressure_col_obj.raw(i)} {pressure_unit} "
            f"({pressure_kpa[i]:.6g} kPa) is below -{ATMOSPHERE_KPA} kPa, which would be a "
            "negative absolute pressure; pressure columns hold gauge pressure "
            "(absolute minus atmospheric)",
            column=pressure_col,
            index=i,
        )

    # ---- lengths and nominal length ----
    for name in ("length_mm", "l0_mm"):
        if name in values:
            i = _first_true(values[name] <= 0)
            if i is not None:
                raise table.error(
                    f"{name} must be a positive length in mm, got {cols[name].raw(i)}",
                    column=name,
                    index=i,
                )
    l0_rows: np.ndarray | None = None
    if "l0_mm" in values:
        l0_rows = values["l0_mm"]
        # The first row whose l0 differs from that on the first row of its muscle.
        i = _first_true(l0_rows != l0_rows[first_row[codes]])
        if i is not None:
            ref = int(first_row[codes[i]])
            raise table.error(
                f"l0_mm is {cols['l0_mm'].raw(i)} here but {cols['l0_mm'].raw(ref)} on "
                f"row {ref + 1} for muscle '{uniques[codes[i]]}'; the nominal length must be "
                "constant within a muscle",
                column="l0_mm",
                index=i,
            )
        if l0_value is not None:
            i = _first_true(l0_rows != l0_value)
            if i is not None:
                raise table.error(
                    f"l0_mm is {cols['l0_mm'].raw(i)} here but the l0_mm argument is "
                    f"{l0_value:g}; give the nominal length in one place only",
                    column="l0_mm",
                    index=i,
                )
    elif l0_value is not None:
        l0_rows = np.full(n, l0_value)

    # ---- contraction: in % of l0 (Sárosi) and as a length in mm (Cullinan) ----
    # Each is taken from its own column, else derived from length_mm and l0, else from the
    # other one and l0; one that cannot be derived is left out of the frame.
    lo, hi = CONTRACTION_RANGE_PCT
    contraction = contraction_mm = None
    if "contraction_pct" in values:
        contraction = values["contraction_pct"]
        i = _first_true((contraction < lo) | (contraction > hi))
        if i is not None:
            raise table.error(
                f"contraction {cols['contraction_pct'].raw(i)} % is outside the physical "
                f"range {lo:g} % to {hi:g} % (values are percent of the nominal length: "
                "20 means 20 %)",
                column="contraction_pct",
                index=i,
            )
    elif "length_mm" in values and l0_rows is not None:
        length = values["length_mm"]
        contraction = 100.0 * (l0_rows - length) / l0_rows
        i = _first_true((contraction < lo) | (contraction > hi))
        if i is not None:
            raise table.error(
                f"length {cols['length_mm'].raw(i)} mm with l0 {l0_rows[i]:g} mm gives a "
                f"contraction of {contraction[i]:.4g} %, outside the physical range "
                f"{lo:g} % to {hi:g} %; check the length and l0 (both in mm)",
                column="length_mm",
                index=i,
            )
    if "contraction_mm" in values:
        contraction_mm = values["contraction_mm"]
        if l0_rows is not None:
            pct = 100.0 * contraction_mm / l0_rows
            i = _first_true((pct < lo) | (pct > hi))
            if i is not None:
                raise table.error(
                    f"contraction {cols['contraction_mm'].raw(i)} mm with l0 {l0_rows[i]:g} mm "
                    f"is {pct[i]:.4g} % of the nominal length, outside the physical range "
                    f"{lo:g} % to {hi:g} %",
                    column="contraction_mm",
                    index=i,
                )
            if contraction is None:
                contraction = pct
    elif l0_rows is not None and contraction is not None:
        contraction_mm = contraction * l0_rows / 100.0

    # ---- direction, cycle, time ----
    if "direction" in values:
        direction = values["direction"]
        i = _first_true((direction != 1.0) & (direction != -1.0) & ~np.isnan(direction))
        if i is not None:
            raise table.error(
                f"direction must be +1 (contracting) or -1 (extending), got "
                f"{cols['direction'].raw(i)}",
                column="direction",
                index=i,
            )
    if "cycle" in values:
        cycle = values["cycle"]
        i = _first_true((cycle != np.round(cycle)) & ~np.isnan(cycle))
        if i is not None:
            raise table.error(
                f"cycle must be a whole number, got {cols['cycle'].raw(i)}",
                column="cycle",
                index=i,
            )
    if "time_s" in values:
        blank_time = blanks.get("time_s")
        if trial_labels is None:
            _check_time_increases(table, cols["time_s"].raw, values["time_s"], codes, uniques,
                                  "muscle", has_muscle, blank=blank_time)
        else:  # time restarts in every trial
            pairs, first_of_pair = np.unique(codes * len(trial_uniques) + trial_codes,
                                             return_index=True)
            group_codes = np.searchsorted(pairs, codes * len(trial_uniques) + trial_codes)
            described = np.array([
                (f"muscle '{uniques[codes[r]]}', " if has_muscle else "")
                + f"trial '{trial_uniques[trial_codes[r]]}'" for r in first_of_pair
            ], dtype=object)
            _check_time_increases(table, cols["time_s"].raw, values["time_s"], group_codes,
                                  described, "trial", True, blank=blank_time, described=True)

    # ---- assemble the frame ----
    data: dict[str, object] = {"muscle": ids if ids is not None else _text_values(uniques, codes)}
    if trial_labels is not None:
        data["trial"] = trial_labels
    data["pressure_kPa"] = pressure_kpa.astype(np.float64)
    if contraction is not None:
        data["contraction_pct"] = np.asarray(contraction, dtype=np.float64)
    if contraction_mm is not None:
        data["contraction_mm"] = np.asarray(contraction_mm, dtype=np.float64)
    data["force_N"] = values["force_N"]
    for name in _OPTIONAL_NUMERIC:
        if name == "l0_mm":
            if l0_rows is not None:
                data[name] = np.asarray(l0_rows, dtype=np.float64)
        elif name in values:
            column = values[name]
            whole = name in ("direction", "cycle") and name not in blanks
            data[name] = column.astype(np.int64) if whole else column
    for name in names:
        if name in is_covariate:
            data[name] = values[name]
        elif name in text_extras:
            data[name] = cols[name].original
    data["source_row"] = np.arange(1, n + 1, dtype=np.int64)
    # No copy: every array in ``data`` was made here for this frame.
    frame = pd.DataFrame(
        {k: (v.to_numpy() if isinstance(v, pd.Series) else v) for k, v in data.items()},
        copy=False,
    )

    if blanks:
        warnings.warn(
            MissingValuesWarning(
                _blank_cells_message(table, blanks, codes, uniques, has_muscle),
                {table.file_names.get(k, k): int(m.sum()) for k, m in blanks.items()},
            ),
            stacklevel=3,  # the caller of load_bench
        )

    # ---- censoring ----
    censored = frame["force_N"].to_numpy() == 0.0
    n_censored = int(censored.sum())
    if n_censored and not keep_censored:
        if n_censored == n:
            raise table.error(
                f"all {n} data rows have force_N exactly 0 (censored points); nothing is left. "
                "Pass keep_censored=True (--keep-censored) to keep them",
                column="force_N",
            )
        frame = frame.loc[~censored].reset_index(drop=True)
        kept_codes = codes[~censored]
        present = np.zeros(len(uniques), dtype=bool)
        present[kept_codes] = True
        gone = uniques[~present].tolist()
        note = ""
        if gone:
            note = "; muscles with only censored rows, left out: " + ", ".join(
                repr(m) for m in gone
            )
        warnings.warn(
            f"{shown}: dropped {n_censored} censored rows (force_N exactly 0) out of {n}"
            f"{note}; pass keep_censored=True to keep them",
            CensoredRowsWarning,
            stacklevel=3,  # the caller of load_bench
        )
    else:
        n_censored = 0
        kept_codes = codes

    # Muscles in order of first appearance among the kept rows.
    kept_muscles = pd.unique(kept_codes) if len(kept_codes) < n else np.arange(len(uniques))
    muscles = tuple(uniques[kept_muscles].tolist())
    if l0_rows is not None:  # constant within a muscle, checked above
        l0_of = l0_rows[first_row[kept_muscles]].astype(float).tolist()
        l0_per_muscle: dict[str, float | None] = dict(zip(muscles, l0_of, strict=True))
    else:
        l0_per_muscle = dict.fromkeys(muscles)

    return BenchData(
        frame=frame,
        path=shown,
        has_muscle_column=has_muscle,
        muscles=muscles,
        l0_mm=l0_per_muscle,
        covariates=tuple(covariates),
        n_censored=n_censored,
        pressure_unit_in_file=pressure_unit,
    )
