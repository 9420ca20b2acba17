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
    * ``contraction_pct``, 100 (l0 - length) / l0 in percent, or ``contraction_ratio``
      (the same as a ratio, a strain as labs log it; converted to percent), or
      ``contraction_mm`` (the contraction as a length, l0 - length), or else ``length_mm`` together
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

Reading
-------
The reader comes from the registry of formats (:mod:`._readers`): CSV (:mod:`._csv`: the
delimiter and decimal mark are detected; ``sep=`` and ``decimal=`` override them; a plain
file is read column by column with pyarrow, any other cell by cell, with the same result;
``PAMID_FAST_CSV=0`` in the environment reads every file cell by cell, to time the two or to
rule the fast reader out), Parquet (:mod:`._parquet`), and ``.xlsx``, ``.xlsm``, ``.xlsb``,
``.xls``, ``.ods`` (:mod:`._spreadsheet`: the first sheet unless ``sheet=`` names one, or
every sheet as a muscle with ``sheet="all"``; the header below notes found or given by
``header_row=``; a date or time cell in a numeric column is an error). A pipe, a FIFO or
``/dev/stdin`` is read once, whole, and its first byte must arrive within
:data:`~pamid._data._streams.STREAM_TIMEOUT_S` (10 s); one without an extension is read as
the format its first bytes name, else as CSV (:mod:`._streams`).

Censoring
---------
Published force maps mark the lengths a muscle cannot reach at a given pressure with a
force of exactly 0 N. Such rows are dropped (with a :class:`CensoredRowsWarning`) unless
``keep_censored=True``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._errors import BenchDataError
from .._units import ATMOSPHERE_KPA, pressure_text_to_kPa, pressure_to_kPa
from ._cells import (
    _LABELS,
    DECIMAL_MARKS,
    FLAG_COLUMNS,
    PRESSURE_COLUMNS,
    _blank_ok,
    _quantity_of,
)
from ._checks import _check_missing, _check_time_increases, _check_units, _first_true
from ._columns import Coded, Columns, factorize
from ._readers import ALL_SHEETS, FORMATS, reader_for, readers_taking
from ._streams import _stream_bytes
from ._table import (
    NoTable,
    _as_floats,
    _Column,
    _first_problem,
    _is_numeric_extra,
    _Table,
)

if TYPE_CHECKING:  # pandas is imported where it is used, after a fit's file is parsed
    import pandas as pd

__all__ = ["BenchData", "CensoredRowsWarning", "MissingValuesWarning", "load_bench",
           "load_bench_chunks"]

#: Physical range of the contraction, in percent of the nominal length.
CONTRACTION_RANGE_PCT: tuple[float, float] = (-10.0, 50.0)

# Canonical optional columns, in the order they appear in BenchData.frame.
_OPTIONAL_NUMERIC = ("time_s", "direction", "temperature_C", "cycle", "length_mm", "l0_mm")


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
    columns:
        The rows as NumPy columns (:class:`~pamid._data._columns.Columns`): what a fit
        reads, with the muscle ids as codes (``columns.codes("muscle")``), without pandas.
    frame:
        The same rows as a pandas DataFrame, made from :attr:`columns` when first asked
        for (a property; a fit never asks). One row per kept sample, in file order.
        Columns: ``muscle`` (str), ``trial`` (str, where the file gives one),
        ``pressure_kPa`` (gauge pressure, kPa), ``contraction_pct`` (%, positive when
        shorter than l0) and ``contraction_mm``
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

    columns: Columns
    path: str
    has_muscle_column: bool
    muscles: tuple[str, ...]
    l0_mm: dict[str, float | None] = field(default_factory=dict)
    covariates: tuple[str, ...] = ()
    n_censored: int = 0
    pressure_unit_in_file: str = "kPa"

    @functools.cached_property
    def frame(self) -> pd.DataFrame:
        """The rows as a pandas DataFrame (see the class's attributes), made once."""
        return self.columns.to_frame()

    @functools.cached_property
    def curves(self):
        """The file's curves, direction, trials and repeats (:func:`pamid._data._curves.
        find_curves`), aligned with :attr:`frame`; found once and kept."""
        from ._curves import find_curves

        return find_curves(self.columns)

    @property
    def muscle_codes(self) -> np.ndarray:
        """Every row's muscle as its index into :attr:`muscles`."""
        return self.columns.codes("muscle")[0]

    def take(self, rows, **changes) -> BenchData:
        """The same file with a subset of its rows (a boolean mask or integer indices) and
        any other attribute changed (``muscles=...`` where rows of muscles go)."""
        return dataclasses.replace(self, columns=self.columns.take(rows), **changes)

    def with_frame(self, frame: pd.DataFrame, **changes) -> BenchData:
        """The same file with the rows of ``frame`` (rows selected or columns added with
        pandas) and any other attribute changed."""
        bench = dataclasses.replace(self, columns=Columns.of_frame(frame), **changes)
        bench.__dict__["frame"] = frame
        return bench

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
        return self.columns.n_rows


