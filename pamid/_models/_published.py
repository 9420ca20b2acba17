"""Published static force laws of the braided pneumatic muscle, as :class:`ForceModel`\\ s.

Each class states its equation and source in its docstring; the constants are its fields
(their defaults are start values), with their units in ``units`` and physical bounds in
``bounds``. Geometry a law needs but a bench file does not give (the initial radius, the
braid angle, the wall thickness) is either a fitted constant with physical bounds or a
static field (``eqx.field(static=True)``) with a documented default for the Festo fluidic
muscle DMSP-10 (10 mm inner diameter); give another muscle's value by making an instance,
e.g. ``MartensBoblan(D0_mm=20.0)``, and fitting that from Python
(``pamid.fit_least_squares(bench, instance)``: its field values are the start and the
static settings). A law's own ``start`` is a classmethod and so starts from the class's
default geometry; the solver then corrects the angle for another r0.

Shared notation: gauge pressure P; contraction ratio ε = (l0 − l)/l0 (``contraction_ratio``,
converted by pamid from the file's contraction in %); θ0 the braid angle at rest, measured
from the muscle's axis; for a braid of fixed thread length b wound n times, l = b·cos θ and
the braid diameter is D = b·sin θ/(nπ), so that at contraction ε

    cos θ = (1 − ε)·cos θ0,   sin θ = √(1 − (1 − ε)²·cos²θ0)          (Chou–Hannaford 1996)

Lengths are in mm and pressures in kPa unless a class says otherwise; kPa·mm² = 10⁻³ N.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from ._protocol import ForceModel

#: N per (kPa·mm²).
_N_PER_KPA_MM2 = 1e-3
#: The braid angle above which an ideal braided muscle pushes instead of pulling at rest:
#: arccos(1/√3) = 54.7356° (3·cos²θ0 − 1 = 0; Chou & Hannaford 1996).
NEUTRAL_ANGLE_DEG = 54.7356103172


def _braid_angle(contraction_ratio, theta0_deg):
    """(cos θ, sin θ, cos θ0, sin θ0) of the braid at contraction ε (fixed thread length)."""
    theta0 = jnp.deg2rad(theta0_deg)
    c0, s0 = jnp.cos(theta0), jnp.sin(theta0)
    cos_t = (1.0 - contraction_ratio) * c0
    # cos θ < 1 for every contraction > −(1/cos θ0 − 1); the floor keeps a stray sample
    # beyond that (a muscle stretched past its braid's length) finite instead of NaN.
    sin_t = jnp.sqrt(jnp.maximum(1.0 - cos_t**2, 1e-12))
    return cos_t, sin_t, c0, s0


#: Trial values of Tondu–Lopez's correction factor k for the start (k = 1: the ideal braid).
_K_TRIALS = tuple(0.5 + 0.05 * i for i in range(91))
#: Default rest radius of the braid: 5 mm, half the 10 mm nominal inner diameter of the
#: Festo fluidic muscle DMSP-10 (Festo's type code). Festo's
#: braid lies inside the tube's wall, a little outside that radius: a fitted braid angle
#: absorbs the difference. For a DMSP-20 give ``r0_mm=10.0``.
FESTO_10MM_R0_MM = 5.0


def _braid_law_start(pressure_kPa, contraction_ratio, force_N, weight, r0_mm,
                     k_trials=_K_TRIALS):
    """Start values (θ0 [deg], k) of F = π·r0²·P·[3·cot²θ0·(1 − kε)² − 1/sin²θ0] for a batch.

    With 1/sin²θ0 = 1 + cot²θ0 the law is linear in u = cot²θ0 for a fixed k: for each
    trial k, u is the weighted least-squares solution, clipped to a real braid angle
    (1° to 54.2°), and the k of the smallest weighted residual is kept."""
    p, e, y, w = (jnp.asarray(v, dtype=jnp.float64)
                  for v in (pressure_kPa, contraction_ratio, force_N, weight))
    ks = jnp.asarray(k_trials)[:, None, None]                    # (K, 1, 1)
    scale = _N_PER_KPA_MM2 * jnp.pi * r0_mm**2 * p               # N per unit bracket
    g = scale * (3.0 * (1.0 - ks * e) ** 2 - 1.0)                 # (K, M, N)
    target = y + scale
    u = jnp.sum(w * g * target, axis=-1) / jnp.maximum(jnp.sum(w * g * g, axis=-1), 1e-300)
    u = jnp.clip(u, jnp.tan(jnp.deg2rad(NEUTRAL_ANGLE_DEG - 0.5)) ** -2,
                 jnp.tan(jnp.deg2rad(1.0)) ** -2)
    sse = jnp.sum(w * (u[..., None] * g - target) ** 2, axis=-1)  # (K, M)
    best = jnp.argmin(sse, axis=0)
    u = u[best, jnp.arange(p.shape[0])]
    return jnp.rad2deg(jnp.arctan(1.0 / jnp.sqrt(u))), jnp.asarray(k_trials)[best]


class ChouHannaford(ForceModel):
    """Chou & Hannaford 1996: the ideal braid with the bladder-wall-thickness correction.

    C.-P. Chou and B. Hannaford, "Measurement and modeling of McKibben pneumatic artificial
    muscles", IEEE Transactions on Robotics and Automation 12(1):90–102, 1996. The virtual
    work of the pressure on the volume inside a bladder of constant wall thickness t_k:

        F = (π·D90²·P/4)·(3·cos²θ − 1) + π·P·[D90·t_k·(2·sin θ − 1/sin θ) − t_k²]

    with D90 = b/(nπ) the braid diameter at θ = 90°, written here through the rest geometry
    as D90 = 2·r0/sin θ0 (r0: the braid's outer radius at rest), and cos θ = (1 − ε)·cos θ0.
    With t_k = 0 it is the ideal law F = π·r0²·P·[3(1 − ε)²/tan²θ0 − 1/sin²θ0].

    Constants: θ0 [deg], t_k [mm]; r0 is a static field (default
    :data:`FESTO_10MM_R0_MM`). The force is proportional to P (no threshold pressure): the
    law has no term for the Festo muscle's pretension.
    """

    theta0_deg: float = 25.0
    t_mm: float = 0.5
    r0_mm: float = eqx.field(static=True, default=FESTO_10MM_R0_MM)

    units: ClassVar[dict[str, str]] = {"r0_mm": "mm", "theta0_deg": "deg", "t_mm": "mm"}
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "theta0_deg": (1.0, NEUTRAL_ANGLE_DEG),
        "t_mm": (0.0, 5.0),
    }
    name: ClassVar[str] = "chou_hannaford"
    source: ClassVar[str] = "Chou–Hannaford 1996, with wall thickness"

    @classmethod
    def start(cls, inputs, force_N, weight):
        """The ideal law's θ0 (t_k = 0, solved exactly), and a thin wall of 0.1 mm."""
        theta0, _ = _braid_law_start(*inputs, force_N, weight, FESTO_10MM_R0_MM,
                                     k_trials=(1.0,))
        return jnp.stack([theta0, jnp.full_like(theta0, 0.1)], axis=-1)

    def __call__(self, pressure_kPa, contraction_ratio):
        cos_t, sin_t, _, s0 = _braid_angle(contraction_ratio, self.theta0_deg)
        d90 = 2.0 * self.r0_mm / s0
        ideal = jnp.pi * d90**2 / 4.0 * (3.0 * cos_t**2 - 1.0)
        wall = jnp.pi * (d90 * self.t_mm * (2.0 * sin_t - 1.0 / sin_t) - self.t_mm**2)
        return _N_PER_KPA_MM2 * pressure_kPa * (ideal + wall)


class TonduLopez(ForceModel):
    """Tondu & Lopez 2000, the static law with the contraction correction factor k.

    B. Tondu and P. Lopez, "Modeling and control of McKibben artificial muscle robot
    actuators", IEEE Control Systems Magazine 20(2):15–38, 2000:

        F = π·r0²·P·[a·(1 − k·ε)² − b],   a = 3/tan²α0,   b = 1/sin²α0

    with α0 the initial braid angle and r0 the initial radius. k ≥ 1 accounts for the
    conical ends, which make the real muscle reach its maximum contraction sooner than the
    ideal cylinder: the force vanishes at ε_max = (1/k)·(1 − 1/(√3·cos α0))
    (:meth:`epsilon_max`), so k = (1 − 1/(√3·cos α0))/ε_max for a measured ε_max.

    Constants: α0 [deg], k [1]; r0 is a static field (default :data:`FESTO_10MM_R0_MM`).
    r0 and α0 cannot both be fitted on a Festo muscle: the law's unconstrained optimum on
    the DMSP-10-250 map has 1/sin²α0 < 0 (no real braid), and a fit of all three within
    bounds put r0 on its lower bound (1 mm) with α0 = 5°.
    """

    alpha0_deg: float = 25.0
    k: float = 1.2
    r0_mm: float = eqx.field(static=True, default=FESTO_10MM_R0_MM)

    units: ClassVar[dict[str, str]] = {"r0_mm": "mm", "alpha0_deg": "deg", "k": "1"}
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "alpha0_deg": (1.0, NEUTRAL_ANGLE_DEG),
        "k": (0.1, 10.0),
    }
    name: ClassVar[str] = "tondu_lopez"
    source: ClassVar[str] = "Tondu–Lopez 2000, correction factor k"

    @classmethod
    def start(cls, inputs, force_N, weight):
        """α0 solved exactly for each of a grid of k (0.5 to 5), the best kept."""
        return jnp.stack(_braid_law_start(*inputs, force_N, weight, FESTO_10MM_R0_MM),
                         axis=-1)

    def __call__(self, pressure_kPa, contraction_ratio):
        return _tondu_lopez(pressure_kPa, contraction_ratio, self.r0_mm, self.alpha0_deg,
                            self.k)

    def epsilon_max(self):
        """The contraction ratio at which the force vanishes, (1/k)(1 − 1/(√3·cos α0))."""
        alpha0 = jnp.deg2rad(self.alpha0_deg)
        return (1.0 - 1.0 / (jnp.sqrt(3.0) * jnp.cos(alpha0))) / self.k


