"""What the commands share: progress lines on stderr, checks of option values that name the
option and the accepted range, reading negative numbers as values, an angle axis's unit."""

from __future__ import annotations

import argparse
import math
import sys

__all__ = ["MAX_SEED", "NonNegative", "allow_negative_numbers", "count", "finite", "plot_unit",
           "shown", "stage"]


def stage(message: str, quiet: bool) -> None:
    if not quiet:
        print(f"[pamid] {message}", file=sys.stderr, flush=True)


def shown(value) -> str:
    """An option's value as the user wrote it, with NaN spelled out."""
    if isinstance(value, float) and math.isnan(value):
        return "nan (not a number)"
    return f"{value:g}" if isinstance(value, float) else repr(value)


def finite(name: str, value: float, *, positive: bool = False, low=None, high=None,
            unit: str = "") -> float:
    """``value`` of the option ``name`` if it is a finite number in the accepted range, else
    ValueError with one line that names the option, the range and the value (NaN, ±inf,
    out of range alike). ``positive``: > 0; ``low``/``high``: inclusive bounds."""
    u = f" {unit}" if unit else ""
    if positive and high is not None:
        accepted = f"positive and at most {high:g}{u}"
    elif positive:
        accepted = f"positive (> 0{u})"
    elif low is not None and high is not None:
        accepted = f"lie in [{low:g}, {high:g}]{u}"
    elif low is not None:
        accepted = f"be at least {low:g}{u}"
    elif high is not None:
        accepted = f"be at most {high:g}{u}"
    else:
        accepted = "be a finite number"
    if not accepted.startswith(("be ", "lie ")):
        accepted = "be " + accepted
    ok = (isinstance(value, (int, float)) and math.isfinite(value)
          and not (positive and value <= 0)
          and not (low is not None and value < low) and not (high is not None and value > high))
    if not ok:
        raise ValueError(f"{name} must {accepted}, got {shown(value)}")
    return float(value)


def count(name: str, value: int, *, low: int = 0, high: int | None = None) -> int:
    """An integer option in [low, high]; ValueError naming the option and the range."""
    if value < low or high is not None and value > high:
        accepted = f"in [{low}, {high}]" if high is not None else f"≥ {low}"
        raise ValueError(f"{name} must be an integer {accepted}, got {value}")
    return value


class NonNegative(argparse.Action):
    """The ``action`` of an ``int`` option that counts (``--max-plots``): a value below
    :attr:`minimum` is argparse's one-line error, ``argument --max-plots: must be an integer
    ≥ 0, got -1`` (exit 2), as a value that is no integer is (``invalid int value: '1.5'``)."""

    minimum = 0

    def __call__(self, parser, namespace, values, option_string=None):
        if values < self.minimum:
            raise argparse.ArgumentError(
                self, f"must be an integer ≥ {self.minimum}, got {values}")
        setattr(namespace, self.dest, values)


class Positive(NonNegative):
    """The same for an ``int`` option that must be 1 or more (``--chunk-rows``)."""

    minimum = 1


#: Seeds that :func:`jax.random.key` turns into distinct keys.
MAX_SEED = 2**32 - 1


def allow_negative_numbers(parser) -> None:
    """Let ``parser`` read ``--x0-mm -1e-3``, ``--v0-mm-s -inf`` and ``--zeta -nan`` as values.

    argparse takes an argument for a value only if it looks like ``-5`` or ``-.5``; ``-1e-3``
    or ``-inf`` would be taken for an unknown option ("expected one argument"). This parser
    has no option that looks like a number, so every float literal is a value.
    """
    import re

    parser._negative_number_matcher = re.compile(
        r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE)


def plot_unit(y) -> tuple[float, str]:
    """(unit, label) for an angle axis: rad, or a power of ten of rad for angles whose
    largest magnitude lies outside 1e-6 … 1e6 rad."""
    import numpy as np

    top = float(np.max(np.abs(y))) if len(y) else 0.0
    if top == 0.0 or not np.isfinite(top) or 1e-6 <= top <= 1e6:
        return 1.0, "rad"
    k = math.floor(math.log10(top))
    return 10.0**k, f"1e{k} rad"
