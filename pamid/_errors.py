"""Errors that pamid raises for bad input: each names the file, the column and the row."""

from __future__ import annotations


class BenchDataError(ValueError):
    """Bad bench data. The message names the file, and where it applies the column and row.

    Attributes ``path``, ``column`` and ``row`` (1-based data row, the header not counted)
    carry the same facts for programs; any of them may be None where it does not apply.
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
    ):
        self.path, self.column, self.row, self.line = path, column, row, line
        where = [str(path) if path is not None else "<data>"]
        if column is not None:
            where.append(f"column '{column}'")
        if row is not None:
            where.append(f"row {row}" + (f" (line {line})" if line is not None else ""))
        super().__init__(": ".join([", ".join(where), message]))