def _tondu_lopez(pressure_kPa, contraction_ratio, r0_mm, alpha0_deg, k):
    alpha0 = jnp.deg2rad(alpha0_deg)
    a = 3.0 / jnp.tan(alpha0) ** 2
    b = 1.0 / jnp.sin(alpha0) ** 2
    return (_N_PER_KPA_MM2 * jnp.pi * r0_mm**2 * pressure_kPa
            * (a * (1.0 - k * contraction_ratio) ** 2 - b))


class TonduLopezPressure(ForceModel):
    """Tondu & Lopez 2000 with a pressure-dependent correction k(P) = a_k·e^(−P/p_k) + b_k.

    The same law as :class:`TonduLopez`, F = π·r0²·P·[a·(1 − k·ε)² − b], with the correction
    factor falling with pressure, k(P) = a_k·exp(−P) + b_k, as Tondu & Lopez (IEEE Control
    Systems Magazine 20(2):15–38, 2000) give it for their muscles (restated in B. Tondu,
    "Modelling of the McKibben artificial muscle: a review", J. Intell. Mater. Syst. Struct.
    23(3):225–253, 2012). The exponent needs a pressure unit: here P/p_k with p_k a static
    field, default 100 kPa (1 bar: pressure taken in bar, the unit of those papers'
    experiments; the unit of the source's exponent could not be checked against its text).

    Constants: α0 [deg], a_k [1], b_k [1]; r0 and p_k are static fields.
    """

    alpha0_deg: float = 25.0
    a_k: float = 0.5
    b_k: float = 1.2
    r0_mm: float = eqx.field(static=True, default=FESTO_10MM_R0_MM)
    p_k_kPa: float = eqx.field(static=True, default=100.0)

    units: ClassVar[dict[str, str]] = {"r0_mm": "mm", "alpha0_deg": "deg", "a_k": "1",
                                       "b_k": "1", "p_k_kPa": "kPa"}
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "alpha0_deg": (1.0, NEUTRAL_ANGLE_DEG),
        "a_k": (-10.0, 1000.0),  # k(P) > 0 needs a_k > −b_k; k(0) = a_k + b_k
        "b_k": (0.1, 10.0),
    }
    name: ClassVar[str] = "tondu_lopez_kp"
    source: ClassVar[str] = "Tondu–Lopez 2000, k(P) = a_k·exp(−P/p_k) + b_k"

    @classmethod
    def start(cls, inputs, force_N, weight):
        """The constant-k start of :class:`TonduLopez`, with a_k = 0 and b_k = k."""
        alpha0, k = _braid_law_start(*inputs, force_N, weight, FESTO_10MM_R0_MM)
        return jnp.stack([alpha0, jnp.zeros_like(k), k], axis=-1)

    def __call__(self, pressure_kPa, contraction_ratio):
        k = self.a_k * jnp.exp(-pressure_kPa / self.p_k_kPa) + self.b_k
        return _tondu_lopez(pressure_kPa, contraction_ratio, self.r0_mm, self.alpha0_deg, k)


