"""Muscles and joints like Cullinan's, with constants obtained from a physical braided-PAM model.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints". The paper prints no numbers for the
constants A–G of eq. 3, nor for the volume model of its ref. [12]. What it does give
(Section III): an active length of 190 mm ± 2, a 40 mm inner-diameter latex bladder with a
1.5 mm wall, a PET braid, aluminium end fittings and internal element, an 80 mm pulley,
a 500 kPa supply and a 414 kPa maximum operating pressure; the traditional joint rotates
±0.6 rad with at least 15 N·m in both directions at the limits at 414 kPa.

How the presets are obtained. Rather than guessing A–E, pamid writes down a physical muscle
with a few geometric and material constants, measures it on a virtual static bench, and fits
eq. 3 to those data with :func:`pamid.fit_least_squares` — the same path a real bench file
takes. The presets therefore come with 95 % intervals, and the mismatch between eq. 3 and a
braided muscle is visible in the fit's RMSE.
:func:`pamid._virtual._braided.fit_cullinan_presets` repeats the fit; the numbers stored below
are its result (the tests check that they agree).

The physical muscle (:class:`BraidedPam`). By virtual work, the gas's work P′·dV equals
the work of the pull plus the strain energy stored in the bladder, so

    F(P′, y) = P′·dV/dy − dW/dy,

with V(y) the gas volume of :func:`~pamid._models._volume.volume_mm3` (Chou & Hannaford's
braid kinematics, the sleeve's internal element removed, a constant dead volume) and W(y)
the bladder's strain energy. Writing V_braid = π·D²·L/4 (L = L0 − y, D the current diameter)
splits the first term into the braid's contractile force and Cullinan's eq. 1:

    P′·dV/dy = F_braid − P′·A_d,   A_d = π·D(y)²/4 − π·d²/4,

where F_braid = P′·(π·L·D/2)·(−dD/dL) is the pressure on the bladder's wall turned into pull
by the braid, and A_d is the end-fitting area on which the pressure pushes the fittings apart
(eq. 1). The sleeve's internal element of diameter d passes through the sliding end fitting,
so its section does not count: A_d is smaller by π·d²/4 and the sleeve pulls harder by
P′·π·d²/4 at every contraction. The same V(y) serves the closed-system stiffness and the
compressor energy, so force, volume and energy are one consistent model.

The bladder is a neo-Hookean tube whose mid-surface follows the braid: hoop stretch
λθ = D/D0 = sin θ / sin θ0, axial stretch λz = L/L0, radial stretch 1/(λθ·λz) (incompressible),
W = μ·V_wall/2·(λθ² + λz² + (λθ·λz)⁻² − 3) with V_wall = π·(D0 + t)·t·L0. It resists
contraction with a force that does not depend on the pressure (Cullinan's C and E).

Assumed constants (none is printed by Cullinan; each is a round number, checked against a
statement of the paper):

* rest braid angle θ0 = 30° — ASSUMED. Typical braids sit at 20°–30° at rest. With 25°
  (the default of :func:`~pamid._models._volume.traditional_pam_volume`) the traditional
  muscle would pull 931 N at y = 48 mm (r·β_range) and 414 kPa, 37 N·m at the ±0.6 rad
  limits, and a joint built for "at least 15 N·m" would have been given a wider range. With
  30° it pulls 430 N there; with the cables' stretch and eq. 3 fitted, the presets give
  15.8 N·m at the limits: the paper's "at least 15 N·m at ±0.6 rad", nearly tight.
* bladder shear modulus μ = 0.3 MPa — ASSUMED (soft natural latex, Young's modulus ≈ 0.9
  MPa). With 0.4 MPa the traditional joint would fall to 14.4 N·m at its limits.
* internal element diameter d = 30 mm — ASSUMED: the largest round size that passes through
  a sliding end fitting inside the 40 mm bladder with a 5 mm wall for the seal. Check: the
  sleeve's free contraction (F = 0) exceeds the traditional one's by 3.8–4.6 % of L0 over
  69–414 kPa (36.2 % against 31.6 % at 414 kPa), against "an additional 5 % contraction"
  reported for the sleeve PAM of the paper's ref. [11].
* dead volume 5 cm³ for both muscle types — ASSUMED (ports, fitting bores, tube to the valve),
  as in :mod:`pamid._models._volume`.
* damping G = 0.3 N·s/mm (traditional) and 0.8 N·s/mm (sleeve) — ASSUMED, not fitted: G
  needs dynamic data. Joint damping is 2·G·r² = 3.2·G N·m·s/rad for r = 40 mm; 0.3 gives a
  damping ratio ≈ 0.07 at 88 N·m/rad and J0 = 0.46 kg·m² (Fig. 7 shows many oscillations),
  and the sleeve's larger value follows the paper's "damping greater for sleeve" (seal
  friction), with fewer oscillations (ζ ≈ 0.15–0.2 at 100–150 N·m/rad).

The geometry of the joints (Section III): an 80 mm pulley (r = 40 mm) and Dyneema cables that
stretch 0.0017 mm/N. The traditional joint and sleeve configuration B have β_range = 1.2 rad
(B: "the same limits of rotation"); configuration A moves both muscles closer to the pulley,
and its β_range follows the rule "maintain the torque available across the range": the
largest β_range at which the torque available at the limits at 414 kPa is at least the
traditional joint's (:func:`config_a_beta_range_rad`).

Units: N, kPa (gauge), mm, s; μ in MPa = N/mm².
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._checks import require
from ._cullinan import Cullinan
from ._joint import (
    CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    CULLINAN_P_MAX_KPA,
    CULLINAN_PULLEY_RADIUS_MM,
    CULLINAN_TRADITIONAL_BETA_RANGE_RAD,
    JointGeometry,
    available_torque_Nm,
)
from ._volume import PamVolume, sleeve_pam_volume, traditional_pam_volume, volume_mm3

#: Cullinan Section III: active length (mm) and bladder inner diameter (mm) and wall (mm).
CULLINAN_ACTIVE_LENGTH_MM = 190.0
CULLINAN_BLADDER_DIAMETER_MM = 40.0
CULLINAN_BLADDER_WALL_MM = 1.5
#: ASSUMED constants of the physical muscle (see the module docstring for the reasoning).
REST_BRAID_ANGLE_DEG = 30.0
BLADDER_SHEAR_MODULUS_MPA = 0.3
ELEMENT_DIAMETER_MM = 30.0
DEAD_VOLUME_MM3 = 5000.0
TRADITIONAL_G_N_S_PER_MM = 0.3
SLEEVE_G_N_S_PER_MM = 0.8
#: Six test pressures, 10–60 psi in 10 psi steps (414 kPa is 60 psi) — ASSUMED: the paper
#: shows six test pressures in Fig. 4 without naming them.
TEST_PRESSURES_KPA = tuple(round(6.894757293168361 * psi, 3) for psi in (10, 20, 30, 40, 50, 60))
#: Key of the virtual static bench whose fit gave the stored presets.
PRESET_SEED = 20190520


class BraidedPam(eqx.Module):
    """A physical braided PAM: braid, end fittings (eq. 1) and a neo-Hookean bladder.

    * ``volume``: the gas volume's geometry (:class:`~pamid._models._volume.PamVolume`:
      L0, D0, θ0, dead volume, element diameter d; d = 0 for a traditional PAM).
    * ``bladder_wall_mm``: t, the latex wall.
    * ``bladder_shear_modulus_MPa``: μ of the latex (N/mm²).

    See the module docstring for the force law; :func:`braided_pam_force_N` evaluates it.
    """

    volume: PamVolume
    bladder_wall_mm: Float[Array, "..."]
    bladder_shear_modulus_MPa: Float[Array, "..."]

    def __init__(self, volume: PamVolume, bladder_wall_mm, bladder_shear_modulus_MPa):
        require("bladder_wall_mm", bladder_wall_mm, lambda a: a >= 0, ">= 0")
        require("bladder_shear_modulus_MPa", bladder_shear_modulus_MPa, lambda a: a >= 0, ">= 0")
        self.volume = volume
        self.bladder_wall_mm = jnp.asarray(bladder_wall_mm, float)
        self.bladder_shear_modulus_MPa = jnp.asarray(bladder_shear_modulus_MPa, float)


def bladder_energy_Nmm(muscle: BraidedPam, contraction_mm: ArrayLike) -> Float[Array, "..."]:
    """Strain energy (N·mm) of the neo-Hookean bladder at the contraction y (0 at rest)."""
    v = muscle.volume
    y = jnp.asarray(contraction_mm, float)
    length = v.active_length_mm - y
    cos_theta = length / v.fibre_length_mm
    hoop = jnp.sqrt(1.0 - cos_theta**2) / jnp.sin(v.rest_braid_angle_rad)
    axial = length / v.active_length_mm
    t = muscle.bladder_wall_mm
    wall_mm3 = jnp.pi * (v.rest_diameter_mm + t) * t * v.active_length_mm
    invariant = hoop**2 + axial**2 + 1.0 / (hoop * axial) ** 2 - 3.0
    return muscle.bladder_shear_modulus_MPa * wall_mm3 / 2.0 * invariant


def braided_pam_force_N(
    muscle: BraidedPam, pressure_kPa: ArrayLike, contraction_mm: ArrayLike
) -> Float[Array, "..."]:
    """Static pull in N of the physical muscle: F = P′·dV/dy − dW/dy (virtual work).

    P′ in kPa and V in mm³, so P′·dV/dy is in 10⁻³ N. Broadcasts; differentiable.
    """
    y = jnp.asarray(contraction_mm, float)
    p = jnp.asarray(pressure_kPa, float)
    ones = jnp.ones_like(y)
    _, dv = jax.jvp(lambda yy: volume_mm3(muscle.volume, yy), (y,), (ones,))
    _, dw = jax.jvp(lambda yy: bladder_energy_Nmm(muscle, yy), (y,), (ones,))
    return 1e-3 * p * dv - dw


def braided_pam(
    element_diameter_mm: float = 0.0,
    *,
    rest_braid_angle_deg: float = REST_BRAID_ANGLE_DEG,
    bladder_shear_modulus_MPa: float = BLADDER_SHEAR_MODULUS_MPA,
    dead_volume_mm3: float = DEAD_VOLUME_MM3,
) -> BraidedPam:
    """A physical PAM like Cullinan's (L0 190 mm, D0 40 mm, 1.5 mm wall); d = 0: traditional.

    The defaults are the ASSUMED constants of the module docstring; change one to see how a
    claim depends on it.
    """
    volume = sleeve_pam_volume(
        CULLINAN_ACTIVE_LENGTH_MM,
        CULLINAN_BLADDER_DIAMETER_MM,
        rest_braid_angle_deg,
        dead_volume_mm3,
        element_diameter_mm,
    )
    return BraidedPam(volume, CULLINAN_BLADDER_WALL_MM, bladder_shear_modulus_MPa)


def traditional_braided_pam() -> BraidedPam:
    """The physical traditional PAM (no internal element); constants in the module docstring."""
    return braided_pam(0.0)


def sleeve_braided_pam() -> BraidedPam:
    """The physical sleeve PAM: the traditional one with a 30 mm internal element (ASSUMED)."""
    return braided_pam(ELEMENT_DIAMETER_MM)


def traditional_volume() -> PamVolume:
    """Gas volume of the traditional PAM (L0 190, D0 40, θ0 30°, 5 cm³ dead; no element)."""
    return traditional_pam_volume(rest_braid_angle_deg=REST_BRAID_ANGLE_DEG,
                                  dead_volume_mm3=DEAD_VOLUME_MM3)


def sleeve_volume() -> PamVolume:
    """Gas volume of the sleeve PAM: the traditional one less a 30 mm internal element."""
    return sleeve_pam_volume(rest_braid_angle_deg=REST_BRAID_ANGLE_DEG,
                             dead_volume_mm3=DEAD_VOLUME_MM3,
                             element_diameter_mm=ELEMENT_DIAMETER_MM)


# --------------------------------------------------------------------------------------
# The presets.

#: A–E fitted by :func:`fit_cullinan_presets` (default key and protocol), in N, kPa, mm:
#: N, N/kPa, N/mm, N/(kPa·mm), N/mm². 95 % Wald intervals (n = 240, RMSE 9.69 N against
#: 2 N of load-cell noise: eq. 3 cannot follow the braid exactly) — A (14.61, 25.83),
#: B (6.1305, 6.1710), C (7.911, 8.499), D (0.10222, 0.10358), E (−0.13194, −0.12213).
TRADITIONAL_FIT: dict[str, float] = {
    "A": 20.223008051,
    "B": 6.1507612193,
    "C": 8.2048715661,
    "D": 0.10290241784,
    "E": -0.12703215218,
}
#: As :data:`TRADITIONAL_FIT` for the sleeve PAM (RMSE 11.37 N) — A (17.98, 31.60),
#: B (6.8069, 6.8545), C (7.816, 8.501), D (0.10068, 0.10213), E (−0.12204, −0.11187).
#: B − B_traditional = 0.680 N/kPa, close to the element's section π·d²/4 = 0.707 N/kPa
#: (eq. 1).
SLEEVE_FIT: dict[str, float] = {
    "A": 24.792628418,
    "B": 6.8306737035,
    "C": 8.1585792105,
    "D": 0.10140462497,
    "E": -0.11695360152,
}


def traditional_pam() -> Cullinan:
    """Eq. 3 constants of a traditional PAM like Cullinan's (fitted; G ASSUMED)."""
    return Cullinan(**TRADITIONAL_FIT, G=TRADITIONAL_G_N_S_PER_MM)


