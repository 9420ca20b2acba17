"""Sárosi's positioning rigs, simulated: muscles, valve, controller, encoder, in one scan.

Source: Sárosi, dissertation summary, Sections 2.4 and 3.3. Three rigs:

* linear (Fig. 2-4, Fig. 3-7): two DMSP-20-200N muscles in an antagonistic pair pulling a
  carriage, one MPYE 5/3 valve (port A → muscle A, port B → muscle B), 600 kPa, 10 ms,
  linear encoder 0.01 mm, gradient 0.35 (:func:`linear_rig`);
* single muscle (Fig. 2-6, Fig. 3-9 to 3-12): one DMSP-20-400N lifting 20 kg, port A only,
  the temperature and hysteresis experiments (:func:`single_muscle_rig`);
* rotary (Section 2.4.3, Fig. 3-13): two DMSP-10-250N on a pulley, rotary encoder 0.036°
  (10 000 counts per turn), gradient 0.3 (:func:`rotary_rig`).

Plant (continuous, integrated by RK4 at a fixed step inside each 10 ms sample). State: the
travel x (m; muscle A shortens by x, muscle B lengthens by x), its rate v, the air masses
m_A, m_B (kg) in the muscles and their hysteresis states z_A, z_B. Per muscle i:

    V_i = V(y_i)                       volume model of pamid (braid geometry), y_i its contraction
    p_i = m_i·R·T/V_i                  ideal gas, isothermal at the muscle temperature T
    ṁ_i = valve flow (ISO 6358, choked and unchoked; see ``_valve``)
    F_i = F_2.1(p_i, κ_i) − h·p_i·z_i                  Sárosi eq. 2.1 with a hysteresis loop
    ż_i = (ẏ_i/δ)·(1 − z_i·sign(ẏ_i))                 (Dahl's model, z_i ∈ [−1, 1])

so the pressure follows from the mass flow and the volume change,
ṗ_i = (R·T·ṁ_i − p_i·V̇_i)/V_i, without being a state of its own (mass is, so a shut valve
holds it exactly). The hysteresis state z_i moves the muscle onto the loop's lower branch
(z = 1) within a travel of a few δ after it starts to shorten and onto the upper one
(z = −1) after it starts to lengthen, and keeps its value at rest, so the loop has memory
and no rate dependence, like the measured loop (the ±h·p loop of
:func:`pamid.sarosi.hysteresis_branches`; h = 3 N/bar, the loop of pamid's bundled data set;
δ = 0.05 mm assumed). A loop written as h·p·tanh(ẏ/v) instead forgets its branch at rest:
in a first version the shut rig crept back towards the loop's middle after each move and
the controller kept hunting around the target.
Motion (the pair; the single muscle has no B and carries the load's weight instead):

    M·ẍ = F_A − F_B − W − c·ẋ,     c = ζ·2·√(k·M)        (Sárosi eq. 2.6 and 2.10)

with k the summed muscle stiffness of eq. 2.9 and ζ = 0.3 (assumed: the muscles' and the
guides' damping together; pamid's hysteresis ζ of eq. 2.3–2.5, ``default_zeta``, is about
0.05 for the muscle alone). The rotary rig is the same with x = r·θ and M = J/r².

Controller (discrete, in the same ``lax.scan``): at each sample the encoder reading is the
position rounded to the encoder's resolution; the sliding-mode law of ``_sliding_mode``
sets the valve voltage, held until the next sample.

Constants the summary does not give (assumptions, chosen once for all experiments; the
valve's effective conductance and overlap are calibrated, see ``_valve``): the
muscles' rest braid angle 25°, their inner diameter as the gas column's, 10 cm³ (DMSP-20)
and 5 cm³ (DMSP-10) of tube and port volume; the pre-contraction 10 % of the pairs; the
linear pair's pre-pressure 300 kPa and carriage 2 kg; the rotary rig's inertia
(0.005 kg·m², a light arm); the DMSP-20-200N's constants equal to Table 3-1's (same
diameter; eq. 2.1 is written in κ in %, which removes the length); the DMSP-10-250N's
constants are pamid's fit to Martens & Boblan's force map (``experiments/martens_dmsp10.py``)
and its hysteresis loop is the DMSP-20's scaled by the muscles' force per bar
(:data:`DMSP10_HYSTERESIS_N_PER_BAR`).

Calibrated (rig constants only; valve and controller are shared by all rigs): the rotary
rig's pulley radius r = 40 mm and pre-pressure 400 kPa, to Fig. 3-13 (5.004° reached in
about 0.8 s, overshoot 0.072° = 2 counts, error within one count). With the first guess
(r = 30 mm, 300 kPa, the DMSP-20's loop) the rig overshot by 7 counts; the scan of
``experiments/sarosi_positioning.py`` (r 35–45 mm, J 0.003–0.008 kg·m², 300/400 kPa, each
also perturbed by ±5 % in r, ±10 % in J and ±20 kPa) finds 400 kPa the setting at which the
overshoot stays at 0–2 counts under those perturbations (at 300 kPa it scatters over
1–8 counts), and r = 40 mm the radius at which the arrival time is near 0.8 s. The single
muscle's rig has no free geometry (20 kg, Fig. 2-6) and keeps its constants: no rig
constant in the scan brings its overshoot from 4–7 counts down to the text's 2 (see the
experiment's findings).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._models._energy import R_AIR_J_PER_KG_K
from .._models._sarosi import TABLE_3_1, Sarosi, sarosi_force, sarosi_stiffness, table_3_1
from .._models._volume import PamVolume, volume_mm3
from .._sim._lifting_mass import DEFAULT_HYSTERESIS_N_PER_BAR, STANDARD_GRAVITY_M_PER_S2
from .._sim._oscillator import batch_apply, rk4_scan
from .._units import ATMOSPHERE_KPA, PA_PER_KPA
from ._sliding_mode import SlidingModeController, sliding_mode_voltage, sliding_surface
from ._thermal import REFERENCE_TEMPERATURE_C, sarosi_at_temperature
from ._valve import ProportionalValve, valve_mass_flows_kg_s

__all__ = [
    "DMSP10_250_MARTENS",
    "DMSP10_HYSTERESIS_N_PER_BAR",
    "PositioningRig",
    "PositioningRun",
    "initial_state",
    "linear_rig",
    "positioning_metrics",
    "rotary_rig",
    "simulate_positioning",
    "single_muscle_rig",
    "sarosi_from_fit_json",
    "wald_draws",
]

_KELVIN = 273.15
_PA_PER_BAR = 1e5
#: Eq. 2.1 constants of a DMSP-10-250N: pamid's least-squares fit to Martens & Boblan's
#: force map (experiments/out/martens_dmsp10/martens_dmsp10.json, 2026-11-21), a1 … a6.
DMSP10_250_MARTENS = (
    -3.0515449450656704,
    168.2350670267749,
    -0.4245541017880748,
    -2.902061021539087,
    91.40416950787578,
    -201.02673811747857,
)
#: Hysteresis loop half height h of a DMSP-10 (N/bar): the DMSP-20's loop
#: (:data:`DEFAULT_HYSTERESIS_N_PER_BAR`, measured on a DMSP-20-400N) scaled by the ratio of
#: the two muscles' force per bar at rest, ∂F/∂p = a1 + a5 of eq. 2.1 at κ = 0 (88.4 N/bar
#: for the Martens fit, 297.8 N/bar for Table 3-1): a braid friction in proportion to the
#: force the braid carries (an assumption; no loop of a DMSP-10 is in pamid's data).
DMSP10_HYSTERESIS_N_PER_BAR = (
    DEFAULT_HYSTERESIS_N_PER_BAR
    * (DMSP10_250_MARTENS[0] + DMSP10_250_MARTENS[4])
    / (TABLE_3_1["a1"]["value"] + TABLE_3_1["a5"]["value"])
)
#: Elastic temperature coefficient γ of ``_thermal.sarosi_at_temperature`` (1/K). Calibrated
#: to 0: the gas law alone (p = m·R·T/V at the muscle's temperature) gives 1.45 s at −10 °C
#: and 1.14 s at 39 °C (2 % band, 0 → 40 mm) against Sárosi's 1.4 s and 1.2 s; the scan of
#: ``experiments/sarosi_positioning.py`` (γ down to −0.01/K) fits no better within the
#: ±0.1 s scatter that the sampled relay brings, so the extra constant is left at 0. Read as
#: the first arrival within one count, the same runs take 1.71 s and 1.40 s (falling
#: monotonically over −10, 0, 10, 20, 30, 39 °C; ratio −10 °C/39 °C 1.22 against the text's
#: 1.17); γ < 0 makes both readings slower and the 39 °C end jumpier.
ELASTIC_TEMPERATURE_COEFFICIENT = 0.0


class PositioningRig(eqx.Module):
    """One positioning rig (see the module docstring). Fields may carry batch axes.

    * ``muscle``: Sárosi eq. 2.1 constants at ``reference_C``; ``l0_mm``: nominal length.
    * ``volume``: the gas-volume model (:class:`pamid.PamVolume`), contraction in mm.
    * ``pre_contraction_mm``: contraction of muscle A (and B) at travel 0.
    * ``pre_pressure_kPa``: muscle A's gauge pressure at rest at the start (pair only).
    * ``moving_mass_kg``: M, the mass moved by the muscles (J/r² on a pulley).
    * ``load_N``: constant force against muscle A (the hanging weight; 0 for a pair).
    * ``zeta``: damping ratio of eq. 2.10; ``hysteresis_N_per_bar``, ``hysteresis_mm``:
      half height h of the loop per bar and Dahl's pre-sliding travel δ.
    * ``supply_kPa`` (gauge), ``air_C`` (supply air), ``temperature_C`` (muscle and its air),
      ``temperature_coefficient_per_K`` γ and ``reference_C`` (eq. 2.1 at temperature).
    * ``output_per_mm``: position units per mm of travel (1 linear; 180/(π·r) on a pulley,
      for degrees); ``resolution``: the encoder's step in position units.
    * ``valve``: the proportional valve; ``antagonistic`` (static): a pair, or one muscle.
    """

    muscle: Sarosi
    l0_mm: Float[Array, "..."]
    volume: PamVolume
    pre_contraction_mm: Float[Array, "..."]
    pre_pressure_kPa: Float[Array, "..."]
    moving_mass_kg: Float[Array, "..."]
    load_N: Float[Array, "..."]
    zeta: Float[Array, "..."]
    hysteresis_N_per_bar: Float[Array, "..."]
    hysteresis_mm: Float[Array, "..."]
    supply_kPa: Float[Array, "..."]
    air_C: Float[Array, "..."]
    temperature_C: Float[Array, "..."]
    temperature_coefficient_per_K: Float[Array, "..."]
    reference_C: Float[Array, "..."]
    output_per_mm: Float[Array, "..."]
    resolution: Float[Array, "..."]
    valve: ProportionalValve
    antagonistic: bool = eqx.field(static=True)

    def __init__(
        self,
        muscle,
        l0_mm,
        volume,
        *,
        antagonistic,
        pre_contraction_mm=0.0,
        pre_pressure_kPa=300.0,
        moving_mass_kg=2.0,
        load_N=0.0,
        zeta=0.3,
        hysteresis_N_per_bar=DEFAULT_HYSTERESIS_N_PER_BAR,
        hysteresis_mm=0.05,
        supply_kPa=600.0,
        air_C=24.0,
        temperature_C=REFERENCE_TEMPERATURE_C,
        temperature_coefficient_per_K=ELASTIC_TEMPERATURE_COEFFICIENT,
        reference_C=REFERENCE_TEMPERATURE_C,
        output_per_mm=1.0,
        resolution=0.01,
        valve=None,
    ):
        f = lambda x: jnp.asarray(x, float)  # noqa: E731
        self.muscle = muscle
        self.l0_mm, self.volume = f(l0_mm), volume
        self.pre_contraction_mm, self.pre_pressure_kPa = f(pre_contraction_mm), f(pre_pressure_kPa)
        self.moving_mass_kg, self.load_N, self.zeta = f(moving_mass_kg), f(load_N), f(zeta)
        self.hysteresis_N_per_bar, self.hysteresis_mm = f(hysteresis_N_per_bar), f(hysteresis_mm)
        self.supply_kPa, self.air_C, self.temperature_C = f(supply_kPa), f(air_C), f(temperature_C)
        self.temperature_coefficient_per_K = f(temperature_coefficient_per_K)
        self.reference_C = f(reference_C)
        self.output_per_mm, self.resolution = f(output_per_mm), f(resolution)
        self.valve = ProportionalValve() if valve is None else valve
        self.antagonistic = bool(antagonistic)


def _dmsp_volume(l0_mm, diameter_mm, dead_mm3):
    return PamVolume(l0_mm, diameter_mm, math.radians(25.0), dead_mm3)


def linear_rig(muscle: Sarosi | None = None, **overrides) -> PositioningRig:
    """Fig. 2-4: two DMSP-20-200N (Table 3-1 constants unless ``muscle``), 0.01 mm encoder."""
    kw = dict(
        antagonistic=True,
        pre_contraction_mm=20.0,
        pre_pressure_kPa=300.0,
        moving_mass_kg=2.0,
        resolution=0.01,
    )
    kw.update(overrides)
    return PositioningRig(
        table_3_1() if muscle is None else muscle, 200.0, _dmsp_volume(200.0, 20.0, 10_000.0), **kw
    )


def single_muscle_rig(muscle: Sarosi | None = None, **overrides) -> PositioningRig:
    """Fig. 2-6: one DMSP-20-400N (Table 3-1) lifting 20 kg; travel 0 at κ = 0."""
    kw = dict(
        antagonistic=False,
        pre_contraction_mm=0.0,
        moving_mass_kg=20.0,
        load_N=20.0 * STANDARD_GRAVITY_M_PER_S2,
        resolution=0.01,
    )
    kw.update(overrides)
    return PositioningRig(
        table_3_1() if muscle is None else muscle, 400.0, _dmsp_volume(400.0, 20.0, 10_000.0), **kw
    )


def rotary_rig(
    muscle: Sarosi | None = None,
    *,
    radius_mm: ArrayLike = 40.0,
    inertia_kg_m2: ArrayLike = 0.005,
    **overrides,
) -> PositioningRig:
    """Section 2.4.3: two DMSP-10-250N on a pulley, rotary encoder 0.036°, position in °.

    ``radius_mm`` (40 mm) and the pre-pressure (400 kPa) are calibrated to Fig. 3-13, the
    inertia (0.005 kg·m²) is assumed (see the module docstring); both may be arrays."""
    radius_mm = jnp.asarray(radius_mm, float)
    kw = dict(
        antagonistic=True,
        pre_contraction_mm=25.0,
        pre_pressure_kPa=400.0,
        hysteresis_N_per_bar=DMSP10_HYSTERESIS_N_PER_BAR,
        moving_mass_kg=inertia_kg_m2 / (radius_mm / 1000.0) ** 2,
        output_per_mm=180.0 / (jnp.pi * radius_mm),
        resolution=0.036,
    )
    kw.update(overrides)
    return PositioningRig(
        Sarosi(*DMSP10_250_MARTENS) if muscle is None else muscle,
        250.0,
        _dmsp_volume(250.0, 10.0, 5_000.0),
        **kw,
    )


# --------------------------------------------------------------------------------------
# the plant
# --------------------------------------------------------------------------------------


def _muscle_at_temperature(rig: PositioningRig) -> Sarosi:
    return sarosi_at_temperature(
        rig.muscle, rig.temperature_C, rig.temperature_coefficient_per_K, rig.reference_C
    )


def _contractions_mm(rig, x_m):
    y_a = rig.pre_contraction_mm + 1000.0 * x_m
    return y_a, rig.pre_contraction_mm - 1000.0 * x_m


def _gas_K(rig):
    return rig.temperature_C + _KELVIN


def _pressure_Pa(rig, mass_kg, y_mm):
    return mass_kg * R_AIR_J_PER_KG_K * _gas_K(rig) / (volume_mm3(rig.volume, y_mm) * 1e-9)


def _muscle_force(rig, muscle, p_abs_Pa, y_mm, z):
    """Eq. 2.1 at the gauge pressure, minus the hysteresis loop's h·p·z; ≥ 0."""
    p_bar = p_abs_Pa / _PA_PER_BAR - ATMOSPHERE_KPA / 100.0
    kappa = 100.0 * y_mm / rig.l0_mm
    loop = rig.hysteresis_N_per_bar * jnp.maximum(p_bar, 0.0) * z
    force = sarosi_force(muscle, p_bar, kappa) - loop
    k = sarosi_stiffness(muscle, p_bar, kappa, rig.l0_mm / 1000.0)
    return jnp.maximum(force, 0.0), jnp.maximum(k, 0.0)


