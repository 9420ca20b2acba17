"""The linear damped rotational oscillator of a PAM-driven joint, and the fixed-step integrator
that pamid's simulators share.

Model (Cullinan, section VI and Fig. 7(a): the two muscles act as a rotational spring and a
viscous damper on the arm of moment of inertia J0):

    J·β̈ + c·β̇ + k·(β − β_eq) = 0,
    ω_n = √(k/J),   ζ = c / (2·√(k·J))   (Cullinan eq. 11),   ω_d = ω_n·√(1 − ζ²).

Three ways to get a trajectory:

* :func:`oscillator_response`, the closed form (exact for every ζ: under-, critically and
  over-damped), evaluated at any times. This is what the decay fits use.
* :func:`simulate_oscillator` with ``method="exact"`` (the default): the same closed form
  on a uniform grid, computed blockwise with the exact transition Φ = exp(A·dt): two
  multiply-adds per output sample, the cheapest way to many sampled linear decays
  (``benchmarks/simulate_batch.py``, section 2).
* :func:`simulate_oscillator` with ``method="rk4"``: the classical fourth-order Runge–Kutta
  method with a fixed step inside :func:`jax.lax.scan` (:func:`rk4_scan`), ``substeps``
  steps per output sample. The same integrator drives the nonlinear lifting mass
  (:mod:`pamid._sim._lifting_mass`); on the linear oscillator it is checked against the
  closed form. Why a fixed step and not diffrax's adaptive solvers is measured in
  ``benchmarks/simulate_batch.py`` and summarised in :mod:`pamid._sim._lifting_mass`.

Batches: every field of :class:`DampedOscillator` and the initial state may carry leading
batch axes; they broadcast together and one call simulates the whole batch (one vmapped,
jit-compiled scan). Everything is differentiable with ``jax.grad``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "DampedOscillator",
    "OscillatorRun",
    "batch_apply",
    "oscillator_response",
    "rk4_scan",
    "sample_times",
    "simulate_oscillator",
]


class DampedOscillator(eqx.Module):
    """J·β̈ + c·β̇ + k·(β − β_eq) = 0 (Cullinan section VI, Fig. 7(a)); SI units, angles in rad.

    Every field may carry leading batch axes (one oscillator per trial, parameter set or
    posterior draw).
    """

    inertia_kg_m2: Float[Array, "..."]
    stiffness_Nm_per_rad: Float[Array, "..."]
    damping_Nms_per_rad: Float[Array, "..."]
    equilibrium_rad: Float[Array, "..."]

    def __init__(self, inertia_kg_m2, stiffness_Nm_per_rad, damping_Nms_per_rad,
                 equilibrium_rad=0.0):
        self.inertia_kg_m2 = jnp.asarray(inertia_kg_m2, float)
        self.stiffness_Nm_per_rad = jnp.asarray(stiffness_Nm_per_rad, float)
        self.damping_Nms_per_rad = jnp.asarray(damping_Nms_per_rad, float)
        self.equilibrium_rad = jnp.asarray(equilibrium_rad, float)

    @classmethod
    def from_modal(cls, zeta, natural_frequency_Hz, inertia_kg_m2, equilibrium_rad=0.0):
        """From the damping ratio ζ and the natural frequency f_n = ω_n/2π:
        k = J·ω_n², c = 2·ζ·√(k·J) = 2·ζ·J·ω_n (Cullinan eq. 11)."""
        inertia = jnp.asarray(inertia_kg_m2, float)
        omega_n = 2.0 * jnp.pi * jnp.asarray(natural_frequency_Hz, float)
        damping = 2.0 * jnp.asarray(zeta, float) * inertia * omega_n
        return cls(inertia, inertia * omega_n**2, damping, equilibrium_rad)

    @property
    def natural_frequency_rad_s(self) -> Float[Array, "..."]:
        """ω_n = √(k/J)."""
        return jnp.sqrt(self.stiffness_Nm_per_rad / self.inertia_kg_m2)

    @property
    def zeta(self) -> Float[Array, "..."]:
        """Damping ratio ζ = c / (2·√(k·J)), Cullinan eq. 11 solved for ζ."""
        return self.damping_Nms_per_rad / (
            2.0 * jnp.sqrt(self.stiffness_Nm_per_rad * self.inertia_kg_m2)
        )

    @property
    def damped_frequency_rad_s(self) -> Float[Array, "..."]:
        """ω_d = ω_n·√(1 − ζ²) (NaN when over-damped)."""
        return self.natural_frequency_rad_s * jnp.sqrt(1.0 - self.zeta**2)


def cos_sinc(w2, t):
    """C = cos(√w2·t) and S = sin(√w2·t)/√w2, continued to w2 ≤ 0 (cosh, sinh/√−w2).

    Near w2·t² = 0 a Taylor series replaces the quotient, so values and gradients are finite
    at critical damping too (the double-where keeps NaN out of the unused branch's gradient).
    """
    x = w2 * t**2
    small = jnp.abs(x) < 1e-4
    w2_safe = jnp.where(small, 1.0, w2)
    w = jnp.sqrt(jnp.abs(w2_safe))
    c_osc, s_osc = jnp.cos(w * t), jnp.sin(w * t) / w
    c_hyp, s_hyp = jnp.cosh(w * t), jnp.sinh(w * t) / w
    c = jnp.where(w2_safe > 0, c_osc, c_hyp)
    s = jnp.where(w2_safe > 0, s_osc, s_hyp)
    c_series = 1.0 - x / 2.0 + x**2 / 24.0
    s_series = t * (1.0 - x / 6.0 + x**2 / 120.0)
    return jnp.where(small, c_series, c), jnp.where(small, s_series, s)


def oscillator_response(
    osc: DampedOscillator, angle0_rad: ArrayLike, rate0_rad_s: ArrayLike, t_s: ArrayLike
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Closed-form angle and rate of the linear oscillator at times ``t_s`` after the start.

    With u = β − β_eq, σ = c/(2J) = ζ·ω_n and ω_d² = ω_n² − σ² (any sign):

        u(t) = e^(−σt)·[u0·C(t) + (v0 + σ·u0)·S(t)],
        u̇(t) = e^(−σt)·[v0·C(t) − (σ·v0 + ω_n²·u0)·S(t)],

    C = cos ω_d t, S = sin(ω_d t)/ω_d (cosh and sinh when over-damped). Broadcasts over all
    arguments (``t_s`` usually last: give the oscillator fields a trailing axis of 1 for a
    batch of trajectories).
    """
    t = jnp.asarray(t_s, float)
    u0 = jnp.asarray(angle0_rad, float) - osc.equilibrium_rad
    v0 = jnp.asarray(rate0_rad_s, float)
    sigma = osc.damping_Nms_per_rad / (2.0 * osc.inertia_kg_m2)
    wn2 = osc.stiffness_Nm_per_rad / osc.inertia_kg_m2
    c, s = cos_sinc(wn2 - sigma**2, t)
    decay = jnp.exp(-sigma * t)
    angle = osc.equilibrium_rad + decay * (u0 * c + (v0 + sigma * u0) * s)
    rate = decay * (v0 * c - (sigma * v0 + wn2 * u0) * s)
    return angle, rate


def rk4_scan(
    rhs: Callable[[Array], Array], y0: Array, dt_s: float, n_samples: int, substeps: int = 1
) -> Float[Array, "n_samples state"]:
    """Integrate the autonomous ODE ẏ = rhs(y) with classical RK4 at a fixed step.

    Returns the state at ``n_samples`` times 0, dt, 2·dt, … (the first row is ``y0``); each
    output interval is covered by ``substeps`` equal RK4 steps. A ``lax.scan`` over output
    samples with a ``fori_loop`` of substeps inside: one compiled loop, differentiable in
    reverse mode, and vmappable (the batch advances in lockstep, which costs nothing at a
    fixed step).
    """
    h = dt_s / substeps

    def rk4(_, y):
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * h * k1)
        k3 = rhs(y + 0.5 * h * k2)
        k4 = rhs(y + h * k3)
        return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def step(y, _):
        y = jax.lax.fori_loop(0, substeps, rk4, y) if substeps > 1 else rk4(0, y)
        return y, y

    _, ys = jax.lax.scan(step, y0, None, length=n_samples - 1)
    return jnp.concatenate([y0[None], ys], axis=0)


