"""Reading bench tables from spreadsheets (``.xlsx``, ``.xlsm``, ``.xlsb``, ``.xls``, ``.ods``).

The reader is python-calamine: on a 100,000-row sheet it read every cell in 0.45 s against
3.7 s for openpyxl (``benchmarks/read_xlsx.py``, benchmarks/README.md). fastexcel, built on
the same Rust library, was a little faster (0.34 s) but infers a column's type from a sample
of its rows and turns a text cell in a number column into a null without a word; pamid must
see every cell as written.

The table starts at the sheet's first non-empty row (the header) and column; blank rows are
skipped, as blank lines of a CSV file are. Number cells are numbers and text cells text
(stripped). A date or time cell cannot be a number: in a numeric column it is an error
naming the cell ("write the time as seconds"), in any other column it is kept as ISO text.
Booleans read as TRUE/FALSE text. Errors name the sheet and the cell, e.g. ``sheet 'Data',
cell C17``.
"""

from __future__ import annotations

import datetime as dt
import io
from pathlib import Path

import numpy as np

from .._errors import BenchDataError
from ._streams import _read_bytes
from ._table import _check_duplicates, _Column, _Table

__all__ = ["SPREADSHEET_SUFFIXES", "column_letter", "read_spreadsheet", "spreadsheet_names"]

#: Extensions read as spreadsheets.
SPREADSHEET_SUFFIXES: tuple[str, ...] = (".xlsx", ".xlsm", ".xlsb", ".xls", ".ods")
#: The first bytes of a spreadsheet: a zip (xlsx, ods) or an OLE file (xls).
SPREADSHEET_SIGNATURES: tuple[bytes, ...] = (b"PK\x03\x04", b"\xd0\xcf\x11\xe0")

_DATES = (dt.datetime, dt.date, dt.time, dt.timedelta)


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


def read_spreadsheet(path: Path, shown: str, *, sheet: str | None = None,
                     decimal: str = ".", data: bytes | None = None) -> _Table:
    """Read one sheet of a spreadsheet as a table (the first sheet unless ``sheet`` names one).

    ``decimal`` is the decimal mark of numbers written as text cells; ``data`` the file's
    bytes where a stream (a pipe) was read already."""
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
        raise BenchDataError(shown, "the sheet is empty; expected a table with a header",
                             sheet=sheet)
    header_row, header = records[0]
    names = [_text(cell) for cell in header]
    records = records[1:]
    width = len(names)
    while width and not names[width - 1] and not any(
        _filled([row[width - 1]]) for _, row in records
    ):
        width -= 1  # empty columns right of the table
    names = names[:width]
    for j, name in enumerate(names):
        if not name:
            raise BenchDataError(
                shown, f"the header has no name in cell {column_letter(left + j)}{header_row}",
                sheet=sheet,
            )
    _check_duplicates(shown, names)
    columns = {
        name: _column(name, [row[j] for _, row in records], decimal)
        for j, name in enumerate(names)
    }
    letters = {name: column_letter(left + j) for j, name in enumerate(names)}
    lines = [number for number, _ in records]
    return _Table(shown, names, columns, len(records), lines, is_csv=False, sheet=sheet,
                  letters=letters)


def spreadsheet_names(path: Path, shown: str, data: bytes | None = None) -> list[str]:
    """The header of the first sheet (its first non-empty row) as text (``data``: a stream's
    bytes); the rows below it are not turned into Python objects."""
    from python_calamine import CalamineWorkbook

    workbook = (CalamineWorkbook.from_path(str(path)) if data is None
                else CalamineWorkbook.from_filelike(io.BytesIO(data)))
    for row in workbook.get_sheet_by_index(0).iter_rows():
        if _filled(row):
            return [_text(cell) for cell in row]
    return []