def load_bench(
    path: str | os.PathLike,
    *,
    l0_mm: float | None = None,
    keep_censored: bool = False,
    sep: str | None = None,
    decimal: str | None = None,
    sheet: str | None = None,
    header_row: int | None = None,
    columns: dict[str, str] | None = None,
    on_rows=None,
) -> BenchData:
    """Load a bench file (CSV, Parquet or a spreadsheet) of pneumatic-muscle measurements.

    Parameters
    ----------
    path:
        The file. ``.parquet`` and ``.pq`` are read as Parquet; ``.xlsx``, ``.xlsm``,
        ``.xlsb``, ``.xls`` and ``.ods`` as spreadsheets; anything else as CSV (comma-,
        semicolon- or tab-separated, as the header shows): the registry of formats,
        :mod:`._readers`. A pipe or ``/dev/stdin`` is read once (see "Reading" in the
        module's documentation).
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
        Spreadsheets only: the name of the sheet to read (default: the first), or
        ``"all"``: every sheet, each one muscle named by its sheet (a sheet where no row
        names pamid's columns, notes say, is left out with a warning).
    header_row:
        Spreadsheets only: the header's row, 1-based as the sheet shows it. By default the
        header is the first row whose cells name known columns (``Pressure [kPa]``,
        ``force_N``, ``P/DP``, a header of ``columns``...; no number cell), rows above it
        being notes; else the first filled row.
    columns:
        Maps headers of the file to pamid's names, e.g. ``{"Druck": "pressure_bar",
        "Kraft": "force_N"}``, for namings pamid does not recognise by itself. In a
        spreadsheet, a header that is not in the header row but written as a label above
        it (``{"resting length": "l0_mm"}``; a trailing colon is ignored) takes the value in
        the next filled cell to the label's right, for every row of the sheet.
    on_rows:
        Called with the number of rows each muscle keeps (an int array, muscles in the
        order of the file) as soon as the muscles are known, before the remaining checks
        and the frame are made: a caller can start work that depends only on the data's
        shape meanwhile (``pamid fit`` loads its compiled programs). It may be called again
        for the same file (where the fast reader's table is read once more, cell by cell);
        a file refused before that point never calls it.

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
    shown = str(path)
    p = Path(path)
    l0_value = _l0_argument(shown, l0_mm)
    sep = _check_reading_options(shown, sep, decimal, columns)
    if header_row is not None and (
        isinstance(header_row, bool) or not isinstance(header_row, (int, np.integer))
        or header_row < 1
    ):
        raise BenchDataError(
            shown, f"header_row (--header-row) must be a row number, 1 or more, as the "
                   f"spreadsheet shows it; got {header_row!r}")

    # A pipe, FIFO or /dev/stdin is read here, once, and its bytes handed to every reader
    # that looks at the file (None for a regular file).
    stream = _stream_bytes(p, shown)
    reader = reader_for(p, stream)
    options = _reader_options(reader, shown, sheet=sheet, header_row=header_row, sep=sep,
                              decimal=decimal)
    if sheet == ALL_SHEETS and reader.parts is not None:
        return _load_sheets(p, shown, stream, reader, options, columns, l0_value,
                            keep_censored, on_rows)
    if reader.fast is not None:
        table = reader.fast(p, shown, data=stream, columns=columns, **options)
        if table is not None:
            try:
                return _interpret(table, l0_value, keep_censored, on_rows)
            except BenchDataError:
                pass  # the reference reader finds the problem again and words it exactly
            del table
    table = reader.read(p, shown, data=stream, columns=columns, **options)
    table.rename(columns)
    return _interpret(table, l0_value, keep_censored, on_rows)


#: Rows per chunk of :func:`load_bench_chunks` (``pamid fit --stream``) unless told: about
#: 3,300 muscles of a Sárosi sweep of 300 rows, ~200 MB of arrays while a chunk is read.
CHUNK_ROWS = 1_000_000


def load_bench_chunks(
    path: str | os.PathLike,
    rows: int = CHUNK_ROWS,
    *,
    l0_mm: float | None = None,
    keep_censored: bool = False,
    columns: dict[str, str] | None = None,
    share: tuple[int, int] | None = None,
    sep: str | None = None,
    decimal: str | None = None,
    sheet: str | None = None,
    header_row: int | None = None,
) -> Iterator[BenchData]:
    """A bench file bigger than memory, as :class:`BenchData` of whole muscles, about
    ``rows`` rows each, in file order; memory holds one chunk at a time.

    Each chunk is read and checked as :func:`load_bench` checks a whole file (the same
    messages; rows numbered as in the file). The format must be one that can be read a part
    at a time (Parquet: :attr:`pamid._data._readers.Reader.chunks`), and each muscle's
    rows must be together: a muscle that comes back after other muscles' rows is an error
    naming its row (sort the file by muscle). Warnings (censored rows, blank cells) are
    those of each chunk. ``share`` = (index, count): the muscles of process ``index`` of
    ``count`` only, every muscle in exactly one share (``pamid fit --stream --processes``).
    The reading options are :func:`load_bench`'s; one the format does not take is the same
    error there.
    """
    shown = str(path)
    p = Path(path)
    if isinstance(rows, bool) or not isinstance(rows, (int, np.integer)) or rows < 1:
        raise ValueError(f"rows per chunk must be a whole number, 1 or more; got {rows!r}")
    l0_value = _l0_argument(shown, l0_mm)
    sep = _check_reading_options(shown, sep, decimal, columns)
    reader = reader_for(p, None)
    if reader.chunks is None:
        able = " or ".join(r.name for r in FORMATS if r.chunks is not None)
        raise BenchDataError(
            shown, f"only {able} can be read a part at a time (--stream); this file is read "
                   f"as one of the {reader.name}: convert it (pandas: "
                   "pd.read_csv(path).to_parquet(new_path)) or load it whole")
    _reader_options(reader, shown, sheet=sheet, header_row=header_row, sep=sep,
                    decimal=decimal)
    seen: set[str] = set()
    for table in reader.chunks(p, shown, int(rows), columns=columns, share=share):
        table.rename(columns)
        bench = _interpret(table, l0_value, keep_censored)
        again = [m for m in bench.muscles if m in seen]
        if again:
            row = int(bench.frame["source_row"][bench.frame["muscle"] == again[0]].iloc[0])
            raise table.error(
                f"muscle '{again[0]}' comes back here after the rows of other muscles: a file "
                "read in chunks (--stream) needs the rows of each muscle together (sort it "
                "by muscle, keeping each muscle's rows in their order)",
                column="muscle", index=row - 1 - table.row_offset)
        seen.update(bench.muscles)
        yield bench


def _reader_options(reader, shown: str, **given) -> dict:
    """The reading options given (not None); an error naming the formats for one that
    ``reader``'s format does not take."""
    options = {name: value for name, value in given.items() if value is not None}
    for name, value in options.items():
        if name not in reader.options:
            raise BenchDataError(shown, _not_applicable(name, value))
    return options


