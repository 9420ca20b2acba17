"""Per-muscle descriptors: what is known of a muscle before it is tested.

A descriptor is one number per muscle: its resting length ``l0_mm``, its ``diameter_mm``,
or any numeric column of the bench file that holds one value per muscle. One is derived:
``emax_pct``, the maximal contraction at the top pressure, 100·(l0 − l620)/l0, from an
``l620_mm`` column (the muscle's length at 620 kPa with no load, as the AARL file logs it).

A pooled model uses a descriptor d through g_d = ln(d/d_ref), d_ref the geometric mean over
the fitted muscles (the length study, :mod:`pamid._diagnose._length`, found ln l0 the better
of the two forms it tried on the AARL file). A descriptor that takes one value on every
muscle of the file (the AARL file's diameter) cannot show an effect: it is left out of the
fit with a note, and a prediction for another value of it is refused.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from .._data._bench import BenchData
from .._errors import BenchDataError

#: The derived descriptor: the maximal contraction at the top pressure, in %.
EMAX = "emax_pct"
#: Per-muscle columns read wherever the file has them: the diameter (a prediction for another
#: diameter than the one every tested muscle had is refused) and l620_mm (for ε_max).
KNOWN = ("diameter_mm", "l620_mm")


@dataclasses.dataclass(frozen=True)
class Descriptors:
    """The descriptors of a file's muscles.

    Attributes:
        muscles: the muscles, in the file's order.
        values: {name: (M,) values}, every descriptor asked for and ``l0_mm``, and
            ``emax_pct`` where the file gives ``l620_mm``.
        used: the descriptors a smooth constant depends on (those asked for that vary).
        constant: {name: value} of those asked for, and of ``diameter_mm`` or ``l620_mm``
            where the file has them, that take one value on every muscle.
        ref: {name: d_ref} of the used ones (geometric mean).
        described: the descriptors asked for (and l0_mm).
    """

    muscles: tuple[str, ...]
    values: dict[str, np.ndarray]
    used: tuple[str, ...]
    constant: dict[str, float]
    ref: dict[str, float]
    described: tuple[str, ...] = ("l0_mm",)

    def features(self, values: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """g_d = ln(d/d_ref) of the used descriptors, (M, D), for the file's muscles or for
        the ``values`` given (each (K,))."""
        values = self.values if values is None else values
        if not self.used:
            n = len(next(iter(values.values()))) if values else len(self.muscles)
            return np.zeros((n, 0))
        return np.stack([np.log(np.asarray(values[d], dtype=np.float64) / self.ref[d])
                         for d in self.used], axis=1)

    @property
    def notes(self) -> tuple[str, ...]:
        return tuple(f"{name} is {value:g} on every muscle of the file: its effect cannot be "
                     "fitted and is left out" for name, value in self.constant.items()
                     if name in self.described)


def muscle_descriptors(bench: BenchData, describe: tuple[str, ...] = ("l0_mm",)) -> Descriptors:
    """The descriptors ``describe`` of every muscle of ``bench`` (module text).

    Raises:
        BenchDataError: a muscle without l0, a descriptor that is not a numeric column, that
            differs within a muscle (naming the row), or is not positive.
    """
    frame = bench.frame
    muscles = tuple(bench.muscles)
    names = tuple(dict.fromkeys(("l0_mm", *describe)))
    values: dict[str, np.ndarray] = {}
    l0 = np.array([np.nan if bench.l0_mm.get(mu) is None else float(bench.l0_mm[mu])
                   for mu in muscles])
    if np.isnan(l0).any():
        bad = muscles[int(np.flatnonzero(np.isnan(l0))[0])]
        raise BenchDataError(bench.path, f"muscle '{bad}' has no resting length: a pooled fit "
                             "needs each muscle's l0 (an l0_mm column)", column="l0_mm")
    values["l0_mm"] = l0
    columns = [n for n in names if n not in ("l0_mm", EMAX)]
    for known in KNOWN:  # kept where the file has them, described or not
        if known in frame.columns and known not in columns:
            columns.append(known)
    for name in columns:
        values[name] = _per_muscle(bench, name)
    if "l620_mm" in values:
        values[EMAX] = 100.0 * (l0 - values["l620_mm"]) / l0
    elif EMAX in names:
        raise BenchDataError(bench.path, "emax_pct (the maximal contraction at the top "
                             "pressure) is derived from an l620_mm column, which the file "
                             "lacks", column="l620_mm")
    for name in names:
        if np.any(values[name] <= 0):
            bad = muscles[int(np.flatnonzero(values[name] <= 0)[0])]
            raise BenchDataError(bench.path, f"descriptor {name} must be positive (a pooled "
                                 f"model uses ln({name})); muscle '{bad}' has "
                                 f"{values[name][muscles.index(bad)]:g}", column=name)
    used, constant, fixed = [], {}, {}
    for name in values:
        varies = np.ptp(values[name]) > 1e-9 * np.max(np.abs(values[name]))
        if name in names and varies:
            used.append(name)
        elif name in names:
            constant[name] = float(values[name][0])
        elif not varies and name in KNOWN:
            fixed[name] = float(values[name][0])
    ref = {d: float(np.exp(np.mean(np.log(values[d])))) for d in used}
    return Descriptors(muscles=muscles, values=values, used=tuple(used),
                       constant=constant | fixed, ref=ref, described=names)


def _per_muscle(bench: BenchData, name: str) -> np.ndarray:
    frame = bench.frame
    if name not in frame.columns:
        raise BenchDataError(bench.path, f"--describe names {name}, which is not a column of "
                             "the file (a descriptor is a numeric column with one value per "
                             "muscle, or l0_mm, or emax_pct)", column=name)
    col = pd.to_numeric(frame[name], errors="coerce")
    if col.isna().any():
        i = int(np.flatnonzero(col.isna().to_numpy())[0])
        raise BenchDataError(bench.path, f"descriptor {name} must be a number on every row",
                             column=name, row=_row(frame, i))
    out = []
    for mu in bench.muscles:
        sel = (frame["muscle"] == mu).to_numpy()
        v = col.to_numpy(np.float64)[sel]
        if np.ptp(v) > 1e-9 * max(1.0, float(np.max(np.abs(v)))):
            i = int(np.flatnonzero(sel)[int(np.flatnonzero(v != v[0])[0])])
            raise BenchDataError(bench.path, f"descriptor {name} must hold one value per "
                                 f"muscle; muscle '{mu}' has {v[0]:g} and {col.iloc[i]:g}",
                                 column=name, row=_row(frame, i))
        out.append(float(v[0]))
    return np.asarray(out)


def _row(frame: pd.DataFrame, i: int) -> int | None:
    if "source_row" in frame.columns:
        return int(frame["source_row"].iloc[i])
    return i + 1