def _rhs(rig: PositioningRig, voltage_V):
    muscle = _muscle_at_temperature(rig)
    p_atm = ATMOSPHERE_KPA * PA_PER_KPA
    supply = (rig.supply_kPa + ATMOSPHERE_KPA) * PA_PER_KPA
    t_gas, t_air = _gas_K(rig), rig.air_C + _KELVIN

    def dahl(z, rate_m_s):  # Dahl's hysteresis state, driven by the shortening rate
        return 1000.0 * rate_m_s / rig.hysteresis_mm * (1.0 - z * jnp.sign(rate_m_s))

    def rhs(y):
        x, v, m_a, m_b, z_a, z_b = y[0], y[1], y[2], y[3], y[4], y[5]
        y_a, y_b = _contractions_mm(rig, x)
        p_a = _pressure_Pa(rig, m_a, y_a)
        f_a, k_a = _muscle_force(rig, muscle, p_a, y_a, z_a)
        if rig.antagonistic:
            p_b = _pressure_Pa(rig, m_b, y_b)
            f_b, k_b = _muscle_force(rig, muscle, p_b, y_b, z_b)
        else:
            p_b, f_b, k_b = p_atm, 0.0, 0.0
        dm_a, dm_b = valve_mass_flows_kg_s(
            rig.valve, voltage_V, p_a, p_b, t_gas, t_gas, supply, t_air, p_atm
        )
        if not rig.antagonistic:
            dm_b = 0.0 * dm_b
        c = rig.zeta * 2.0 * jnp.sqrt((k_a + k_b) * rig.moving_mass_kg)
        accel = (f_a - f_b - rig.load_N - c * v) / rig.moving_mass_kg
        return jnp.stack([v, accel, dm_a, dm_b, dahl(z_a, v), dahl(z_b, -v)])

    return rhs


