"""pamid: system identification for pneumatic artificial muscles, built on JAX.

The public API has three tiers (docs/architecture.md):

* ``pamid``: the workflows (read a file, fit, sample, diagnose, compare, simulate, the
  virtual benches), their result types, errors and warnings, and the extension points
  (:class:`ForceModel` and :func:`register_model`, the effects a virtual bench can inject,
  the ensemble kernel and its moves).
* ``pamid.sarosi`` and ``pamid.cullinan``: each paper's artefacts (tables, eq.-numbered
  functions, presets, constants); ``pamid.io``: writing results atomically;
  ``pamid.report``: results written out (JSON text, tables, NetCDF, figures);
  ``pamid.engine``: the low-level tier (model registry, batched solver, starts, interval
  estimators, sampler pieces) for code that builds on them.
* everything under a leading underscore: private, grouped by concept: ``_data`` (reading
  files), ``_virtual`` (the virtual benches), ``_effects``, ``_models`` (force laws),
  ``_fit`` (batched least squares and intervals), ``_sim`` (simulators), ``_decays`` (free
  decays), ``_sampling`` (MCMC), ``_diagnose`` (closing the loop), ``_control``
  (positioning control), ``_commands`` (the command line).

float64 is switched on at import, because fitting needs it (``JAX_ENABLE_X64=1`` in this
process' environment when JAX is not imported yet: ``import pamid`` does not import JAX).
"""

import importlib
import importlib.metadata
import os
import sys
import warnings
from typing import TYPE_CHECKING

# float64 on, without importing JAX here: the command line reads its data file while JAX
# starts on another thread (pamid._lanes._export_cache.prepare_in_background). JAX imported
# before pamid gets the setting now; otherwise JAX reads it from this process' environment
# when it is first imported (and child processes inherit it).
if "jax" in sys.modules:
    sys.modules["jax"].config.update("jax_enable_x64", True)
else:
    os.environ["JAX_ENABLE_X64"] = "1"

