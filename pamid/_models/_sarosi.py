"""Sárosi's six-constant static force model of a pneumatic artificial muscle.

Source: J. Sárosi, dissertation summary "Modelling the Static and Dynamic Operation of
Pneumatic Artificial Muscles and Their Accurate Positioning", eq. 2.1 and eq. 2.7–2.9,
Table 3-1.

Units, as in the source: pressure ``p`` in bar (gauge), contraction ``κ`` in percent of the
nominal length ``l0``, force in N. The constants therefore carry units
``a1`` [N/bar], ``a2`` [N], ``a3`` [1/%], ``a4`` [N/(bar·%)], ``a5`` [N/bar], ``a6`` [N].
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._protocol import ForceModel

PARAM_NAMES: tuple[str, ...] = ("a1", "a2", "a3", "a4", "a5", "a6")
PARAM_UNITS: dict[str, str] = {
    "a1": "N/bar",
    "a2": "N",
    "a3": "1/%",
    "a4": "N/(bar*%)",
    "a5": "N/bar",
    "a6": "N",
}


class Sarosi(ForceModel):
    """Sárosi eq. 2.1: F = (a1·p + a2)·exp(a3·κ) + a4·κ·p + a5·p + a6 (p in bar, κ in %).

    A small pytree: every field may carry leading batch dimensions (one set per muscle),
    and every function below works on it under ``jit``, ``vmap`` and ``grad``. Fitted by its
    registered written-out kernels (``pamid._solvers._sarosi``), with its own start.
    """

    a1: Float[Array, "..."]
    a2: Float[Array, "..."]
    a3: Float[Array, "..."]
    a4: Float[Array, "..."]
    a5: Float[Array, "..."]
    a6: Float[Array, "..."]

    names: ClassVar[tuple[str, ...]] = PARAM_NAMES
    units: ClassVar[dict[str, str]] = PARAM_UNITS
    inputs: ClassVar[tuple[str, ...]] = ("pressure_bar", "contraction_pct")
    name: ClassVar[str] = "sarosi"
    source: ClassVar[str] = "Sárosi eq. 2.1"
    #: a3 < 0: the force falls with contraction (Table 3-1: a3 = −0.329 /%, 95% CI −0.335 …
    #: −0.322; a DMSP-10: −0.342 /%); a3 = −3 /% is a fall of e⁻³ within 1 % of contraction,
    #: finer than any bench's contraction steps resolve.
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"a3": (-3.0, 0.0)}

    def __init__(self, a1, a2, a3, a4, a5, a6):
        self.a1, self.a2, self.a3 = jnp.asarray(a1), jnp.asarray(a2), jnp.asarray(a3)
        self.a4, self.a5, self.a6 = jnp.asarray(a4), jnp.asarray(a5), jnp.asarray(a6)

    @classmethod
    def from_vector(cls, theta: Float[ArrayLike, "... 6"]) -> Sarosi:
        """Build from a vector ordered (a1, …, a6) in its last axis."""
        theta = jnp.asarray(theta)
        return cls(*(theta[..., i] for i in range(6)))

    def to_vector(self) -> Float[Array, "... 6"]:
        """The constants as a vector (a1, …, a6) in the last axis."""
        return jnp.stack([self.a1, self.a2, self.a3, self.a4, self.a5, self.a6], axis=-1)

    def __call__(self, pressure_bar: ArrayLike, contraction_pct: ArrayLike):
        """The force in N, eq. 2.1 (:func:`sarosi_force`)."""
        return sarosi_force(self, pressure_bar, contraction_pct)


def sarosi_force(
    params: Sarosi, pressure_bar: ArrayLike, contraction_pct: ArrayLike
) -> Float[Array, "..."]:
    """Static muscle force in N, Sárosi eq. 2.1.

    F(p, κ) = (a1·p + a2)·exp(a3·κ) + a4·κ·p + a5·p + a6, with p in bar and κ in %.
    """
    p = jnp.asarray(pressure_bar)
    k = jnp.asarray(contraction_pct)
    return (
        (params.a1 * p + params.a2) * jnp.exp(params.a3 * k)
        + params.a4 * k * p
        + params.a5 * p
        + params.a6
    )


def sarosi_force_slope(
    params: Sarosi, pressure_bar: ArrayLike, contraction_pct: ArrayLike
) -> Float[Array, "..."]:
    """dF/dκ in N per % of contraction at constant pressure, closed form, Sárosi eq. 2.8.

    dF/dκ = (a1·p + a2)·a3·exp(a3·κ) + a4·p.
    """
    p = jnp.asarray(pressure_bar)
    k = jnp.asarray(contraction_pct)
    return (params.a1 * p + params.a2) * params.a3 * jnp.exp(params.a3 * k) + params.a4 * p


def sarosi_stiffness_eq_2_9(
    params: Sarosi, pressure_bar: ArrayLike, contraction_pct: ArrayLike, l0_m: ArrayLike
) -> Float[Array, "..."]:
    """Stiffness in N/m by the closed form of Sárosi eq. 2.9, with κ in %.

    Eq. 2.7 defines k = dF/dl = (1/l0)·dF/dκ for κ as a fraction of l0. With κ in percent
    (how eq. 2.1 and Table 3-1 are stated) a factor of 100 appears: κ[%] = 100·(l0 − l)/l0.
    Eq. 2.7 also differentiates with respect to contraction, which grows as the length
    shrinks; the spring stiffness (force gained per metre of elongation) is its negative,
    and is positive for a real muscle. This function returns that physical stiffness:

        k(κ) = −(100 / l0) · [(a1·p + a2)·a3·exp(a3·κ) + a4·p]      (eq. 2.9, κ in %)
    """
    return -100.0 / jnp.asarray(l0_m) * sarosi_force_slope(params, pressure_bar, contraction_pct)


def sarosi_stiffness(
    params: Sarosi, pressure_bar: ArrayLike, contraction_pct: ArrayLike, l0_m: ArrayLike
) -> Float[Array, "..."]:
    """Stiffness in N/m, k = dF/dl, by automatic differentiation of eq. 2.1 (Sárosi eq. 2.7).

    The derivative is taken by JAX (forward mode), not from the closed form; the tests check
    it against :func:`sarosi_stiffness_eq_2_9`.

    Equal to :func:`sarosi_stiffness_eq_2_9`; see there for the units and the sign.
    Broadcasts over its arguments.
    """
    p = jnp.asarray(pressure_bar, float)
    k = jnp.asarray(contraction_pct, float)
    # Forward mode (one tangent on κ) differentiates elementwise and broadcasts over the
    # inputs and over constants with leading batch axes alike.
    _, slope = jax.jvp(lambda kk: sarosi_force(params, p, kk), (k,), (jnp.ones_like(k),))
    return -100.0 / jnp.asarray(l0_m) * slope


def sarosi_pressure_for_force(
    params: Sarosi, force_N: ArrayLike, contraction_pct: ArrayLike
) -> Float[Array, "..."]:
    """Inverse of eq. 2.1: the gauge pressure in bar that gives ``force_N`` at ``contraction_pct``.

    Eq. 2.1 is linear in p: F = p·(a1·e + a4·κ + a5) + (a2·e + a6) with e = exp(a3·κ), so
    p = (F − a2·e − a6) / (a1·e + a4·κ + a5). The result can be negative (force not reachable
    with positive pressure) or infinite where the muscle's force no longer depends on
    pressure; callers that drive a valve should clip it to their supply range.
    """
    f = jnp.asarray(force_N)
    k = jnp.asarray(contraction_pct)
    e = jnp.exp(params.a3 * k)
    return (f - params.a2 * e - params.a6) / (params.a1 * e + params.a4 * k + params.a5)


# Sárosi Table 3-1: DMSP-20-400N-RM-RM (20 mm inner diameter, l0 = 400 mm), fitted with
# MS Excel Solver; 95% confidence intervals from the Excel Data Analysis add-in.
TABLE_3_1: dict[str, dict[str, float | tuple[float, float]]] = {
    "a1": {"value": -4.35572689, "ci95": (-5.775448554, -2.936005225)},
    "a2": {"value": 281.2237983, "ci95": (278.065759, 284.3818376)},
    "a3": {"value": -0.32866293, "ci95": (-0.335236188, -0.322089671)},
    "a4": {"value": -9.27034945, "ci95": (-9.348917301, -9.191781595)},
    "a5": {"value": 302.2010663, "ci95": (300.3018044, 304.1003281)},
    "a6": {"value": -263.691854, "ci95": (-268.3566557, -259.0270514)},
}
TABLE_3_1_L0_MM = 400.0  # nominal length of the DMSP-20-400N muscle of Table 3-1


def table_3_1() -> Sarosi:
    """The constants of Sárosi Table 3-1 (DMSP-20-400N, l0 = 400 mm) as a :class:`Sarosi`."""
    return Sarosi(*(TABLE_3_1[name]["value"] for name in PARAM_NAMES))


def table_3_1_fit_json() -> dict:
    """Table 3-1 in the layout of ``pamid fit --json`` (one muscle; value and 95 % interval
    of each constant), for whatever reads a fit: ``--fit`` options, comparisons."""
    params = {k: {"value": v["value"], "ci95": list(v["ci95"])} for k, v in TABLE_3_1.items()}
    return {"model": "sarosi", "muscles": [{"params": params}]}


def contraction_at_force_pct(params: Sarosi, pressure_bar, kappa_max_pct, min_force_N):
    """Contraction at which the model force falls to ``min_force_N``, capped at κ_max.

    Bisection on [0, κ_max]; the force of a real muscle falls monotonically with
    contraction at constant pressure, so the root is unique where it exists.
    """

    def f(k):
        return sarosi_force(params, pressure_bar, k) - min_force_N

    lo = jnp.zeros_like(pressure_bar)
    hi = jnp.full_like(pressure_bar, kappa_max_pct)
    reaches_end = f(hi) > 0

    def body(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        above = f(mid) > 0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    lo, hi = jax.lax.fori_loop(0, 80, body, (lo, hi))
    return jnp.where(reaches_end, kappa_max_pct, lo)
