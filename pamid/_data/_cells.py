"""What a bench file's column names and cells mean.

The quantities a column name may start with and the units each accepts (``pressure_kPa``,
``force_N``, ...), the columns read as labels, and the rules for a number written as text:
which cells are numbers, which are blank ("not recorded"), and why a cell is not a number.
These rules are the same whichever reader (:mod:`._readers`) read the file; header spellings
as labs write them (``Pressure [kPa]``) are mapped to these names by :mod:`._names`.
"""

from __future__ import annotations

import math

from .._units import PRESSURE_UNITS

#: Accepted units for each quantity that bench-file column names may start with.
QUANTITY_UNITS: dict[str, tuple[str, ...]] = {
    "pressure": PRESSURE_UNITS,
    "force": ("N",),
    "length": ("mm",),
    "l0": ("mm",),
    "contraction": ("pct", "mm", "ratio"),
    "time": ("s",),
    "temperature": ("C",),
    "velocity": ("mm_s",),
}

#: Pressure column names and the unit each one carries.
PRESSURE_COLUMNS: dict[str, str] = {f"pressure_{unit}": unit for unit in PRESSURE_UNITS}

#: Decimal marks a number written as text may use.
DECIMAL_MARKS: tuple[str, ...] = (".", ",")

# Quantities whose cells must all be numbers; a blank cell of any other numeric column
# (time, temperature, direction, cycle, covariates) means "not recorded".
_STRICT_QUANTITIES = ("pressure", "force", "contraction", "length", "l0")

#: Numeric columns known by name that carry no unit: whole numbers, blank where not recorded
#: (``pressurizing`` is a 0/1 flag the loader turns into ``direction``).
FLAG_COLUMNS: tuple[str, ...] = ("direction", "cycle", "pressurizing")

# Columns read as labels (text), never as numbers.
_LABELS = ("muscle", "trial")
_RESERVED = ("source_row",)

# Swaps the decimal comma and the point: a decimal-comma cell then reads as Python reads
# numbers, and one written with a point does not read at all (it would be ambiguous).
_SWAP_MARKS = str.maketrans({",": ".", ".": ","})


def _quantity_of(name: str, quantities=None) -> str | None:
    """The known quantity a column name starts with (case-insensitive), or None.

    ``quantities`` maps quantity → accepted units (default: the bench-file table; decay
    files pass their own)."""
    quantities = QUANTITY_UNITS if quantities is None else quantities
    # One look-up, not a loop over the quantities (a file may have 40,000 columns): the
    # quantities are lower-case words without an underscore.
    head = name.lower().partition("_")[0]
    return head if head in quantities else None


def _blank_ok(name: str) -> bool:
    """Whether a blank cell of this numeric column (pamid's name) means "not recorded"."""
    return name not in _LABELS and _quantity_of(name) not in _STRICT_QUANTITIES


def _parsed_as_float(name: str) -> bool:
    """Whether the fast reader has pyarrow parse this column (pamid's name) as float64: a
    number pamid knows by name whose text is not needed (a pressure in kPa, not in bar,
    whose kPa come from the text)."""
    known = name in FLAG_COLUMNS or _quantity_of(name) is not None
    return known and name not in _LABELS and PRESSURE_COLUMNS.get(name, "kPa") == "kPa"


def _point(cells, decimal: str):
    """Cells written with ``decimal`` as Python reads numbers (a decimal comma made a point,
    and a point made a comma, so that a cell with a point does not read as a number)."""
    return cells if decimal == "." else [cell.translate(_SWAP_MARKS) for cell in cells]


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