#: THE list of public names: name -> (module, attribute; None for a namespace module).
#: ``__all__``, ``dir(pamid)`` and the lazy loading below come from it, and
#: tests/test_public_api.py checks the ``TYPE_CHECKING`` imports at the end against it.
#: Modules load on first use (PEP 562), so that ``import pamid`` and the command line do
#: not pay for what they do not touch.
_EXPORTS: dict[str, tuple[str, str | None]] = {
    # Reading bench and decay files; errors and warnings.
    "BenchData": ("._data._bench", "BenchData"),
    "CensoredRowsWarning": ("._data._bench", "CensoredRowsWarning"),
    "MissingValuesWarning": ("._data._bench", "MissingValuesWarning"),
    "load_bench": ("._data._bench", "load_bench"),
    "DecayData": ("._data._decay_file", "DecayData"),
    "load_decay": ("._data._decay_file", "load_decay"),
    "BenchDataError": ("._errors", "BenchDataError"),
    "UntrustedResultError": ("._errors", "UntrustedResultError"),
    # Force laws: the base class users subclass, pamid's own laws, the registry.
    "ForceModel": ("._models._protocol", "ForceModel"),
    "ModelDefinitionError": ("._fit._spec", "ModelDefinitionError"),
    "register_model": ("._fit._spec", "register_model"),
    "Sarosi": ("._models._sarosi", "Sarosi"),
    "Cullinan": ("._models._cullinan", "Cullinan"),
    "Bolen2026": ("._models._bolen", "Bolen2026"),
    # Least squares, model comparison, devices.
    "FitResult": ("._fit._api", "FitResult"),
    "bench_to_fit_data": ("._fit._api", "bench_to_fit_data"),
    "fit_least_squares": ("._fit._api", "fit_least_squares"),
    "FitData": ("._lanes._batch", "FitData"),
    "pack_muscles": ("._lanes._batch", "pack"),
    "Comparison": ("._fit._compare", "Comparison"),
    "compare_models": ("._fit._compare", "compare_models"),
    "use_devices": ("._lanes._sharding", "use_devices"),
    # Posterior sampling, and the ensemble kernel with its moves.
    "McmcBudgetWarning": ("._sampling._mcmc", "McmcBudgetWarning"),
    "McmcResult": ("._sampling._mcmc", "McmcResult"),
    "fit_mcmc": ("._sampling._mcmc", "fit_mcmc"),
    "Prior": ("._sampling._posterior", "Prior"),
    "default_prior": ("._sampling._posterior", "default_prior"),
    "load_inference_data": ("._sampling._arviz", "load_inference_data"),
    "EnsembleState": ("._sampling._ensemble", "EnsembleState"),
    "de_move": ("._sampling._ensemble", "de_move"),
    "ensemble_init": ("._sampling._ensemble", "ensemble_init"),
    "ensemble_step": ("._sampling._ensemble", "ensemble_step"),
    "run_ensembles": ("._sampling._ensemble", "run_ensembles"),
    "stretch_move": ("._sampling._ensemble", "stretch_move"),
    # Closing the loop.
    "Diagnosis": ("._diagnose._result", "Diagnosis"),
    "diagnose": ("._diagnose._api", "diagnose"),
    "LengthStudy": ("._diagnose._length", "LengthStudy"),
    "length_study": ("._diagnose._length", "length_study"),
    # Pooled models across muscles: a muscle nobody has tested.
    "MusclePrediction": ("._pooled._predict", "MusclePrediction"),
    "predict_muscle": ("._pooled._predict", "predict_muscle"),
    "PooledComparison": ("._pooled._lomo", "PooledComparison"),
    "PooledModel": ("._pooled._lomo", "PooledModel"),
    "compare_pooled": ("._pooled._lomo", "compare_pooled"),
    # Virtual benches and the effects they can hide in their data.
    "SarosiProtocol": ("._virtual._sweeps", "SarosiProtocol"),
    "simulate_sarosi_bench": ("._virtual._sweeps", "simulate_sarosi_bench"),
    "IsometricProtocol": ("._virtual._isometric", "IsometricProtocol"),
    "simulate_isometric_bench": ("._virtual._isometric", "simulate_isometric_bench"),
    "simulate_population_bench": ("._virtual._population", "simulate_population_bench"),
    "virtual_lab_file": ("._virtual._isometric", "virtual_lab_file"),
    "write_bench_csv": ("._virtual._isometric", "write_bench_csv"),
    "DecayProtocol": ("._virtual._decay", "DecayProtocol"),
    "simulate_decays": ("._virtual._decay", "simulate_decays"),
    "DeflectionProtocol": ("._virtual._joint", "DeflectionProtocol"),
    "JointSweepProtocol": ("._virtual._joint", "JointSweepProtocol"),
    "deflection_test_stiffness": ("._virtual._joint", "deflection_test_stiffness"),
    "simulate_deflection_test": ("._virtual._joint", "simulate_deflection_test"),
    "simulate_joint_sweep": ("._virtual._joint", "simulate_joint_sweep"),
    "StaticBenchProtocol": ("._virtual._braided", "StaticBenchProtocol"),
    "simulate_braided_pam_bench": ("._virtual._braided", "simulate_braided_pam_bench"),
    "default_bench_path": ("._virtual._default", "default_bench_path"),
    "Injected": ("._effects._inject", "Injected"),
    "InjectedCompliance": ("._effects._compliance", "InjectedCompliance"),
    "InjectedCovariate": ("._effects._covariate", "InjectedCovariate"),
    "InjectedDrift": ("._effects._drift", "InjectedDrift"),
    "InjectedHysteresis": ("._effects._hysteresis", "InjectedHysteresis"),
    "InjectedMaxwellSlip": ("._effects._hysteresis", "InjectedMaxwellSlip"),
    "InjectedRelativeTemperature": ("._effects._temperature", "InjectedRelativeTemperature"),
    "InjectedTemperature": ("._effects._temperature", "InjectedTemperature"),
    "InjectedViscousDamping": ("._effects._viscous_damping", "InjectedViscousDamping"),
    # Free decays.
    "DecayReport": ("._decays._analysis", "DecayReport"),
    "DecrementEstimate": ("._decays._analysis", "DecrementEstimate"),
    "Extrema": ("._decays._analysis", "Extrema"),
    "TrajectoryFit": ("._decays._analysis", "TrajectoryFit"),
    "analyze_decays": ("._decays._analysis", "analyze_decays"),
    "decrement_estimate": ("._decays._analysis", "decrement_estimate"),
    "find_extrema": ("._decays._analysis", "find_extrema"),
    "fit_decay_trajectories": ("._decays._analysis", "fit_decay_trajectories"),
    "log_decrement_to_zeta": ("._decays._analysis", "log_decrement_to_zeta"),
    "DECAY_EFFECTS": ("._decays._coulomb", "DECAY_EFFECTS"),
    "DecayModelFit": ("._decays._coulomb", "DecayModelFit"),
    "DecayTrialModelFit": ("._decays._coulomb", "DecayTrialModelFit"),
    "coulomb_response": ("._decays._coulomb", "coulomb_response"),
    "fit_decay_models": ("._decays._coulomb", "fit_decay_models"),
    "JointDecayFit": ("._decays._joint_fit", "JointDecayFit"),
    "fit_joint_decays": ("._decays._joint_fit", "fit_joint_decays"),
    "DecayPosterior": ("._decays._posterior", "DecayPosterior"),
    "DecayPredictive": ("._decays._posterior", "DecayPredictive"),
    "decay_prior": ("._decays._posterior", "decay_prior"),
    "fit_decay_mcmc": ("._decays._posterior", "fit_decay_mcmc"),
    # Simulators.
    "LiftingMass": ("._sim._lifting_mass", "LiftingMass"),
    "LiftingMassRun": ("._sim._lifting_mass", "LiftingMassRun"),
    "lifting_mass_equilibrium": ("._sim._lifting_mass", "lifting_mass_equilibrium"),
    "simulate_lifting_mass": ("._sim._lifting_mass", "simulate_lifting_mass"),
    "DampedOscillator": ("._sim._oscillator", "DampedOscillator"),
    "OscillatorRun": ("._sim._oscillator", "OscillatorRun"),
    "oscillator_response": ("._sim._oscillator", "oscillator_response"),
    "simulate_oscillator": ("._sim._oscillator", "simulate_oscillator"),
    "JointArm": ("._sim._joint_sim", "JointArm"),
    "JointArmRun": ("._sim._joint_sim", "JointArmRun"),
    "joint_equilibrium_rad": ("._sim._joint_sim", "joint_equilibrium_rad"),
    "simulate_joint_arm": ("._sim._joint_sim", "simulate_joint_arm"),
    "PositioningRig": ("._control._positioning", "PositioningRig"),
    "PositioningRun": ("._control._positioning", "PositioningRun"),
    "positioning_metrics": ("._control._positioning", "positioning_metrics"),
    "simulate_positioning": ("._control._positioning", "simulate_positioning"),
    "wald_draws": ("._control._positioning", "wald_draws"),
    "SlidingModeController": ("._control._sliding_mode", "SlidingModeController"),
    "ProportionalValve": ("._control._valve", "ProportionalValve"),
    "PamVolume": ("._models._volume", "PamVolume"),
    # The papers' artefacts, writing results as pamid's commands do, and the low-level tier.
    "cullinan": (".cullinan", None),
    "engine": (".engine", None),
    "io": (".io", None),
    "report": (".report", None),
    "sarosi": (".sarosi", None),
}

