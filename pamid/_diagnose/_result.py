"""What a diagnosis found: the :class:`Diagnosis` record, the residual analysis before and
after (whiteness, dependence on each covariate) and what the final residual still depends
on. Shared by the diagnosis of bench files and of free decays."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from .._io import json_ready
from ._residual import covariate_dependence, ljung_box, runs_test

__all__ = ["Diagnosis", "analyse_residual", "build_diagnosis", "unexplained"]


#: A covariate stays "unexplained" when the final residual depends on it with p below this
#: and a smooth function of it explains at least UNEXPLAINED_SHARE of the residual variance
#: (with many muscles, a structure far too small to matter is still "significant").
UNEXPLAINED_P = 1e-3
UNEXPLAINED_SHARE = 0.02
#: ... and the time order is unexplained when the residual is not white (p below
#: UNEXPLAINED_P) and its lag-1 autocorrelation is at least this large in magnitude.
UNEXPLAINED_RHO1 = 0.1
#: In a map (rows sorted by the inputs, no time), the covariate that carries a residual not
#: white in row order is named when its dependence has p below this (:func:`unexplained`).
CARRIER_P = 0.01


@dataclasses.dataclass
class Diagnosis:
    """What :func:`diagnose` found: it holds results only. :meth:`to_dict` is their plain-data
    view (the ``--json`` object); the text report and the residual figures are written by
    :mod:`pamid.report` (``diagnosis_report``, ``plot_diagnosis_residuals``,
    ``plot_diagnosis_time_order``)."""

    path: str
    kind: str
    model: str
    n: int
    n_groups: int
    rmse_before: float
    rmse_after: float
    max_error_before: float
    max_error_after: float
    cv_rmse_before: float
    cv_rmse_after: float
    selected: list[str]
    dropped: list[dict]
    candidates: list[dict]
    steps: list[dict]
    constants: list[dict]
    groups: list[str]
    residual_before: dict
    residual_after: dict
    unexplained: list[str]
    table: pd.DataFrame = dataclasses.field(repr=False, default=None)
    rows_used: int | None = None  # samples diagnosed (a subsample with ``max_rows``)
    rows_total: int | None = None  # samples in the file
    subsample: str | None = None  # how the subsample was drawn; None for all rows
    #: Numeric columns of the file not used as covariates: [{"column", "why"}].
    covariates_not_used: list[dict] = dataclasses.field(default_factory=list)
    #: The force law's shape (:mod:`pamid._diagnose._shape`): where the model's misfit was
    #: the shape of another built-in law, the verdict (that law, the CV RMSEs), and
    #: ``model`` is that law, the one the effects were diagnosed on; else None.
    force_law_shape: dict | None = None
    #: The model asked for (``model`` unless the force law's shape replaced it).
    model_requested: str | None = None
    #: Whether the rows' order is a time order; False for a map sorted by its inputs,
    #: whose unexplained structure is named by its covariate, never ``time_order``.
    order_is_time: bool = True
    #: Muscles whose baseline fit did not converge: [{"muscle", "status", "why",
    #: "diagnosed"}]; diagnosed: its best fit within bounds (a constant the data do not
    #: determine held on its bound) is diagnosed with the others; else left out.
    muscles_flagged: list[dict] = dataclasses.field(default_factory=list)
    #: Where a selected effect left its own covariate in the residual, the other form tried
    #: in its place and the one kept, with why (:func:`pamid._diagnose._forms.other_forms`):
    #: [{"effect", "covariate", "left", "tried", "delta_bic", "cv_rmse_N", "left_by_tried",
    #: "kept", "why"}].
    forms: list[dict] = dataclasses.field(default_factory=list)
    #: How the selection judged (:func:`pamid._diagnose._select.forward_select`): its
    #: thresholds, and per group the rows n, the lag-1 autocorrelation of the residual and
    #: the effective sample size n_eff, of the baseline and of the final fit. Every
    #: candidate row and every dropped effect also says its ``n_eff`` and which criterion
    #: decided (``decided_by``).
    selection: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.rows_used is None:
            self.rows_used = self.n
        if self.rows_total is None:
            self.rows_total = self.n

    def to_dict(self) -> dict:
        """The diagnosis as plain data (JSON-ready: lists, floats, None for NaN): the
        ``pamid diagnose --json`` object."""
        return json_ready({
            "file": self.path, "kind": self.kind, "model": self.model, "n": self.n,
            "rows_used": self.rows_used, "rows_total": self.rows_total,
            "subsample": self.subsample,
            "groups": self.groups,
            "rmse_before": self.rmse_before, "rmse_after": self.rmse_after,
            "max_error_before": self.max_error_before, "max_error_after": self.max_error_after,
            "cv_rmse_before": self.cv_rmse_before, "cv_rmse_after": self.cv_rmse_after,
            "selected": self.selected, "dropped": self.dropped,
            "candidates": self.candidates, "steps": self.steps,
            "constants": self.constants, "residual_before": self.residual_before,
            "residual_after": self.residual_after, "unexplained": self.unexplained,
            "covariates_not_used": self.covariates_not_used,
            "muscles_flagged": self.muscles_flagged,
            "forms": self.forms,
            "selection": self.selection,
            "order_is_time": self.order_is_time,
            "model_requested": self.model_requested or self.model,
            "force_law_shape": self.force_law_shape,
        })


def _candidate_rows(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "fit"} for r in rows]


def analyse_residual(table: pd.DataFrame, column: str, covariates: list[str],
                     group: str = "group") -> dict:
    """Whiteness and covariate dependence of ``table[column]`` (rows in time order)."""
    series = [g[column].to_numpy(float) for _, g in table.groupby(group, sort=False)]
    r = table[column].to_numpy(float)
    direction = table["direction"].to_numpy(float) if "direction" in table else None
    deps = {}
    for c in covariates:
        d = None if c == "direction" else direction
        deps[c] = covariate_dependence(r, table[c].to_numpy(float),
                                       table[group].to_numpy(), d)
    return {"rmse": float(np.sqrt(np.mean(r**2))), "max_abs": float(np.max(np.abs(r))),
            "runs": runs_test(series), "ljung_box": ljung_box(series), "covariates": deps}


def depends(dep: dict) -> bool:
    """Whether a residual depends on a covariate materially: ``dep`` is its
    :func:`~pamid._diagnose._residual.covariate_dependence`, p below
    :data:`UNEXPLAINED_P` and at least :data:`UNEXPLAINED_SHARE` of the variance explained."""
    p = dep["p_value"]
    return (p is not None and bool(np.isfinite(p)) and p < UNEXPLAINED_P
            and dep.get("explained_fraction", 1.0) >= UNEXPLAINED_SHARE)


def unexplained(analysis: dict, *, runs_test_applies: bool = True,
                order_is_time: bool = True) -> list[str]:
    """Covariates the final residual still depends on, and ``time_order`` when it is not
    white. ``runs_test_applies=False`` for records read through a coarse encoder: rounding
    to a step holds the residual's sign over the slow parts of the motion (near each turning
    point), so the runs test rejects even for a perfect model; Ljung–Box still applies.

    ``order_is_time=False`` for a map whose rows are sorted by its inputs
    (:func:`pamid._diagnose._static.order_is_time`): there is no time order to name, and a
    residual that is not white in row order is named by the covariate that carries it —
    the one a smooth function of which explains the largest share of the residual's
    variance, at p < :data:`CARRIER_P` (the whiteness test has already rejected at
    p < :data:`UNEXPLAINED_P`; this only says where the structure lies) — or not at all
    when no covariate does."""
    deps = analysis["covariates"]
    out = [c for c, d in deps.items() if depends(d)]
    runs_p = analysis["runs"]["p_value"]
    rho1 = analysis["ljung_box"]["lag1_autocorrelation"]
    not_white = analysis["ljung_box"]["p_value"] < UNEXPLAINED_P or (
        runs_test_applies and np.isfinite(runs_p) and runs_p < UNEXPLAINED_P
    )
    if not_white and abs(rho1) >= UNEXPLAINED_RHO1:
        if order_is_time:
            out.append("time_order")
        else:
            carriers = [(d.get("explained_fraction", 0.0), c) for c, d in deps.items()
                        if c != "direction" and d["p_value"] is not None
                        and np.isfinite(d["p_value"]) and d["p_value"] < CARRIER_P
                        and d.get("explained_fraction", 0.0) >= UNEXPLAINED_SHARE]
            if carriers and max(carriers)[1] not in out:
                out.append(max(carriers)[1])
    return out


def build_diagnosis(path, kind, model, groups, result, before, after, constants, table,
                    unexplained) -> Diagnosis:
    """The :class:`Diagnosis` of a forward selection (``forward_select``'s result) and the
    residual analyses before and after, for bench and decay files alike."""
    base, final = result["baseline"], result["final"]
    return Diagnosis(
        path=str(path), kind=kind, model=model, n=int(np.sum(base.n)),
        n_groups=len(groups), groups=groups,
        rmse_before=base.rmse, rmse_after=final.rmse,
        max_error_before=before["max_abs"], max_error_after=after["max_abs"],
        cv_rmse_before=base.cv_rmse, cv_rmse_after=final.cv_rmse,
        selected=result["selected"], dropped=result["dropped"],
        candidates=_candidate_rows(result["steps"][0]["candidates"]),
        steps=[{**{k: v for k, v in s.items() if k != "candidates"},
                "candidates": _candidate_rows(s["candidates"])} for s in result["steps"]],
        constants=constants, residual_before=before, residual_after=after,
        unexplained=unexplained, table=table, selection=result.get("selection", {}),
    )
