"""Sárosi's dissertation as pamid reproduces it: Table 3-1 and Table 3-2, the eq.-numbered
functions, and the presets and constants of his rigs.

Source: J. Sárosi, dissertation summary "Modelling the Static and Dynamic Operation of
Pneumatic Artificial Muscles and Their Accurate Positioning". ``pamid.sarosi.TABLE_3_1``,
``pamid.sarosi.sarosi_stiffness_eq_2_9(...)``: the paper's artefacts live here, the workflows
(:func:`pamid.fit_least_squares`, :func:`pamid.simulate_positioning`, …) in ``pamid``.
:class:`Sarosi`, :class:`SlidingModeController` and :class:`ProportionalValve` are in both:
a workflow takes them as arguments.
"""

from ._control._positioning import linear_rig as sarosi_linear_rig
from ._control._positioning import rotary_rig as sarosi_rotary_rig
from ._control._positioning import sarosi_from_fit_json
from ._control._positioning import single_muscle_rig as sarosi_single_muscle_rig
from ._control._sliding_mode import (
    FAST_BACKWARD_V,
    FAST_FORWARD_V,
    IN_POSITION_V,
    LINEAR_GRADIENT,
    PRECISION_ZONE_COUNTS,
    ROTARY_GRADIENT,
    SLOW_BACKWARD_V,
    SLOW_BAND_COUNTS,
    SLOW_FORWARD_V,
    SlidingModeController,
    plain_switching,
    sliding_mode_voltage,
    sliding_surface,
)
from ._control._thermal import (
    TABLE_3_2,
    MuscleThermal,
    fit_table_3_2,
    sarosi_at_temperature,
    steady_state_temperature_C,
    temperature_after_C,
)
from ._control._valve import (
    CONDUCTANCE_CALIBRATION,
    ProportionalValve,
    orifice_mass_flow_kg_s,
    sonic_conductance_from_nominal_flow,
    valve_mass_flows_kg_s,
)
from ._models._hysteresis import hysteresis_damping, sarosi_force_integral
from ._models._sarosi import (
    TABLE_3_1,
    TABLE_3_1_L0_MM,
    Sarosi,
    sarosi_force,
    sarosi_force_slope,
    sarosi_pressure_for_force,
    sarosi_stiffness,
    sarosi_stiffness_eq_2_9,
    table_3_1,
    table_3_1_fit_json,
)
from ._sim._lifting_mass import (
    default_zeta,
    hysteresis_branches,
    lifting_mass_damping,
    lifting_mass_force,
    zeta_from_hysteresis,
)

__all__ = [
    # The static model: eq. 2.1 and eq. 2.7–2.9, Table 3-1 (DMSP-20-400N).
    "Sarosi", "TABLE_3_1", "TABLE_3_1_L0_MM", "sarosi_force", "sarosi_force_slope",
    "sarosi_pressure_for_force", "sarosi_stiffness", "sarosi_stiffness_eq_2_9", "table_3_1",
    "table_3_1_fit_json",
    # Hysteresis and damping: eq. 2.3–2.10 (the lifting mass of Fig. 2-3: eq. 2.2).
    "default_zeta", "hysteresis_branches", "hysteresis_damping", "lifting_mass_damping",
    "lifting_mass_force", "sarosi_force_integral", "zeta_from_hysteresis",
    # Temperature: Section 3.3.2, Table 3-2.
    "TABLE_3_2", "MuscleThermal", "fit_table_3_2", "sarosi_at_temperature",
    "steady_state_temperature_C", "temperature_after_C",
    # The positioning rigs of Sections 2.4 and 3.3: presets, controller, valve.
    "sarosi_from_fit_json", "sarosi_linear_rig", "sarosi_rotary_rig",
    "sarosi_single_muscle_rig",
    "FAST_BACKWARD_V", "FAST_FORWARD_V", "IN_POSITION_V", "LINEAR_GRADIENT",
    "PRECISION_ZONE_COUNTS", "ROTARY_GRADIENT", "SLOW_BACKWARD_V", "SLOW_BAND_COUNTS",
    "SLOW_FORWARD_V", "SlidingModeController", "plain_switching", "sliding_mode_voltage",
    "sliding_surface",
    "CONDUCTANCE_CALIBRATION", "ProportionalValve", "orifice_mass_flow_kg_s",
    "sonic_conductance_from_nominal_flow", "valve_mass_flows_kg_s",
]
