"""Command-line options for reading a bench file, shared by ``pamid fit`` and ``pamid diagnose``.

:func:`add_reading_arguments` adds ``--l0-mm``, ``--keep-censored``, ``--sep``,
``--decimal``, ``--sheet``, ``--header-row`` and ``--columns`` to a parser;
:func:`reading_options` turns the parsed arguments into the keyword arguments of
:func:`pamid.load_bench`.
"""

from __future__ import annotations

import argparse

__all__ = ["add_reading_arguments", "parse_column_mapping", "reading_options"]


def add_reading_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options that say how to read the bench file."""
    group = parser.add_argument_group("reading the bench file")
    group.add_argument("--l0-mm", type=float, dest="l0_mm",
                       help="nominal length in mm when the file gives length_mm without l0_mm")
    group.add_argument("--keep-censored", action="store_true",
                       help="keep rows whose force is exactly 0 (dropped by default)")
    group.add_argument("--sep", metavar="CHAR",
                       help="CSV delimiter: ',' ';' or 'tab' (default: detected from the header)")
    group.add_argument("--decimal", choices=[".", ","],
                       help="decimal mark of numbers written as text (default: detected; a "
                            "comma in ';'- or tab-separated files written like 499,911)")
    group.add_argument("--sheet", metavar="NAME",
                       help="spreadsheet (.xlsx, .ods, ...) sheet to read (default: the "
                            "first); 'all': every sheet, each one muscle named by its sheet")
    group.add_argument("--header-row", metavar="N", type=_row_number, dest="header_row",
                       help="spreadsheets: the header's row, as the sheet numbers it "
                            "(default: the first row naming known columns; rows above are "
                            "notes)")
    group.add_argument("--columns", metavar="MAP", type=parse_column_mapping,
                       help="map the file's headers to pamid's names, e.g. "
                            "'Druck=pressure_bar,Kraft=force_N'; in a spreadsheet, a label "
                            "written above the header with its value to its right gives "
                            "that value to every row: 'resting length=l0_mm'")


def _row_number(text: str) -> int:
    """A spreadsheet row number: a whole number, 1 or more."""
    try:
        number = int(text)
    except ValueError:
        number = 0
    if number < 1:
        raise argparse.ArgumentTypeError(f"expected a row number, 1 or more; got {text!r}")
    return number


def parse_column_mapping(text: str) -> dict[str, str]:
    """``"Druck=pressure_bar,Kraft=force_N"`` as ``{"Druck": "pressure_bar", ...}``."""
    mapping: dict[str, str] = {}
    for item in text.split(","):
        if not item.strip():
            continue
        header, eq, name = item.partition("=")
        if not eq or not header.strip() or not name.strip():
            raise argparse.ArgumentTypeError(
                f"expected HEADER=NAME pairs separated by commas, e.g. "
                f"'Druck=pressure_bar,Kraft=force_N'; got {item.strip()!r}"
            )
        mapping[header.strip()] = name.strip()
    if not mapping:
        raise argparse.ArgumentTypeError("--columns needs at least one HEADER=NAME pair")
    return mapping


def reading_options(args: argparse.Namespace) -> dict:
    """The keyword arguments of :func:`pamid.load_bench` that the options give."""
    return {
        "l0_mm": args.l0_mm,
        "keep_censored": args.keep_censored,
        "sep": args.sep,
        "decimal": args.decimal,
        "sheet": args.sheet,
        "header_row": args.header_row,
        "columns": args.columns,
    }


def expecting(args: argparse.Namespace, then=None):
    """:func:`pamid.load_bench`'s ``on_rows`` for the command ``args`` runs: once the rows
    per muscle are known, the programs that the last run of its kind called start to be
    read back (:func:`pamid._lanes._export_cache.expect`, by the command, the model and the
    options that make other programs), then ``then(rows)`` where given."""

    def on_rows(rows_per_muscle):
        from .._lanes import _export_cache

        _export_cache.expect(args.command, rows_per_muscle, *(
            str(getattr(args, name, None)) for name in (
                "model", "folds", "solver", "intervals", "method", "laws", "max_rows")))
        if then is not None:
            then(rows_per_muscle)

    return on_rows
