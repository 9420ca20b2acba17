"""Free motion of Cullinan's antagonistic joint with its arm and masses, valves shut.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", sections II, V and VI.

Equation of motion (one rotational degree of freedom β, rad):

    J·β̈ = T_muscles(β, β̇) − M·cos(β − β_h)

* J: moment of inertia of the arm and its masses about the pivot (Cullinan eq. 12 with its
  squares restored, :func:`pamid.cullinan.moment_of_inertia_eq12`; 0.46 kg·m² with two 1.2 kg
  masses).
* T_muscles = r·(F1 − F2) (eq. 4), each F_i from eq. 3 INCLUDING its damper term −G·ẏ_i,
  with ẏ1 = r·β̇ and ẏ2 = −r·β̇ (eq. 5), cable stretch and slack muscles as in
  :mod:`pamid._models._joint` (it is :func:`pamid._models._joint.joint_state`, the function
  behind :func:`pamid.cullinan.muscle_state` and :func:`pamid.cullinan.closed_system_torque_Nm`).
* Valves shut (section V): each muscle was sealed at the joint angle β_s with the gauge
  pressure P_i; its air mass is then constant and its pressure follows its volume,
  P′_i(y_i) = (P_i + P_atm)·(V(y_i,s)/V(y_i))^n − P_atm
  (:func:`pamid.cullinan.closed_system_pressure_kPa`; n = 1 isothermal by default, n = 1.4
  adiabatic).
* Gravity. Angle convention: the arm is HORIZONTAL at β = β_h (default 0) and +β raises it,
  so the weight of the arm and its masses exerts the torque −M·cos(β − β_h), M = g·Σ m·l_cg
  (N·m; :func:`gravity_moment_Nm`). This is the reading of Cullinan's Fig. 6 caption: "2
  masses (1.2 Kg each) on the arm (11 Nm static torque at 0 rad)" — the gravity torque is
  largest, 11 N·m, at 0 rad, which makes 0 rad the horizontal arm (the apparatus is
  vertical, section III: "the mass must be lifted against gravity"). M = 0 models a
  horizontal apparatus.

At rest T_muscles(β, 0) = M·cos(β − β_h): :func:`joint_equilibrium_rad` solves it (the
"static solution"); a run released anywhere settles there (checked in the tests).

Integrator: classical RK4 at a fixed step in ``lax.scan`` (:func:`pamid._sim._oscillator.
rk4_scan`), the integrator pamid's other simulators use, chosen by measurement in
``benchmarks/simulate_batch.py`` (see :mod:`pamid._sim._lifting_mass`). This system is as
slow (f_n ≈ 1–3 Hz) and not stiff, so one step per 1 kHz sample is accurate to ~1e-10 rad
against ``scipy.integrate.solve_ivp(DOP853, rtol=1e-10)`` (``tests/test_joint_sim.py``).

Batches: every field of :class:`JointArm` (muscle constants, geometry, volume, inertia, seal
point, gravity) and the initial state may carry leading batch axes; they broadcast together
and one call runs the whole batch (one vmapped, jit-compiled scan). Differentiable with
``jax.grad`` with respect to every field and the initial state.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._models._cullinan import Cullinan
from .._models._joint import JointGeometry, joint_state, muscle_state, torque_from_state
from .._models._volume import PamVolume, closed_system_pressure_kPa
from .._units import ATMOSPHERE_KPA
from ._oscillator import batch_apply, rk4_scan, sample_times

__all__ = [
    "STANDARD_GRAVITY_M_PER_S2",
    "JointArm",
    "JointArmRun",
    "gravity_moment_Nm",
    "joint_arm_torque_Nm",
    "joint_equilibrium_rad",
    "simulate_joint_arm",
]

STANDARD_GRAVITY_M_PER_S2 = 9.81
_BISECTION_STEPS = 60


def gravity_moment_Nm(
    rod_mass_kg: ArrayLike,
    rod_length_m: ArrayLike,
    mass_kg: ArrayLike,
    mass_distance_m: ArrayLike,
    gravity_m_per_s2: ArrayLike = STANDARD_GRAVITY_M_PER_S2,
) -> Float[Array, "..."]:
    """M = g·(m1·l1/2 + m2·l2) in N·m: the gravity torque of the horizontal arm.

    The same bodies as Cullinan eq. 12: a uniform rod of mass m1 and length l1 pivoted at one
    end (centre of mass at l1/2) and masses m2 (all of them together) at the distance l2.
    """
    g = jnp.asarray(gravity_m_per_s2, float)
    return g * (jnp.asarray(rod_mass_kg, float) * jnp.asarray(rod_length_m, float) / 2.0
                + jnp.asarray(mass_kg, float) * jnp.asarray(mass_distance_m, float))


class JointArm(eqx.Module):
    """The antagonistic joint, valves shut, driving an arm under gravity (module docstring).

    Fields (any may carry leading batch axes):

    * ``muscle1``, ``muscle2``: Cullinan eq. 3 constants (N, kPa, mm, s), G included.
    * ``geometry``: pulley radius, β_range, cable compliance
      (:class:`pamid.cullinan.JointGeometry`).
    * ``volume``: the volume model of both muscles (:class:`pamid.PamVolume`).
    * ``inertia_kg_m2``: J about the pivot (Cullinan eq. 12, corrected).
    * ``gravity_moment_Nm``: M, the gravity torque of the arm when horizontal (≥ 0).
    * ``seal_angle_rad``, ``p1_kPa``, ``p2_kPa``: angle and gauge pressures at which the
      valves shut.
    * ``horizontal_angle_rad``: β_h, where the arm is horizontal (default 0).
    * ``polytropic_n`` (default 1, isothermal), ``p_atm_kPa``.
    """

    muscle1: Cullinan
    muscle2: Cullinan
    geometry: JointGeometry
    volume: PamVolume
    inertia_kg_m2: Float[Array, "..."]
    gravity_moment_Nm: Float[Array, "..."]
    seal_angle_rad: Float[Array, "..."]
    p1_kPa: Float[Array, "..."]
    p2_kPa: Float[Array, "..."]
    horizontal_angle_rad: Float[Array, "..."]
    polytropic_n: Float[Array, "..."]
    p_atm_kPa: Float[Array, "..."]

    def __init__(self, muscle1, muscle2, geometry, volume, inertia_kg_m2, gravity_moment_Nm,
                 seal_angle_rad, p1_kPa, p2_kPa, horizontal_angle_rad=0.0, polytropic_n=1.0,
                 p_atm_kPa=ATMOSPHERE_KPA):
        self.muscle1, self.muscle2 = muscle1, muscle2
        self.geometry, self.volume = geometry, volume
        self.inertia_kg_m2 = jnp.asarray(inertia_kg_m2, float)
        self.gravity_moment_Nm = jnp.asarray(gravity_moment_Nm, float)
        self.seal_angle_rad = jnp.asarray(seal_angle_rad, float)
        self.p1_kPa = jnp.asarray(p1_kPa, float)
        self.p2_kPa = jnp.asarray(p2_kPa, float)
        self.horizontal_angle_rad = jnp.asarray(horizontal_angle_rad, float)
        self.polytropic_n = jnp.asarray(polytropic_n, float)
        self.p_atm_kPa = jnp.asarray(p_atm_kPa, float)


def sealed_pressure_laws(arm: JointArm):
    """The two pressure laws P′_i(y_i) of the sealed muscles (contractions at the seal from
    eq. 3–5 at the seal angle and pressures, cable stretch included)."""
    seal = muscle_state(arm.muscle1, arm.muscle2, arm.geometry, arm.seal_angle_rad,
                        arm.p1_kPa, arm.p2_kPa)

    def law(y0, p0):
        return lambda y: closed_system_pressure_kPa(arm.volume, y0, p0, y, arm.polytropic_n,
                                                    arm.p_atm_kPa)

    return law(seal.y1_mm, arm.p1_kPa), law(seal.y2_mm, arm.p2_kPa)


def _torques(arm: JointArm, laws, beta, beta_dot):
    """(T_muscles, T_gravity) in N·m at (β, β̇)."""
    state = joint_state(arm.muscle1, arm.muscle2, arm.geometry, beta, laws[0], laws[1], beta_dot,
                   True)
    gravity = -arm.gravity_moment_Nm * jnp.cos(beta - arm.horizontal_angle_rad)
    return torque_from_state(arm.geometry, state), gravity


@eqx.filter_jit
def joint_arm_torque_Nm(arm: JointArm, beta_rad: ArrayLike, beta_dot_rad_s: ArrayLike = 0.0):
    """Net torque T_muscles(β, β̇) − M·cos(β − β_h) in N·m (J·β̈), valves shut.

    Broadcasts over β and β̇; the arm must then be unbatched (``vmap`` over it otherwise).
    """
    muscles, gravity = _torques(arm, sealed_pressure_laws(arm), jnp.asarray(beta_rad, float),
                                jnp.asarray(beta_dot_rad_s, float))
    return muscles + gravity


def _equilibrium_one(arm: JointArm, lo, hi):
    laws = sealed_pressure_laws(arm)

    def f(beta):  # net static torque; decreasing in β for a stable joint
        muscles, gravity = _torques(arm, laws, beta, 0.0)
        return muscles + gravity

    inside = (f(lo) > 0) & (f(hi) < 0)

    def body(_, bracket):
        a, b = bracket
        mid = 0.5 * (a + b)
        above = f(mid) > 0
        return jnp.where(above, mid, a), jnp.where(above, b, mid)

    a, b = jax.lax.fori_loop(0, _BISECTION_STEPS, body,
                             (jax.lax.stop_gradient(lo), jax.lax.stop_gradient(hi)))
    b0 = jax.lax.stop_gradient(0.5 * (a + b))
    value, slope = jax.jvp(f, (b0,), (jnp.ones_like(b0),))
    beta = b0 - value / slope  # one Newton step: exact value, implicit-function derivative
    return jnp.where(inside, beta, jnp.nan)


@eqx.filter_jit
def _equilibrium(arm, lo, hi):
    return batch_apply(_equilibrium_one, arm, lo, hi)


def joint_equilibrium_rad(
    arm: JointArm, bracket_rad: tuple[ArrayLike, ArrayLike] | None = None
) -> Float[Array, "..."]:
    """The static solution: β at which T_muscles(β, 0) = M·cos(β − β_h), valves shut.

    Bisection on the net torque in ``bracket_rad`` (default: the joint's range
    ±β_range/2), then one Newton step from the gradient-stopped point, so the result is
    differentiable (implicit-function derivative). NaN where the net torque does not change
    sign from + to − across the bracket (no stable equilibrium there). Batched like the arm.
    """
    if bracket_rad is None:
        half = arm.geometry.beta_range_rad / 2.0
        lo, hi = -half, half
    else:
        lo, hi = bracket_rad
    return _equilibrium(arm, jnp.asarray(lo, float), jnp.asarray(hi, float))


class JointArmRun(NamedTuple):
    """A simulated run; arrays (*batch, T) except ``time_s`` (T,)."""

    time_s: Float[Array, " T"]
    angle_rad: Float[Array, "... T"]
    rate_rad_s: Float[Array, "... T"]
    pressure1_kPa: Float[Array, "... T"]  # gauge, sealed muscle 1
    pressure2_kPa: Float[Array, "... T"]
    torque_Nm: Float[Array, "... T"]  # T_muscles (eq. 4, with the damper term)


def arm_rhs(arm: JointArm, laws):
    def rhs(y):
        muscles, gravity = _torques(arm, laws, y[0], y[1])
        return jnp.stack([y[1], (muscles + gravity) / arm.inertia_kg_m2])

    return rhs


@eqx.filter_jit
def _simulate(arm, angle0, rate0, n, dt, substeps):
    def one(a, b0, v0):
        laws = sealed_pressure_laws(a)
        ys = rk4_scan(arm_rhs(a, laws), jnp.stack([b0, v0]), dt, n, substeps)
        beta, rate = ys[:, 0], ys[:, 1]
        state = joint_state(a.muscle1, a.muscle2, a.geometry, beta, laws[0], laws[1], rate, True)
        return (beta, rate, laws[0](state.y1_mm), laws[1](state.y2_mm),
                torque_from_state(a.geometry, state))

    return batch_apply(one, arm, angle0, rate0)


def simulate_joint_arm(
    arm: JointArm,
    angle0_rad: ArrayLike,
    rate0_rad_s: ArrayLike = 0.0,
    *,
    duration_s: float = 4.0,
    sample_rate_Hz: float = 1000.0,
    substeps: int = 1,
) -> JointArmRun:
    """Simulate the joint and arm, valves shut, from (β0, β̇0); one run or a batch.

    The arm's fields and the initial state broadcast together; the whole batch is one
    compiled, vmapped RK4 scan with ``substeps`` steps per output sample. Differentiable
    with respect to the arm and the initial state.
    """
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    n, dt = sample_times(duration_s, sample_rate_Hz)
    out = _simulate(arm, jnp.asarray(angle0_rad, float), jnp.asarray(rate0_rad_s, float), n,
                    dt, int(substeps))
    return JointArmRun(dt * jnp.arange(n), *out)
