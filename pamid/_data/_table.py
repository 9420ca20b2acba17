"""The raw table: a file's columns and cells as a reader (:mod:`._readers`) read them, before
any interpretation, and what every loader asks of a column (are its cells numbers, and which).

A reader gives a :class:`_Table` of :class:`_Column`; :func:`pamid._data._bench.load_bench`
and :func:`pamid._data._decay_file.load_decay` check and convert it. :meth:`_Table.error`
words a problem with the file, the column, the data row and the line (CSV) or the sheet and
cell (spreadsheets).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._errors import BenchDataError
from ._cells import QUANTITY_UNITS, _all_numbers, _number_problem, _point
from ._names import NameProblem, canonical_names


class NoTable(BenchDataError):
    """A part of a file that holds no table (a workbook's sheet of notes: no row names
    pamid's columns); ``load_bench(sheet="all")`` leaves such a sheet out, with a warning."""


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
    # Spreadsheets: columns of one value written above the header, and its cell ("B2")
    fixed_cells: dict[str, str] | None = None
    #: Data rows of the file before this table's first (a part of a file read in chunks,
    #: :func:`pamid._data._parquet.parquet_chunks`): row numbers in messages are the file's.
    row_offset: int = 0

    def row_number(self, index: int) -> int:
        """The 1-based data row of the file that holds this table's row ``index``."""
        return int(index) + 1 + self.row_offset

    def error(self, message: str, *, column: str | None = None, index: int | None = None):
        """A BenchDataError for data row ``index`` (0-based) of ``column``."""
        fixed = (self.fixed_cells or {}).get(column) if column is not None else None
        if fixed is not None:  # one value above the header: its cell, not a row
            return BenchDataError(
                self.path, f"{message} (the value in sheet '{self.sheet}', cell {fixed})",
                column=self.file_names.get(column, column), sheet=self.sheet, cell=fixed)
        row = line = cell = None
        if index is not None:
            row = self.row_number(index)
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
                                                                       strict=True)
                            if old in self.letters}
        if self.fixed_cells:
            self.fixed_cells = {new: self.fixed_cells[old] for new, old
                                in zip(names, self.names, strict=True)
                                if old in self.fixed_cells}
        self.names = names
        self.canonical = True


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


def _text_values(uniques: np.ndarray, codes: np.ndarray):
    """A frame column holding ``uniques[codes]``, of the dtype pandas gives a list of str."""
    import pandas as pd

    return pd.Series(uniques.tolist()).take(codes).array


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