def _pressure_for_force_bar(muscle, force_N, kappa):
    """Eq. 2.1 solved for p (it is linear in p) at the contraction κ."""
    e = jnp.exp(muscle.a3 * kappa)
    return (force_N - muscle.a2 * e - muscle.a6) / (muscle.a1 * e + muscle.a4 * kappa + muscle.a5)


def initial_state(rig: PositioningRig, position0: ArrayLike = 0.0) -> Float[Array, "6"]:
    """[x, v, m_A, m_B, z_A, z_B] at rest at ``position0`` (position units), valve shut,
    on the middle of the hysteresis loop (z = 0).

    Single muscle: muscle A holds the load (eq. 2.1 solved for p). Pair: muscle A at
    ``pre_pressure_kPa``, muscle B at the pressure that balances it. Air mass m = p·V/(R·T).
    """
    muscle = _muscle_at_temperature(rig)
    x = jnp.asarray(position0, float) / rig.output_per_mm / 1000.0
    y_a, y_b = _contractions_mm(rig, x)
    p_atm_bar = ATMOSPHERE_KPA / 100.0
    if rig.antagonistic:
        p_a = rig.pre_pressure_kPa / 100.0
        f_a = sarosi_force(muscle, p_a, 100.0 * y_a / rig.l0_mm)
        p_b = _pressure_for_force_bar(muscle, f_a, 100.0 * y_b / rig.l0_mm)
    else:
        p_a = _pressure_for_force_bar(muscle, rig.load_N, 100.0 * y_a / rig.l0_mm)
        p_b = 0.0

    def mass(p_bar, y):
        v_m3 = volume_mm3(rig.volume, y) * 1e-9
        return (p_bar + p_atm_bar) * _PA_PER_BAR * v_m3 / (R_AIR_J_PER_KG_K * _gas_K(rig))

    m_b = mass(p_b, y_b) if rig.antagonistic else jnp.zeros_like(x)
    zero = jnp.zeros_like(x)
    return jnp.stack([x, zero, mass(p_a, y_a), m_b, zero, zero])