def sample_times(duration_s: float, sample_rate_Hz: float) -> tuple[int, float]:
    """Number of samples (both ends included) and the sample interval for a uniform grid."""
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise ValueError(f"duration_s must be a positive number of seconds, got {duration_s!r}")
    if not (sample_rate_Hz > 0 and math.isfinite(sample_rate_Hz)):
        raise ValueError(f"sample_rate_Hz must be positive, got {sample_rate_Hz!r}")
    n = int(round(duration_s * sample_rate_Hz)) + 1
    if n < 2:
        raise ValueError(
            f"duration_s = {duration_s} s at {sample_rate_Hz} Hz gives fewer than 2 samples"
        )
    return n, 1.0 / sample_rate_Hz


def batch_apply(fn: Callable, model: eqx.Module, *args: ArrayLike):
    """Apply ``fn(model, *args)`` (written for one run) to a batch, with one ``vmap``.

    The model's array fields and ``args`` broadcast to a common batch shape B; the result has
    leaves of shape (*B, ...). Broadcast leaves are materialised once (cheap: one number per
    run per field).
    """
    leaves, treedef = jax.tree_util.tree_flatten(model)
    arrays = [jnp.asarray(x, float) for x in leaves] + [jnp.asarray(a, float) for a in args]
    shape = jnp.broadcast_shapes(*(a.shape for a in arrays))
    size = math.prod(shape)
    flat = [jnp.broadcast_to(a, shape).reshape(size) for a in arrays]

    def one(*xs):
        m = jax.tree_util.tree_unflatten(treedef, list(xs[: len(leaves)]))
        return fn(m, *xs[len(leaves):])

    out = jax.vmap(one)(*flat)
    return jax.tree_util.tree_map(lambda y: y.reshape(*shape, *y.shape[1:]), out)


