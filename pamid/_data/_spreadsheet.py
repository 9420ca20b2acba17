"""Reading bench tables from spreadsheets (``.xlsx``, ``.xlsm``, ``.xlsb``, ``.xls``, ``.ods``).

The reader is python-calamine: on a 100,000-row sheet it read every cell in 0.45 s against
3.7 s for openpyxl (``benchmarks/read_xlsx.py``, benchmarks/README.md). fastexcel, built on
the same Rust library, was a little faster (0.34 s) but infers a column's type from a sample
of its rows and turns a text cell in a number column into a null without a word; pamid must
see every cell as written.

The header is the first of the sheet's first :data:`HEADER_SEARCH_ROWS` filled rows that
names two known columns (:func:`._names.known_name`, the user's mapped headers included) and
holds no number cell, else its first filled row, or the row the caller names
(``header_row``, 1-based as the sheet shows it); rows above it are notes, read only for the
labels the user's mapping names (:func:`_values_above`). The table spans the header's
columns; blank rows are skipped, as blank lines of a CSV file are. A workbook's sheets are
listed by :func:`sheet_names` (``load_bench(sheet="all")`` reads each as a muscle). Number
cells are numbers and text cells text (stripped). A date or time cell cannot be a number: in
a numeric column it is an error naming the cell ("write the time as seconds"), in any other
column it is kept as ISO text. Booleans read as TRUE/FALSE text. Errors name the sheet and
the cell, e.g. ``sheet 'Data', cell C17``.
"""

from __future__ import annotations

import datetime as dt
import io
from pathlib import Path

import numpy as np

from .._errors import BenchDataError
from ._cells import QUANTITY_UNITS
from ._names import known_name
from ._streams import _read_bytes
from ._table import NoTable, _check_duplicates, _Column, _Table

__all__ = ["ALL_SHEETS", "SPREADSHEET_SUFFIXES", "column_letter",
           "read_spreadsheet", "sheet_names", "spreadsheet_names"]

#: Extensions read as spreadsheets.
SPREADSHEET_SUFFIXES: tuple[str, ...] = (".xlsx", ".xlsm", ".xlsb", ".xls", ".ods")
#: The first bytes of a spreadsheet: a zip (xlsx, ods) or an OLE file (xls).
SPREADSHEET_SIGNATURES: tuple[bytes, ...] = (b"PK\x03\x04", b"\xd0\xcf\x11\xe0")

_DATES = (dt.datetime, dt.date, dt.time, dt.timedelta)
#: The header is looked for among a sheet's first this many filled rows (notes above it).
HEADER_SEARCH_ROWS = 100
#: ``sheet=`` that reads every sheet of a workbook, each as one muscle (:func:`~pamid.
#: load_bench`).
ALL_SHEETS = "all"


def column_letter(j: int) -> str:
    """The spreadsheet letters of 0-based column ``j``: 0 → A, 25 → Z, 26 → AA."""
    letters = ""
    j += 1
    while j:
        j, r = divmod(j - 1, 26)
        letters = chr(ord("A") + r) + letters
    return letters


def _text(cell) -> str:
    """A cell as text: numbers in their shortest exact form, dates in ISO form."""
    if isinstance(cell, str):
        return cell.strip()
    if isinstance(cell, bool):
        return "TRUE" if cell else "FALSE"
    if isinstance(cell, float):
        return str(int(cell)) if cell.is_integer() and abs(cell) < 1e15 else repr(cell)
    if isinstance(cell, dt.timedelta):
        return str(cell)
    if isinstance(cell, (dt.datetime, dt.date, dt.time)):
        return cell.isoformat(sep=" ") if isinstance(cell, dt.datetime) else cell.isoformat()
    return str(cell)


def _filled(row) -> bool:
    """Whether a row has a cell that is not blank."""
    return any(not (isinstance(c, str) and not c.strip()) for c in row)


def _column(name: str, cells: list, decimal: str) -> _Column:
    """One column: numbers (with nulls for empty cells) where every cell is a number or
    empty, else text, with date cells marked as problems for numeric use."""
    kinds = set(map(type, cells))
    if kinds <= {float, int}:
        values = np.asarray(cells, dtype=np.float64)
        null = np.zeros(len(cells), dtype=bool)
        return _Column(name, values=values, null=null, original=values.copy(),
                       null_word="empty cell")
    if kinds <= {float, int, str} and all(c == "" for c in cells if isinstance(c, str)):
        null = np.fromiter((isinstance(c, str) for c in cells), dtype=bool, count=len(cells))
        if not null.all():
            values = np.array([np.nan if isinstance(c, str) else c for c in cells],
                              dtype=np.float64)
            return _Column(name, values=values, null=null, original=values.copy(),
                           null_word="empty cell")
    text = [_text(cell) for cell in cells]
    problems = {
        i: f"a date/time cell ({text[i]}), not a number; write the time as seconds in a "
           "number cell"
        for i, cell in enumerate(cells) if isinstance(cell, _DATES)
    }
    return _Column(name, text=text, original=text, decimal=decimal, problems=problems or None)