def sleeve_pam() -> Cullinan:
    """Eq. 3 constants of a sleeve PAM like Cullinan's (fitted; G ASSUMED)."""
    return Cullinan(**SLEEVE_FIT, G=SLEEVE_G_N_S_PER_MM)


def traditional_joint() -> JointGeometry:
    """Cullinan's traditional joint: r = 40 mm, β_range = 1.2 rad, cables 0.0017 mm/N."""
    return JointGeometry(
        CULLINAN_PULLEY_RADIUS_MM,
        CULLINAN_TRADITIONAL_BETA_RANGE_RAD,
        CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    )


def sleeve_joint_B() -> JointGeometry:  # noqa: N802 (the paper's configuration name)
    """Configuration B: sleeve PAMs at the traditional joint's limits (β_range = 1.2 rad)."""
    return traditional_joint()


def config_a_beta_range_rad(
    traditional: Cullinan | None = None,
    sleeve: Cullinan | None = None,
    p_max_kPa: float = CULLINAN_P_MAX_KPA,
) -> float:
    """β_range of configuration A: the largest at which the sleeve joint's limit torque holds.

    The rule (Section III, "maintain the torque available across the range"): the torque
    available at the limits at ``p_max_kPa`` must be at least the traditional joint's at its
    ±0.6 rad limits. At a limit the smaller of the two directions is the pull towards the
    limit, by the muscle that is fully contracted there (muscle 1 at +β_range/2; its
    y1 = r·β_range), :func:`~pamid._models._joint.available_torque_Nm`. That torque falls as β_range
    grows, so the answer is the root of "sleeve limit torque = traditional limit torque"
    (Brent's method; cable stretch included).
    """
    import scipy.optimize

    traditional = traditional_pam() if traditional is None else traditional
    sleeve = sleeve_pam() if sleeve is None else sleeve
    trad = traditional_joint()
    half = float(trad.beta_range_rad) / 2.0
    target = float(available_torque_Nm(traditional, trad, half, p_max_kPa).toward_positive_Nm)

    def excess(beta_range):
        geometry = JointGeometry(
            CULLINAN_PULLEY_RADIUS_MM, beta_range, CULLINAN_CABLE_COMPLIANCE_MM_PER_N
        )
        limit = available_torque_Nm(sleeve, geometry, beta_range / 2.0, p_max_kPa)
        return float(limit.toward_positive_Nm) - target

    lo, hi = float(trad.beta_range_rad) * 0.5, float(trad.beta_range_rad) * 2.0
    if excess(lo) < 0.0:
        raise ValueError("the sleeve muscle is weaker than the traditional one at its limits")
    return float(scipy.optimize.brentq(excess, lo, hi, xtol=1e-12))


def sleeve_joint_A(beta_range_rad: float | None = None) -> JointGeometry:  # noqa: N802
    """Configuration A: sleeve PAMs moved closer to the pulley (a larger β_range).

    β_range from :func:`config_a_beta_range_rad` with the presets unless given.
    """
    if beta_range_rad is None:
        beta_range_rad = CONFIG_A_BETA_RANGE_RAD
    return JointGeometry(
        CULLINAN_PULLEY_RADIUS_MM, beta_range_rad, CULLINAN_CABLE_COMPLIANCE_MM_PER_N
    )


#: β_range of configuration A, :func:`config_a_beta_range_rad` with the presets: 1.3946 rad,
#: 16.2 % more rotation than the traditional joint (the paper: 14 %).
CONFIG_A_BETA_RANGE_RAD = 1.3946168015
