"""A joint driven antagonistically by two PAMs over a pulley: torque, stiffness, and the most
stiffness available for a given torque, isobaric and with the valves shut.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", eq. 3–7 and Sections IV–V.

    F_i = A + B·P′_i − (C + D·P′_i + E·y_i)·y_i − G·ẏ_i              (Cullinan eq. 3)
    T   = r·(F1 − F2)                                                 (Cullinan eq. 4)
    y1  = r·(β_range/2 + β),   y2 = r·(β_range/2 − β)                 (Cullinan eq. 5)

Muscle 1 is at full extension (y1 = 0) at β = −β_range/2 and pulls the joint towards +β;
muscle 2 is at full extension at β = +β_range/2 and pulls towards −β.

Units. Eq. 3 is in N, kPa, mm and s (see :mod:`pamid._models._cullinan`), so inside eq. 3–5
the pulley radius r is in mm: y = r_mm·β is in mm and ẏ = r_mm·β̇ in mm/s. The torque is in
N·m, T = (r_mm / 1000)·(F1 − F2); a stiffness dT/dβ therefore carries r_mm² / 1000, one
factor r from eq. 4 (in m) and one from eq. 5 (in mm).

Eq. 6, a sign error. Composing eq. 3–5 for two identical muscles, with h = β_range/2:
F1 − F2 = B·(P1 − P2) − C·(y1 − y2) − D·(P1·y1 − P2·y2) − E·(y1² − y2²) − G·(ẏ1 − ẏ2), where
y1 − y2 = 2rβ, y1² − y2² = (y1 − y2)(y1 + y2) = 4r²hβ and P1·y1 − P2·y2 = rh(P1 − P2) +
rβ(P1 + P2), so

    T = r·[(P1 − P2)·(B − D·r·β_range/2) − β·r·(2C + D·(P1 + P2) + 2·E·r·β_range) − 2·G·r·β̇].

The paper prints "− 2Erβ_range" inside the bracket of eq. 6; that is a sign error. Its own
eq. 7, the derivative of eq. 6, prints "+ 2Erβ_range", which is right and agrees with the
composition. The tests check both: eq. 6 with "+" equals eq. 3–5 composed, the printed "−"
does not, and eq. 7 equals the derivative of both.

Cable stretch (Section IV). Each cable lengthens by c·F_i under the tension F_i (Cullinan
measured c = 0.0017 mm/N over each 30 cm Dyneema cable); at the same joint angle the muscle
must then contract that much more, y_i = y_geom,i + c·F_i(P_i, y_i). This is implicit in y_i.
At a constant pressure F is quadratic in y and the root is taken in closed form; for sealed
muscles, whose pressure follows the volume, a few Newton steps solve it (c·∂F/∂y is small,
so they reach machine precision in two or three). The closed forms eq. 6 and eq. 7 assume
rigid cables and ignore ``cable_compliance_mm_per_N``; the composed functions use it. The
damper term uses the geometric velocity ẏ = ±r·β̇ (the cable's rate of stretch is
neglected).

Tension only. A PAM can only pull: with ``tensile_only=True`` (the default) a muscle whose
eq. 3 force is negative is slack, carries no cable tension and adds nothing to the torque.
Eq. 6 and eq. 7 assume both muscles in tension.

Stiffness signs. ``joint_stiffness_*`` return dT/dβ as eq. 7 defines it (negative for a
joint that resists deflection). :func:`max_isobaric_stiffness` and
:func:`closed_system_stiffness` return the magnitude −dT/dβ (positive), as Cullinan's
Fig. 5 and Fig. 6 report it.

Everything here is plain JAX: it works under ``jit``, ``vmap`` and ``grad`` and broadcasts
over angles and pressures. Arguments of the same call must broadcast together; the muscle
constants may carry batch axes only where they broadcast with the angles. The composed
functions are compiled with ``jax.jit`` (after their argument checks, which look at values
only where they are concrete), so that calling them outside ``jit`` is fast too.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._checks import require
from .._units import ATMOSPHERE_KPA
from ._cullinan import Cullinan, cullinan_force
from ._volume import PamVolume, closed_system_pressure_kPa

#: Cullinan Section III: an 80 mm diameter pulley.
CULLINAN_PULLEY_RADIUS_MM = 40.0
#: Cullinan Section IV: each 30 cm Dyneema cable stretches 0.0017 mm per N.
CULLINAN_CABLE_COMPLIANCE_MM_PER_N = 0.0017
#: Cullinan Section III: the maximum muscle operating pressure (gauge).
CULLINAN_P_MAX_KPA = 414.0
#: Cullinan Section III: the traditional-PAM joint rotates by ±0.6 rad.
CULLINAN_TRADITIONAL_BETA_RANGE_RAD = 1.2

_MM_PER_M = 1000.0
_NEWTON_STEPS = 5  # cable stretch of sealed muscles; machine precision after 2–3
_BISECTION_STEPS = 64  # halves [0, P_max] below one float64 ulp of P_max


class JointGeometry(eqx.Module):
    """Pulley and muscle placement of an antagonistic joint (Cullinan eq. 4–5).

    * ``pulley_radius_mm``: r (Cullinan: 80 mm diameter, so 40 mm).
    * ``beta_range_rad``: β_range, the total range of rotation; muscle 1 is at full extension
      at β = −β_range/2, muscle 2 at β = +β_range/2 (Cullinan's traditional joint: 1.2 rad).
    * ``cable_compliance_mm_per_N``: c, stretch of each cable per newton of tension
      (Cullinan: 0.0017 mm/N); 0, the default, means rigid cables.
    """

    pulley_radius_mm: Float[Array, "..."]
    beta_range_rad: Float[Array, "..."]
    cable_compliance_mm_per_N: Float[Array, "..."]

    def __init__(self, pulley_radius_mm, beta_range_rad, cable_compliance_mm_per_N=0.0):
        require("pulley_radius_mm", pulley_radius_mm, lambda a: a > 0, "> 0")
        require("beta_range_rad", beta_range_rad, lambda a: a > 0, "> 0 (the total range)")
        require("cable_compliance_mm_per_N", cable_compliance_mm_per_N, lambda a: a >= 0, ">= 0")
        self.pulley_radius_mm = jnp.asarray(pulley_radius_mm, float)
        self.beta_range_rad = jnp.asarray(beta_range_rad, float)
        self.cable_compliance_mm_per_N = jnp.asarray(cable_compliance_mm_per_N, float)


class MuscleState(NamedTuple):
    """Contractions (mm) and cable tensions (N) of both muscles at one joint state."""

    y1_mm: Float[Array, "..."]
    y2_mm: Float[Array, "..."]
    f1_N: Float[Array, "..."]
    f2_N: Float[Array, "..."]


class AvailableTorque(NamedTuple):
    """Torque (N·m, ≥ 0) one muscle at P_max exerts towards each direction (Cullinan Fig. 4)."""

    toward_positive_Nm: Float[Array, "..."]  # muscle 1, pulling towards +β
    toward_negative_Nm: Float[Array, "..."]  # muscle 2, pulling towards −β


class IsobaricStiffness(NamedTuple):
    """Result of :func:`max_isobaric_stiffness` (Cullinan Fig. 5).

    ``stiffness_Nm_per_rad`` is −dT/dβ (positive); it and the pressures are NaN where the
    torque cannot be produced within 0 ≤ P1, P2 ≤ P_max (``feasible`` False).
    """

    stiffness_Nm_per_rad: Float[Array, "..."]
    p1_kPa: Float[Array, "..."]
    p2_kPa: Float[Array, "..."]
    feasible: Bool[Array, "..."]


class ClosedSystemStiffness(NamedTuple):
    """Result of :func:`closed_system_stiffness`; every stiffness is −dT/dβ in N·m/rad.

    * ``derivative_Nm_per_rad``: at the set point, valves shut (by ``jax.jvp``).
    * ``regression_Nm_per_rad``: one slope per deflection (last axis), as Cullinan measures.
    * ``regression_mean_Nm_per_rad``: their mean (Cullinan Fig. 6 plots the mean).
    * ``isobaric_Nm_per_rad``: at the same set point with the pressures held constant.
    """

    derivative_Nm_per_rad: Float[Array, "..."]
    regression_Nm_per_rad: Float[Array, "... k"]
    regression_mean_Nm_per_rad: Float[Array, "..."]
    isobaric_Nm_per_rad: Float[Array, "..."]


def contractions_mm(
    geometry: JointGeometry, beta_rad: ArrayLike
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """(y1, y2) in mm for rigid cables, Cullinan eq. 5.

    y1 = r·(β_range/2 + β),  y2 = r·(β_range/2 − β), with r in mm.

    Outside −β_range/2 ≤ β ≤ β_range/2 one muscle would be stretched past its full extension
    (y < 0); eq. 3 is then extrapolated, nothing is checked.
    """
    beta = jnp.asarray(beta_rad, float)
    half = geometry.beta_range_rad / 2.0
    r = geometry.pulley_radius_mm
    return r * (half + beta), r * (half - beta)


def _stretched_contraction_isobaric(
    params: Cullinan,
    pressure_kPa: Array,
    y_geom_mm: Array,
    velocity_mm_s: Array,
    compliance_mm_per_N: Array,
    tensile_only: bool,
) -> Array:
    """Solve y = y_geom + c·F(P, y) in closed form, at a constant pressure.

    Eq. 3 is quadratic in y, F = a0 − a1·y − E·y² with a0 = A + B·P − G·ẏ and a1 = C + D·P,
    so c·E·y² + (1 + c·a1)·y − (y_geom + c·a0) = 0. Its root, written without cancellation,
    is y = 2·(y_geom + c·a0) / ((1 + c·a1) + √((1 + c·a1)² + 4·c·E·(y_geom + c·a0))); with
    c = 0 it is y_geom exactly. A slack muscle (F < 0 at the root, i.e. y < y_geom) carries
    no tension, so with ``tensile_only`` its contraction is y_geom.
    """
    p = pressure_kPa
    c = compliance_mm_per_N
    a0 = params.A + params.B * p - params.G * velocity_mm_s
    a1 = params.C + params.D * p
    rhs = y_geom_mm + c * a0
    lin = 1.0 + c * a1
    y = 2.0 * rhs / (lin + jnp.sqrt(jnp.maximum(lin**2 + 4.0 * c * params.E * rhs, 0.0)))
    return jnp.maximum(y, y_geom_mm) if tensile_only else y


def _stretched_contraction_newton(
    y_geom_mm: Array, tension_N: Callable[[Array], Array], compliance_mm_per_N: Array
) -> Array:
    """Solve y = y_geom + c·F(y) by Newton's method, where the pressure depends on y.

    ``tension_N`` maps a contraction to the cable tension elementwise. The first guess is one
    fixed-point step, which also broadcasts y to the shape of the tension; c·∂F/∂y is small,
    so a few steps reach machine precision. With c = 0 every step returns y_geom exactly.
    The steps run in a ``fori_loop`` (XLA compiles an unrolled chain much more slowly);
    ``jvp`` and ``grad`` go through it.
    """
    c = compliance_mm_per_N

    def residual(y):
        return y - y_geom_mm - c * tension_N(y)

    def newton_step(_, y):
        g, dg = jax.jvp(residual, (y,), (jnp.ones_like(y),))
        return y - g / dg

    return jax.lax.fori_loop(0, _NEWTON_STEPS, newton_step, y_geom_mm + c * tension_N(y_geom_mm))


def _tension_fn(
    params: Cullinan,
    pressure_kPa: Callable[[Array], Array],
    velocity_mm_s: Array,
    tensile_only: bool,
) -> Callable[[Array], Array]:
    """y ↦ cable tension of one muscle, eq. 3 at the pressure ``pressure_kPa(y)``."""

    def tension(y):
        force = cullinan_force(params, pressure_kPa(y), y, velocity_mm_s)
        return jnp.maximum(force, 0.0) if tensile_only else force

    return tension


def joint_state(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    pressure1_kPa: ArrayLike | Callable[[Array], Array],
    pressure2_kPa: ArrayLike | Callable[[Array], Array],
    beta_dot_rad_s: ArrayLike,
    tensile_only: bool,
) -> MuscleState:
    """Both muscles at the angle β.

    Each pressure is either a constant (isobaric: the stretched contraction in closed form)
    or a function of the muscle's contraction (sealed: Newton's method).
    """
    y1_geom, y2_geom = contractions_mm(geometry, beta_rad)
    v1 = geometry.pulley_radius_mm * jnp.asarray(beta_dot_rad_s, float)  # ẏ1 = r·β̇
    c = geometry.cable_compliance_mm_per_N
    contractions, tensions = [], []
    for params, pressure, y_geom, v in (
        (params1, pressure1_kPa, y1_geom, v1),
        (params2, pressure2_kPa, y2_geom, -v1),  # ẏ2 = −r·β̇
    ):
        if callable(pressure):
            tension = _tension_fn(params, pressure, v, tensile_only)
            y = _stretched_contraction_newton(y_geom, tension, c)
        else:
            p = jnp.asarray(pressure, float)
            tension = _tension_fn(params, lambda y, p=p: p, v, tensile_only)
            y = _stretched_contraction_isobaric(params, p, y_geom, v, c, tensile_only)
        contractions.append(y)
        tensions.append(tension(y))
    return MuscleState(contractions[0], contractions[1], tensions[0], tensions[1])


@functools.partial(jax.jit, static_argnames=("tensile_only",))
def muscle_state(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    beta_dot_rad_s: ArrayLike = 0.0,
    tensile_only: bool = True,
) -> MuscleState:
    """Contractions y1, y2 (mm) and cable tensions F1, F2 (N), Cullinan eq. 3 and eq. 5.

    With cable stretch, y_i = r(β_range/2 ± β) + c·F_i(P_i, y_i) is solved in closed form
    (eq. 3 is quadratic in y_i).
    With ``tensile_only`` a slack muscle's tension is 0 (a PAM only pulls); otherwise the
    tensions are eq. 3's forces as they are, negative ones included.
    """
    return joint_state(
        params1,
        params2,
        geometry,
        beta_rad,
        p1_kPa,
        p2_kPa,
        beta_dot_rad_s,
        tensile_only,
    )


def torque_from_state(geometry: JointGeometry, state: MuscleState) -> Float[Array, "..."]:
    """Cullinan eq. 4 in N·m: T = (r_mm / 1000)·(F1 − F2)."""
    return geometry.pulley_radius_mm / _MM_PER_M * (state.f1_N - state.f2_N)


@functools.partial(jax.jit, static_argnames=("tensile_only",))
def joint_torque_Nm(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    beta_dot_rad_s: ArrayLike = 0.0,
    tensile_only: bool = True,
) -> Float[Array, "..."]:
    """Joint torque in N·m, Cullinan eq. 4, T = r·(F1 − F2), composed with eq. 3 and eq. 5.

    r is taken in m for eq. 4 (T = r_mm/1000·(F1 − F2)) and in mm inside eq. 5. Muscles may
    differ (``params1``, ``params2``); cable stretch and slack muscles are handled as in
    :func:`muscle_state`. Positive torque turns the joint towards +β.
    """
    state = muscle_state(
        params1, params2, geometry, beta_rad, p1_kPa, p2_kPa, beta_dot_rad_s, tensile_only
    )
    return torque_from_state(geometry, state)


def joint_torque_eq6_Nm(
    params: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    beta_dot_rad_s: ArrayLike = 0.0,
) -> Float[Array, "..."]:
    """Joint torque in N·m, closed form of Cullinan eq. 6 (two identical muscles), corrected.

    T = r·[(P1 − P2)(B − D·r·β_range/2) − β·r·(2C + D(P1 + P2) + 2·E·r·β_range) − 2·G·r·β̇]

    with r in m outside the bracket and in mm inside. The paper prints "− 2Erβ_range" inside
    the bracket: a sign error (see the module docstring for the derivation). Its eq. 7 has
    the right sign. Assumes both muscles in tension and rigid cables (the geometry's
    ``cable_compliance_mm_per_N`` is ignored).
    """
    beta = jnp.asarray(beta_rad, float)
    p1 = jnp.asarray(p1_kPa, float)
    p2 = jnp.asarray(p2_kPa, float)
    beta_dot = jnp.asarray(beta_dot_rad_s, float)
    r = geometry.pulley_radius_mm
    beta_range = geometry.beta_range_rad
    force_difference_N = (
        (p1 - p2) * (params.B - params.D * r * beta_range / 2.0)
        - beta * r * (2.0 * params.C + params.D * (p1 + p2) + 2.0 * params.E * r * beta_range)
        - 2.0 * params.G * r * beta_dot
    )
    return r / _MM_PER_M * force_difference_N


def joint_stiffness_eq7_Nm_per_rad(
    params: Cullinan, geometry: JointGeometry, p1_kPa: ArrayLike, p2_kPa: ArrayLike
) -> Float[Array, "..."]:
    """dT/dβ in N·m/rad, closed form of Cullinan eq. 7 (identical muscles, both in tension).

    dT/dβ = −r²·(2C + D·(P1 + P2) + 2·E·r·β_range), with r² = r_mm·r_mm/1000 (one r from
    eq. 4 in m, one from eq. 5 in mm) and r in mm inside the bracket. Negative: the joint
    resists deflection. Independent of β; rigid cables assumed.
    """
    p1 = jnp.asarray(p1_kPa, float)
    p2 = jnp.asarray(p2_kPa, float)
    r = geometry.pulley_radius_mm
    bracket_N_per_mm = (
        2.0 * params.C + params.D * (p1 + p2) + 2.0 * params.E * r * geometry.beta_range_rad
    )
    return -(r / _MM_PER_M) * r * bracket_N_per_mm


@functools.partial(jax.jit, static_argnames=("tensile_only",))
def joint_stiffness_Nm_per_rad(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    tensile_only: bool = True,
) -> Float[Array, "..."]:
    """dT/dβ in N·m/rad at constant pressures, by forward-mode differentiation of eq. 3–5.

    The static torque (β̇ = 0; "without the effect of the damper", Cullinan Section II) of
    :func:`joint_torque_Nm` is differentiated by ``jax.jvp``, so cable stretch, different
    muscles and slack muscles are included. Equal to eq. 7 for identical muscles in tension
    with rigid cables. Broadcasts over its arguments.
    """
    beta = jnp.asarray(beta_rad, float)

    def torque(b):
        return joint_torque_Nm(params1, params2, geometry, b, p1_kPa, p2_kPa, 0.0, tensile_only)

    # Each output element depends on one element of β (broadcasting), so a tangent of ones
    # gives the elementwise derivative.
    _, slope = jax.jvp(torque, (beta,), (jnp.ones_like(beta),))
    return slope


def available_torque_Nm(
    params: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    p_max_kPa: ArrayLike = CULLINAN_P_MAX_KPA,
) -> AvailableTorque:
    """Torque in N·m each muscle exerts at ``p_max_kPa`` towards its direction (Cullinan Fig. 4).

    Towards +β: muscle 1 at P_max, r·max(F(P_max, y1(β)), 0); towards −β: muscle 2,
    r·max(F(P_max, y2(β)), 0). As in Cullinan's Fig. 4 model lines, the other muscle's pull
    is not subtracted. Cable stretch is included when the geometry has it.
    """
    require("p_max_kPa", p_max_kPa, lambda a: a > 0, "> 0")
    state = muscle_state(params, params, geometry, beta_rad, p_max_kPa, p_max_kPa)
    scale = geometry.pulley_radius_mm / _MM_PER_M
    return AvailableTorque(scale * state.f1_N, scale * state.f2_N)


def pressures_for_torque_stiffness_kPa(
    params: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    torque_Nm: ArrayLike,
    stiffness_Nm_per_rad: ArrayLike,
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """(P1, P2) in kPa that give a static torque and an isobaric stiffness, eq. 6 and eq. 7.

    ``stiffness_Nm_per_rad`` is the magnitude k = −dT/dβ > 0. Eq. 7 fixes the sum,
    S = P1 + P2 = (1000·k/r_mm² − 2C − 2E·r·β_range)/D; eq. 6 (static, corrected sign) then
    gives the difference, since its β-term equals β·k: P1 − P2 = 1000·(T + β·k) /
    (r_mm·(B − D·r·β_range/2)). Two identical muscles in tension, rigid cables; D ≠ 0 (else
    the stiffness does not depend on the pressures). The result is not clipped to any
    pressure range.
    """
    beta = jnp.asarray(beta_rad, float)
    torque = jnp.asarray(torque_Nm, float)
    k = jnp.asarray(stiffness_Nm_per_rad, float)
    r = geometry.pulley_radius_mm
    beta_range = geometry.beta_range_rad
    total = (_MM_PER_M * k / r**2 - 2.0 * params.C - 2.0 * params.E * r * beta_range) / params.D
    difference = (
        _MM_PER_M * (torque + beta * k) / (r * (params.B - params.D * r * beta_range / 2.0))
    )
    return (total + difference) / 2.0, (total - difference) / 2.0


def _bisect_increasing(
    fn: Callable[[Array], Array], upper: Array, shape: tuple[int, ...]
) -> tuple[Array, Array]:
    """Root of a nondecreasing ``fn`` in [0, upper], elementwise, and whether one exists.

    Bisection with a fixed number of steps (``lax.fori_loop``), then one Newton step from the
    bisection's answer held constant, so that derivatives follow the implicit function
    theorem (the value moves by ~one rounding error).
    """
    lo = jnp.zeros(shape)
    hi = jnp.broadcast_to(upper, shape).astype(float)
    f_lo, f_hi = fn(lo), fn(hi)
    tol = 1e-9 * (1.0 + jnp.maximum(jnp.abs(f_lo), jnp.abs(f_hi)))
    exists = (f_lo <= tol) & (f_hi >= -tol)

    def step(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = fn(mid) < 0.0
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    lo, hi = jax.lax.fori_loop(0, _BISECTION_STEPS, step, (lo, hi))
    root = jax.lax.stop_gradient(0.5 * (lo + hi))
    value, slope = jax.jvp(fn, (root,), (jnp.ones_like(root),))
    safe_slope = jnp.where(slope > 0.0, slope, 1.0)
    root = root - jnp.where(slope > 0.0, value / safe_slope, 0.0)
    return root, exists


def max_isobaric_stiffness(
    params: Cullinan,
    geometry: JointGeometry,
    beta_rad: ArrayLike,
    torque_Nm: ArrayLike,
    p_max_kPa: ArrayLike = CULLINAN_P_MAX_KPA,
) -> IsobaricStiffness:
    """Largest isobaric stiffness −dT/dβ (N·m/rad) that still gives the static torque (Fig. 5).

    Maximises −dT/dβ over 0 ≤ P1, P2 ≤ P_max subject to T(β, P1, P2) = ``torque_Nm``, for two
    identical muscles (composed eq. 3–5, so cable stretch and slack muscles count). By eq. 7
    the stiffness grows with P1 + P2 (for D > 0), and along the torque constraint both
    pressures rise together, so the optimum has one muscle at P_max. For each candidate
    (P1 = P_max, or P2 = P_max) the other pressure is found in [0, P_max] by bisection on the
    torque, which is monotone in it; infeasible candidates are dropped and the stiffer one is
    kept. Where neither exists the torque cannot be produced at that angle: the stiffness and
    pressures are NaN and ``feasible`` is False.

    Broadcasts over ``beta_rad`` and ``torque_Nm`` (and works under ``vmap``); differentiable
    in the inputs through the implicit function theorem at the solution.
    """
    require("p_max_kPa", p_max_kPa, lambda a: a > 0, "> 0")
    return _max_isobaric_stiffness(params, geometry, beta_rad, torque_Nm, p_max_kPa)


@jax.jit
def _max_isobaric_stiffness(params, geometry, beta_rad, torque_Nm, p_max_kPa):
    beta = jnp.asarray(beta_rad, float)
    target = jnp.asarray(torque_Nm, float)
    p_max = jnp.asarray(p_max_kPa, float)

    def torque(p1, p2):
        return joint_torque_Nm(params, params, geometry, beta, p1, p2)

    shape = jnp.broadcast_shapes(jnp.shape(torque(p_max, p_max)), target.shape)
    # Both candidates at once, on a new leading axis: a (index 0) holds muscle 1 at P_max and
    # solves for P2, the torque falling as P2 rises; b (index 1) holds muscle 2 at P_max and
    # solves for P1, the torque rising with P1. One bisection loop serves both.
    is_a = jnp.array([True, False]).reshape((2,) + (1,) * len(shape))
    sign = jnp.where(is_a, -1.0, 1.0)

    def pressures(x):
        return jnp.where(is_a, p_max, x), jnp.where(is_a, x, p_max)

    x, ok = _bisect_increasing(
        lambda x: sign * (torque(*pressures(x)) - target), p_max, (2,) + shape
    )
    p1, p2 = pressures(x)
    k = -joint_stiffness_Nm_per_rad(params, params, geometry, beta, p1, p2)
    # The barrier changes no value; without it XLA fuses the selection below into the
    # solver and takes twice as long to compile.
    p1, p2, k, ok = jax.lax.optimization_barrier((p1, p2, k, ok))
    (p1_a, p1_b), (p2_a, p2_b), (k_a, k_b), (ok_a, ok_b) = p1, p2, k, ok
    take_a = ok_a & (~ok_b | (k_a >= k_b))
    feasible = ok_a | ok_b
    nan = jnp.full(shape, jnp.nan)
    return IsobaricStiffness(
        jnp.where(feasible, jnp.where(take_a, k_a, k_b), nan),
        jnp.where(feasible, jnp.where(take_a, p1_a, p1_b), nan),
        jnp.where(feasible, jnp.where(take_a, p2_a, p2_b), nan),
        feasible,
    )


def closed_system_torque_Nm(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    volume: PamVolume,
    beta0_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    beta_rad: ArrayLike,
    polytropic_n: ArrayLike = 1.0,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
    tensile_only: bool = True,
) -> Float[Array, "..."]:
    """Static torque in N·m at ``beta_rad`` with both muscles sealed at (β0, P1, P2).

    Cullinan Section V: the valves shut at the set point, so each muscle's pressure follows
    its volume, P′_i(y_i) from :func:`~pamid._models._volume.closed_system_pressure_kPa`
    (both muscles have the geometry ``volume``); the torque is eq. 3–5 at those pressures.
    With cable stretch, y_i = y_geom,i + c·F_i(P′_i(y_i), y_i) is solved by Newton's method.
    """
    _check_gas(polytropic_n, p_atm_kPa)
    return _closed_system_torque(
        params1,
        params2,
        geometry,
        volume,
        beta0_rad,
        p1_kPa,
        p2_kPa,
        beta_rad,
        polytropic_n,
        p_atm_kPa,
        tensile_only,
    )


def _check_gas(polytropic_n, p_atm_kPa) -> None:
    require("polytropic_n", polytropic_n, lambda a: a > 0, "> 0")
    require("p_atm_kPa", p_atm_kPa, lambda a: a > 0, "> 0 (an absolute pressure)")


@functools.partial(jax.jit, static_argnames=("tensile_only",))
def _closed_system_torque(
    params1,
    params2,
    geometry,
    volume,
    beta0_rad,
    p1_kPa,
    p2_kPa,
    beta_rad,
    polytropic_n,
    p_atm_kPa,
    tensile_only,
):
    set_point = muscle_state(
        params1, params2, geometry, beta0_rad, p1_kPa, p2_kPa, 0.0, tensile_only
    )

    def sealed(y0, p0):
        return lambda y: closed_system_pressure_kPa(volume, y0, p0, y, polytropic_n, p_atm_kPa)

    state = joint_state(
        params1,
        params2,
        geometry,
        beta_rad,
        sealed(set_point.y1_mm, jnp.asarray(p1_kPa, float)),
        sealed(set_point.y2_mm, jnp.asarray(p2_kPa, float)),
        0.0,
        tensile_only,
    )
    return torque_from_state(geometry, state)


def closed_system_stiffness(
    params1: Cullinan,
    params2: Cullinan,
    geometry: JointGeometry,
    volume: PamVolume,
    beta0_rad: ArrayLike,
    p1_kPa: ArrayLike,
    p2_kPa: ArrayLike,
    deflections_deg: Sequence[float] = (3.0, 5.0, 8.0),
    direction: int = 1,
    polytropic_n: ArrayLike = 1.0,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
    n_samples: int = 21,
    tensile_only: bool = True,
) -> ClosedSystemStiffness:
    """Closed-system stiffness of the joint sealed at (β0, P1, P2), Cullinan Section V.

    Three numbers, each −dT/dβ in N·m/rad: the derivative at β0 with the valves shut (by
    ``jax.jvp`` through :func:`closed_system_torque_Nm`); Cullinan's measurement, the slope
    of a least-squares line (with intercept) through the torque over ``n_samples`` evenly
    spaced angles from β0 to β0 + ``direction``·δ, one slope per deflection δ in
    ``deflections_deg`` (Cullinan: 3°, 5° and 8°, in one direction, valves closed) and their
    mean; and the isobaric stiffness at the same set point, for comparison.

    ``beta0_rad``, ``p1_kPa`` and ``p2_kPa`` broadcast together; the muscle constants and
    the volume must then be unbatched (use ``vmap`` over them otherwise).
    """
    if direction not in (1, -1):
        raise ValueError(
            f"direction must be +1 or -1 (the side of the deflection); got {direction}"
        )
    if n_samples < 2:
        raise ValueError(f"n_samples must be >= 2 to fit a line; got {n_samples}")
    deflections = jnp.asarray(deflections_deg, float)
    if deflections.ndim != 1 or deflections.size == 0:
        raise ValueError("deflections_deg must be a non-empty sequence of angles in degrees")
    require("deflections_deg", deflections_deg, lambda a: a > 0, "> 0 (magnitudes)")
    _check_gas(polytropic_n, p_atm_kPa)
    return _closed_system_stiffness(
        params1,
        params2,
        geometry,
        volume,
        beta0_rad,
        p1_kPa,
        p2_kPa,
        deflections,
        direction,
        polytropic_n,
        p_atm_kPa,
        n_samples,
        tensile_only,
    )


@functools.partial(jax.jit, static_argnames=("n_samples", "tensile_only"))
def _closed_system_stiffness(
    params1,
    params2,
    geometry,
    volume,
    beta0_rad,
    p1_kPa,
    p2_kPa,
    deflections,
    direction,
    polytropic_n,
    p_atm_kPa,
    n_samples,
    tensile_only,
):
    beta0, p1, p2 = jnp.broadcast_arrays(
        jnp.asarray(beta0_rad, float), jnp.asarray(p1_kPa, float), jnp.asarray(p2_kPa, float)
    )

    def sealed_torque(beta, expand=0):
        idx = (...,) + (None,) * expand
        return _closed_system_torque(
            params1,
            params2,
            geometry,
            volume,
            beta0[idx],
            p1[idx],
            p2[idx],
            beta,
            polytropic_n,
            p_atm_kPa,
            tensile_only,
        )

    _, slope = jax.jvp(sealed_torque, (beta0,), (jnp.ones_like(beta0),))

    # Deflection grid (k deflections, n samples each) on the trailing axes.
    fraction = jnp.linspace(0.0, 1.0, n_samples)
    offsets = direction * jnp.deg2rad(deflections)[:, None] * fraction[None, :]
    torques = sealed_torque(beta0[..., None, None] + offsets, expand=2)
    x = offsets - offsets.mean(axis=-1, keepdims=True)
    t = torques - torques.mean(axis=-1, keepdims=True)
    slopes = (x * t).sum(axis=-1) / (x * x).sum(axis=-1)

    isobaric = joint_stiffness_Nm_per_rad(params1, params2, geometry, beta0, p1, p2, tensile_only)
    return ClosedSystemStiffness(-slope, -slopes, -slopes.mean(axis=-1), -isobaric)