class KluteHannaford(ForceModel):
    """Klute & Hannaford 2000: ideal braid plus the Mooney–Rivlin strain energy of the bladder.

    G. K. Klute and B. Hannaford, "Accounting for elastic energy storage in McKibben
    artificial muscle actuators", ASME J. Dynamic Systems, Measurement, and Control
    122(2):386–388, 2000. The virtual work of pressure, load and the bladder's stored
    energy, F·dL = −P·dV + V_b·dW, gives

        F = −P·dV/dL + V_b·dW/dL
          = π·r0²·P·[3(1 − ε)²/tan²θ0 − 1/sin²θ0] − (V_b/l0)·dW/dε

    with the bladder (volume V_b = π·(r0² − (r0 − t)²)·l0, incompressible) a Mooney–Rivlin
    solid, W = C10·(I1 − 3) + C01·(I2 − 3), I1 = λ1² + λ2² + λ3², I2 = λ1⁻² + λ2⁻² + λ3⁻²,
    stretched axially by λ1 = 1 − ε and around by λ2 = sin θ/sin θ0, λ3 = 1/(λ1·λ2).
    l0 cancels: F = π·r0²·P·[…] − π·(r0² − (r0 − t)²)·dW/dε.

    Constants: θ0 [deg], C10 and C01 [kPa]. r0 is a static field (default
    :data:`FESTO_10MM_R0_MM`): fitted too, r0 and θ0 trade off, and on the AARL 10 mm
    tests the fits wandered between r0 = 2.6 and 9 mm. The wall thickness t enters only
    through the wall's cross-section times C (a thicker wall of softer rubber stores the
    same energy), so it is a static field too, default 1.8 mm (the
    Festo DMSP membrane thickness H0 used with Martens & Boblan's model in the Agile &
    Adaptive Robotics Lab's public Muscle_Sensory scripts); the fitted C10 and C01 are those
    of a wall of that thickness.
    """

    theta0_deg: float = 25.0
    C10_kPa: float = 100.0
    C01_kPa: float = 0.0
    r0_mm: float = eqx.field(static=True, default=FESTO_10MM_R0_MM)
    t_mm: float = eqx.field(static=True, default=1.8)

    units: ClassVar[dict[str, str]] = {"r0_mm": "mm", "theta0_deg": "deg", "C10_kPa": "kPa",
                                       "C01_kPa": "kPa", "t_mm": "mm"}
    inputs: ClassVar[tuple[str, ...]] = ("pressure_kPa", "contraction_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "theta0_deg": (1.0, NEUTRAL_ANGLE_DEG),
        "C10_kPa": (0.0, 1e5),
        "C01_kPa": (-1e5, 1e5),
    }
    name: ClassVar[str] = "klute_hannaford"
    source: ClassVar[str] = "Klute–Hannaford 2000, Mooney–Rivlin bladder"

    def __call__(self, pressure_kPa, contraction_ratio):
        cos_t, sin_t, c0, s0 = _braid_angle(contraction_ratio, self.theta0_deg)
        ideal = jnp.pi * (self.r0_mm / s0) ** 2 * (3.0 * cos_t**2 - 1.0)
        l1 = 1.0 - contraction_ratio
        l2 = sin_t / s0
        l3 = 1.0 / (l1 * l2)
        dl1 = -1.0
        dl2 = l1 * c0**2 / (s0 * sin_t)  # d(sin θ/sin θ0)/dε
        dl3 = -(dl1 * l2 + l1 * dl2) * l3**2
        di1 = 2.0 * (l1 * dl1 + l2 * dl2 + l3 * dl3)
        di2 = -2.0 * (dl1 / l1**3 + dl2 / l2**3 + dl3 / l3**3)
        dw = self.C10_kPa * di1 + self.C01_kPa * di2
        wall_area = jnp.pi * (self.r0_mm**2 - (self.r0_mm - self.t_mm) ** 2)
        return _N_PER_KPA_MM2 * (pressure_kPa * ideal - wall_area * dw)