def _l0_argument(shown: str, l0_mm) -> float | None:
    """The ``l0_mm`` argument as a float; an error for anything but a positive length."""
    if l0_mm is None:
        return None
    try:
        l0_value = float(l0_mm)
    except (TypeError, ValueError):
        l0_value = math.nan
    if not math.isfinite(l0_value) or l0_value <= 0:
        raise BenchDataError(
            shown, f"the l0_mm argument must be a positive length in mm, got {l0_mm!r}"
        )
    return l0_value


def _load_sheets(p: Path, shown: str, stream, reader, options: dict, columns, l0_value,
                 keep_censored: bool, on_rows) -> BenchData:
    """``load_bench(sheet="all")``: every sheet of a workbook read and checked as one muscle,
    named by its sheet (a sheet with a ``muscle`` column of its own is an error); the
    muscles in sheet order. A sheet where no row names pamid's columns is left out with a
    warning (unless ``header_row`` says where the header is); warnings name their sheet;
    columns that some sheets lack are not recorded there (NaN), with a warning.
    ``source_row`` counts the data rows of each sheet."""
    import pandas as pd

    options = {name: value for name, value in options.items() if name != "sheet"}
    benches: list[BenchData] = []
    skipped: list[str] = []
    for name in reader.parts(p, shown, data=stream):
        try:
            table = reader.read(p, shown, data=stream, columns=columns, sheet=name,
                                need_header="header_row" not in options, **options)
        except NoTable:
            skipped.append(name)
            continue
        table.rename(columns)
        if "muscle" in table.names:
            raise table.error(
                "with sheet='all' (--sheet all) each sheet is one muscle, named by the "
                "sheet, but this sheet has a muscle column of its own; read it alone with "
                f"sheet={name!r} (--sheet '{name}')",
                column="muscle",
            )
        table.names.insert(0, "muscle")
        ids = [name] * table.n_rows
        table.columns = {"muscle": _Column("muscle", text=ids, original=ids),
                         **table.columns}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            benches.append(_interpret(table, l0_value, keep_censored))
        for w in caught:  # the same warnings, saying which sheet
            text = str(w.message).replace(f"{shown}: ", f"{shown}, sheet '{name}': ", 1)
            message = (MissingValuesWarning(text, w.message.counts)
                       if isinstance(w.message, MissingValuesWarning) else text)
            warnings.warn(message, w.category, stacklevel=3)
    if skipped:
        listed = ", ".join(f"'{name}'" for name in skipped)
        if not benches:
            raise BenchDataError(
                shown, f"no sheet holds a table: no row of {listed} names two of pamid's "
                       "columns (map the lab's names with columns=..., --columns, or say "
                       "the header's row with header_row=, --header-row)")
        warnings.warn(f"{shown}: sheet{'s' if len(skipped) > 1 else ''} {listed} left out: "
                      "no row there names pamid's columns (notes?)", UserWarning,
                      stacklevel=3)
    frame = pd.concat([b.frame for b in benches], ignore_index=True, sort=False)
    lacking = {
        column: [b.muscles[0] for b in benches if column not in b.frame.columns]
        for column in frame.columns
    }
    lacking = {column: sheets for column, sheets in lacking.items() if sheets}
    if lacking:
        counts = {column: int(sum(len(b.frame) for b in benches if b.muscles[0] in sheets))
                  for column, sheets in lacking.items()}
        parts = [f"{column} (sheet{'s' if len(sheets) > 1 else ''} "
                 + ", ".join(f"'{s}'" for s in sheets) + ")"
                 for column, sheets in lacking.items()]
        warnings.warn(MissingValuesWarning(
            f"{shown}: columns that some sheets lack: {'; '.join(parts)}: treated as not "
            "recorded there", counts), stacklevel=3)
    covariates = tuple(dict.fromkeys(c for b in benches for c in b.covariates))
    muscles = tuple(m for b in benches for m in b.muscles)
    if on_rows is not None:
        on_rows(np.array([len(b) for b in benches], dtype=np.int64))
    bench = BenchData(
        columns=Columns.of_frame(frame),
        path=shown,
        has_muscle_column=True,
        muscles=muscles,
        l0_mm={m: v for b in benches for m, v in b.l0_mm.items()},
        covariates=covariates,
        n_censored=sum(b.n_censored for b in benches),
        pressure_unit_in_file=benches[0].pressure_unit_in_file,
    )
    bench.__dict__["frame"] = frame  # made already
    return bench


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