class OscillatorRun(NamedTuple):
    """A simulated decay: ``time_s`` (T,), and ``angle_rad``, ``rate_rad_s`` of shape (*B, T)
    (``rate_rad_s`` is None when not asked for)."""

    time_s: Float[Array, " T"]
    angle_rad: Float[Array, "... T"]
    rate_rad_s: Float[Array, "... T"] | None


def _oscillator_rhs(osc: DampedOscillator):
    def rhs(y):
        angle, rate = y[0], y[1]
        torque = -osc.stiffness_Nm_per_rad * (angle - osc.equilibrium_rad) - (
            osc.damping_Nms_per_rad * rate
        )
        return jnp.stack([rate, torque / osc.inertia_kg_m2])

    return rhs


def _propagator(osc: DampedOscillator, dt_s: float):
    """Entries of Φ = exp(A·dt), the exact one-sample map of (β − β_eq, β̇), from the closed
    form of :func:`oscillator_response` (columns: response to a unit angle, to a unit rate)."""
    sigma = osc.damping_Nms_per_rad / (2.0 * osc.inertia_kg_m2)
    wn2 = osc.stiffness_Nm_per_rad / osc.inertia_kg_m2
    c, s = cos_sinc(wn2 - sigma**2, jnp.asarray(dt_s, float))
    e = jnp.exp(-sigma * dt_s)
    return e * (c + sigma * s), e * s, -e * wn2 * s, e * (c - sigma * s)


