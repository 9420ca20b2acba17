"""Effect forms that follow physics (issue 30, item 2): where a selected effect leaves its own
covariate in the residual, try its other form and say so.

An effect may come in more than one physical form (``EffectDefinition.form_of``): the
muscle's temperature as newtons added per kelvin (``temperature``: a load cell's thermal
zero shift, or a rubber force that changes by the same amount at every load) or as a share
of the force per kelvin (``temperature_relative``: a rubber modulus that changes with
temperature scales the force it carries; entropy elasticity, G = N·k·T, Treloar 1975). The
forward selection offers every form and never selects two forms of one effect together
(:func:`pamid._diagnose._select.forward_select`, ``forms``).

A form chosen at one step may still be the wrong one: chosen before the other effects were
in, or the better of two that both miss. So after the selection, a selected form is
judged to have left its own covariate behind where

* the generic ``covariate:<its covariate>`` was selected beside it (what the form left of
  its covariate, a smooth function of it took up), or
* the residual of the selected set (without that generic) still depends on the covariate,
  alone or in proportion to the force: the F test of
  :func:`pamid._diagnose._residual.covariate_dependence` on Legendre terms P1…P3 of the
  covariate and their products with the baseline's force F_model (the two ways an effect
  enters, added or scaling; the test's interaction slot, which the report fills with the
  direction), by the report's criterion for "unexplained"
  (:func:`pamid._diagnose._result.depends`: p < 0.001 and at least 2 % of the residual's
  variance).

Then each other form is fitted in its place, the rest of the selected set (without the
generic) kept. A form whose set has a lower BIC (the selection's, with each muscle's effective
sample size: :func:`pamid._diagnose._select.delta_bic`) and a lower cross-validated RMSE, with
physical constants, replaces it: the selection is run again without the form that left its
covariate behind, so that no effect stays selected that only stood in for the wrong form.
Otherwise the selected form is kept. Either way the diagnosis says which form it kept and
why (:attr:`pamid._diagnose._result.Diagnosis.forms`).
"""

from __future__ import annotations

import numpy as np

from ._residual import covariate_dependence
from ._result import depends
from ._select import delta_bic

__all__ = ["form_groups", "other_forms", "residual_dependence"]


def form_groups(problem) -> dict[str, str]:
    """Every candidate's name → the effect it is a form of (its own name for most)."""
    return {e.name: e.definition.form_of or e.name for e in problem.effects}


def residual_dependence(problem, fit, covariate: str) -> dict:
    """The dependence of ``fit``'s residual (all muscles, each with its own mean) on
    ``covariate``, alone and in proportion to the baseline's force (module text)."""
    frames = problem.frames
    r = np.concatenate([np.asarray(fit.extra["residual"][i][: len(f)], float)
                        for i, f in enumerate(frames)])
    x = np.concatenate([f[covariate].to_numpy(float) for f in frames])
    groups = np.concatenate([np.full(len(f), i) for i, f in enumerate(frames)])
    force = np.concatenate([np.asarray(m.baseline_N, float) for m in problem.muscles])
    return covariate_dependence(r, x, groups, force)


def _share(dep: dict) -> str:
    p = dep["p_value"]
    p_text = "—" if p is None or not np.isfinite(p) else (f"{p:.1e}" if p < 1e-3 else f"{p:.3f}")
    return f"p = {p_text}, {100.0 * dep.get('explained_fraction', 0.0):.1f} % of its variance"


def other_forms(problem, result: dict, select) -> tuple[dict, list[dict]]:
    """Try the other forms of every selected effect that left its covariate behind (module
    text). ``result`` is :func:`~pamid._diagnose._select.forward_select`'s;
    ``select(candidates)`` runs that selection again over ``candidates``.

    Returns the result kept (``result`` itself, or the selection run again without the
    form replaced) and one record per form tried: ``{"effect", "covariate", "left"`` (how
    the selected set without the generic covariate left it: the generic's name where it
    was selected, the dependence's p and share), ``"tried"``, ``"delta_bic"`` and
    ``"cv_rmse_N"`` (of that set with the tried form in its place: ΔBIC, and the CV RMSEs
    before / with it), ``"left_by_tried"``, ``"unphysical"``, ``"kept"``, ``"why"}``.
    """
    groups = form_groups(problem)
    records: list[dict] = []
    selected = list(result["selected"])
    for name in selected:
        others = [o for o in problem.candidate_names
                  if o != name and groups[o] == groups[name]]
        covariate = problem.covariate_of[name]
        if not others or covariate not in problem.frames[0]:
            continue
        generic = f"covariate:{covariate}"
        reduced = [e for e in selected if e != generic]
        base = (result["final"] if len(reduced) == len(selected)
                else problem.evaluate([tuple(reduced)])[0])
        dep = residual_dependence(problem, base, covariate)
        if generic not in selected and not depends(dep):
            continue
        left = {"generic_selected": generic if generic in selected else None, **_left(dep)}
        sets = [tuple(o if e == name else e for e in reduced) for o in others]
        rows = []
        for o, fit in zip(others, problem.evaluate(sets), strict=True):
            bad = problem.unphysical(fit, o)
            d_bic = delta_bic(base, fit)  # the selection's, n_eff where the residual is not white
            better = (bool(np.all(fit.converged)) and bad is None and d_bic < 0
                      and fit.cv_rmse < base.cv_rmse)
            rows.append({"effect": name, "covariate": covariate, "left": left,
                         "tried": o, "delta_bic": d_bic,
                         "cv_rmse_N": [base.cv_rmse, fit.cv_rmse],
                         "left_by_tried": _left(residual_dependence(problem, fit, covariate)),
                         "unphysical": bad, "better": better})
        winner = min((r for r in rows if r["better"]), key=lambda r: r["delta_bic"],
                     default=None)
        kept = winner["tried"] if winner is not None else name
        for r in rows:
            r["kept"] = kept
            r["why"] = _why(r, winner)
            del r["better"]
        records += rows
        if winner is not None:
            # run the selection again without the form that left its covariate behind:
            # the effects chosen beside it may only have stood in for its misfit
            problem.refresh_grids(result["baseline"])  # grids chosen afresh, as at the start
            rerun = select([c for c in problem.candidate_names if c != name])
            if kept not in rerun["selected"]:
                for r in rows:
                    r["kept"] = None
                    r["why"] += (f"; run again without {name}, the selection did not keep "
                                 f"{kept} either")
            return rerun, records
    return result, records


def _left(dep: dict) -> dict:
    return {"p_value": dep["p_value"], "explained_fraction": dep.get("explained_fraction")}


def _why(r: dict, winner: dict | None) -> str:
    name, o, cov = r["effect"], r["tried"], r["covariate"]
    how = (f"{r['left']['generic_selected']} was selected beside it" if
           r["left"]["generic_selected"] else "")
    left = f"{how}; without it, " if how else ""
    head = (f"{name} left {cov} in the residual ({left}{_share(r['left'])}, alone or in "
            f"proportion to the force); {o} in its place: "
            f"ΔBIC {r['delta_bic']:+.1f}, CV RMSE {r['cv_rmse_N'][0]:.4g} → "
            f"{r['cv_rmse_N'][1]:.4g} N, leaving {_share(r['left_by_tried'])}")
    if winner is r:
        return (f"{head}: kept {o}, the form that follows the data; the selection was run "
                f"again without {name}")
    if r["unphysical"]:
        return f"{head}, but {r['unphysical']}: kept {name}"
    return f"{head}: it fits no better, kept {name} (what is left is reported as unexplained)"
