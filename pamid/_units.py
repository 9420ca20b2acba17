"""Unit constants and pressure conversion to kPa, the one pressure unit used inside pamid.

Pressures in bench files are gauge pressures (relative to the atmosphere). pamid works in
kPa, mm, N and s throughout; this module holds the factors that bring other pressure units
to kPa.

The psi factor follows from the exact definitions of the pound-force and the inch:
1 lbf = 4.4482216152605 N and 1 in = 0.0254 m, so 1 psi = 4.4482216152605 N / (0.0254 m)^2
= 6894.757293168361... Pa.
"""

from __future__ import annotations

import math
from decimal import Context, Decimal

import numpy as np

#: kPa in one bar (exact).
KPA_PER_BAR = 100.0
#: kPa in one pascal (exact as a decimal; the loader divides by :data:`PA_PER_KPA` instead,
#: which rounds correctly).
KPA_PER_PA = 1e-3
#: Pascals in one kPa (exact).
PA_PER_KPA = 1000.0
#: kPa in one psi (pound-force per square inch), rounded to the nearest float64.
KPA_PER_PSI = 6.894757293168361
#: Standard atmosphere in kPa (exact by definition). A gauge pressure below
#: ``-ATMOSPHERE_KPA`` would be a negative absolute pressure.
ATMOSPHERE_KPA = 101.325

#: Units that a muscle's resting length l0 restates in another: a constant in % of l0 per
#: newton (a compliance in contraction) is also a length per newton, value·l0_mm/divisor.
#: The one place the diagnosis's reports find that conversion (:func:`per_l0`).
L0_UNITS: dict[str, tuple[str, float]] = {"%/N": ("mm/N", 100.0)}


def per_l0(unit: str, l0_mm) -> tuple[str, float] | None:
    """(other unit, factor) of a constant in ``unit`` for a muscle of resting length
    ``l0_mm``: its value times the factor is the value in the other unit; None where the
    unit has no such form or l0 is not known (0, None or NaN)."""
    if unit not in L0_UNITS or not l0_mm or not math.isfinite(l0_mm):
        return None
    other, divisor = L0_UNITS[unit]
    return other, float(l0_mm) / divisor

#: Pressure units accepted in bench-file column names (``pressure_<unit>``).
PRESSURE_UNITS: tuple[str, ...] = ("kPa", "bar", "Pa", "psi")

# Exact decimal factors, used when a pressure is still the text written in the file.
_LBF_N = Decimal("4.4482216152605")  # newtons in one pound-force (exact)
_INCH_M = Decimal("0.0254")  # metres in one inch (exact)
_EXACT_KPA_PER_UNIT: dict[str, Decimal] = {
    "kPa": Decimal(1),
    "bar": Decimal(100),
    "Pa": Decimal("0.001"),
    "psi": _LBF_N / (_INCH_M * _INCH_M) / Decimal(1000),
}
_CONTEXT = Context(prec=50)


def _check_unit(unit: str) -> None:
    if unit not in PRESSURE_UNITS:
        raise ValueError(
            f"unknown pressure unit {unit!r}; accepted units: {', '.join(PRESSURE_UNITS)}"
        )


def pressure_to_kPa(values, unit: str) -> np.ndarray:
    """Convert pressures given in ``unit`` to kPa; returns a float64 array.

    ``values`` is anything numpy turns into numbers (a scalar, a list, an array, a Series).
    ``unit`` is one of ``"kPa"``, ``"bar"``, ``"Pa"``, ``"psi"``; any other raises ValueError.
    Each result is the float64 product (or, for Pa, quotient) rounded once, so bar and Pa
    values that are exact binary fractions convert without error.
    """
    _check_unit(unit)
    arr = np.asarray(values, dtype=np.float64)
    if unit == "kPa":
        return arr.copy()
    if unit == "bar":
        return arr * KPA_PER_BAR
    if unit == "Pa":
        return arr / PA_PER_KPA
    return arr * KPA_PER_PSI


def pressure_text_to_kPa(texts, unit: str) -> np.ndarray:
    """Convert pressures written as decimal text (e.g. ``"2.505"``) in ``unit`` to kPa.

    The scaling is done in decimal arithmetic and rounded to float64 only once at the end,
    so ``"2.505"`` bar gives exactly the same float as ``"250.5"`` kPa; psi uses the exact
    definition of the psi. Returns a float64 array; raises ValueError for an unknown unit
    or a text that is not a decimal number.
    """
    _check_unit(unit)
    factor = _EXACT_KPA_PER_UNIT[unit]
    out = np.empty(len(texts), dtype=np.float64)
    for i, text in enumerate(texts):
        value = Decimal(str(text).strip())
        out[i] = float(_CONTEXT.multiply(value, factor))
    return out
