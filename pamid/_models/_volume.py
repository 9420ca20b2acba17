"""Gas volume of a braided PAM, traditional and sleeve, and its pressure when sealed.

Source of the geometry: C.-P. Chou and B. Hannaford, "Measurement and modelling of McKibben
pneumatic artificial muscles" (1996), ref. [21] of Cullinan, McGinn and Kelly, "Sleeve
Pneumatic Artificial Muscles for Antagonistically Actuated Joints".
Cullinan uses the volume of a PAM for the closed-system stiffness (Section V) and the energy
of the ideal compressor (Section VII, eq. 13–14); its own volume model, fitted to
measurements in its ref. [12], is not printed, so pamid uses the braid's geometry instead.

The braid (Chou & Hannaford): each fibre has the length ``b`` and winds ``n`` times around
the muscle; both are fixed. At the braid angle θ (between fibre and axis) the active length
and the diameter are

    L = b·cos θ,        D = b·sin θ / (n·π),

so the volume of the cylinder they bound is

    V_braid(L) = π·D²·L/4 = L·(b² − L²) / (4·π·n²).

With L = L0 − y (y the contraction) and the rest state (y = 0) at the diameter D0 and the
braid angle θ0, b = L0 / cos θ0 and n = L0·tan θ0 / (π·D0), which gives the form used here,

    V_braid(y) = (π·D0²/4) · L · (b² − L²) / (b² − L0²),   L = L0 − y.

dV_braid/dy = (π·D0²/4)·(3·L² − b²)/(b² − L0²) > 0 while θ < arctan √2 ≈ 54.74°: the muscle
bulges as it contracts, so its gas volume grows with contraction over the whole working range,
and the model stops at ``max_contraction_mm`` (θ = 54.74°, where V_braid is largest).

Sleeve PAM (Cullinan Fig. 2): a solid internal element of diameter d fills the core between
the end fittings; it is fixed to one fitting and slides through the other, so the length of
element inside the gas space is the active length L = L0 − y, and it displaces π·d²/4·L.

Assumptions (none of these numbers is printed by Cullinan):

* The gas column follows the braid's kinematics with the bladder's inner diameter as D0
  (40 mm in Cullinan Section III); the 1.5 mm latex wall is taken as thin. Putting the braid
  at the wall's outside (43 mm at rest) with the gas column 3 mm narrower would give the
  same volume at rest and about 6 % more at 48 mm of contraction.
* The rest braid angle θ0 = 25° is assumed (typical braided PAMs sit at 20°–25° at rest);
  the volume's growth with contraction depends strongly on it.
* The tapered ends near the end fittings are treated as part of the cylinder.
* A constant dead volume (ports, end-fitting bores, the tube to the valve) is added; 5 cm³ is
  assumed for both PAM types.
* The sleeve PAM's internal element is assumed to be 25 mm in diameter.

Closed system: with the valves shut at (y0, P0′) the mass of air is constant and, for a
polytropic change, P·V^k = const in absolute pressure (k = 1: isothermal, the default;
k = 1.4: adiabatic), so P′(y) = (P0′ + P_atm)·(V(y0)/V(y))^k − P_atm.

Units: mm, mm³, kPa (gauge unless named otherwise), rad.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._checks import concrete_or_none, require
from .._units import ATMOSPHERE_KPA

#: The braid angle at which a braided muscle stops contracting, arctan √2 ≈ 54.74°.
MAX_BRAID_ANGLE_RAD = math.atan(math.sqrt(2.0))


class PamVolume(eqx.Module):
    """Geometry that fixes the gas volume of one braided PAM (see the module docstring).

    Fields, all float64 arrays that may carry leading batch axes:

    * ``active_length_mm``: L0, the distance between the end fittings at rest (y = 0).
    * ``rest_diameter_mm``: D0, the gas column's diameter at rest.
    * ``rest_braid_angle_rad``: θ0, the braid angle at rest, in (0, 54.74°).
    * ``dead_volume_mm3``: constant volume added (ports, fittings, tube to the valve).
    * ``element_diameter_mm``: d, the sleeve PAM's internal element; 0 for a traditional PAM.
    """

    active_length_mm: Float[Array, "..."]
    rest_diameter_mm: Float[Array, "..."]
    rest_braid_angle_rad: Float[Array, "..."]
    dead_volume_mm3: Float[Array, "..."]
    element_diameter_mm: Float[Array, "..."]

    def __init__(
        self,
        active_length_mm,
        rest_diameter_mm,
        rest_braid_angle_rad,
        dead_volume_mm3=0.0,
        element_diameter_mm=0.0,
    ):
        require("active_length_mm", active_length_mm, lambda a: a > 0, "> 0")
        require("rest_diameter_mm", rest_diameter_mm, lambda a: a > 0, "> 0")
        require(
            "rest_braid_angle_rad",
            rest_braid_angle_rad,
            lambda a: (a > 0) & (a < MAX_BRAID_ANGLE_RAD),
            f"in (0, {MAX_BRAID_ANGLE_RAD:.4f}) rad, i.e. below 54.74°",
        )
        require("dead_volume_mm3", dead_volume_mm3, lambda a: a >= 0, ">= 0")
        require("element_diameter_mm", element_diameter_mm, lambda a: a >= 0, ">= 0")
        d_el, d_0 = concrete_or_none(element_diameter_mm), concrete_or_none(rest_diameter_mm)
        if d_el is not None and d_0 is not None and not np.all(d_el < d_0):
            raise ValueError(
                "element_diameter_mm must be smaller than rest_diameter_mm "
                f"(the element sits inside the bladder); got {d_el.tolist()} >= {d_0.tolist()}"
            )
        self.active_length_mm = jnp.asarray(active_length_mm, float)
        self.rest_diameter_mm = jnp.asarray(rest_diameter_mm, float)
        self.rest_braid_angle_rad = jnp.asarray(rest_braid_angle_rad, float)
        self.dead_volume_mm3 = jnp.asarray(dead_volume_mm3, float)
        self.element_diameter_mm = jnp.asarray(element_diameter_mm, float)

    @property
    def fibre_length_mm(self) -> Float[Array, "..."]:
        """b = L0 / cos θ0, the length of one braid fibre (Chou & Hannaford)."""
        return self.active_length_mm / jnp.cos(self.rest_braid_angle_rad)

    @property
    def turns(self) -> Float[Array, "..."]:
        """n = L0·tan θ0 / (π·D0), the number of turns of one fibre (Chou & Hannaford)."""
        return (
            self.active_length_mm
            * jnp.tan(self.rest_braid_angle_rad)
            / (jnp.pi * self.rest_diameter_mm)
        )

    @property
    def max_contraction_mm(self) -> Float[Array, "..."]:
        """Contraction at θ = 54.74°, L = b/√3, where the braid cannot shorten further."""
        return self.active_length_mm - self.fibre_length_mm / jnp.sqrt(3.0)


def traditional_pam_volume(
    active_length_mm: float = 190.0,
    rest_diameter_mm: float = 40.0,
    rest_braid_angle_deg: float = 30.0,
    dead_volume_mm3: float = 5000.0,
) -> PamVolume:
    """A traditional braided PAM like Cullinan's (Section III): L0 = 190 mm, D0 = 40 mm.

    θ0 = 30° and the 5 cm³ dead volume are assumptions, the same ones behind the fitted
    force presets of ``pamid._models._cullinan_presets`` (θ0 = 30° gives the paper's 15 N·m
    at ±0.6 rad; see there).
    """
    return PamVolume(
        active_length_mm, rest_diameter_mm, math.radians(rest_braid_angle_deg), dead_volume_mm3
    )


def sleeve_pam_volume(
    active_length_mm: float = 190.0,
    rest_diameter_mm: float = 40.0,
    rest_braid_angle_deg: float = 30.0,
    dead_volume_mm3: float = 5000.0,
    element_diameter_mm: float = 30.0,
) -> PamVolume:
    """A sleeve PAM like Cullinan's (Fig. 2): the traditional PAM with an internal element.

    The element's 30 mm diameter is an assumption (a sliding fitting needs a wall around it
    inside the 40 mm bore); it removes π·d²/4·(L0 − y) of gas volume. Same assumptions as
    the force presets of ``pamid._models._cullinan_presets``.
    """
    return PamVolume(
        active_length_mm,
        rest_diameter_mm,
        math.radians(rest_braid_angle_deg),
        dead_volume_mm3,
        element_diameter_mm,
    )


def braid_volume_mm3(volume: PamVolume, contraction_mm: ArrayLike) -> Float[Array, "..."]:
    """Volume in mm³ inside the braid alone (Chou & Hannaford), without element or dead volume.

    V_braid = (π·D0²/4)·L·(b² − L²)/(b² − L0²) with L = L0 − y; equals π·D0²·L0/4 at y = 0.
    """
    y = jnp.asarray(contraction_mm, float)
    length = volume.active_length_mm - y
    b2 = volume.fibre_length_mm**2
    area0 = jnp.pi * volume.rest_diameter_mm**2 / 4.0
    return area0 * length * (b2 - length**2) / (b2 - volume.active_length_mm**2)


def volume_mm3(volume: PamVolume, contraction_mm: ArrayLike) -> Float[Array, "..."]:
    """Gas volume in mm³ of the PAM at the contraction ``contraction_mm``.

    V(y) = V_braid(y) − π·d²/4·(L0 − y) + V_dead, with d = 0 for a traditional PAM. Valid for
    0 ≤ y ≤ ``volume.max_contraction_mm``; outside, the formula is extrapolated unchecked.
    """
    y = jnp.asarray(contraction_mm, float)
    element = jnp.pi * volume.element_diameter_mm**2 / 4.0 * (volume.active_length_mm - y)
    return braid_volume_mm3(volume, y) - element + volume.dead_volume_mm3


def closed_system_pressure_kPa(
    volume: PamVolume,
    contraction0_mm: ArrayLike,
    p0_kPa: ArrayLike,
    contraction_mm: ArrayLike,
    polytropic_n: ArrayLike = 1.0,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
) -> Float[Array, "..."]:
    """Gauge pressure in kPa of a sealed PAM at ``contraction_mm`` (Cullinan Section V).

    The valves shut at the contraction y0 and the gauge pressure P0′; the mass of air stays
    constant and (P′ + P_atm)·V^k is constant (k = ``polytropic_n``; 1 is isothermal):

        P′(y) = (P0′ + P_atm)·(V(y0)/V(y))^k − P_atm.
    """
    require("polytropic_n", polytropic_n, lambda a: a > 0, "> 0")
    require("p_atm_kPa", p_atm_kPa, lambda a: a > 0, "> 0 (an absolute pressure)")
    p0, p_atm0 = concrete_or_none(p0_kPa), concrete_or_none(p_atm_kPa)
    if p0 is not None and p_atm0 is not None and not np.all(p0 + p_atm0 > 0):
        raise ValueError(
            f"p0_kPa is a gauge pressure and must be > -p_atm_kPa = {-p_atm0}; got {p0.tolist()}"
        )
    p_atm = jnp.asarray(p_atm_kPa, float)
    ratio = volume_mm3(volume, contraction0_mm) / volume_mm3(volume, contraction_mm)
    return (jnp.asarray(p0_kPa, float) + p_atm) * ratio ** jnp.asarray(polytropic_n) - p_atm