def _not_applicable(option: str, value) -> str:
    """The message for a reading option (``sheet``, ``sep``, ``decimal``) given for a file
    whose format does not take it, naming the formats that do."""
    readers = readers_taking(option)
    formats = " and ".join(reader.name for reader in readers)
    if option == "sheet":
        suffixes = ", ".join(suffix for reader in readers for suffix in reader.suffixes)
        return f"sheet={value!r} (--sheet) applies to {formats} ({suffixes}) only"
    if option == "sep":
        return f"sep={value!r} (--sep) applies to {formats} only"
    if option == "header_row":
        return f"header_row={value!r} (--header-row) applies to {formats} only"
    return f"decimal= (--decimal) applies to {formats} only"


@dataclass
class _Numbers:
    """A table's numeric columns, checked (:func:`_numbers`)."""

    values: dict[str, np.ndarray]  # float64, NaN where blank: known quantities, covariates
    blanks: dict[str, np.ndarray]  # blank cells ("not recorded") of the optional columns
    covariates: list[str]  # the extra numeric columns, in file order
    text_extras: set[str]  # the extra columns holding text, kept as they are


@dataclass
class _Labels:
    """Every row's muscle id and trial label (:func:`_muscles_and_trials`), as codes into the
    distinct ids in order of first appearance: the muscle id of row i is
    ``uniques[codes[i]]``."""

    codes: np.ndarray
    uniques: np.ndarray
    ids: list[str] | None  # every row's muscle id, where the reader gave text
    has_muscle: bool
    first_row: np.ndarray  # the row where each muscle first appears
    blocks: bool = False  # each muscle's rows in one block (codes never decrease)
    trial_codes: np.ndarray | None = None
    trial_uniques: np.ndarray | None = None


