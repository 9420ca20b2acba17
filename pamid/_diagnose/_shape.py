"""The force law's shape before effects (issue 30, item 3).

A library effect that acts through the model's own inputs — the rig's compliance, a
pressure sensor's offset — or one whose covariate runs with them (a drift, where the
pressure levels follow each other in time) can stand in for a force law of the wrong shape:
a muscle whose force follows Tondu and Lopez's law, diagnosed with Sárosi's eq. 2.1, left a
residual that ``compliance`` or ``drift`` removed in part, while ``pamid compare`` ranked
Tondu–Lopez's law first at the noise level. The effect then names the wrong thing.

So where the first step of the forward selection finds the residual's structure in the
model's inputs — a significant ``covariate:<input>`` or transform effect — the built-in
laws are compared on the same file (:func:`pamid._fit._compare.compare_models`, the
comparison ``pamid compare`` runs: every law fitted to every muscle, on all data and on
held-out trials or curves). When another law alone predicts the held-out data better than
the model with the best effect of the first step *and* better than the model with every
effect the selection kept, the structure is the force law's shape: the diagnosis says so,
names that law, and diagnoses the effects again on top of it (an effect is then selected
only where that law, too, leaves it in the residual). Else nothing changes.
"""

from __future__ import annotations

import math

import numpy as np


def shape_suspected(problem, result) -> list[str]:
    """The significant candidates of the selection's first step that act through the
    model's inputs: ``covariate:<column>`` of a column the model reads (the pressure, the
    contraction) and the transform effects (compliance, sensor offset). Empty: the shape
    is not in question."""
    inputs = set(problem.spec.columns)
    out = []
    for r in result["steps"][0]["candidates"]:
        if not r["significant"]:
            continue
        e = problem.effect(r["effect"])
        if e.transform is not None or (r["effect"].startswith("covariate:")
                                       and e.covariate in inputs):
            out.append(r["effect"])
    return out


def pooled_cv_rmse(mc) -> float:
    """A compared model's CV RMSE over all muscles (√(Σ held-out SSE / Σ held-out rows),
    as the diagnosis pools its own); NaN where a muscle has no CV or a fit to all data did
    not converge."""
    if not (np.all(mc.fit.converged) and np.all(np.isfinite(mc.cv_sse))):
        return math.nan
    return math.sqrt(float(np.sum(mc.cv_sse)) / float(np.sum(mc.cv_n)))


def force_law_shape(bench, spec, result, suspects, *, n_folds: int, order_is_time=True,
                    progress=None) -> dict | None:
    """Compare the built-in laws on ``bench``; return the verdict when another law explains
    the structure (module text), else None.

    Another law must have a lower BIC (n·ln(SSE/n) + p·ln n, summed over muscles, as the
    selection reads it) than the model with the first step's best effect and than the
    model with the effects the selection kept; and, where the rows' order is a time order
    (``order_is_time``: the comparison's folds are then the diagnosis's own — the same
    hold-out rule, round robin), a lower CV RMSE than both too. A map's diagnosis holds out
    points spread over the grid (:func:`pamid._diagnose._static._map_folds`), the
    comparison whole curves: their CV RMSEs are not on one scale, and the BIC decides.

    The verdict: ``{"model", "law", "cv_rmse_model_N", "best_effect",
    "cv_rmse_model_with_best_effect_N", "selected_on_model", "cv_rmse_model_with_selected_N",
    "cv_rmse_law_N", "bic_law", "bic_model_with_best_effect", "suspects", "laws": [{"model",
    "cv_rmse_N", "bic"}, best first]}``; the CV RMSEs of laws are the comparison's.
    """
    from .._fit._compare import compare_models

    first = [r for r in result["steps"][0]["candidates"] if r["significant"]]
    best = min(first, key=lambda r: r["delta_bic"])
    base, final = result["baseline"], result["final"]
    if progress is not None:
        progress(f"the residual lies in the model's inputs ({', '.join(suspects)}): "
                 "comparing the built-in force laws on this file")
    # Every registered law that the file has the inputs for (pamid compare's default set).
    comparison = compare_models(bench, None, n_folds=n_folds, progress=progress)
    laws = []
    for mc in comparison.models:
        bic = float(np.sum(mc.bic)) if np.all(mc.fit.converged) else math.nan
        laws.append({"model": mc.spec.name, "cv_rmse_N": pooled_cv_rmse(mc), "bic": bic})
    key = "cv_rmse_N" if order_is_time else "bic"
    laws.sort(key=lambda law: (not np.isfinite(law[key]), law[key]))
    others = [law for law in laws if law["model"] != spec.name and np.isfinite(law["bic"])
              and (np.isfinite(law["cv_rmse_N"]) or not order_is_time)]
    if not others:
        return None
    law = others[0]
    bic_best = best["fit"].bic  # the plain BIC, as the laws' (the row's ΔBIC is the
    # selection's, with effective sample sizes: pamid._diagnose._select)
    better = law["bic"] < bic_best and law["bic"] < final.bic
    if order_is_time:
        better &= law["cv_rmse_N"] < best["cv_rmse"] and law["cv_rmse_N"] < final.cv_rmse
    if not better:
        return None
    return {"model": spec.name, "law": law["model"], "cv_rmse_model_N": base.cv_rmse,
            "best_effect": best["effect"], "cv_rmse_model_with_best_effect_N": best["cv_rmse"],
            "selected_on_model": list(result["selected"]),
            "cv_rmse_model_with_selected_N": final.cv_rmse,
            "cv_rmse_law_N": law["cv_rmse_N"], "bic_law": law["bic"],
            "bic_model_with_best_effect": bic_best, "suspects": list(suspects),
            "laws": laws}
