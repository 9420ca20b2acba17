"""Diagnosis of free decays: the linear oscillator and what its residual says it lacks.

Baseline: J·β̈ + c·β̇ + k·(β − β_eq) = 0 fitted trial by trial (Cullinan section VI,
eq. 8–11; :func:`pamid._decays._analysis.fit_decay_trajectories`). Its damping is already
viscous, so the candidates for decays are the effects it cannot produce
(:mod:`pamid._decays._coulomb`):

* ``coulomb_friction``: a constant friction torque T_c·sign(β̇) (the sliding seal, the
  cable over the pulley), which makes the amplitude fall linearly instead of geometrically;
* ``drift``: an equilibrium that moves with time, β_eq + r·t (a slow leak).

All sets are fitted, and cross-validated on held-out blocks of each record, in one batched
call; selection is the same as for bench files (:mod:`pamid._diagnose._select`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .._effects._definitions import DECAY_EFFECT_DEFINITIONS
from .._inference import cut_at_bounds
from ._result import analyse_residual, build_diagnosis, unexplained
from ._select import SetFit, forward_select

COVARIATE_OF = {e.name: e.covariate for e in DECAY_EFFECT_DEFINITIONS}
_DEFINITION = {e.name: e for e in DECAY_EFFECT_DEFINITIONS}


def _set_fit(model_fit) -> SetFit:
    trials = model_fit.trials
    n = np.array([f.n for f in trials])
    cv_sse = np.array([f.cv_rmse_rad**2 * f.n for f in trials])
    return SetFit(
        effects=tuple(model_fit.effects), sse=np.array([f.sse for f in trials]), n=n,
        k=np.array([f.n_params for f in trials]), cv_sse=float(np.sum(cv_sse)),
        cv_n=int(np.sum(n)), converged=np.array([f.converged for f in trials]),
        cv_unit_sse=cv_sse, extra={"model": model_fit},
    )


def diagnose_decays(data, inertia_kg_m2, *, n_folds: int = 5, progress=None):
    from .._decays._analysis import analyze_decays, check_inertia
    from .._decays._coulomb import fit_decay_models

    if inertia_kg_m2 is None:
        raise ValueError(f"{data.path}: a decay file needs the arm's moment of inertia: "
                         "give --inertia J in kg·m² (inertia_kg_m2=)")
    check_inertia(inertia_kg_m2, f"{data.path}: the arm's moment of inertia "
                                 "(--inertia, inertia_kg_m2=)")
    report = analyze_decays(data, inertia_kg_m2)
    times, angles = zip(*(data.arrays(t) for t in data.trials), strict=True)

    def evaluate(sets):
        fits = fit_decay_models(list(times), list(angles), report.extrema, report.decrement,
                                inertia_kg_m2, sets, n_folds=n_folds, baseline=report.fits)
        return [_set_fit(f) for f in fits]

    def unphysical(fit, name):
        e = _DEFINITION[name]
        for trial, f in zip(data.trials, fit.extra["model"].trials, strict=True):
            msg = e.violation(float(f.params.get(e.key, np.nan)))
            if msg is not None:
                return f"trial {trial}: {msg}"
        return None

    result = forward_select(list(COVARIATE_OF), evaluate, COVARIATE_OF,
                            progress=progress, unphysical=unphysical)
    base, final = result["baseline"], result["final"]
    table = _long_table(data, base, final)
    covs = [c for c in ("angle_rad", "velocity_rad_s", "elapsed_s", "direction",
                        "temperature_C", "pressure1_kPa", "pressure2_kPa")
            if c in table and table[c].nunique() > 1]
    quantum = max(float(e.quantum_rad) for e in report.extrema)
    before = analyse_residual(table, "residual_before_rad", covs)
    after = analyse_residual(table, "residual_after_rad", covs)
    constants = []
    for trial, f in zip(data.trials, final.extra["model"].trials, strict=True):
        effects = {}
        for name in final.effects:
            e = _DEFINITION[name]
            lo, hi = f.params_ci95.get(e.key, (np.nan, np.nan))
            # cut at the constant's physical bound (a friction torque ≥ 0)
            lo, hi, cut = cut_at_bounds(lo, hi, (e.constant.lower, e.constant.upper))
            effects[name] = {e.key: {"value": float(f.params[e.key]), "ci95": [lo, hi],
                                     "unit": e.constant.unit}}
            if cut:
                effects[name][e.key]["ci95_cut_at_bound"] = True
        constants.append({"trial": trial, "effects": effects,
                          "base": {k: float(f.params[k]) for k in
                                   ("zeta", "omega_n_rad_s", "equilibrium_rad")
                                   if k in f.params}})
    return build_diagnosis(data.path, "decay", "linear oscillator (Cullinan eq. 8–11)",
                           list(data.trials), result, before, after, constants, table,
                           unexplained(after, runs_test_applies=quantum == 0.0))


def _long_table(data, base: SetFit, final: SetFit) -> pd.DataFrame:
    parts = []
    for trial, fb, fa in zip(data.trials, base.extra["model"].trials,
                             final.extra["model"].trials, strict=True):
        rows = data.for_trial(trial)
        t = rows["time_s"].to_numpy(float)
        start = int(np.argmin(np.abs(t - fb.time_s[0])))  # the fit's window, sample exact
        part = rows.iloc[start:start + len(fb.time_s)].reset_index(drop=True)
        part["group"] = trial
        part["residual_before_rad"] = fb.residual_rad
        part["residual_after_rad"] = fa.residual_rad
        tt = part["time_s"].to_numpy(float)
        angle = part["angle_rad"].to_numpy(float)
        part["elapsed_s"] = tt - tt[0]
        part["velocity_rad_s"] = np.gradient(angle, tt) if len(tt) > 1 else 0.0
        part["direction"] = np.where(part["velocity_rad_s"] >= 0, 1.0, -1.0)
        parts.append(part)
    return pd.concat(parts, ignore_index=True)
