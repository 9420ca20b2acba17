"""The normalized force law of the Festo fluidic muscle across resting lengths (Hunt lab).

Bolen, Elzein, Pang and Hunt, "Isometric Force Characterization of Braided Pneumatic
Actuators", *Actuators* 2026, fit one law to 10 mm (and 20 mm) Festo muscles of many
resting lengths: the contraction is taken relative to each muscle's maximal contraction at
620 kPa, and the force relative to that muscle's force at rest length and 620 kPa, which
grows with the resting length as an arctangent. The paper's own text could not be found
with the project's search tools (2026-11-27); the equations below are those of the same
lab's public MATLAB code, which the issue's summary of the paper matches:

    ε_rel = ε/ε_max,   P_n = P/620 kPa                                           (1)
    F_n   = a0·(exp(−a1·ε_rel) − 1) + P_n·exp(−a3·ε_rel²)                       (2)
    F620(l0) = a·atan(b·(l0 − c))                                               (3)
    F     = F620(l0)·F_n

(1)–(2): ``f_festo.m``, (3): ``maxBPAforce.m``, both in github.com/Agile-and-Adaptive-
Robotics/Bipedal_Robot, Code/Matlab/Functions (``maxBPAforce.m`` writes (3) at a pressure
P as P·a1′·atan(a2′·(l0 − c)·P) with l0 in m; at P = 620 kPa that is (3) with
a = 620 kPa·a1′ and b = 620 kPa·a2′). ε_max is the muscle's contraction at 620 kPa with no
load, (l0 − l620)/l0: a per-muscle descriptor (the AARL file's ``l620_mm``), not a fitted
constant. F_n(0, 1) = 1: the law passes through F620 at rest length and 620 kPa, and
F_n(1, 1) = a0·(e^−a1 − 1) + e^−a3 ≈ 0: no force at the maximal contraction.

The coefficients in :data:`HUNT_LAB_CODE_10MM` are those of that code for 10 mm muscles,
**not checked against the published paper** (the issue warns that earlier Hunt-lab
coefficient sets had typos, and ``f_festo.m`` itself exists in two versions with different
10 mm coefficients: a0, a1, a3 = 0.5682, 4.254, 0.5597 and 0.5822, 4.142, 0.5368; the
first is the one also in ``festo_lookup_coeffs.json`` there). pamid fits the six constants
to the data (:class:`Bolen2026`); the code's set is kept as a reference predictor only.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from ._protocol import ForceModel

#: The pressure the law is normalized to (kPa): Festo's 6 bar rating, 620 kPa in the lab.
P_TOP_KPA = 620.0

#: The 10 mm coefficients of the Hunt lab's public code (module text; not checked against
#: the paper): eq. (3) with a = 620·0.4895 N = 303.5 N, b = 620·0.03068 /m = 19.02 /m,
#: c = 0.0075 m, and eq. (2) with a0, a1, a3 of ``f_festo.m``.
HUNT_LAB_CODE_10MM = {
    "a_N": 620.0 * 0.4895,
    "b_per_m": 620.0 * 0.03068,
    "c_mm": 7.5,
    "a0": 0.5682,
    "a1": 4.254,
    "a3": 0.5597,
}


def f620_N(l0_mm, a_N, b_per_m, c_mm):
    """The force at rest length and 620 kPa, F620 = a·atan(b·(l0 − c)) (eq. 3 of the module
    text), in N; b in 1/m, l0 and c in mm."""
    return a_N * jnp.arctan(b_per_m * (l0_mm - c_mm) / 1000.0)


def normalized_force(contraction_rel, pressure_n, a0, a1, a3):
    """F/F620 = a0·(exp(−a1·ε_rel) − 1) + P_n·exp(−a3·ε_rel²) (eq. 2 of the module text)."""
    return a0 * (jnp.exp(-a1 * contraction_rel) - 1.0) + pressure_n * jnp.exp(
        -a3 * contraction_rel**2)


class Bolen2026(ForceModel):
    """Bolen et al. 2026 (Hunt lab): F = F620(l0)·F_n(ε/ε_max, P/620 kPa).

    One set of six constants for muscles of every resting length: F620(l0) =
    a·atan(b·(l0 − c)) (eq. 3 of :mod:`pamid._models._bolen`) and the normalized law
    F_n = a0·(exp(−a1·ε_rel) − 1) + P_n·exp(−a3·ε_rel²) (eq. 2), with ε_rel = ε/ε_max and
    ε_max the muscle's contraction at 620 kPa (input ``emax_ratio``, a ratio). The start
    values are the Hunt lab code's 10 mm coefficients (:data:`HUNT_LAB_CODE_10MM`). c is a
    static field (7.5 mm), as in that code, which fits a and b only: with lengths of
    83–382 mm a, b and c trade off (a fit of all three stopped at the solver's step limit
    with c = −186 mm on the AARL file).

    Inputs: pressure in kPa, contraction ratio, resting length l0 in mm, ε_max (ratio).
    """

    a_N: float = HUNT_LAB_CODE_10MM["a_N"]
    b_per_m: float = HUNT_LAB_CODE_10MM["b_per_m"]
    a0: float = HUNT_LAB_CODE_10MM["a0"]
    a1: float = HUNT_LAB_CODE_10MM["a1"]
    a3: float = HUNT_LAB_CODE_10MM["a3"]
    c_mm: float = eqx.field(static=True, default=HUNT_LAB_CODE_10MM["c_mm"])

    units: ClassVar[dict[str, str]] = {"a_N": "N", "b_per_m": "1/m", "c_mm": "mm",
                                       "a0": "1", "a1": "1", "a3": "1"}
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_ratio", "l0_mm",
                                         "emax_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "a_N": (1.0, 1e5),
        "b_per_m": (1e-3, 1e4),
        "a0": (0.0, 10.0),
        "a1": (0.0, 100.0),
        "a3": (0.0, 100.0),
    }
    name: ClassVar[str] = "bolen2026"
    source: ClassVar[str] = "Bolen et al. 2026 normalized law, F620 = a·atan(b·(l0 − c))"

    @classmethod
    def start(cls, inputs, force_N, weight):
        """The lab code's coefficients with the scale a solved exactly (the law is linear
        in a)."""
        p, e, l0, emax = (jnp.asarray(v, dtype=jnp.float64) for v in inputs)
        c = HUNT_LAB_CODE_10MM
        shape = (jnp.arctan(c["b_per_m"] * (l0 - c["c_mm"]) / 1000.0)
                 * normalized_force(e / emax, p / P_TOP_KPA, c["a0"], c["a1"], c["a3"]))
        y, w = jnp.asarray(force_N), jnp.asarray(weight)
        a = jnp.sum(w * shape * y, axis=-1) / jnp.maximum(jnp.sum(w * shape**2, axis=-1),
                                                           1e-300)
        rest = jnp.asarray([c["b_per_m"], c["a0"], c["a1"], c["a3"]])
        return jnp.concatenate([a[:, None], jnp.broadcast_to(rest, (a.shape[0], 4))],
                               axis=-1)

    def __call__(self, pressure_kPa, contraction_ratio, l0_mm, emax_ratio):
        fn = normalized_force(contraction_ratio / emax_ratio, pressure_kPa / P_TOP_KPA,
                              self.a0, self.a1, self.a3)
        return f620_N(l0_mm, self.a_N, self.b_per_m, self.c_mm) * fn
