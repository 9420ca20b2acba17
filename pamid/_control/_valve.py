"""The 5/3 proportional valve of Sárosi's positioning rig and the mass flow through it.

Source: Sárosi, dissertation summary, Sections 2.4.1 and 3.3.1: the muscles are driven by a
Festo MPYE-5-1/8 HF-010B 5/3 proportional directional valve, 600 kPa supply, control voltage
0–10 V with 5 V the closed middle position ("in position"). The summary gives no flow data
for the valve; the flow model and its coefficients below are pamid's.

Flow through one metering edge (ISO 6358, the standard model for pneumatic valves):

    ṁ = C·ρ_ANR·p_up·√(T_ANR/T_up) · φ(p_down/p_up)
    φ(r) = 1                                   r ≤ b     (choked, sonic)
    φ(r) = √(1 − ((r − b)/(1 − b))²)           r > b     (unchoked, subsonic)

with absolute pressures, the sonic conductance C in m³/(s·Pa), the critical pressure ratio
b, and the standard reference atmosphere of ISO 8778 (ρ_ANR = 1.185 kg/m³ at 100 kPa and
20 °C). Flow runs from the higher to the lower pressure; :func:`orifice_mass_flow_kg_s`
returns it with the sign of p1 − p2, so the same edge can fill and empty.

The valve (5/3, closed centre): at u > 5 V port A (muscle 1) opens to the supply and port B
(muscle 2) to the exhaust; at u < 5 V the reverse. The spool opening grows linearly with
the voltage beyond the spool's overlap d, o = sign(u − 5 V)·(|u − 5 V| − d)/(5 V − d) ∈
[−1, 1] (0 inside the overlap), and each metering edge has the conductance |o|·C. At 5 V
every edge is shut and no air moves (the "closed valve holds mass" test).

Assumptions (none printed by Sárosi):

* The catalogue C of the MPYE-5-1/8-HF follows from its standard nominal flow, 700 l/min
  (ANR) from 6 bar to 5 bar gauge at full opening, with b = 0.3 assumed:
  C = Q_N/(p1·φ(p2/p1)) ≈ 2.75e-8 m³/(s·Pa) (2.75 l/(s·bar); see
  :func:`sonic_conductance_from_nominal_flow`).
* Two constants are calibrated, once for all rigs, against Sárosi's results (positioning
  40 mm in 1.2–1.4 s with 0.02 mm overshoot, holding within one count): the default valve
  has a fifth of the catalogue conductance (:data:`CONDUCTANCE_CALIBRATION`) and a spool
  overlap of 0.3 V (:data:`MPYE_OVERLAP_V`), so that "slow" (±0.35 V) opens the valve by
  only 0.05/4.7 ≈ 1 % and "fast" (±1 V) by 15 %. With the catalogue value and no overlap the
  muscles fill in a few samples at 6 V, and one 10 ms pulse at the slow level moves the
  20 kg load by several encoder counts: the simulated loop then overshoots by millimetres
  and hunts around the target instead of settling. The two numbers stand for what the model
  leaves out (the real spool's lap and flow curve near the middle position, the tubes'
  resistance, the valve's own response); they are calibrations, not datasheet values.
* No leakage at the middle position.
* The valve's own dynamics (its spool settles in a few ms) are neglected against the 10 ms
  sampling time.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._units import ATMOSPHERE_KPA, PA_PER_KPA

__all__ = [
    "CLOSED_VOLTAGE_V",
    "CONDUCTANCE_CALIBRATION",
    "MPYE_OVERLAP_V",
    "MPYE_NOMINAL_FLOW_L_PER_MIN",
    "RHO_ANR_KG_PER_M3",
    "T_ANR_K",
    "ProportionalValve",
    "orifice_mass_flow_kg_s",
    "sonic_conductance_from_nominal_flow",
    "valve_mass_flows_kg_s",
    "valve_opening",
]

#: ISO 8778 standard reference atmosphere: 100 kPa, 20 °C, 65 % RH, ρ = 1.185 kg/m³.
RHO_ANR_KG_PER_M3 = 1.185
T_ANR_K = 293.15
P_ANR_PA = 100_000.0
#: Catalogue standard nominal flow of the MPYE-5-1/8-HF, 6 → 5 bar gauge (an assumption:
#: the value is Festo's, not printed in the dissertation summary).
MPYE_NOMINAL_FLOW_L_PER_MIN = 700.0
#: Assumed critical pressure ratio of the valve's metering edges.
MPYE_CRITICAL_RATIO = 0.3
#: Effective/catalogue conductance ratio of the default valve (calibrated; see above).
CONDUCTANCE_CALIBRATION = 0.2
#: Spool overlap of the default valve in V (calibrated; see above).
MPYE_OVERLAP_V = 0.3
#: The middle ("in position") voltage of the 0–10 V valve (Sárosi Section 2.4.1).
CLOSED_VOLTAGE_V = 5.0


def _phi(ratio, b):
    """ISO 6358 flow function φ(r) of the downstream/upstream ratio r ∈ [0, 1]."""
    x = jnp.clip((ratio - b) / (1.0 - b), 0.0, 1.0)
    y = 1.0 - x * x
    # Exactly 0 at r = 1 (equal pressures), with a finite derivative there (double where).
    return jnp.where(y > 0.0, jnp.sqrt(jnp.where(y > 0.0, y, 1.0)), 0.0)


def sonic_conductance_from_nominal_flow(
    nominal_flow_l_per_min: float = MPYE_NOMINAL_FLOW_L_PER_MIN,
    critical_ratio: float = MPYE_CRITICAL_RATIO,
    p1_gauge_kPa: float = 600.0,
    p2_gauge_kPa: float = 500.0,
    p_atm_kPa: float = ATMOSPHERE_KPA,
) -> float:
    """C in m³/(s·Pa) from a catalogue standard nominal flow (ANR volume flow, 6 → 5 bar).

    ISO 6358: Q_ANR = C·p1·√(T_ANR/T1)·φ(p2/p1), taken at T1 = T_ANR.
    """
    p1 = (p1_gauge_kPa + p_atm_kPa) * PA_PER_KPA
    p2 = (p2_gauge_kPa + p_atm_kPa) * PA_PER_KPA
    q = nominal_flow_l_per_min / 60_000.0
    return float(q / (p1 * _phi(p2 / p1, critical_ratio)))


class ProportionalValve(eqx.Module):
    """A 5/3 closed-centre proportional valve (Festo MPYE-5-1/8 HF-010B by default).

    Fields: ``conductance_m3_per_s_Pa`` (C of one edge at full opening), ``critical_ratio``
    (b), ``closed_V`` (middle voltage), ``span_V`` (voltage from the middle to full
    opening) and ``overlap_V`` (the spool's lap d: no flow while |u − 5 V| ≤ d).
    """

    conductance_m3_per_s_Pa: Float[Array, "..."]
    critical_ratio: Float[Array, "..."]
    closed_V: Float[Array, "..."]
    span_V: Float[Array, "..."]
    overlap_V: Float[Array, "..."]

    def __init__(
        self,
        conductance_m3_per_s_Pa=None,
        critical_ratio=MPYE_CRITICAL_RATIO,
        closed_V=CLOSED_VOLTAGE_V,
        span_V=5.0,
        overlap_V=MPYE_OVERLAP_V,
    ):
        if conductance_m3_per_s_Pa is None:
            conductance_m3_per_s_Pa = CONDUCTANCE_CALIBRATION * (
                sonic_conductance_from_nominal_flow(critical_ratio=float(critical_ratio))
            )
        self.conductance_m3_per_s_Pa = jnp.asarray(conductance_m3_per_s_Pa, float)
        self.critical_ratio = jnp.asarray(critical_ratio, float)
        self.closed_V = jnp.asarray(closed_V, float)
        self.span_V = jnp.asarray(span_V, float)
        self.overlap_V = jnp.asarray(overlap_V, float)


def valve_opening(valve: ProportionalValve, voltage_V: ArrayLike) -> Float[Array, "..."]:
    """Signed spool opening o ∈ [−1, 1]; > 0 fills port A.

    o = sign(u − 5 V)·max(|u − 5 V| − d, 0)/(5 V − d), with the spool's overlap d (0: the
    opening is linear in the voltage from the middle on).
    """
    du = jnp.asarray(voltage_V, float) - valve.closed_V
    travel = jnp.maximum(jnp.abs(du) - valve.overlap_V, 0.0) / (valve.span_V - valve.overlap_V)
    return jnp.sign(du) * jnp.clip(travel, 0.0, 1.0)


def orifice_mass_flow_kg_s(
    conductance_m3_per_s_Pa: ArrayLike,
    p1_Pa: ArrayLike,
    p2_Pa: ArrayLike,
    t1_K: ArrayLike,
    t2_K: ArrayLike,
    critical_ratio: ArrayLike = MPYE_CRITICAL_RATIO,
) -> Float[Array, "..."]:
    """Mass flow in kg/s from side 1 to side 2 (negative when it runs 2 → 1), ISO 6358.

    Pressures absolute in Pa, temperatures in K (of each side; the upstream one is used).
    """
    p1, p2 = jnp.asarray(p1_Pa, float), jnp.asarray(p2_Pa, float)
    forward = p1 >= p2
    p_up = jnp.where(forward, p1, p2)
    p_down = jnp.where(forward, p2, p1)
    t_up = jnp.where(forward, t1_K, t2_K)
    flow = (
        jnp.asarray(conductance_m3_per_s_Pa, float)
        * RHO_ANR_KG_PER_M3
        * p_up
        * jnp.sqrt(T_ANR_K / t_up)
        * _phi(p_down / p_up, critical_ratio)
    )
    return jnp.where(forward, flow, -flow)


def valve_mass_flows_kg_s(
    valve: ProportionalValve,
    voltage_V: ArrayLike,
    pA_Pa: ArrayLike,
    pB_Pa: ArrayLike,
    tA_K: ArrayLike,
    tB_K: ArrayLike,
    supply_Pa: ArrayLike,
    supply_K: ArrayLike,
    exhaust_Pa: ArrayLike = ATMOSPHERE_KPA * PA_PER_KPA,
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Mass flows (kg/s) into port A and into port B at the control voltage ``voltage_V``.

    u > 5 V: A ← supply, B → exhaust; u < 5 V: A → exhaust, B ← supply; 5 V: both zero.
    Pressures absolute (Pa), temperatures in K. The exhaust is at ``supply_K`` (it is only
    ever downstream, where its temperature does not enter).
    """
    o = valve_opening(valve, voltage_V)
    c = jnp.abs(o) * valve.conductance_m3_per_s_Pa
    b = valve.critical_ratio
    fill_a = orifice_mass_flow_kg_s(c, supply_Pa, pA_Pa, supply_K, tA_K, b)
    vent_a = -orifice_mass_flow_kg_s(c, pA_Pa, exhaust_Pa, tA_K, supply_K, b)
    fill_b = orifice_mass_flow_kg_s(c, supply_Pa, pB_Pa, supply_K, tB_K, b)
    vent_b = -orifice_mass_flow_kg_s(c, pB_Pa, exhaust_Pa, tB_K, supply_K, b)
    into_a = jnp.where(o > 0, fill_a, jnp.where(o < 0, vent_a, 0.0))
    into_b = jnp.where(o > 0, vent_b, jnp.where(o < 0, fill_b, 0.0))
    return into_a, into_b
