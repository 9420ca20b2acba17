"""Loading free-decay recordings (CSV, Parquet or a spreadsheet), checked as thoroughly as
bench files.

A decay file holds one row per encoder sample of one or more free decays of a PAM-driven
joint (Cullinan, section VI): released from a deflection, the arm oscillates and comes to
rest. Every problem raises :class:`~pamid._errors.BenchDataError` naming the file and, where
it applies, the column, the 1-based data row and (CSV) the line.

Columns
-------
Required:
    * ``time_s``, time in s, strictly increasing within a trial;
    * the angle, as exactly one of ``angle_rad`` or ``angle_deg`` (converted to rad).
Optional:
    * ``trial``: identifier of the decay (read as text); several decays in one file are
      analysed as a batch. Without it the whole file is one trial, named ``"1"``;
    * ``pressure1_<unit>``, ``pressure2_<unit>``: the two muscles' gauge pressures, unit one
      of kPa, bar, Pa, psi (converted to kPa);
    * ``temperature_C``.
Others:
    Further numeric columns are kept as they are; text columns are kept but not used.

A column whose name starts with a known quantity (``time``, ``angle``, ``temperature``,
``pressure1``, ``pressure2``) must carry one of that quantity's units (``angle_grad`` or
``time_ms`` are errors, not ignored columns). Each trial needs at least
:data:`MIN_SAMPLES` samples; whether it holds an oscillation at all is checked when it is
analysed (:func:`pamid._decays._analysis.analyze_decays`), with the same kind of message.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .._units import ATMOSPHERE_KPA, PRESSURE_UNITS, pressure_to_kPa
from ._cells import _quantity_of as _bench_quantity_of
from ._checks import _check_missing, _check_time_increases, _first_true
from ._checks import _check_units as _bench_check_units
from ._columns import Coded
from ._readers import reader_for
from ._streams import _stream_bytes
from ._table import _as_floats, _first_problem, _Table, _text_values

__all__ = ["MIN_SAMPLES", "DecayData", "load_decay"]

#: Fewest samples a trial may have (a few per half cycle over at least a couple of cycles).
MIN_SAMPLES = 20
#: Accepted units per quantity that a column name may start with.
DECAY_QUANTITIES: dict[str, tuple[str, ...]] = {
    "time": ("s",),
    "angle": ("rad", "deg"),
    "temperature": ("C",),
    "pressure1": PRESSURE_UNITS,
    "pressure2": PRESSURE_UNITS,
}


@dataclass(frozen=True, eq=False)
class DecayData:
    """Decay recordings, checked and converted to rad, s and kPa.

    Attributes:
        frame: one row per sample: ``trial`` (str), ``time_s``, ``angle_rad``, then those of
            ``pressure1_kPa``, ``pressure2_kPa``, ``temperature_C`` that the file gives, the
            other columns as given, and ``source_row`` (1-based data row in the file).
        path: the file, as given.
        trials: trial ids in order of first appearance.
        has_trial_column: False when the file had no ``trial`` column (one trial, ``"1"``).
        angle_unit_in_file: ``"rad"`` or ``"deg"``.
        angle_column: the angle column's name in the file (for messages).
    """

    frame: pd.DataFrame
    path: str
    trials: tuple[str, ...]
    has_trial_column: bool
    angle_unit_in_file: str
    angle_column: str

    def for_trial(self, trial: str) -> pd.DataFrame:
        """The rows of one trial (fresh 0-based index). KeyError naming the known ids."""
        if trial not in self.trials:
            known = ", ".join(repr(t) for t in self.trials)
            raise KeyError(f"{self.path}: no trial {trial!r}; trials in the file: {known}")
        return self.frame[self.frame["trial"] == trial].reset_index(drop=True)

    def arrays(self, trial: str) -> tuple[np.ndarray, np.ndarray]:
        """(time_s, angle_rad) of one trial as float64 arrays."""
        rows = self.for_trial(trial)
        return rows["time_s"].to_numpy(float), rows["angle_rad"].to_numpy(float)

    def __len__(self) -> int:
        return len(self.frame)


def _quantity_of(name: str) -> str | None:
    return _bench_quantity_of(name, DECAY_QUANTITIES)


def _check_units(table: _Table) -> None:
    _bench_check_units(table, DECAY_QUANTITIES)


def _check_required(table: _Table) -> tuple[str, str]:
    """The angle column and its unit; errors for missing or ambiguous columns."""
    names = table.names
    angles = [n for n in names if n in ("angle_rad", "angle_deg")]
    if len(angles) > 1:
        raise table.error(
            "both angle_rad and angle_deg are given; the angle is ambiguous, keep exactly one",
            column=angles[1],
        )
    missing = []
    if "time_s" not in names:
        missing.append("time_s")
    if not angles:
        missing.append("angle_rad (or angle_deg)")
    _check_missing(table, missing, n_required=2, kind="decay")
    for quantity in ("pressure1", "pressure2"):
        columns = [n for n in names if _quantity_of(n) == quantity]
        if len(columns) > 1:
            raise table.error(
                f"more than one {quantity} column ({', '.join(columns)}); keep exactly one",
                column=columns[1],
            )
    return angles[0], angles[0].split("_", 1)[1]


def load_decay(path: str | os.PathLike) -> DecayData:
    """Load a decay file; see the module docstring. The reader is that of the file's format
    (:func:`pamid._data._readers.reader_for`: CSV, Parquet for ``.parquet``/``.pq``, a
    spreadsheet's first sheet for ``.xlsx``, ``.ods``, ...).

    Raises:
        BenchDataError: for any problem with the file, naming the file and, where it
            applies, the column and the 1-based data row (and the CSV line).
    """
    shown = str(path)
    p = Path(path)
    stream = _stream_bytes(p, shown)  # a pipe or /dev/stdin, read once (None for a file)
    table = reader_for(p, stream).read(p, shown, data=stream)
    _check_units(table)
    angle_col, angle_unit = _check_required(table)
    names, cols, n = table.names, table.columns, table.n_rows

    numeric = [name for name in names if _quantity_of(name) is not None]
    is_numeric = set(numeric)
    first = None
    for order, name in enumerate(names):
        if name not in is_numeric:
            continue
        problem = _first_problem(cols[name])
        if problem is not None and (first is None or problem[0] < first[0]):
            first = (problem[0], order, name, problem[1])
    if first is not None:
        raise table.error(first[3], column=first[2], index=first[0])
    values = {name: _as_floats(cols[name]) for name in numeric}

    # ---- trial ids ----
    if "trial" in cols:
        col = cols["trial"]
        ids = list(col.text) if col.text is not None else [col.raw(i) for i in range(n)]
        missing = [c == "" for c in col.text] if col.text is not None else list(col.null)
        i = _first_true(np.asarray(missing, dtype=bool))
        if i is not None:
            raise table.error("empty trial id; every row needs one", column="trial", index=i)
        has_trial = True
    else:
        ids, has_trial = ["1"] * n, False
    ids_arr = np.asarray(ids, dtype=object)

    # ---- time: strictly increasing within a trial ----
    time = values["time_s"]
    trial_codes, trial_names = pd.factorize(ids_arr)
    _check_time_increases(table, cols["time_s"].raw, time, trial_codes, trial_names, "trial",
                          has_trial)

    # ---- enough samples per trial ----
    trials = tuple(dict.fromkeys(ids))
    counts = pd.Series(ids_arr).value_counts()
    for trial in trials:
        if counts[trial] < MIN_SAMPLES:
            first_row = ids.index(trial)
            whose = f"trial '{trial}' has" if has_trial else "the file has"
            raise table.error(
                f"too few samples: {whose} {counts[trial]} samples; a decay needs at least "
                f"{MIN_SAMPLES} (several per half cycle over a few cycles)",
                column="time_s",
                index=first_row,
            )

    # ---- angle in rad ----
    angle = values[angle_col]
    angle_rad = np.deg2rad(angle) if angle_unit == "deg" else angle

    data: dict[str, object] = {"trial": ids, "time_s": time, "angle_rad": angle_rad}
    for quantity in ("pressure1", "pressure2"):
        columns = [name for name in names if _quantity_of(name) == quantity]
        if not columns:
            continue
        name = columns[0]
        unit = name.split("_", 1)[1]
        kpa = pressure_to_kPa(values[name], unit)
        i = _first_true(kpa < -ATMOSPHERE_KPA)
        if i is not None:
            raise table.error(
                f"gauge pressure {cols[name].raw(i)} {unit} ({kpa[i]:.6g} kPa) is below "
                f"-{ATMOSPHERE_KPA} kPa, which would be a negative absolute pressure; "
                "pressure columns hold gauge pressure (absolute minus atmospheric)",
                column=name,
                index=i,
            )
        data[f"{quantity}_kPa"] = kpa
    if "temperature_C" in values:
        data["temperature_C"] = values["temperature_C"]
    for name in names:
        if name in ("trial",) or _quantity_of(name) is not None:
            continue
        original = cols[name].original
        data[name] = (_text_values(original.uniques, original.codes)
                      if isinstance(original, Coded) else original)
    data["source_row"] = np.arange(1, n + 1, dtype=np.int64)
    frame = pd.DataFrame(
        {k: (v.to_numpy() if isinstance(v, pd.Series) else v) for k, v in data.items()}
    )
    return DecayData(frame, shown, trials, has_trial, angle_unit, angle_col)