class MartensBoblan(ForceModel):
    """Martens & Boblan 2017: the Festo muscle's pressure force less the rubber's elastic forces.

    M. Martens and I. Boblan, "Modeling the static force of a Festo pneumatic muscle
    actuator: a new approach and a comparison to existing models", Actuators 6(4):33, 2017
    (erratum: Actuators 7(1):9, 2018); its Appendix A publishes the measured force maps.
    The braid of the Festo muscle lies in its rubber tube (inner diameter D0, wall H0); the
    threads' length b = l0/cos θ and turns n = l0·tan θ/(π·D0) fix the diameter D(L) and
    volume at length L. The pressure force is reduced by the tube's axial and lateral
    elastic stresses, with a length-dependent rubber modulus E(L):

        D(L)   = √(b² − L²)/(nπ),            dD/dL = −L/(nπ·√(b² − L²))
        dV/dL  = (b² − 3L²)/(4πn²)
        E(L)   = c0 + c1·L + c2·L² + c3·L³   (the paper: a cubic in L, in m)
        σ_L    = E·(L − l0)/l0,               F_L  = σ_L·H0·π·D
        σ_PE   = E·(D − D0)/D0,               F_PE = σ_PE·H0·L·π
        F      = −P·dV/dL + F_PE·dD/dL − F_L

    with θ = θ0 + Δθ, θ0 = 28.6° (static) and Δθ the paper's fitted angle correction. The
    equations are taken as restated in the Agile & Adaptive Robotics Lab's public
    ModelComparison2.m (github.com/Agile-and-Adaptive-Robotics, Muscle_Sensory), with
    θ0 = 28.6° and H0 = 1.8 mm from there and D0 = 10 mm the DMSP-10's nominal inner
    diameter (give ``D0_mm=20.0`` for a DMSP-20). The constants quoted there for the
    DMSP-10-250 (c0…c3 = 74.085 MPa, −689.20 MPa/m, 1837 MPa/m², −848.79 MPa/m³,
    Δθ = −0.1°) do not reproduce the paper's own map with these geometric settings (295 N
    instead of 542 N at l0 and 650 kPa; RMSE 103 N over the map): fit Δθ rather than
    trust them. Fitted to that map (E3 = 0) it gives Δθ = −5.9°, E0 = 3.35 MPa (the quoted
    cubic has E(l0) = 3.33 MPa), RMSE 10.0 N and a largest error of 24.0 N, 4.4 % of the
    largest force, the paper's own figure for this muscle.

    The same cubic is written here about the rest length, in the axial strain
    s = (L − l0)/l0 ≤ 0 (an exact change of basis for one muscle, far better conditioned
    than powers of L in m):

        E = E0 + E1·s + E2·s² + E3·s³,   E0 = E(l0), E1 = l0·E′(l0), E2 = l0²·E″(l0)/2,
                                          E3 = c3·l0³

    E does not act at l0 (σ_L = σ_PE = 0 there), so a design with forces at three contracted
    lengths (the DMSP-10-250 map; the AARL isometric tests) gives E at three lengths only:
    ``pamid fit --model martens_boblan`` fits E0, E1, E2 and Δθ with E3 = 0 (its default);
    fit all five from Python (``spec_from_model(MartensBoblan)``) on data with four or more.

    Written so, the law depends on the length only through λ = L/l0 = 1 − ε (l0 cancels
    from every term): inputs are the pressure in Pa and the contraction ratio.
    Constants: E0, E1, E2, E3 [MPa], Δθ [deg].
    """

    E0_MPa: float = 3.3
    E1_MPa: float = 17.5
    E2_MPa: float = 75.0
    dtheta_deg: float = -0.1
    E3_MPa: float = 0.0
    theta0_deg: float = eqx.field(static=True, default=28.6)
    D0_mm: float = eqx.field(static=True, default=10.0)
    H0_mm: float = eqx.field(static=True, default=1.8)

    units: ClassVar[dict[str, str]] = {
        "E0_MPa": "MPa", "E1_MPa": "MPa", "E2_MPa": "MPa", "E3_MPa": "MPa",
        "dtheta_deg": "deg", "theta0_deg": "deg", "D0_mm": "mm", "H0_mm": "mm",
    }
    inputs: ClassVar[tuple[str, ...]] = ("pressure_Pa", "contraction_ratio")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        # θ = θ0 + Δθ stays a braid angle of a contracting muscle, 1° to 54.7°.
        "dtheta_deg": (1.0 - 28.6, NEUTRAL_ANGLE_DEG - 28.6),
    }
    name: ClassVar[str] = "martens_boblan"
    source: ClassVar[str] = "Martens–Boblan 2017"

    @staticmethod
    def modulus_from_paper(c0_MPa, c1_MPa_m, c2_MPa_m2, c3_MPa_m3, l0_m):
        """(E0, E1, E2, E3) in MPa of the paper's E(L) = c0 + c1·L + c2·L² + c3·L³ (L in m)
        for a muscle of rest length ``l0_m``."""
        e0 = c0_MPa + c1_MPa_m * l0_m + c2_MPa_m2 * l0_m**2 + c3_MPa_m3 * l0_m**3
        e1 = l0_m * (c1_MPa_m + 2.0 * c2_MPa_m2 * l0_m + 3.0 * c3_MPa_m3 * l0_m**2)
        e2 = l0_m**2 * (c2_MPa_m2 + 3.0 * c3_MPa_m3 * l0_m)
        return e0, e1, e2, c3_MPa_m3 * l0_m**3

    def __call__(self, pressure_Pa, contraction_ratio):
        # With λ = L/l0 = 1 − ε, b = l0/cos θ and n = l0·tan θ/(π·D0), l0 cancels from
        # every term: D = D0·√(1/cos²θ − λ²)/tan θ, −dV/dL = π·D0²·(3λ² − 1/cos²θ)/(4·tan²θ)
        # and L·dD/dL = −λ²·D0/(tan θ·√(1/cos²θ − λ²)).
        theta = jnp.deg2rad(self.theta0_deg + self.dtheta_deg)
        d0 = self.D0_mm * 1e-3
        h0 = self.H0_mm * 1e-3
        lam = 1.0 - contraction_ratio
        sec2, tan_t = 1.0 / jnp.cos(theta) ** 2, jnp.tan(theta)
        root = jnp.sqrt(jnp.maximum(sec2 - lam**2, 1e-18))
        diameter = d0 * root / tan_t
        minus_dv_dl = jnp.pi * d0**2 * (3.0 * lam**2 - sec2) / (4.0 * tan_t**2)
        l_dd_dl = -lam**2 * d0 / (tan_t * root)
        strain = -contraction_ratio  # (L − l0)/l0
        modulus = 1e6 * (self.E0_MPa + strain * (self.E1_MPa + strain * (
            self.E2_MPa + strain * self.E3_MPa)))
        f_axial = modulus * strain * h0 * jnp.pi * diameter          # F_L
        lateral = modulus * (diameter - d0) / d0 * h0 * jnp.pi       # F_PE / L
        return pressure_Pa * minus_dv_dl + lateral * l_dd_dl - f_axial


def published_models() -> tuple[tuple[type[ForceModel], dict], ...]:
    """The published force laws of this module, each with the options it is registered
    with (:func:`pamid._fit._spec.register_model`), in the order they are registered."""
    return (
        (ChouHannaford, {}),
        (TonduLopez, {}),
        (TonduLopezPressure, {}),
        (KluteHannaford, {}),
        (MartensBoblan, {"params": ("E0_MPa", "E1_MPa", "E2_MPa", "dtheta_deg")}),
    )
