"""Checks of a raw table (:mod:`._table`) that bench files and decay files share: units in the
column names, required columns, and time that increases within a group."""

from __future__ import annotations

import numpy as np

from ._cells import _RESERVED, QUANTITY_UNITS, _quantity_of
from ._table import _Table


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
        header = table.file_names.get(name, name)
        raise table.error(
            f"{what} for {quantity}; accepted units: {units} "
            f"(name the column {' or '.join(accepted)}, or map it with its unit, e.g. "
            f"--columns '{header}={accepted[0]}')",
            column=name,
        )


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
        found = _first_not_later(codes[kept], time[kept])
        found = None if found is None else (int(kept[found[0]]), int(kept[found[1]]))
    else:
        found = _first_not_later(codes, time)
    if found is not None:
        i, j = found
        whose = ""
        if has_group:
            whose = f" of {names[codes[i]]}" if described else f" of {group} '{names[codes[i]]}'"
        raise table.error(
            f"time_s {time_raw(i)} s is not later than {time_raw(j)} s "
            f"on row {table.row_number(j)}{whose}; time must increase strictly within a {group}",
            column="time_s",
            index=i,
        )


def _first_not_later(codes: np.ndarray, time: np.ndarray) -> tuple[int, int] | None:
    """The first row i whose time is not later than that of j, the row before it with the
    same code, as (i, j); None where time increases within every code."""
    if len(codes) < 2:
        return None
    step = np.diff(codes)
    if (step >= 0).all():  # the usual layout, each group in one block: j = i - 1
        i = _first_true((step == 0) & (time[1:] <= time[:-1]))
        return None if i is None else (i + 1, i)
    # The rows grouped by code, in file order within: each row's previous one of its code.
    order = np.argsort(codes, kind="stable")
    previous = np.full(len(codes), -1, dtype=np.int64)
    same = codes[order[1:]] == codes[order[:-1]]
    previous[order[1:][same]] = order[:-1][same]
    i = _first_true((previous >= 0) & (time <= time[np.maximum(previous, 0)]))
    return None if i is None else (i, int(previous[i]))