class PositioningRun(NamedTuple):
    """A simulated positioning run, sampled at the controller's instants.

    ``time_s`` (T,) and ``target`` (T,); the rest (*batch, T): ``position`` (true, position
    units), ``reading`` (encoder), ``voltage_V`` (applied from this sample to the next),
    ``surface`` (s), ``pressure_A_kPa``, ``pressure_B_kPa`` (gauge), ``air_A_kg``,
    ``air_B_kg``.
    """

    time_s: Float[Array, " T"]
    target: Float[Array, " T"]
    position: Float[Array, "... T"]
    reading: Float[Array, "... T"]
    voltage_V: Float[Array, "... T"]
    surface: Float[Array, "... T"]
    pressure_A_kPa: Float[Array, "... T"]
    pressure_B_kPa: Float[Array, "... T"]
    air_A_kg: Float[Array, "... T"]
    air_B_kg: Float[Array, "... T"]


def _quantize(rig, position):
    return jnp.round(position / rig.resolution) * rig.resolution


def _run_one(rig, controller, position0, targets, dt, substeps):
    y0 = initial_state(rig, position0)
    q0 = _quantize(rig, 1000.0 * y0[0] * rig.output_per_mm)

    def step(carry, target):
        y, q_prev = carry
        position = 1000.0 * y[0] * rig.output_per_mm
        q = _quantize(rig, position)
        s = sliding_surface(controller, target - q, q_prev, q)
        u = sliding_mode_voltage(controller, s, target - q)
        y_next = rk4_scan(_rhs(rig, u), y, dt, 2, substeps)[-1]
        y_a, y_b = _contractions_mm(rig, y[0])
        p_a = _pressure_Pa(rig, y[2], y_a) / PA_PER_KPA - ATMOSPHERE_KPA
        p_b = (
            _pressure_Pa(rig, y[3], y_b) / PA_PER_KPA - ATMOSPHERE_KPA
            if rig.antagonistic
            else jnp.zeros_like(p_a)
        )
        return (y_next, q), (position, q, u, s, p_a, p_b, y[2], y[3])

    _, out = jax.lax.scan(step, (y0, q0), targets)
    return out


