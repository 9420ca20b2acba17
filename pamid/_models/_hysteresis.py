"""Damping of a PAM from the hysteresis loop of its force–contraction curve.

Source: Sárosi, eq. 2.3–2.10. At constant pressure the force on the extending branch (upper
curve F_f) lies above the force on the contracting branch (lower curve F_a). The energy
under the upper branch is U0 (eq. 2.3), the loop area ΔU (eq. 2.4), the damping ratio
ζ = ΔU/U0 (eq. 2.5), the critical damping c_cr = 2·√(k·m) (eq. 2.6) with the stiffness k of
eq. 2.9, and the damping coefficient c = ζ·c_cr (eq. 2.10).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._sarosi import Sarosi, sarosi_stiffness


def sarosi_force_integral(
    params: Sarosi, pressure_bar: ArrayLike, kappa_min_pct: ArrayLike, kappa_max_pct: ArrayLike
) -> Float[Array, "..."]:
    """∫ F(p, κ) dκ from κ_min to κ_max in N·%, closed form of Sárosi eq. 2.3 (without l0).

    The antiderivative is [2·a1·p·e + 2·a3·a6·κ + 2·a2·e + 2·a3·a5·p·κ + a3·a4·p·κ²] / (2·a3)
    with e = exp(a3·κ). The printed eq. 2.3 has a typo: its first lower-limit bracket uses
    κ_max² in the last term; the lower limit is evaluated at κ_min throughout, as here.
    """
    p = jnp.asarray(pressure_bar)

    def antiderivative(k):
        e = jnp.exp(params.a3 * k)
        return (
            2 * params.a1 * p * e
            + 2 * params.a3 * params.a6 * k
            + 2 * params.a2 * e
            + 2 * params.a3 * params.a5 * p * k
            + params.a3 * params.a4 * p * k**2
        ) / (2 * params.a3)

    return antiderivative(jnp.asarray(kappa_max_pct)) - antiderivative(jnp.asarray(kappa_min_pct))


def hysteresis_damping(
    upper: Sarosi,
    lower: Sarosi,
    pressure_bar: ArrayLike,
    kappa_min_pct: ArrayLike,
    kappa_max_pct: ArrayLike,
    contraction_pct: ArrayLike,
    l0_m: ArrayLike,
    mass_kg: ArrayLike,
) -> dict[str, Float[Array, "..."]]:
    """Damping from a hysteresis loop, Sárosi eq. 2.3–2.10.

    ``upper`` and ``lower`` are the constants fitted to the upper (extending, F_f) and lower
    (contracting, F_a) branches; the loop is integrated over [κ_min, κ_max] at the given
    pressure. The stiffness of eq. 2.9 is taken from the upper branch at ``contraction_pct``.
    ``l0`` converts κ in % to length: U in J = l0[m]/100 · ∫F dκ[%].

    Returns U0_J (eq. 2.3), delta_U_J (eq. 2.4), zeta (eq. 2.5), stiffness_N_per_m (eq. 2.9),
    c_critical_Ns_per_m (eq. 2.6) and c_Ns_per_m (eq. 2.10).
    """
    l0 = jnp.asarray(l0_m)
    u0 = l0 / 100.0 * sarosi_force_integral(upper, pressure_bar, kappa_min_pct, kappa_max_pct)
    u_lower = l0 / 100.0 * sarosi_force_integral(lower, pressure_bar, kappa_min_pct, kappa_max_pct)
    delta_u = u0 - u_lower  # eq. 2.4
    zeta = delta_u / u0  # eq. 2.5
    k = sarosi_stiffness(upper, pressure_bar, contraction_pct, l0)  # eq. 2.7–2.9
    c_cr = 2.0 * jnp.sqrt(k * jnp.asarray(mass_kg))  # eq. 2.6
    return {
        "U0_J": u0,
        "delta_U_J": delta_u,
        "zeta": zeta,
        "stiffness_N_per_m": k,
        "c_critical_Ns_per_m": c_cr,
        "c_Ns_per_m": zeta * c_cr,  # eq. 2.10
    }
