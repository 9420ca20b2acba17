"""The public model protocol: a force law as a small pytree of its constants.

A user's force model is an ``equinox.Module`` subclass of :class:`ForceModel` whose fields
are the constants to fit (their defaults are the start values), with three class-level
attributes and a call::

    class Quadratic(pamid.ForceModel):
        c0: float = 0.0
        c1: float = 1.0
        units = {"c0": "N", "c1": "N/kPa"}
        inputs = ("pressure_kPa",)

        def __call__(self, pressure_kPa):
            return self.c0 + self.c1 * pressure_kPa

``inputs`` names bench columns, in call order, with their unit after the last underscore
(``pressure_kPa``, ``pressure_bar``, ``contraction_pct``, ``contraction_ratio``,
``contraction_mm``, ``velocity_mm_s``, ``temperature_C``, ``time_s``, ``l0_mm`` or any
numeric column of the file); pamid converts the file's columns to the units asked for
(:data:`INPUT_CONVERSIONS`). ``__call__`` returns the force in N and must be a pure JAX
function of the constants (it is fitted under ``jit``, ``vmap`` and ``grad``).

Optional class attributes:

* ``bounds``: physical bounds of constants, ``{"alpha0_deg": (0.0, 90.0)}``; a fit never
  reports a constant outside them, and one that lands on a bound is marked as such.
* ``prior``: for ``--method mcmc``, ``{name: (low, high)}`` uniform priors (the bounds are
  used where no prior is given; a constant with neither gets a wide uniform prior built from
  its start and the least-squares fit).
* ``start``: a classmethod ``start(cls, inputs, force_N, weight) -> (muscles, constants)``
  for a batch (leading muscle axis; ``weight`` is 0 on padding). Without it pamid starts
  from the defaults, solves the constants the model is linear in exactly for each of a set of
  trial values of the others (variable projection), and keeps the best
  (:func:`pamid._fit._spec.spec_from_model`).
* ``name`` (the model's name in outputs; default: the class name in lower case) and
  ``source`` (the equation fitted, e.g. ``"Tondu–Lopez 2000, eq. 3"``; default: the first
  line of the class docstring).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx


class ForceModel(eqx.Module):
    """Base class of a static force law ``F = model(*inputs)`` in N; see the module text."""

    units: ClassVar[dict[str, str]] = {}
    inputs: ClassVar[tuple[str, ...]] = ()
    bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    prior: ClassVar[dict[str, tuple[float, float]]] = {}
    name: ClassVar[str | None] = None
    source: ClassVar[str | None] = None

    def __call__(self, *inputs):
        raise NotImplementedError(
            f"{type(self).__name__} must define __call__({', '.join(self.inputs)}) "
            "returning the force in N"
        )


#: Model input names pamid can make from a bench frame's canonical columns:
#: name -> (frame column, multiplier, divisor): input = column · multiplier / divisor (a
#: division where the factor is a reciprocal, so that bar from kPa is exactly kPa / 100).
#: Any other input must be a numeric column of the file under exactly that name.
INPUT_CONVERSIONS: dict[str, tuple[str, float, float]] = {
    "pressure_kPa": ("pressure_kPa", 1.0, 1.0),
    "pressure_bar": ("pressure_kPa", 1.0, 100.0),
    "pressure_MPa": ("pressure_kPa", 1.0, 1000.0),
    "pressure_Pa": ("pressure_kPa", 1000.0, 1.0),
    "contraction_pct": ("contraction_pct", 1.0, 1.0),
    "contraction_ratio": ("contraction_pct", 1.0, 100.0),
    "contraction_mm": ("contraction_mm", 1.0, 1.0),
    "contraction_m": ("contraction_mm", 1.0, 1000.0),
    "velocity_mm_s": ("velocity_mm_s", 1.0, 1.0),
    "velocity_m_s": ("velocity_mm_s", 1.0, 1000.0),
    "length_mm": ("length_mm", 1.0, 1.0),
    "length_m": ("length_mm", 1.0, 1000.0),
    "l0_mm": ("l0_mm", 1.0, 1.0),
    "l0_m": ("l0_mm", 1.0, 1000.0),
}