@eqx.filter_jit
def _simulate(rig, controller, position0, targets, dt, substeps):
    def one(pair, x0):
        return _run_one(pair[0], pair[1], x0, targets, dt, substeps)

    return batch_apply(one, (rig, controller), position0)


def simulate_positioning(
    rig: PositioningRig,
    controller: SlidingModeController,
    target: ArrayLike,
    *,
    duration_s: float = 3.0,
    position0: ArrayLike = 0.0,
    sample_time_s: float = 0.01,
    substeps: int = 20,
) -> PositioningRun:
    """Simulate closed-loop positioning from rest at ``position0`` to ``target``.

    ``target`` is a number (position units: mm, or degrees on the rotary rig) or a schedule
    of shape (T,), one target per sample (e.g. Sárosi's hysteresis sequence). The
    controller acts every ``sample_time_s`` (Sárosi: 10 ms); between samples the plant is
    integrated by ``substeps`` RK4 steps. The rig's and the controller's fields and
    ``position0`` broadcast to one batch, simulated in one compiled, vmapped ``lax.scan``.
    """
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    if not (sample_time_s > 0 and math.isfinite(sample_time_s)):
        raise ValueError(f"sample_time_s must be a positive number, got {sample_time_s!r}")
    target = jnp.asarray(target, float)
    if target.ndim == 0:
        if not (duration_s > 0 and math.isfinite(duration_s)):
            raise ValueError(f"duration_s must be a positive number, got {duration_s!r}")
        n = int(round(duration_s / sample_time_s)) + 1
        targets = jnp.full((n,), target)
    elif target.ndim == 1:
        targets, n = target, target.shape[0]
    else:
        raise ValueError(f"target must be a number or a (T,) schedule, got shape {target.shape}")
    out = _simulate(
        rig, controller, jnp.asarray(position0, float), targets, float(sample_time_s), int(substeps)
    )
    return PositioningRun(sample_time_s * jnp.arange(n), targets, *out)