#: Names that ``pamid`` exported flat before the tiers, and where they are now. They still
#: resolve, with a DeprecationWarning, for one release; they are not in ``__all__``.
_MOVED: dict[str, str] = {
    "TABLE_3_1": "pamid.sarosi",
    "TABLE_3_1_L0_MM": "pamid.sarosi",
    "table_3_1": "pamid.sarosi",
    "table_3_1_fit_json": "pamid.sarosi",
    "sarosi_force": "pamid.sarosi",
    "sarosi_force_slope": "pamid.sarosi",
    "sarosi_pressure_for_force": "pamid.sarosi",
    "sarosi_stiffness": "pamid.sarosi",
    "sarosi_stiffness_eq_2_9": "pamid.sarosi",
    "sarosi_force_integral": "pamid.sarosi",
    "hysteresis_damping": "pamid.sarosi",
    "hysteresis_branches": "pamid.sarosi",
    "zeta_from_hysteresis": "pamid.sarosi",
    "TABLE_3_2": "pamid.sarosi",
    "fit_table_3_2": "pamid.sarosi",
    "MuscleThermal": "pamid.sarosi",
    "sarosi_at_temperature": "pamid.sarosi",
    "steady_state_temperature_C": "pamid.sarosi",
    "temperature_after_C": "pamid.sarosi",
    "sarosi_linear_rig": "pamid.sarosi",
    "sarosi_rotary_rig": "pamid.sarosi",
    "sarosi_single_muscle_rig": "pamid.sarosi",
    "sarosi_from_fit_json": "pamid.sarosi",
    "sliding_surface": "pamid.sarosi",
    "sliding_mode_voltage": "pamid.sarosi",
    "plain_switching": "pamid.sarosi",
    "orifice_mass_flow_kg_s": "pamid.sarosi",
    "valve_mass_flows_kg_s": "pamid.sarosi",
    "cullinan_force": "pamid.cullinan",
    "cullinan_spring_rate": "pamid.cullinan",
    "end_fitting_force": "pamid.cullinan",
    "BraidedPam": "pamid.cullinan",
    "braided_pam": "pamid.cullinan",
    "braided_pam_force_N": "pamid.cullinan",
    "config_a_beta_range_rad": "pamid.cullinan",
    "sleeve_joint_A": "pamid.cullinan",
    "sleeve_joint_B": "pamid.cullinan",
    "sleeve_pam": "pamid.cullinan",
    "traditional_joint": "pamid.cullinan",
    "traditional_pam": "pamid.cullinan",
    "fit_cullinan_presets": "pamid.cullinan",
    "CULLINAN_CABLE_COMPLIANCE_MM_PER_N": "pamid.cullinan",
    "CULLINAN_P_MAX_KPA": "pamid.cullinan",
    "CULLINAN_PULLEY_RADIUS_MM": "pamid.cullinan",
    "AvailableTorque": "pamid.cullinan",
    "ClosedSystemStiffness": "pamid.cullinan",
    "IsobaricStiffness": "pamid.cullinan",
    "JointGeometry": "pamid.cullinan",
    "MuscleState": "pamid.cullinan",
    "available_torque_Nm": "pamid.cullinan",
    "closed_system_stiffness": "pamid.cullinan",
    "closed_system_torque_Nm": "pamid.cullinan",
    "contractions_mm": "pamid.cullinan",
    "joint_stiffness_eq7_Nm_per_rad": "pamid.cullinan",
    "joint_stiffness_Nm_per_rad": "pamid.cullinan",
    "joint_torque_eq6_Nm": "pamid.cullinan",
    "joint_torque_Nm": "pamid.cullinan",
    "max_isobaric_stiffness": "pamid.cullinan",
    "muscle_state": "pamid.cullinan",
    "pressures_for_torque_stiffness_kPa": "pamid.cullinan",
    "braid_volume_mm3": "pamid.cullinan",
    "closed_system_pressure_kPa": "pamid.cullinan",
    "sleeve_pam_volume": "pamid.cullinan",
    "traditional_pam_volume": "pamid.cullinan",
    "pam_volume_mm3": "pamid.cullinan",
    "R_AIR_J_PER_KG_K": "pamid.cullinan",
    "ROOM_TEMPERATURE_K": "pamid.cullinan",
    "TrajectoryEnergy": "pamid.cullinan",
    "air_mass_kg": "pamid.cullinan",
    "compressor_work_J": "pamid.cullinan",
    "trajectory_energy_J": "pamid.cullinan",
    "moment_of_inertia_eq12": "pamid.cullinan",
    "gravity_moment_Nm": "pamid.cullinan",
    "joint_arm_torque_Nm": "pamid.cullinan",
    "lane_devices": "pamid._lanes._sharding",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        module, attr = _EXPORTS[name]
        value = importlib.import_module(module, __name__)
        if attr is not None:
            value = getattr(value, attr)
        globals()[name] = value  # later lookups skip this function
        return value
    if name in _MOVED:
        place = _MOVED[name]
        if place.startswith("pamid._"):
            hint = "it is no longer public (pamid.use_devices chooses the devices)"
        else:
            hint = f"use {place}.{name}"
        warnings.warn(f"pamid.{name} is deprecated and goes in the next release: {hint}",
                      DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(place), name)
    raise AttributeError(f"module 'pamid' has no attribute {name!r}")


def __dir__():
    return sorted({*__all__, *(n for n in globals() if n.startswith("__"))})


if TYPE_CHECKING:  # for type checkers and editors: exactly the names of ``_EXPORTS``
    from . import cullinan as cullinan
    from . import engine as engine
    from . import io as io
    from . import report as report
    from . import sarosi as sarosi
    from ._control._positioning import PositioningRig as PositioningRig
    from ._control._positioning import PositioningRun as PositioningRun
    from ._control._positioning import positioning_metrics as positioning_metrics
    from ._control._positioning import simulate_positioning as simulate_positioning
    from ._control._positioning import wald_draws as wald_draws
    from ._control._sliding_mode import SlidingModeController as SlidingModeController
    from ._control._valve import ProportionalValve as ProportionalValve
    from ._data._bench import BenchData as BenchData
    from ._data._bench import CensoredRowsWarning as CensoredRowsWarning
    from ._data._bench import MissingValuesWarning as MissingValuesWarning
    from ._data._bench import load_bench as load_bench
    from ._data._decay_file import DecayData as DecayData
    from ._data._decay_file import load_decay as load_decay
    from ._decays._analysis import DecayReport as DecayReport
    from ._decays._analysis import DecrementEstimate as DecrementEstimate
    from ._decays._analysis import Extrema as Extrema
    from ._decays._analysis import TrajectoryFit as TrajectoryFit
    from ._decays._analysis import analyze_decays as analyze_decays
    from ._decays._analysis import decrement_estimate as decrement_estimate
    from ._decays._analysis import find_extrema as find_extrema
    from ._decays._analysis import fit_decay_trajectories as fit_decay_trajectories
    from ._decays._analysis import log_decrement_to_zeta as log_decrement_to_zeta
    from ._decays._coulomb import DECAY_EFFECTS as DECAY_EFFECTS
    from ._decays._coulomb import DecayModelFit as DecayModelFit
    from ._decays._coulomb import DecayTrialModelFit as DecayTrialModelFit
    from ._decays._coulomb import coulomb_response as coulomb_response
    from ._decays._coulomb import fit_decay_models as fit_decay_models
    from ._decays._joint_fit import JointDecayFit as JointDecayFit
    from ._decays._joint_fit import fit_joint_decays as fit_joint_decays
    from ._decays._posterior import DecayPosterior as DecayPosterior
    from ._decays._posterior import DecayPredictive as DecayPredictive
    from ._decays._posterior import decay_prior as decay_prior
    from ._decays._posterior import fit_decay_mcmc as fit_decay_mcmc
    from ._diagnose._api import diagnose as diagnose
    from ._diagnose._length import LengthStudy as LengthStudy
    from ._diagnose._length import length_study as length_study
    from ._diagnose._result import Diagnosis as Diagnosis
    from ._effects._compliance import InjectedCompliance as InjectedCompliance
    from ._effects._covariate import InjectedCovariate as InjectedCovariate
    from ._effects._drift import InjectedDrift as InjectedDrift
    from ._effects._hysteresis import InjectedHysteresis as InjectedHysteresis
    from ._effects._hysteresis import InjectedMaxwellSlip as InjectedMaxwellSlip
    from ._effects._inject import Injected as Injected
    from ._effects._temperature import InjectedRelativeTemperature as InjectedRelativeTemperature
    from ._effects._temperature import InjectedTemperature as InjectedTemperature
    from ._effects._viscous_damping import InjectedViscousDamping as InjectedViscousDamping
    from ._errors import BenchDataError as BenchDataError
    from ._errors import UntrustedResultError as UntrustedResultError
    from ._fit._api import FitResult as FitResult
    from ._fit._api import bench_to_fit_data as bench_to_fit_data
    from ._fit._api import fit_least_squares as fit_least_squares
    from ._fit._compare import Comparison as Comparison
    from ._fit._compare import compare_models as compare_models
    from ._fit._spec import ModelDefinitionError as ModelDefinitionError
    from ._fit._spec import register_model as register_model
    from ._lanes._batch import FitData as FitData
    from ._lanes._batch import pack as pack_muscles
    from ._lanes._sharding import use_devices as use_devices
    from ._models._bolen import Bolen2026 as Bolen2026
    from ._models._cullinan import Cullinan as Cullinan
    from ._models._protocol import ForceModel as ForceModel
    from ._models._sarosi import Sarosi as Sarosi
    from ._models._volume import PamVolume as PamVolume
    from ._pooled._lomo import PooledComparison as PooledComparison
    from ._pooled._lomo import PooledModel as PooledModel
    from ._pooled._lomo import compare_pooled as compare_pooled
    from ._pooled._predict import MusclePrediction as MusclePrediction
    from ._pooled._predict import predict_muscle as predict_muscle
    from ._sampling._arviz import load_inference_data as load_inference_data
    from ._sampling._ensemble import EnsembleState as EnsembleState
    from ._sampling._ensemble import de_move as de_move
    from ._sampling._ensemble import ensemble_init as ensemble_init
    from ._sampling._ensemble import ensemble_step as ensemble_step
    from ._sampling._ensemble import run_ensembles as run_ensembles
    from ._sampling._ensemble import stretch_move as stretch_move
    from ._sampling._mcmc import McmcBudgetWarning as McmcBudgetWarning
    from ._sampling._mcmc import McmcResult as McmcResult
    from ._sampling._mcmc import fit_mcmc as fit_mcmc
    from ._sampling._posterior import Prior as Prior
    from ._sampling._posterior import default_prior as default_prior
    from ._sim._joint_sim import JointArm as JointArm
    from ._sim._joint_sim import JointArmRun as JointArmRun
    from ._sim._joint_sim import joint_equilibrium_rad as joint_equilibrium_rad
    from ._sim._joint_sim import simulate_joint_arm as simulate_joint_arm
    from ._sim._lifting_mass import LiftingMass as LiftingMass
    from ._sim._lifting_mass import LiftingMassRun as LiftingMassRun
    from ._sim._lifting_mass import lifting_mass_equilibrium as lifting_mass_equilibrium
    from ._sim._lifting_mass import simulate_lifting_mass as simulate_lifting_mass
    from ._sim._oscillator import DampedOscillator as DampedOscillator
    from ._sim._oscillator import OscillatorRun as OscillatorRun
    from ._sim._oscillator import oscillator_response as oscillator_response
    from ._sim._oscillator import simulate_oscillator as simulate_oscillator
    from ._virtual._braided import StaticBenchProtocol as StaticBenchProtocol
    from ._virtual._braided import simulate_braided_pam_bench as simulate_braided_pam_bench
    from ._virtual._decay import DecayProtocol as DecayProtocol
    from ._virtual._decay import simulate_decays as simulate_decays
    from ._virtual._default import default_bench_path as default_bench_path
    from ._virtual._isometric import IsometricProtocol as IsometricProtocol
    from ._virtual._isometric import simulate_isometric_bench as simulate_isometric_bench
    from ._virtual._isometric import virtual_lab_file as virtual_lab_file
    from ._virtual._isometric import write_bench_csv as write_bench_csv
    from ._virtual._joint import DeflectionProtocol as DeflectionProtocol
    from ._virtual._joint import JointSweepProtocol as JointSweepProtocol
    from ._virtual._joint import deflection_test_stiffness as deflection_test_stiffness
    from ._virtual._joint import simulate_deflection_test as simulate_deflection_test
    from ._virtual._joint import simulate_joint_sweep as simulate_joint_sweep
    from ._virtual._population import simulate_population_bench as simulate_population_bench
    from ._virtual._sweeps import SarosiProtocol as SarosiProtocol
    from ._virtual._sweeps import simulate_sarosi_bench as simulate_sarosi_bench

__version__ = importlib.metadata.version("pamid")