def _interpret(table: _Table, l0_value: float | None, keep_censored: bool,
               on_rows=None) -> BenchData:
    """Check the table's columns and build the BenchData (the body of :func:`load_bench`).

    The steps, in the order their errors come: units in the column names, required columns,
    cells that must be numbers, labels, pressure, lengths, contraction, direction, cycle and
    time; then the frame, the warning for blank cells, and censoring."""
    _check_units(table)
    pressure_col = _check_required(table, l0_value)
    numbers = _numbers(table)
    _direction_from_flag(table, numbers)
    labels = _muscles_and_trials(table)
    censored = numbers.values["force_N"] == 0.0  # force maps mark lengths not held with 0 N
    if on_rows is not None:
        kept = labels.codes if keep_censored else labels.codes[~censored]
        counts = np.bincount(kept, minlength=len(labels.uniques))
        on_rows(counts[counts > 0])
    pressure_kpa = _pressure_kpa(table, pressure_col, numbers.values)
    l0_rows = _nominal_length(table, numbers.values, labels, l0_value)
    contraction, contraction_mm = _contraction(table, numbers.values, l0_rows)
    _check_direction_cycle_time(table, numbers, labels)
    columns = _frame(table, numbers, labels, pressure_kpa, contraction, contraction_mm,
                     l0_rows)
    codes, uniques, has_muscle = labels.codes, labels.uniques, labels.has_muscle
    if numbers.blanks:
        warnings.warn(
            MissingValuesWarning(
                _blank_cells_message(table, numbers.blanks, codes, uniques, has_muscle),
                {table.file_names.get(k, k): int(m.sum()) for k, m in numbers.blanks.items()},
            ),
            stacklevel=3,  # the caller of load_bench
        )

    # ---- censoring ----
    n = table.n_rows
    n_censored = int(censored.sum())
    if n_censored and not keep_censored:
        if n_censored == n:
            raise table.error(
                f"all {n} data rows have force_N exactly 0 (censored points); nothing is left. "
                "Pass keep_censored=True (--keep-censored) to keep them",
                column="force_N",
            )
        columns = columns.take(~censored)
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
            f"{table.path}: dropped {n_censored} censored rows (force_N exactly 0) out of {n}"
            f"{note}; pass keep_censored=True to keep them",
            CensoredRowsWarning,
            stacklevel=3,  # the caller of load_bench
        )
    else:
        n_censored = 0
        kept_codes = codes

    # Muscles in order of first appearance among the kept rows.
    kept_muscles = factorize(kept_codes)[1] if len(kept_codes) < n else np.arange(len(uniques))
    muscles = tuple(uniques[kept_muscles].tolist())
    if l0_rows is not None:  # constant within a muscle, checked above
        l0_of = l0_rows[labels.first_row[kept_muscles]].astype(float).tolist()
        l0_per_muscle: dict[str, float | None] = dict(zip(muscles, l0_of, strict=True))
    else:
        l0_per_muscle = dict.fromkeys(muscles)

    return BenchData(
        columns=columns,
        path=table.path,
        has_muscle_column=has_muscle,
        muscles=muscles,
        l0_mm=l0_per_muscle,
        covariates=tuple(numbers.covariates),
        n_censored=n_censored,
        pressure_unit_in_file=PRESSURE_COLUMNS[pressure_col],
    )