def _open(path: Path, shown: str, data: bytes | None):
    """The workbook and its sheet names; errors for a file that is not a spreadsheet."""
    from python_calamine import CalamineWorkbook

    read = _read_bytes(path, shown, data)  # existence, directory and empty-file checks
    try:
        workbook = (CalamineWorkbook.from_path(str(path)) if data is None
                    else CalamineWorkbook.from_filelike(io.BytesIO(read)))
        sheets = list(workbook.sheet_names)
    except Exception as exc:  # calamine raises several types for a corrupt file
        raise BenchDataError(shown, f"not a table: cannot read it as a spreadsheet ({exc})"
                             ) from exc
    if not sheets:
        raise BenchDataError(shown, "the workbook has no sheets")
    return workbook, sheets


def sheet_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The names of a workbook's sheets, in order (``sheet="all"`` reads each of them)."""
    return _open(path, shown, data)[1]


def _names_known(row, columns: dict[str, str] | None) -> int:
    """How many cells of a row name columns pamid knows (:func:`._names.known_name`); 0 for a
    row holding a number cell, which is data or a note with its value, never a header."""
    if any(isinstance(cell, (float, int, *_DATES)) for cell in row):
        return 0
    return sum(known_name(cell.strip(), QUANTITY_UNITS, columns) for cell in row
               if isinstance(cell, str))


def _find_header(records, columns) -> int | None:
    """The index (into ``records``) of the header: the first of the first
    :data:`HEADER_SEARCH_ROWS` filled rows that names at least two known columns; None if
    none does."""
    for k, (_, row) in enumerate(records[:HEADER_SEARCH_ROWS]):
        if _names_known(row, columns) >= 2:
            return k
    return None


def _chosen_header(shown, sheet, records, left, header_row, columns, need_header) -> int:
    """The index of the header row in ``records``: the row ``header_row`` (1-based, as the
    sheet shows it) where given, else the first that names known columns, else the first
    filled row (or, with ``need_header``, :class:`._table.NoTable`). ``left``: the 0-based
    column of the records' first cell, for messages."""
    found = _find_header(records, columns)
    if header_row is None:
        if found is None:
            if need_header:
                raise NoTable(
                    shown, "no row names two of pamid's columns (pressure, force, "
                           "contraction, length, ...), so the sheet holds no table pamid "
                           "can read", sheet=sheet)
            return 0
        return found
    hint = (f"; row {records[found][0]} names pamid's columns (--header-row "
            f"{records[found][0]}, or leave --header-row out to find it)"
            if found is not None else "")
    at = [k for k, (line, _) in enumerate(records) if line == header_row]
    if not at:
        where = ("below the last filled row " + str(records[-1][0])
                 if header_row > records[-1][0] else "empty")
        raise BenchDataError(
            shown, f"--header-row {header_row} (header_row={header_row}): row {header_row} "
                   f"of the sheet is {where}; the header must be a row of column names"
                   + hint, sheet=sheet)
    k = at[0]
    row = records[k][1]
    numbers = [j for j, cell in enumerate(row) if isinstance(cell, (float, int, *_DATES))]
    if numbers:
        j = numbers[0]
        raise BenchDataError(
            shown, f"--header-row {header_row} (header_row={header_row}): row {header_row} "
                   f"holds numbers (cell {column_letter(left + j)}{header_row} is "
                   f"{_text(row[j])}), not column names" + hint, sheet=sheet)
    if _names_known(row, columns) == 0 and found is not None and found != k:
        cells = ", ".join(repr(_text(c)) for c in row if _filled([c]))
        raise BenchDataError(
            shown, f"--header-row {header_row} (header_row={header_row}): row {header_row} "
                   f"({cells}) names none of pamid's columns" + hint, sheet=sheet)
    return k


