"""Sárosi's single-surface sliding-mode position controller with its precision zone.

Source: Sárosi, dissertation summary, Sections 2.4.1, 3.3 and result 5 of Section 4: a
LabVIEW sliding-mode controller with one sliding surface whose gradient sets the quality of
the control (best 0.35 for the linear rig, 0.3 for the rotary one), five valve voltages —
fast backward 4 V, slow backward 4.65 V, in position 5 V, slow forward 5.35 V, fast
forward 6 V — a 10 ms sampling time, and a "barrier zone (precision zone) along the sliding
surface" that removes the chattering.

The summary does not print the switching law, so pamid reads it as follows (documented
interpretation, not a quotation). At sample k, with the encoder reading q_k, the target r_k
and the position error e_k = r_k − q_k,

    s_k = λ·e_k − (q_k − q_{k−1})                                   (the sliding surface)

i.e. s = λ·e + Δe with the error's change per sample taken from the measurement (so a new
target does not kick it). λ (the gradient) is per sample, as a LabVIEW loop sees it, which
makes it dimensionless: the surface s = 0 is the line Δe = −λ·e of the phase plane
(e, Δe), along which the error decays by the factor (1 − λ) per sample (λ/T = 35 s⁻¹ for
λ = 0.35 at T = 10 ms). The voltage is a five-level relay:

    |e| < ε_p                    in position   5 V      (the precision zone)
    otherwise |s| < λ·ε_s        slow          5 ± 0.35 V
    otherwise                    fast          5 ± 1 V

with the sign of s choosing forward (+) or backward (−). The precision zone is the strip
|e| < ε_p of the phase plane around the end of the sliding line: inside it the valve is
shut whatever the error's rate, and the muscles' own damping ends the motion. ε_p = 1.5
encoder counts by default, so an error of one count is held and one of two is corrected:
the steady-state error is limited by the encoder, as Sárosi concludes. (A zone bounded by
lines parallel to the surface, |s| < λ·ε_p, was tried first: it admits only states at rest,
and on the 20 kg rig the sampled relay then hunted around a 5 mm target by ±6 counts, where
the strip settles.) The slow band |s| < λ·ε_s is, at rest, |e| < ε_s; ε_s is
not given in the source and its default (:data:`SLOW_BAND_COUNTS`) is an assumption.

The plain switching controller is the same law without the precision zone (ε_p = 0): it
never commands "in position", so it keeps switching between slow forward and slow backward
at the target — the chattering the zone removes.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "FAST_BACKWARD_V",
    "FAST_FORWARD_V",
    "IN_POSITION_V",
    "LINEAR_GRADIENT",
    "ROTARY_GRADIENT",
    "SLOW_BACKWARD_V",
    "SLOW_FORWARD_V",
    "SlidingModeController",
    "plain_switching",
    "sliding_mode_voltage",
    "sliding_surface",
]

#: The five valve voltages of Sárosi Sections 2.4.1 and 3.3.1.
FAST_BACKWARD_V = 4.0
SLOW_BACKWARD_V = 4.65
IN_POSITION_V = 5.0
SLOW_FORWARD_V = 5.35
FAST_FORWARD_V = 6.0
#: Best gradients of the sliding surface: linear rig (Section 3.3.1), rotary (Section 3.3.3).
LINEAR_GRADIENT = 0.35
ROTARY_GRADIENT = 0.3
#: Precision zone half-width in encoder counts (pamid's reading; see the module docstring).
PRECISION_ZONE_COUNTS = 1.5
#: Slow band half-width on the error axis, in encoder counts (an assumption: 200 counts,
#: 2 mm on the linear encoder, 7.2° on the rotary one). The sensitivity scan of
#: ``experiments/sarosi_positioning.py`` keeps it: 100 counts shortens the linear 15 mm move
#: (settled 1.71 s instead of 2.49 s) but doubles the 20 kg rig's overshoot (median 12
#: counts instead of 5), and 400 counts slows every move (40 mm reached in 2.1 s, not 1.5 s).
SLOW_BAND_COUNTS = 200.0


class SlidingModeController(eqx.Module):
    """Sárosi's five-level sliding-mode controller (see the module docstring).

    Fields (arrays; may carry batch axes): ``gradient`` λ (per sample), ``precision_zone``
    ε_p and ``slow_band`` ε_s (half-widths on the error axis, in position units: mm or
    degrees), and the five ``*_V`` voltages.
    """

    gradient: Float[Array, "..."]
    precision_zone: Float[Array, "..."]
    slow_band: Float[Array, "..."]
    fast_backward_V: Float[Array, "..."]
    slow_backward_V: Float[Array, "..."]
    in_position_V: Float[Array, "..."]
    slow_forward_V: Float[Array, "..."]
    fast_forward_V: Float[Array, "..."]

    def __init__(
        self,
        gradient=LINEAR_GRADIENT,
        precision_zone=0.015,
        slow_band=2.0,
        fast_backward_V=FAST_BACKWARD_V,
        slow_backward_V=SLOW_BACKWARD_V,
        in_position_V=IN_POSITION_V,
        slow_forward_V=SLOW_FORWARD_V,
        fast_forward_V=FAST_FORWARD_V,
    ):
        self.gradient = jnp.asarray(gradient, float)
        self.precision_zone = jnp.asarray(precision_zone, float)
        self.slow_band = jnp.asarray(slow_band, float)
        self.fast_backward_V = jnp.asarray(fast_backward_V, float)
        self.slow_backward_V = jnp.asarray(slow_backward_V, float)
        self.in_position_V = jnp.asarray(in_position_V, float)
        self.slow_forward_V = jnp.asarray(slow_forward_V, float)
        self.fast_forward_V = jnp.asarray(fast_forward_V, float)

    @classmethod
    def for_encoder(
        cls,
        resolution: float,
        gradient: float = LINEAR_GRADIENT,
        precision_counts: float = PRECISION_ZONE_COUNTS,
        slow_counts: float = SLOW_BAND_COUNTS,
    ) -> SlidingModeController:
        """The controller with its zones set in counts of an encoder of ``resolution``."""
        return cls(gradient, precision_counts * resolution, slow_counts * resolution)


def plain_switching(controller: SlidingModeController) -> SlidingModeController:
    """The same controller without its precision zone (ε_p = 0): plain switching."""
    return eqx.tree_at(
        lambda c: c.precision_zone, controller, jnp.zeros_like(controller.precision_zone)
    )


def sliding_surface(
    controller: SlidingModeController,
    error: ArrayLike,
    previous_reading: ArrayLike,
    reading: ArrayLike,
) -> Float[Array, "..."]:
    """s = λ·e − (q_k − q_{k−1}), in position units (see the module docstring)."""
    return controller.gradient * jnp.asarray(error, float) - (
        jnp.asarray(reading, float) - jnp.asarray(previous_reading, float)
    )


def sliding_mode_voltage(
    controller: SlidingModeController, s: ArrayLike, error: ArrayLike
) -> Float[Array, "..."]:
    """The valve voltage for the surface value ``s`` and the error ``error`` (= r − q):
    the five-level relay of Sárosi (see the module docstring)."""
    s = jnp.asarray(s, float)
    error = jnp.asarray(error, float)
    lam = controller.gradient
    a = jnp.abs(s)
    forward = s > 0
    slow = jnp.where(forward, controller.slow_forward_V, controller.slow_backward_V)
    fast = jnp.where(forward, controller.fast_forward_V, controller.fast_backward_V)
    u = jnp.where(a < lam * controller.slow_band, slow, fast)
    return jnp.where(jnp.abs(error) < controller.precision_zone, controller.in_position_V, u)