def _exact_blocked(osc, a0, r0, dt, n, block, with_rate):
    """The sampled exact solution of a flat batch (fields and states of shape (B,)).

    Samples come in blocks of ``block``: the block-start states follow from one another by
    the exact map over a block, Φ(block·dt), in a short ``lax.scan``; within a block the
    sample j is Φ(j·dt) applied to the block start, with Φ(j·dt) from the closed form. Every
    output element is then two multiply-adds in a (B, blocks, block) array that is written
    in place of the (B, T) output, without the transpose a scan over samples would need.
    Exact up to rounding (the scan has only T/block steps).
    """
    n_blocks = -(-n // block)
    column = jax.tree_util.tree_map(lambda x: x[:, None], osc)
    p_uu, p_uv, p_vu, p_vv = _propagator(column, dt * jnp.arange(block))  # (B, block)
    q_uu, q_uv, q_vu, q_vv = _propagator(osc, block * dt)  # (B,)

    def step(carry, _):
        u, v = carry
        return (q_uu * u + q_uv * v, q_vu * u + q_vv * v), carry

    u0 = a0 - osc.equilibrium_rad
    _, (u_start, v_start) = jax.lax.scan(step, (u0, r0), None, length=n_blocks)
    u_start, v_start = u_start.T[:, :, None], v_start.T[:, :, None]  # (B, blocks, 1)
    batch = a0.shape[0]
    angle = osc.equilibrium_rad[:, None, None] + (
        p_uu[:, None, :] * u_start + p_uv[:, None, :] * v_start
    )
    angle = angle.reshape(batch, n_blocks * block)[:, :n]
    if not with_rate:
        return angle, None
    rate = p_vu[:, None, :] * u_start + p_vv[:, None, :] * v_start
    return angle, rate.reshape(batch, n_blocks * block)[:, :n]


#: Samples per block of the exact method (measured: 64–256 are equally fast; 128 used).
EXACT_BLOCK = 128


@eqx.filter_jit
def _simulate_oscillator(osc, angle0, rate0, n, dt, method, substeps, with_rate):
    if method == "exact":
        leaves, treedef = jax.tree_util.tree_flatten(osc)
        shape = jnp.broadcast_shapes(*(x.shape for x in (*leaves, angle0, rate0)))
        size = math.prod(shape)

        def flat(x):
            return jnp.broadcast_to(x, shape).reshape(size)

        flat_osc = jax.tree_util.tree_unflatten(treedef, [flat(x) for x in leaves])
        angle, rate = _exact_blocked(flat_osc, flat(angle0), flat(rate0), dt, n,
                                     min(EXACT_BLOCK, n), with_rate)
        angle = angle.reshape(*shape, n)
        return angle, None if rate is None else rate.reshape(*shape, n)

    def one(osc, a0, r0):
        ys = rk4_scan(_oscillator_rhs(osc), jnp.stack([a0, r0]), dt, n, substeps)
        return ys[:, 0], (ys[:, 1] if with_rate else None)

    return batch_apply(one, osc, angle0, rate0)


def simulate_oscillator(
    osc: DampedOscillator,
    angle0_rad: ArrayLike,
    rate0_rad_s: ArrayLike = 0.0,
    *,
    duration_s: float,
    sample_rate_Hz: float = 1000.0,
    method: str = "exact",
    substeps: int = 1,
    with_rate: bool = True,
) -> OscillatorRun:
    """Simulate free decays of the linear oscillator, one or a batch, sampled uniformly.

    Args:
        osc: the oscillator; fields of shape () or with leading batch axes.
        angle0_rad, rate0_rad_s: the state at t = 0 (broadcast with the fields).
        duration_s, sample_rate_Hz: output grid 0, 1/rate, …, duration (both ends included).
        method: ``"exact"`` (default): the sampled closed form, computed blockwise with the
            exact transition Φ = exp(A·dt) (exact up to rounding, and the fastest); or
            ``"rk4"``: fixed-step RK4 in ``lax.scan``, the integrator pamid's nonlinear
            simulators use (kept here to check it against the exact solution).
        substeps: RK4 steps per output interval.
        with_rate: also return the rate (``rate_rad_s`` is None otherwise; skipping it
            halves the memory written for large batches).

    Returns:
        :class:`OscillatorRun` with arrays of shape (*batch, T).
    """
    if method not in ("rk4", "exact"):
        raise ValueError(f"method must be 'rk4' or 'exact', got {method!r}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    n, dt = sample_times(duration_s, sample_rate_Hz)
    angle, rate = _simulate_oscillator(
        osc, jnp.asarray(angle0_rad, float), jnp.asarray(rate0_rad_s, float), n, dt, method,
        int(substeps), bool(with_rate),
    )
    return OscillatorRun(dt * jnp.arange(n), angle, rate)