def _values_above(shown, sheet, above, left, names, columns, n) -> tuple[dict, dict]:
    """Columns from per-muscle values written above the header, for the headers of the
    mapping ``columns`` that the header row does not have: a cell holding such a label
    (``resting length``; a trailing colon is ignored) and the value in the next filled cell
    to its right. Each becomes a column of that value on every data row; returns the
    columns and the cell each value came from."""
    out, cells = {}, {}
    for label in columns or {}:
        if label in names:
            continue
        found = [(line, j) for line, row in above for j, cell in enumerate(row)
                 if isinstance(cell, str) and cell.strip().removesuffix(":").strip() == label]
        if not found:
            continue  # the loader says the mapping names a column the file does not have
        if len(found) > 1:
            where = " and ".join(f"{column_letter(left + j)}{line}" for line, j in found[:2])
            raise BenchDataError(
                shown, f"the label '{label}' of the column mapping is written twice above "
                       f"the header (cells {where}); which value is meant?", sheet=sheet,
                column=label)
        line, j = found[0]
        row = dict(above)[line]
        right = [i for i in range(j + 1, len(row)) if _filled([row[i]])]
        if not right:
            raise BenchDataError(
                shown, f"the label '{label}' (cell {column_letter(left + j)}{line}) has no "
                       "value in a cell to its right", sheet=sheet, column=label)
        i = right[0]
        cell, where = row[i], f"{column_letter(left + i)}{line}"
        if isinstance(cell, _DATES) or isinstance(cell, bool):
            raise BenchDataError(
                shown, f"the value of '{label}' (cell {where}) is {_text(cell)}, not a number",
                sheet=sheet, column=label)
        out[label] = _column(label, [cell] * n, ".")
        cells[label] = where
    return out, cells


def read_spreadsheet(path: Path, shown: str, *, sheet: str | None = None,
                     header_row: int | None = None, decimal: str = ".",
                     data: bytes | None = None, columns: dict[str, str] | None = None,
                     need_header: bool = False) -> _Table:
    """Read one sheet of a spreadsheet as a table (the first sheet unless ``sheet`` names one).

    The header is row ``header_row`` (1-based, as the sheet shows it) where given, else the
    first row that names known columns (:func:`._names.known_name`; the headers of the
    mapping ``columns`` count), else the first filled row; rows above it are notes, except
    the labels ``columns`` maps (:func:`_values_above`). ``decimal`` is the decimal mark of
    numbers written as text cells; ``data`` the file's bytes where a stream (a pipe) was read
    already; ``need_header``: raise :class:`._table.NoTable` rather than take the first row."""
    workbook, sheets = _open(path, shown, data)
    if sheet is None:
        sheet = sheets[0]
    elif sheet not in sheets:
        raise BenchDataError(
            shown, f"no sheet named '{sheet}'; the sheets are "
                   + ", ".join(f"'{name}'" for name in sheets)
        )
    try:
        ws = workbook.get_sheet_by_name(sheet)
        rows = ws.to_python(skip_empty_area=True)
        top, left = ws.start or (0, 0)
    except Exception as exc:
        raise BenchDataError(shown, f"cannot read the sheet's cells ({exc})", sheet=sheet
                             ) from exc

    records = [(top + k + 1, row) for k, row in enumerate(rows) if _filled(row)]
    if not records:
        if need_header:
            raise NoTable(shown, "the sheet is empty", sheet=sheet)
        raise BenchDataError(shown, "the sheet is empty; expected a table with a header",
                             sheet=sheet)
    k = _chosen_header(shown, sheet, records, left, header_row, columns, need_header)
    above = records[:k]
    header_row, header = records[k]
    names = [_text(cell) for cell in header]
    records = records[k + 1:]
    width = len(names)
    while width and not names[width - 1] and not any(
        _filled([row[width - 1]]) for _, row in records
    ):
        width -= 1  # empty columns right of the table
    first = 0
    while first < width and not names[first] and not any(
        _filled([row[first]]) for _, row in records
    ):
        first += 1  # empty columns left of the table (notes above it reach further left)
    names = names[first:width]
    left += first
    records = [(line, row[first:width]) for line, row in records]
    for j, name in enumerate(names):
        if not name:
            raise BenchDataError(
                shown, f"the header has no name in cell {column_letter(left + j)}{header_row}",
                sheet=sheet,
            )
    extra, fixed = _values_above(shown, sheet, above, left, names, columns, len(records))
    _check_duplicates(shown, names + list(extra))
    table_columns = {
        name: _column(name, [row[j] for _, row in records], decimal)
        for j, name in enumerate(names)
    }
    letters = {name: column_letter(left + j) for j, name in enumerate(names)}
    lines = [number for number, _ in records]
    return _Table(shown, names + list(extra), {**table_columns, **extra}, len(records), lines,
                  is_csv=False, sheet=sheet, letters=letters, fixed_cells=fixed)


def spreadsheet_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The header of the first sheet as text (``data``: a stream's bytes): the first of its
    first :data:`HEADER_SEARCH_ROWS` filled rows that names known columns, else its first
    filled row; the rows below are not turned into Python objects."""
    from python_calamine import CalamineWorkbook

    workbook = (CalamineWorkbook.from_path(str(path)) if data is None
                else CalamineWorkbook.from_filelike(io.BytesIO(data)))
    first, seen = None, 0
    for row in workbook.get_sheet_by_index(0).iter_rows():
        if not _filled(row):
            continue
        first = row if first is None else first
        if _names_known(row, None) >= 2:
            return [_text(cell) for cell in row]
        seen += 1
        if seen >= HEADER_SEARCH_ROWS:
            break
    return [_text(cell) for cell in first] if first is not None else []
