"""Bench-file column names as labs write them, mapped to pamid's canonical names.

pamid's own names carry the unit after an underscore (``pressure_kPa``, ``force_N``); lab
files write units in other ways. :func:`canonical_names` maps each header to its canonical
name, leaving alone any header it does not recognise (a covariate, a note):

* the unit in brackets, parentheses or after a slash: ``Pressure [kPa]``, ``force (N)``,
  ``p / bar``, ``Temperature [°C]``, ``Contraction [%]``;
* the quantity in any case (``Force_N``), or as a symbol: ``p``/``P`` pressure, ``F``
  force, ``κ``/``kappa`` contraction, ``t`` time and ``T`` temperature (case matters
  there), ``l``/``L`` length;
* unit spellings ``%`` (pct), ``°C``/``degC`` (C), ``mm/s`` (mm_s);
* ``muscle``, ``direction``, ``cycle`` in any case, and ``trial``, ``test`` or ``run``
  (any case) for the trial label, with or without a bracketed note (``direction [-]``);
* a pressurizing flag, 1 while the muscle is pressurized and 0 while it is let down:
  ``pressurizing`` (or ``pressurising``), and ``P/DP`` as labs write it (any case); the
  loader turns it into ``direction`` (+1, −1);
* any other naming through an explicit mapping, ``columns={"Druck": "pressure_bar"}``.

A unit stays case-sensitive (``pressure [kpa]`` is an error that says so, as
``pressure_kpa`` is), and a recognised quantity with a unit pamid does not know
(``Force [kN]``) becomes ``force_kN``, which the loader reports as an unknown unit, naming
the column as the file wrote it. A symbol with an underscore is mapped only when the unit is
one the quantity accepts (``T_C`` is temperature, ``t_ambient`` stays a column of its own).
"""

from __future__ import annotations

import re

#: Quantity words (matched in any case) and the quantity each names.
QUANTITY_WORDS: dict[str, str] = {
    "pressure": "pressure",
    "force": "force",
    "contraction": "contraction",
    "kappa": "contraction",
    "κ": "contraction",
    "length": "length",
    "l0": "l0",
    "time": "time",
    "temperature": "temperature",
    "velocity": "velocity",
}
#: One-letter symbols (matched exactly: ``t`` is time, ``T`` temperature).
QUANTITY_SYMBOLS: dict[str, str] = {
    "p": "pressure",
    "P": "pressure",
    "F": "force",
    "t": "time",
    "T": "temperature",
    "l": "length",
    "L": "length",
}
#: Unit spellings and pamid's name for each.
UNIT_SPELLINGS: dict[str, str] = {
    "%": "pct",
    "°C": "C",
    "ºC": "C",
    "℃": "C",
    "degC": "C",
    "deg C": "C",
    "mm/s": "mm_s",
}
#: Label and flag columns (matched in any case) and their canonical names.
IDENTIFIERS: dict[str, str] = {
    "muscle": "muscle",
    "trial": "trial",
    "test": "trial",
    "run": "trial",
    "direction": "direction",
    "cycle": "cycle",
    "pressurizing": "pressurizing",
    "pressurising": "pressurizing",
    "p/dp": "pressurizing",
}

_BRACKETED = re.compile(r"^(?P<q>.+?)\s*(?:\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))$")
_SLASHED = re.compile(r"^(?P<q>[^/]+?)\s*/\s*(?P<u>.+)$")


class NameProblem(Exception):
    """A header that cannot be mapped: ``message`` and the ``column`` as the file names it."""

    def __init__(self, message: str, column: str | None):
        super().__init__(message)
        self.message, self.column = message, column


def _quantity(word: str) -> str | None:
    return QUANTITY_SYMBOLS.get(word) or QUANTITY_WORDS.get(word.lower())


def canonical_name(header: str, units: dict[str, tuple[str, ...]]) -> str:
    """The canonical name of one (stripped) header; the header itself if not recognised.

    ``units`` maps each quantity to the units it accepts (the loader's table)."""
    ident = IDENTIFIERS.get(header.lower())
    if ident is not None:
        return ident
    match = _BRACKETED.match(header) or _SLASHED.match(header)
    if match is not None:
        ident = IDENTIFIERS.get(match["q"].strip().lower())
        if ident is not None:
            return ident  # "direction [-]", "Cycle (#)"
        quantity = _quantity(match["q"].strip())
        if quantity is not None:
            unit = next(u for u in (match.groupdict().get(k) for k in ("u1", "u2", "u")) if u
                        is not None).strip()
            return f"{quantity}_{UNIT_SPELLINGS.get(unit, unit)}" if unit else quantity
        return header
    word, sep, unit = header.partition("_")
    if word in QUANTITY_SYMBOLS and sep:
        quantity = QUANTITY_SYMBOLS[word]
        unit = UNIT_SPELLINGS.get(unit, unit)
        return f"{quantity}_{unit}" if unit in units.get(quantity, ()) else header
    quantity = QUANTITY_WORDS.get(word.lower())
    if quantity is not None:
        return f"{quantity}{sep}{UNIT_SPELLINGS.get(unit, unit)}"
    return header


def known_name(header: str, units: dict[str, tuple[str, ...]],
               columns: dict[str, str] | None = None) -> bool:
    """Whether a (stripped) header names a column pamid knows: one the mapping ``columns``
    names, an identifier (``muscle``, ``trial``, ``direction``, ...) or a quantity of
    ``units`` (``Pressure [kPa]``, ``force_N``, also with a unit pamid does not accept,
    which the loader then reports). What finds a spreadsheet's header row below notes."""
    if not header:
        return False
    if columns and header in columns:
        return True
    name = canonical_name(header, units)
    return name in IDENTIFIERS.values() or name.partition("_")[0] in units


def canonical_names(
    headers: list[str],
    units: dict[str, tuple[str, ...]],
    columns: dict[str, str] | None = None,
) -> list[str]:
    """Canonical names of a table's (stripped) headers, in order.

    ``columns`` maps headers of the file to names of the caller's choice (which are then
    read like headers: ``"pressure_bar"`` or ``"Pressure [bar]"``). Raises
    :class:`NameProblem` for a mapped header the file does not have, and for two headers
    that mean the same column."""
    columns = {str(k).strip(): v for k, v in (columns or {}).items()}
    absent = [name for name in columns if name not in headers]
    if absent:
        found = ", ".join(headers) if headers else "none"
        raise NameProblem(
            f"the column mapping names {', '.join(repr(a) for a in absent)}, which the file "
            f"does not have. Columns found: {found}",
            absent[0],
        )
    out = []
    seen: dict[str, str] = {}
    for header in headers:
        target = columns.get(header, header)
        name = canonical_name(str(target).strip(), units)
        if name in seen:
            raise NameProblem(
                f"columns '{seen[name]}' and '{header}' both give {name}; keep one of them "
                "(or rename one with the column mapping)",
                header,
            )
        seen[name] = header
        out.append(name)
    return out
