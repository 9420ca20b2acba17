"""The ``coulomb_friction`` effect of a free decay: a constant friction torque against the
motion; the effect as a model that wraps the linear oscillator (:class:`CoulombFriction`)
and its definition. Its injector is the virtual decay bench's ``coulomb_Nm``
(:func:`pamid._virtual._decay.simulate_decays`).

With the friction, J·β̈ + c·β̇ + k·(β − β_eq) + T_c·sign(β̇) = 0, and the arm sticks for good
when it comes to rest where k·|β − β_eq| ≤ T_c. Between two instants of zero velocity the
friction torque is constant, so each half cycle is the base oscillator's closed-form decay
about the shifted centre β_eq − sign(β̇)·u_c, u_c = T_c/k; a half cycle started from rest
lasts exactly π/ω_d. (Neither source has it; it is standard mechanics. Cullinan blames the
sleeve PAM's hysteresis on the seal's friction, section IV.) :mod:`pamid._decays._coulomb`
says how the decay diagnosis fits it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import Constant, DecayEffect
from ._wrappers import EffectWrapper

#: Duration of a half cycle that never ends (over-damped, or stuck), in s: finite, so that
#: no inf or NaN enters a gradient, and longer than any record.
NEVER_S = 1e12


def half_cycles(segment, sigma, wn2, u0, v0, shift, n_half):
    """Start time, centre and start state (x0 about the centre, v0) of each half cycle of
    the oscillator whose free decay about its centre is ``segment(σ, ω_n², x0, v0, s)``,
    started from the displacement ``u0`` and rate ``v0``, with the friction as the angle
    ``shift`` = u_c.

    Returns (starts, centres, x0s, v0s, end): arrays of length ``n_half`` and the end time
    of the last half cycle. The velocity is zero at the start of every half cycle but the
    first; the next rest comes π/ω_d later, or, for the first, at the first zero of the
    rate (as ``_next_rest`` in :mod:`pamid._virtual._decay`, in a form that stays
    accurate near critical damping). Without oscillation (ω_d² ≤ 0) the first half cycle
    never ends, as in the reference. A stuck arm is a "half cycle" that starts at rest on
    its own centre and never ends, so sticking needs no separate branch.
    """
    wd2 = wn2 - sigma**2
    turns = wd2 > 0
    wd = jnp.sqrt(jnp.where(turns, wd2, 1.0))

    def step(carry, _):
        u, v, tau, stuck = carry
        stuck = stuck | ((shift > 0) & (v == 0) & (jnp.abs(u) <= shift))
        direction = jnp.where(v != 0, jnp.where(v > 0, 1.0, -1.0), jnp.where(u >= 0, -1.0, 1.0))
        centre = jnp.where(stuck, u, -direction * shift)
        x0 = jnp.where(stuck, 0.0, u - centre)
        v = jnp.where(stuck, 0.0, v)
        # The rate is e^(−σs)·(v·cos ω_d s − q·sin(ω_d s)/ω_d), q = σ·v + ω_n²·x0: it is next
        # zero at ω_d·s = θ ∈ (0, π] with tan θ = v·ω_d/q. From rest that is exactly π;
        # atan2(|v|·ω_d, sign(v)·q) stays accurate as ω_d → 0 (near critical damping,
        # θ/ω_d → v/q), and runs on safe values so that a stuck arm's atan2(0, 0) puts no
        # NaN into a gradient.
        moving = v != 0
        v_safe = jnp.where(moving, v, 1.0)
        sign = jnp.where(v_safe > 0, 1.0, -1.0)
        theta = jnp.arctan2(jnp.abs(v_safe) * wd, sign * (sigma * v_safe + wn2 * x0))
        theta = jnp.where(moving & (theta > 0), theta, math.pi)
        ends = turns & ~stuck
        span = jnp.where(ends, theta / wd, NEVER_S)
        x_end = segment(sigma, wn2, x0, v, jnp.where(ends, span, 0.0))
        return (centre + x_end, jnp.zeros_like(v), tau + span, stuck), (tau, centre, x0, v)

    init = (u0, v0, jnp.zeros_like(u0), jnp.zeros_like(u0, dtype=bool))
    (_, _, end, _), (starts, centres, x0s, v0s) = jax.lax.scan(step, init, None, length=n_half)
    return starts, centres, x0s, v0s, end


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class CoulombFriction(EffectWrapper):
    """A free decay with Coulomb friction: ``theta`` = (θ of the base oscillator, u_c in
    rad), ``x`` = (time since the start, s,). ``CoulombFriction.wrap(base, n_half=…)``.

    The base is a linear oscillator's free response that says its modal constants
    (``modal(θ) -> (σ, ω_n²)``), its state at t = 0 about its centre (``state0(θ) ->
    (β_eq, u0, v0)``) and its closed form about the centre (``segment(σ, ω_n², x0, v0,
    s)``): :class:`pamid._decays._analysis.Trajectory`. Every sample evaluates the closed
    form of its half cycle (module text; found with ``searchsorted``), so the response is
    exact, with no smoothed sign. The position and the velocity are continuous at the
    half-cycle boundaries, so the samples' derivatives with respect to the boundary times
    are the velocity's (zero there), and every constant has a finite gradient except where
    a change flips a sticking decision.

    u_c may take either sign: a negative u_c is the analytic continuation ("friction" that
    feeds energy in, the amplitude growing by 2·|u_c| per half cycle; it never sticks), so
    that near u_c = 0 the fit and its Wald interval are smooth and an interval can contain
    0; the diagnosis reports T_c = u_c·k ≤ 0 as not physical. ``n_half`` half cycles are
    computed (static); times after the end of the last one are NaN, unless the arm stuck.
    """

    n_half: int
    constants: ClassVar[tuple[Constant, ...]] = (Constant("coulomb_shift_rad", "rad"),)

    def predict(self, theta, x):
        base, (theta_b, (shift,)) = self.base, self.split(theta)
        t = x[0]
        sigma, wn2 = base.modal(theta_b)
        eq, u0, v0 = base.state0(theta_b)
        starts, centres, x0s, v0s, end = half_cycles(
            base.segment, sigma, wn2, u0, v0, shift, self.n_half)
        k = jnp.clip(jnp.searchsorted(starts, t, side="right") - 1, 0, self.n_half - 1)
        u = centres[k] + base.segment(sigma, wn2, x0s[k], v0s[k], t - starts[k])
        return jnp.where(t < end, eq + u, jnp.nan)

    def split(self, theta):
        theta_b, t = super().split(theta)
        return theta_b, (t[0],)

    def _key_fields(self) -> tuple:
        return (self.n_half,)


def coulomb_friction() -> DecayEffect:
    """The ``coulomb_friction`` effect of a free decay (module text)."""
    return DecayEffect(
        "coulomb_friction", "velocity_rad_s", "coulomb_Nm",
        Constant("coulomb_Nm", "N·m", lower=0.0),
        "pamid._virtual._decay.simulate_decays (coulomb_Nm=)",
        "A constant friction torque T_c·sign(β̇) (the sliding seal, the cable over the "
        "pulley): the amplitude falls linearly instead of geometrically; T_c ≥ 0 "
        "(dissipation).",
        model=CoulombFriction)
