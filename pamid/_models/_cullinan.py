"""Cullinan's phenomenological PAM model: contractile force, spring and damper in parallel.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", eq. 1–3.

    F = F_ce − K·y − c·ẏ                                   (eq. 2)
    F = A + B·P′ − (C + D·P′ + E·y)·y − G·ẏ                 (eq. 3)

with P′ the gauge pressure, y the contraction (a length) and ẏ its rate. The same form
describes traditional and sleeve PAMs; only the constants differ. pamid's units are N, kPa,
mm and s, so A [N], B [N/kPa], C [N/mm], D [N/(kPa·mm)], E [N/mm²], G [N·s/mm].

Why the sleeve PAM pulls harder (eq. 1): the pressure also pushes on the end fittings,
F_end = P′·A_d, against the braid's contraction. The sleeve's internal element passes through
the sliding end fitting, so the area A_d on which the pressure acts is smaller, and less of
the braid's force is lost; in eq. 3 this shows as a larger B.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._protocol import ForceModel

CULLINAN_NAMES: tuple[str, ...] = ("A", "B", "C", "D", "E", "G")
CULLINAN_UNITS: dict[str, str] = {
    "A": "N",
    "B": "N/kPa",
    "C": "N/mm",
    "D": "N/(kPa*mm)",
    "E": "N/mm^2",
    "G": "N*s/mm",
}


class Cullinan(ForceModel):
    """Cullinan eq. 3: F = A + B·P′ − (C + D·P′ + E·y)·y − G·ẏ (N, kPa, mm, s).

    Fields may carry leading batch axes, one set per muscle. ``G`` defaults to 0 (a static
    fit determines A–E only; G comes from dynamic data).
    """

    A: Float[Array, "..."]
    B: Float[Array, "..."]
    C: Float[Array, "..."]
    D: Float[Array, "..."]
    E: Float[Array, "..."]
    G: Float[Array, "..."]

    names: ClassVar[tuple[str, ...]] = CULLINAN_NAMES
    units: ClassVar[dict[str, str]] = CULLINAN_UNITS
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_mm", "velocity_mm_s")
    name: ClassVar[str] = "cullinan"
    source: ClassVar[str] = "Cullinan eq. 3"

    def __init__(self, A, B, C, D, E, G=0.0):  # noqa: N803 (the paper's names)
        self.A, self.B, self.C = jnp.asarray(A), jnp.asarray(B), jnp.asarray(C)
        self.D, self.E, self.G = jnp.asarray(D), jnp.asarray(E), jnp.asarray(G)

    @classmethod
    def from_vector(cls, theta: Float[ArrayLike, "... k"]) -> Cullinan:
        """From a vector (A, B, C, D, E) or (A, B, C, D, E, G) in its last axis."""
        theta = jnp.asarray(theta)
        g = theta[..., 5] if theta.shape[-1] == 6 else jnp.zeros_like(theta[..., 0])
        return cls(*(theta[..., i] for i in range(5)), g)

    def to_vector(self, with_g: bool = True) -> Float[Array, "... k"]:
        fields = [self.A, self.B, self.C, self.D, self.E] + ([self.G] if with_g else [])
        return jnp.stack(jnp.broadcast_arrays(*fields), axis=-1)

    def __call__(self, pressure_kPa: ArrayLike, contraction_mm: ArrayLike,
                 velocity_mm_s: ArrayLike = 0.0):
        """The force in N, eq. 3 (:func:`cullinan_force`)."""
        return cullinan_force(self, pressure_kPa, contraction_mm, velocity_mm_s)


def cullinan_force(
    params: Cullinan,
    pressure_kPa: ArrayLike,
    contraction_mm: ArrayLike,
    velocity_mm_s: ArrayLike = 0.0,
) -> Float[Array, "..."]:
    """Muscle force in N, Cullinan eq. 3: F = A + B·P′ − (C + D·P′ + E·y)·y − G·ẏ.

    ``velocity_mm_s`` is the contraction rate ẏ (positive while the muscle shortens).
    """
    p = jnp.asarray(pressure_kPa)
    y = jnp.asarray(contraction_mm)
    v = jnp.asarray(velocity_mm_s)
    return params.A + params.B * p - (params.C + params.D * p + params.E * y) * y - params.G * v


def cullinan_spring_rate(
    params: Cullinan, pressure_kPa: ArrayLike, contraction_mm: ArrayLike
) -> Float[Array, "..."]:
    """−∂F/∂y in N/mm, closed form of eq. 3: C + D·P′ + 2·E·y (the muscle's own stiffness)."""
    return (
        params.C
        + params.D * jnp.asarray(pressure_kPa)
        + 2.0 * params.E * jnp.asarray(contraction_mm)
    )


def end_fitting_force(pressure_kPa: ArrayLike, area_mm2: ArrayLike) -> Float[Array, "..."]:
    """Force in N of the pressure on an end fitting, Cullinan eq. 1: F_end = P′·A_d.

    kPa·mm² = 10⁻³ N. This force acts against the braid's contraction; the sleeve PAM's
    internal element makes A_d smaller.
    """
    return jnp.asarray(pressure_kPa) * jnp.asarray(area_mm2) * 1e-3