def _numbers(table: _Table) -> _Numbers:
    """Which columns are numbers, and are they all finite numbers: an error at the first
    cell (in row order, then column order) that is not; else the values."""
    names = table.names
    cols = table.columns
    # (Sets for every membership test: a file may have tens of thousands of columns.)
    quantities = {name: _quantity_of(name) for name in names}
    known_numeric = [
        name for name in names if name in FLAG_COLUMNS or quantities[name] is not None
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
    return _Numbers(values, blanks, covariates, text_extras)


def _direction_from_flag(table: _Table, numbers: _Numbers) -> None:
    """A pressurizing flag (``P/DP``: 1 while pressurizing, 0 while depressurizing) as
    ``direction`` (+1, −1; blank stays not recorded); an error for any other value, and
    for a file that gives both."""
    flag = numbers.values.pop("pressurizing", None)
    if flag is None:
        return
    if "direction" in numbers.values:
        other = table.file_names.get("direction", "direction")
        raise table.error(
            f"the file gives both a direction column ('{other}') and a pressurizing flag; "
            "keep one of them",
            column="pressurizing",
        )
    i = _first_true((flag != 0.0) & (flag != 1.0) & ~np.isnan(flag))
    if i is not None:
        raise table.error(
            f"a pressurizing flag must be 1 (pressurizing) or 0 (depressurizing), got "
            f"{table.columns['pressurizing'].raw(i)}",
            column="pressurizing",
            index=i,
        )
    numbers.values["direction"] = np.where(np.isnan(flag), np.nan, 2.0 * flag - 1.0)
    if "pressurizing" in numbers.blanks:
        numbers.blanks["direction"] = numbers.blanks.pop("pressurizing")
    table.file_names.setdefault("direction", table.file_names.get("pressurizing",
                                                                  "pressurizing"))


def _muscles_and_trials(table: _Table) -> _Labels:
    """Muscle ids and trial labels; an error for an empty one."""
    n = table.n_rows
    cols = table.columns
    if "muscle" in cols:
        codes, uniques, ids = _labels(table, "muscle", "muscle id")
        has_muscle = True
    else:
        ids = ["muscle"] * n
        codes, uniques = np.zeros(n, dtype=np.int64), np.array(["muscle"], dtype=object)
        has_muscle = False
    # Row where each muscle first appears: code k first appears after code k - 1 does. In
    # the usual layout, each muscle in one block, that is where the code changes.
    step = np.diff(codes)
    blocks = bool((step >= 0).all())
    if blocks:
        first_row = np.concatenate(([0], np.flatnonzero(step) + 1)) if n else step
    else:
        first_row = np.flatnonzero(
            codes > np.maximum.accumulate(np.concatenate(([-1], codes[:-1]))))
    del step
    labels = _Labels(codes, uniques, ids, has_muscle, first_row, blocks)
    if "trial" in cols:
        trial_codes, trial_uniques, _ = _labels(table, "trial", "trial label")
        labels.trial_codes, labels.trial_uniques = trial_codes, trial_uniques
    return labels


def _pressure_kpa(table: _Table, pressure_col: str, values: dict[str, np.ndarray]
                  ) -> np.ndarray:
    """The gauge pressure in kPa, converted exactly from the numbers as the file writes them;
    an error for one below -1 atm."""
    pressure_unit = PRESSURE_COLUMNS[pressure_col]
    pressure_col_obj = table.columns[pressure_col]
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
    return pressure_kpa


def _nominal_length(table: _Table, values: dict[str, np.ndarray], labels: _Labels,
                    l0_value: float | None) -> np.ndarray | None:
    """Every row's nominal length l0 in mm (from the ``l0_mm`` column or argument), or None
    where neither gives it; errors for a length that is not positive and for an l0 that
    changes within a muscle or disagrees with the argument."""
    cols = table.columns
    codes, uniques, first_row = labels.codes, labels.uniques, labels.first_row
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
        i = _first_true(l0_rows != _of_first_rows(l0_rows, labels))
        if i is not None:
            ref = int(first_row[codes[i]])
            raise table.error(
                f"l0_mm is {cols['l0_mm'].raw(i)} here but {cols['l0_mm'].raw(ref)} on "
                f"row {table.row_number(ref)} for muscle '{uniques[codes[i]]}'; the nominal "
                "length must be constant within a muscle",
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
        l0_rows = np.full(table.n_rows, l0_value)
    return l0_rows


def _of_first_rows(values: np.ndarray, labels: _Labels) -> np.ndarray:
    """Every row's value of ``values`` on its muscle's first row."""
    if labels.blocks:  # repeated block by block: no gather of every row
        counts = np.diff(np.append(labels.first_row, len(labels.codes)))
        return np.repeat(values[labels.first_row], counts)
    return values[labels.first_row[labels.codes]]


def _contraction(table: _Table, values: dict[str, np.ndarray], l0_rows: np.ndarray | None
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The contraction in % of l0 (Sárosi) and as a length in mm (Cullinan), each from its
    own column, else derived from length_mm and l0, else from the other one and l0; None for
    one that cannot be derived. An error for one outside :data:`CONTRACTION_RANGE_PCT`."""
    cols = table.columns
    lo, hi = CONTRACTION_RANGE_PCT
    contraction = contraction_mm = None
    if "contraction_pct" in values and "contraction_ratio" in values:
        raise table.error(
            "the contraction is given twice, in % (contraction_pct) and as a ratio "
            "(contraction_ratio); keep one of them",
            column="contraction_ratio",
        )
    if "contraction_ratio" in values:  # a strain as labs log it, 0.12 for 12 %
        ratio = values["contraction_ratio"]
        i = _first_true((100.0 * ratio < lo) | (100.0 * ratio > hi))
        if i is not None:
            raise table.error(
                f"contraction ratio {cols['contraction_ratio'].raw(i)} is "
                f"{100.0 * ratio[i]:.4g} % of the nominal length, outside the physical range "
                f"{lo:g} % to {hi:g} % (a ratio: 0.12 means 12 %; map a column in percent to "
                "contraction_pct)",
                column="contraction_ratio",
                index=i,
            )
        values = {**values, "contraction_pct": 100.0 * ratio}
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
    return contraction, contraction_mm


def _check_direction_cycle_time(table: _Table, numbers: _Numbers, labels: _Labels) -> None:
    """``direction`` is +1 or -1, ``cycle`` a whole number (blank cells aside), and time
    increases strictly within a muscle, or within a trial where the file has trials."""
    cols, values = table.columns, numbers.values
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
        codes, uniques, has_muscle = labels.codes, labels.uniques, labels.has_muscle
        blank_time = numbers.blanks.get("time_s")
        if labels.trial_codes is None:
            _check_time_increases(table, cols["time_s"].raw, values["time_s"], codes, uniques,
                                  "muscle", has_muscle, blank=blank_time)
        else:  # time restarts in every trial
            trial_codes, trial_uniques = labels.trial_codes, labels.trial_uniques
            pairs, first_of_pair = np.unique(codes * len(trial_uniques) + trial_codes,
                                             return_index=True)
            group_codes = np.searchsorted(pairs, codes * len(trial_uniques) + trial_codes)
            described = np.array([
                (f"muscle '{uniques[codes[r]]}', " if has_muscle else "")
                + f"trial '{trial_uniques[trial_codes[r]]}'" for r in first_of_pair
            ], dtype=object)
            _check_time_increases(table, cols["time_s"].raw, values["time_s"], group_codes,
                                  described, "trial", True, blank=blank_time, described=True)


def _frame(table: _Table, numbers: _Numbers, labels: _Labels, pressure_kpa: np.ndarray,
           contraction, contraction_mm, l0_rows) -> Columns:
    """The columns of :class:`BenchData` (all rows, censored ones included), in the frame's
    column order."""
    values, blanks = numbers.values, numbers.blanks
    data: dict[str, object] = {"muscle": Coded(labels.codes, labels.uniques)}
    if labels.trial_codes is not None:
        data["trial"] = Coded(labels.trial_codes, labels.trial_uniques)
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
    is_covariate = set(numbers.covariates)
    for name in table.names:
        if name in is_covariate:
            data[name] = values[name]
        elif name in numbers.text_extras:
            data[name] = table.columns[name].original
    data["source_row"] = np.arange(1, table.n_rows + 1, dtype=np.int64) + table.row_offset
    return Columns(data, table.n_rows)


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
    if not {"contraction_pct", "contraction_ratio", "contraction_mm", "length_mm"} & set(names):
        missing.append("contraction_pct (or contraction_ratio, contraction_mm, or length_mm "
                       "with l0_mm)")
    _check_missing(table, missing, n_required=3, kind="bench")
    if (
        not {"contraction_pct", "contraction_ratio", "contraction_mm"} & set(names)
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
        codes, uniques = factorize(np.asarray(ids, dtype=object))
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
        where = f"row{'s' if count > 1 else ''} {_row_ranges(rows + table.row_offset)}"
        if has_muscle:
            muscles = uniques[factorize(codes[rows])[1]].tolist()
            shown = ", ".join(repr(m) for m in muscles[:3])
            more = f" and {len(muscles) - 3} more" if len(muscles) > 3 else ""
            where += f", muscle{'s' if len(muscles) > 1 else ''} {shown}{more}"
        column = table.file_names.get(name, name)
        parts.append(f"{count:,} {noun + ' ' if noun else ''}in {column} ({where})")
    text = f"{table.path}: {' and '.join(parts)}: treated as not recorded"
    if "direction" in blanks:
        text += "; direction is derived from the data there"
    return text