def positioning_metrics(
    run: PositioningRun, position0: ArrayLike = 0.0, resolution: ArrayLike = 0.01
) -> dict:
    """Arrival and settling times, overshoot and steady-state error of runs with one
    constant target.

    * ``reach_time_s``: the first sample time at which the encoder error is within one count
      (|r − q| ≤ resolution); NaN if it never is. Sárosi's "the position was reached at
      about 0.8 s" (Section 3.3.3) reads as this time.
    * ``settling_time_s``: the first sample time after which the encoder error stays within
      one count (|r − q| ≤ resolution) to the end of the run; NaN if it is outside at the
      end (not settled).
    * ``settling_time_2pct_s``: the same for the true position and the usual band of 2 % of
      the move (|r − x| ≤ 0.02·|r − x0|): when the move is, to the eye, done.
    * ``overshoot``: the largest travel of the true position beyond the target in the
      direction of the move (≥ 0); ``overshoot_reading`` the same for the encoder.
    * ``steady_state_error``: |r − x| of the true position at the end of the run;
      ``steady_state_error_reading``: |r − q| of the encoder there (a multiple of a count).
    * ``valve_switches_settled``: changes of the valve voltage after settling (0 for a
      chattering-free controller).

    A run whose position or reading is not finite (it diverged) gets NaN for every time and
    distance, not the "settled at once" that comparisons with NaN would give.

    Arrays of the batch shape (jnp; works under jit and vmap).
    """
    r = run.target[-1]
    res = jnp.asarray(resolution, float)
    direction = jnp.sign(r - jnp.asarray(position0, float))[..., None]
    err_q = jnp.abs(r - run.reading)
    outside = err_q > res * (1.0 + 1e-9)
    n = run.time_s.shape[0]
    idx = jnp.arange(n)
    last_out = jnp.max(jnp.where(outside, idx, -1), axis=-1)
    dt = run.time_s[1] - run.time_s[0]
    settled = last_out < n - 1
    inside = ~outside
    t_reach = jnp.where(jnp.any(inside, axis=-1), jnp.argmax(inside, axis=-1) * dt, jnp.nan)
    t_settle = jnp.where(settled, (last_out + 1) * dt, jnp.nan)
    out2 = jnp.abs(r - run.position) > 0.02 * jnp.abs(r - jnp.asarray(position0, float))[..., None]
    last_out2 = jnp.max(jnp.where(out2, idx, -1), axis=-1)
    after = idx > last_out[..., None] + 1  # the switch into the zone itself is not counted
    changes = jnp.concatenate(
        [
            jnp.zeros_like(run.voltage_V[..., :1], dtype=bool),
            run.voltage_V[..., 1:] != run.voltage_V[..., :-1],
        ],
        axis=-1,
    )
    finite = jnp.all(jnp.isfinite(run.position) & jnp.isfinite(run.reading), axis=-1)

    def real(x):  # NaN for a diverged run
        return jnp.where(finite, x, jnp.nan)

    return {
        "reach_time_s": real(t_reach),
        "settling_time_s": real(t_settle),
        "settling_time_2pct_s": real(
            jnp.where(last_out2 < n - 1, (last_out2 + 1) * dt, jnp.nan)),
        "overshoot": real(jnp.maximum(jnp.max(direction * (run.position - r), axis=-1), 0.0)),
        "overshoot_reading": real(
            jnp.maximum(jnp.max(direction * (run.reading - r), axis=-1), 0.0)),
        "steady_state_error": real(jnp.abs(r - run.position[..., -1])),
        "steady_state_error_reading": real(jnp.abs(r - run.reading[..., -1])),
        "valve_switches_settled": jnp.sum(changes & after, axis=-1),
    }


