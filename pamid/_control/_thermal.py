"""A lumped thermal model of a PAM heated by cycling, and the muscle force's temperature.

Source: Sárosi, dissertation summary, Section 3.3.2 and Table 3-2: a DMSP-20-400N muscle
cycled at 0.1–1 Hz (20 kg, 600 kPa, air from the compressor at 24 °C) settles at an
internal temperature that rises with the frequency:

    f [Hz]          0.1     0.25    0.5     0.75    1
    internal [°C]   30–42   35–43   40–45   45–50   45–50

The summary gives no thermal constants; pamid's model (one node, the muscle) is

    C·dT/dt = E·f − (G0 + g1·f)·(T − T_air)                                   (1)

* E·f: heat released per cycle E, f cycles per second. The largest part is the charging of
  the muscle from the supply: air entering a closed volume arrives with its enthalpy and is
  heated by the compression (for 1 g of air per cycle R·T ≈ 85 J at 297 K); the hysteresis
  loop's work (eq. 2.3–2.4) adds about a joule.
* G0·(T − T_air): convection from the surface to the room air (T_air = 24 °C, the
  temperature of the entering air and of the sensor nearest the port, Table 3-2).
* g1·f·(T − T_air): every cycle exchanges part of the muscle's air for fresh supply air at
  T_air, which cools it in proportion to the frequency. This term makes the steady state
  saturate with the frequency, as Table 3-2 does (0.75 Hz and 1 Hz read the same).

The steady state of (1) is T_ss(f) = T_air + E·f/(G0 + g1·f), i.e.

    1/(T_ss − T_air) = (G0/E)·(1/f) + g1/E,

a straight line in 1/f: :func:`fit_table_3_2` fits it to the midpoints of Table 3-2 by least
squares (two ratios) and takes G0 as given, which fixes E and g1.

Assumptions: G0 = 0.3 W/K (free convection, h ≈ 10 W/(m²·K) over the ≈ 0.03 m² surface of a
DMSP-20-400N); C = 300 J/K (about 0.3 kg of rubber and aluminium end fittings), which puts
the time constant at a few minutes, so that the 1200 s runs of Section 3.3.2 reach their
steady state as Fig. 3-8 shows.

Force against temperature (pamid's model): the pressure-free part of Sárosi eq. 2.1,
F0(κ) = a2·exp(a3·κ) + a6, is the bladder's elastic resistance; an elastomer softens as it
warms, so F0 is scaled by (1 + γ·(T − T_ref)) with γ < 0 (:func:`sarosi_at_temperature`):
a cold muscle resists contraction more and needs more air for the same position, so it
positions more slowly — the trend of Section 3.3.2 (about 1.4 s at −10 °C, 1.2 s at 39 °C).
γ is not printed. Against those two times it is calibrated to 0: the simulated muscle's
air, at the muscle's temperature, already gives 1.45 s and 1.14 s by the gas law (a warm
muscle reaches the pressure for a position with less air), and γ < 0 fits no better, so
pamid's default is γ = 0 and the elastic term is kept for sensitivity studies
(``experiments/sarosi_positioning.py``).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._models._sarosi import Sarosi

__all__ = [
    "TABLE_3_2",
    "MuscleThermal",
    "fit_table_3_2",
    "sarosi_at_temperature",
    "steady_state_temperature_C",
    "temperature_after_C",
]

#: Sárosi Table 3-2, internal steady-state temperature range (°C) at each frequency (Hz).
TABLE_3_2 = {
    0.1: (30.0, 42.0),
    0.25: (35.0, 43.0),
    0.5: (40.0, 45.0),
    0.75: (45.0, 50.0),
    1.0: (45.0, 50.0),
}
#: Temperature of the entering air and of the port-side sensor, Section 3.3.2 / Table 3-2.
AIR_TEMPERATURE_C = 24.0
#: Assumed free-convection conductance (W/K) and heat capacity (J/K) of a DMSP-20-400N.
CONVECTION_W_PER_K = 0.3
HEAT_CAPACITY_J_PER_K = 300.0
#: Assumed reference temperature of eq. 2.1's constants (the bench ran "at room temperature").
REFERENCE_TEMPERATURE_C = 20.0


class MuscleThermal(eqx.Module):
    """Constants of the lumped model (1): ``heat_per_cycle_J`` E, ``convection_W_per_K``
    G0, ``exchange_W_per_K_Hz`` g1, ``heat_capacity_J_per_K`` C, ``air_C`` T_air."""

    heat_per_cycle_J: Float[Array, "..."]
    convection_W_per_K: Float[Array, "..."]
    exchange_W_per_K_Hz: Float[Array, "..."]
    heat_capacity_J_per_K: Float[Array, "..."]
    air_C: Float[Array, "..."]

    def __init__(
        self,
        heat_per_cycle_J,
        convection_W_per_K,
        exchange_W_per_K_Hz,
        heat_capacity_J_per_K=HEAT_CAPACITY_J_PER_K,
        air_C=AIR_TEMPERATURE_C,
    ):
        self.heat_per_cycle_J = jnp.asarray(heat_per_cycle_J, float)
        self.convection_W_per_K = jnp.asarray(convection_W_per_K, float)
        self.exchange_W_per_K_Hz = jnp.asarray(exchange_W_per_K_Hz, float)
        self.heat_capacity_J_per_K = jnp.asarray(heat_capacity_J_per_K, float)
        self.air_C = jnp.asarray(air_C, float)


def steady_state_temperature_C(thermal: MuscleThermal, frequency_Hz: ArrayLike):
    """T_ss(f) = T_air + E·f/(G0 + g1·f), the steady state of (1)."""
    f = jnp.asarray(frequency_Hz, float)
    return thermal.air_C + thermal.heat_per_cycle_J * f / (
        thermal.convection_W_per_K + thermal.exchange_W_per_K_Hz * f
    )


def temperature_after_C(
    thermal: MuscleThermal, frequency_Hz: ArrayLike, time_s: ArrayLike, start_C: ArrayLike
) -> Float[Array, "..."]:
    """T(t) of (1) at a constant cycling frequency from ``start_C`` (exact solution).

    T(t) = T_ss + (T0 − T_ss)·exp(−t·(G0 + g1·f)/C).
    """
    f = jnp.asarray(frequency_Hz, float)
    t_ss = steady_state_temperature_C(thermal, f)
    rate = (thermal.convection_W_per_K + thermal.exchange_W_per_K_Hz * f) / (
        thermal.heat_capacity_J_per_K
    )
    return t_ss + (jnp.asarray(start_C, float) - t_ss) * jnp.exp(-jnp.asarray(time_s) * rate)


def fit_table_3_2(
    convection_W_per_K: float = CONVECTION_W_PER_K,
    heat_capacity_J_per_K: float = HEAT_CAPACITY_J_PER_K,
    air_C: float = AIR_TEMPERATURE_C,
    table: dict | None = None,
) -> MuscleThermal:
    """E and g1 of (1) from the midpoints of Table 3-2, by least squares on
    1/(T − T_air) = (G0/E)·(1/f) + g1/E (see the module docstring); G0 and C as given."""
    table = TABLE_3_2 if table is None else table
    f = np.array(sorted(table), float)
    mid = np.array([sum(table[x]) / 2.0 for x in sorted(table)])
    design = np.column_stack([1.0 / f, np.ones_like(f)])
    (slope, intercept), *_ = np.linalg.lstsq(design, 1.0 / (mid - air_C), rcond=None)
    heat = convection_W_per_K / slope
    return MuscleThermal(heat, convection_W_per_K, intercept * heat, heat_capacity_J_per_K, air_C)


def sarosi_at_temperature(
    params: Sarosi,
    temperature_C: ArrayLike,
    coefficient_per_K: ArrayLike,
    reference_C: ArrayLike = REFERENCE_TEMPERATURE_C,
) -> Sarosi:
    """Eq. 2.1's constants at ``temperature_C``: the pressure-free part a2·exp(a3·κ) + a6
    scaled by (1 + γ·(T − T_ref)) (see the module docstring); γ = ``coefficient_per_K``."""
    scale = 1.0 + jnp.asarray(coefficient_per_K, float) * (
        jnp.asarray(temperature_C, float) - jnp.asarray(reference_C, float)
    )
    return Sarosi(params.a1, params.a2 * scale, params.a3, params.a4, params.a5, params.a6 * scale)
