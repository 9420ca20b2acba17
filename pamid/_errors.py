"""Errors that pamid raises for bad input: each names the file, the column and the row."""

from __future__ import annotations


class BenchDataError(ValueError):
    """Bad bench data. The message names the file, and where it applies the column and row.

    Attributes ``path``, ``column`` and ``row`` (1-based data row, the header not counted)
    carry the same facts for programs; any of them may be None where it does not apply.
    Spreadsheets add ``sheet`` (its name) and ``cell`` (e.g. ``"C17"``).
    The command-line interface prints the message and exits with code 2.
    """

    def __init__(
        self,
        path: str | None,
        message: str,
        *,
        column: str | None = None,
        row: int | None = None,
        line: int | None = None,
        sheet: str | None = None,
        cell: str | None = None,
    ):
        self.path, self.column, self.row, self.line = path, column, row, line
        self.sheet, self.cell = sheet, cell
        where = [str(path) if path is not None else "<data>"]
        if sheet is not None and cell is None:
            where.append(f"sheet '{sheet}'")
        if column is not None:
            where.append(f"column '{column}'")
        if row is not None:
            at = f"line {line}" if line is not None else None
            if cell is not None:
                at = f"sheet '{sheet}', cell {cell}" if sheet is not None else f"cell {cell}"
            where.append(f"row {row}" + (f" ({at})" if at else ""))
        super().__init__(": ".join([", ".join(where), message]))


class UntrustedResultError(Exception):
    """A result that could be computed but not trusted (a diagnosis of a fit whose
    constants the data do not determine, say). The message says why; the command-line
    interface prints it in one line and exits with code 1, as for a fit that did not
    converge."""