# --------------------------------------------------------------------------------------
# muscle constants from a fit, and draws from their intervals
# --------------------------------------------------------------------------------------


def sarosi_from_fit_json(fit: dict, muscle: int = 0) -> tuple[Sarosi, jnp.ndarray]:
    """Constants and standard errors of muscle ``muscle`` of a ``pamid fit --json`` object.

    Returns (:class:`pamid.Sarosi`, se of a1 … a6). The standard error is the JSON's ``se``,
    or, where it is missing or null, the half width of ``ci95`` over the Student-t quantile
    of a Wald interval with the muscle's n − 6 degrees of freedom (the normal quantile where
    the entry has no ``n``; :func:`pamid._inference.t_critical`, pamid's one Wald routine).
    """
    from .._inference import t_critical
    from .._models._sarosi import PARAM_NAMES

    if not isinstance(fit, dict):
        raise ValueError(f"the fit must be one JSON object (pamid fit --json), not a "
                         f"{type(fit).__name__}")
    if fit.get("model", "sarosi") != "sarosi":
        raise ValueError(f"the fit is of model {fit.get('model')!r}; positioning needs 'sarosi'")
    muscles = fit.get("muscles") or []
    if not isinstance(muscles, list):
        raise ValueError("the fit's 'muscles' must be a list")
    if not 0 <= muscle < len(muscles):
        raise ValueError(f"muscle index {muscle} is outside the fit's {len(muscles)} muscle(s)")
    params = muscles[muscle].get("params", {}) if isinstance(muscles[muscle], dict) else {}
    params = params if isinstance(params, dict) else {}
    missing = [n for n in PARAM_NAMES
               if not isinstance(params.get(n), dict) or params[n].get("value") is None]
    if missing:
        raise ValueError(f"the fit has no value for {', '.join(missing)} (muscle {muscle})")

    def number(name, key, value):
        where = f"muscles[{muscle}].params.{name}.{key}"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{where} must be a number, got {value!r}")
        if not math.isfinite(value):
            what = "NaN (not a number)" if math.isnan(value) else f"{value}"
            raise ValueError(f"{where} is {what}; it must be a finite number")
        return float(value)

    n = muscles[muscle].get("n") if isinstance(muscles[muscle], dict) else None
    dof = (n - len(PARAM_NAMES) if isinstance(n, int) and not isinstance(n, bool)
           and n > len(PARAM_NAMES) else math.inf)
    t = float(t_critical(dof, 0.95))
    values, ses = [], []
    for name in PARAM_NAMES:
        entry = params[name]
        se = entry.get("se")
        if se is None:
            ci = entry.get("ci95")
            lo, hi = ci if isinstance(ci, (list, tuple)) and len(ci) == 2 else (None, None)
            se = ((number(name, "ci95", hi) - number(name, "ci95", lo)) / (2 * t)
                  if lo is not None and hi is not None else 0.0)
        values.append(number(name, "value", entry["value"]))
        se = number(name, "se", se)
        if se < 0:
            raise ValueError(f"muscles[{muscle}].params.{name}: a negative standard error "
                             f"({se:g}) or an interval whose low end is above its high end")
        ses.append(se)
    return Sarosi(*values), jnp.asarray(ses)


def wald_draws(key, muscle: Sarosi, se: ArrayLike, n: int) -> Sarosi:
    """``n`` draws of the constants, independent normals N(value, se²) per constant.

    The Wald approximation of the posterior without the correlations between the constants
    (a fit's JSON does not carry them): a wider spread of force curves than the joint
    posterior, so a conservative study. Each field of the result has shape (n,).
    """
    theta = muscle.to_vector()
    z = jax.random.normal(key, (int(n), theta.shape[-1]))
    return Sarosi.from_vector(theta + z * jnp.asarray(se, float))
