"""Forward selection of effects by BIC and cross-validated error, for any model family.

The family supplies ``evaluate(sets)``: for every candidate set of effect names it fits the
model with those effects, on all data and on each cross-validation fold, and returns a
:class:`SetFit` each. Selection (Schwarz's BIC, 1978, summed over muscles or trials, each
with its own constants):

    BIC = Σ_m [ n_m·ln(SSE_m / n_m) + k_m·ln n_m ]

The BIC counts every sample as independent. A residual that varies slowly (lag-1
autocorrelation 0.985 on a real isometric bench at 100,000 rows) carries far fewer
independent samples than rows, and every ΔBIC is then in the thousands whatever is added.
Two fits are therefore compared with each muscle's effective sample size in place of n,
n_eff = n/τ with τ the integrated autocorrelation time of the residual
(:func:`pamid._diagnose._residual.effective_sample_size`; n·(1 − ρ)/(1 + ρ) for an AR(1)
residual):

    ΔBIC = Σ_m [ n_eff,m·ln(SSE_m′ / SSE_m) + (k_m′ − k_m)·ln n_eff,m ]

with τ that of the larger fit's residual (the one with the effect):
that residual estimates the noise's dependence whether or not the effect is real, whereas
the smaller fit's residual also carries the effect's own structure, slow by nature, and
would hide a real effect. A white residual keeps n_eff = n, and the BIC as it was.

One judge (:func:`judge`) decides every comparison, forward and backward alike: the larger
fit is supported when it converged, lowers that ΔBIC by more than :data:`BIC_THRESHOLD`
("very strong" evidence on Kass and Raftery's scale, 1995), lowers the held-out error (the
cross-validation on held-out whole trials or curves) by at least
:data:`CV_SHARE` of the held-out mean square, and, where there are at least
:data:`CV_MIN_UNITS` held-out units, predicts them better unit by unit (a one-sided
Wilcoxon signed-rank test on each unit's held-out error, p < :data:`CV_P`): held-out units
are the independent units of a dependent residual. The best supported candidate (lowest
ΔBIC) is added and the rest are refitted on top of it, until none is supported. Library
effects, which have a physical reading, come first: a generic ``covariate:<column>``
effect is added only when no library effect is supported any more, so that it names what
the library cannot model rather than a library effect in another form. A backward pass
then drops, one at a time, any selected effect that the same judge no longer supports
given the others: an effect is dropped only on evidence other than that it was added on
(an effect added later that explains it). A library effect is judged there without the
generic terms added after it (they may hold it in another form) but with those added before
it, so that the backward judge repeats the forward verdict where nothing else changed.

A candidate whose fitted constants land at or past a physical bound (a negative compliance,
a transient lagging by more than its whole step: :mod:`pamid._effects._transient`) is
never significant, however much it lowers the BIC; its row says what it would have needed
(``unphysical``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from ._residual import effective_sample_size, signed_rank_greater
from ._result import UNEXPLAINED_SHARE

BIC_THRESHOLD = 10.0
#: Significant candidates within this BIC of the one added are reported as alternatives
#: the data cannot rule out (Kass and Raftery: a difference below 6 is not strong evidence).
BIC_AMBIGUOUS = 6.0
#: One-sided p-value of the paired test on held-out curves that a candidate must beat.
CV_P = 0.05
#: Fewest held-out units for the paired test; with fewer, the CV RMSE alone decides.
CV_MIN_UNITS = 6
#: The effect-size floor: a candidate must explain at least this share of the held-out mean
#: square error (lower the held-out RMSE by about half of it, 1 %). It is the share of the
#: residual's variance below which the report does not call a covariate's structure
#: unexplained (:data:`pamid._diagnose._result.UNEXPLAINED_SHARE`): an effect must remove
#: at least what would be reported as missing. With 100,000 rows any structure is
#: "significant"; this says whether it matters.
CV_SHARE = UNEXPLAINED_SHARE


def held_out_p_value(current: SetFit, candidate: SetFit) -> float:
    """Wilcoxon signed-rank test (one-sided) that the candidate predicts held-out curves
    better than the current model, curve by curve; NaN when there are too few curves.

    The BIC counts every sample as independent; a leftover that is constant along a curve
    (a sweep at its own temperature, say) makes any effect that varies from sweep to sweep
    look significant in-sample. Held-out curves are the independent units here.
    """
    if current.cv_unit_sse is None or candidate.cv_unit_sse is None:
        return math.nan
    diff = np.asarray(current.cv_unit_sse) - np.asarray(candidate.cv_unit_sse)
    diff = diff[np.isfinite(diff) & (diff != 0)]
    if len(diff) < CV_MIN_UNITS:
        return math.nan
    return signed_rank_greater(diff)


def delta_bic(smaller: SetFit, larger: SetFit) -> float:
    """BIC(larger) − BIC(smaller) with the larger fit's effective sample sizes (module
    text); the plain BIC difference where its residual is white."""
    n_eff = larger.n_eff
    ratio = (np.maximum(np.asarray(larger.sse, float), 1e-300)
             / np.maximum(np.asarray(smaller.sse, float), 1e-300))
    dk = np.asarray(larger.k, float) - np.asarray(smaller.k, float)
    return float(np.sum(n_eff * np.log(ratio) + dk * np.log(n_eff)))


def judge(smaller: SetFit, larger: SetFit, why_unphysical: str | None = None) -> dict:
    """Whether ``larger`` (``smaller`` with one effect more) is supported: the one judge of
    the forward and the backward steps (module text).

    Returns ``{"supported", "decided_by", "delta_bic", "delta_bic_independent",
    "cv_p_value", "cv_gain", "n_eff"}``: ``decided_by`` is the criterion that refused it
    (``"not_converged"``, ``"unphysical"``, ``"bic"``, ``"held_out_share"``,
    ``"held_out_test"``), or, when supported, the criteria it passed (``"bic+held_out_share
    +held_out_test"``; without the test where there are fewer than :data:`CV_MIN_UNITS`
    held-out units). ``cv_gain``: the share of the held-out mean square it removes."""
    d_bic = delta_bic(smaller, larger)
    p_cv = held_out_p_value(smaller, larger)
    mse0, mse1 = smaller.cv_rmse**2, larger.cv_rmse**2
    gain = (mse0 - mse1) / mse0 if mse0 > 0 else math.nan
    if not bool(np.all(larger.converged)):
        decided = "not_converged"
    elif why_unphysical is not None:
        decided = "unphysical"
    elif not d_bic < -BIC_THRESHOLD:
        decided = "bic"
    elif not gain >= CV_SHARE:
        decided = "held_out_share"
    elif math.isfinite(p_cv) and not p_cv < CV_P:
        decided = "held_out_test"
    else:
        decided = None
    passed = "bic+held_out_share" + ("+held_out_test" if math.isfinite(p_cv) else "")
    return {"supported": decided is None, "decided_by": decided or passed,
            "delta_bic": d_bic, "delta_bic_independent": larger.bic - smaller.bic,
            "cv_p_value": p_cv, "cv_gain": gain, "n_eff": float(np.sum(larger.n_eff))}


@dataclasses.dataclass
class SetFit:
    """The fit of one set of effects.

    Attributes:
        effects: the effect names.
        sse: per group (muscle or trial), the weighted SSE on all data.
        n: per group, the number of samples.
        k: per group, the number of fitted constants.
        cv_sse: held-out squared error summed over folds and groups.
        cv_n: held-out samples counted.
        converged: per group.
        extra: whatever the family keeps for the report (constants, intervals, residuals).
    """

    effects: tuple[str, ...]
    sse: np.ndarray
    n: np.ndarray
    k: np.ndarray
    cv_sse: float
    cv_n: int
    converged: np.ndarray
    extra: dict = dataclasses.field(default_factory=dict)
    cv_unit_sse: np.ndarray | None = None  # held-out squared error per held-out unit (curve)
    #: per group, the integrated autocorrelation time τ of the residual on all data in time
    #: order, and its lag-1 autocorrelation (:func:`pamid._diagnose._residual.
    #: autocorrelation_time`); None where the family does not give them (then n_eff = n).
    tau: np.ndarray | None = None
    rho1: np.ndarray | None = None

    @property
    def bic(self) -> float:
        """The BIC with every sample counted as independent."""
        n = np.asarray(self.n, float)
        sse = np.maximum(np.asarray(self.sse, float), 1e-300)
        return float(np.sum(n * np.log(sse / n) + np.asarray(self.k) * np.log(n)))

    @property
    def n_eff(self) -> np.ndarray:
        """Per group, the effective sample size of the residual (module text)."""
        n = np.asarray(self.n, float)
        return n if self.tau is None else effective_sample_size(n, self.tau)

    @property
    def rmse(self) -> float:
        return math.sqrt(float(np.sum(self.sse)) / float(np.sum(self.n)))

    @property
    def cv_rmse(self) -> float:
        return math.sqrt(self.cv_sse / self.cv_n) if self.cv_n else math.nan


def forward_select(
    candidates: Sequence[str],
    evaluate: Callable[[list[tuple[str, ...]]], list[SetFit]],
    covariate_of: dict[str, str],
    *,
    max_effects: int = 4,
    progress: Callable[[str], None] | None = None,
    unphysical: Callable[[SetFit, str], str | None] | None = None,
    refresh: Callable[[SetFit], None] | None = None,
    forms: dict[str, str] | None = None,
) -> dict:
    """Run the forward selection; return the baseline, the steps and the final fit.

    ``unphysical(fit, name)``: why effect ``name``'s constants in ``fit`` are not physical,
    or None; such a candidate is not significant. ``refresh(fit)``: called with the fit of
    the effects selected so far before the remaining candidates are refitted on top of it
    (a family may choose its candidates' grid constants again on that fit's residual).
    ``forms``: effect name → the effect it is a form of (``temperature_relative`` →
    ``temperature``; a name not in it is a form of itself): once one form is added, the
    others are no longer candidates (two forms of one effect would fit it twice)."""
    say = progress or (lambda _msg: None)
    selected: tuple[str, ...] = ()
    say("fitting the baseline and every candidate")
    remaining = list(candidates)
    first = evaluate([(), *[(c,) for c in remaining]])
    baseline, current = first[0], first[0]
    fits = first[1:]
    steps = []
    while True:
        rows = []
        for name, fit in zip(remaining, fits, strict=True):
            why = unphysical(fit, name) if unphysical is not None else None
            j = judge(current, fit, why)
            rows.append({"effect": name, "covariate": covariate_of.get(name, name),
                         "delta_bic": j["delta_bic"],
                         "delta_bic_independent": j["delta_bic_independent"],
                         "n_eff": j["n_eff"], "cv_rmse": fit.cv_rmse,
                         "cv_p_value": j["cv_p_value"], "cv_gain": j["cv_gain"],
                         "rmse": fit.rmse, "significant": j["supported"],
                         "decided_by": j["decided_by"], "unphysical": why, "fit": fit})
        rows.sort(key=lambda r: r["delta_bic"])
        choice = _choose(rows)
        alternatives = [] if choice is None else [
            r["effect"] for r in rows
            if r is not choice and r["significant"]
            and r["delta_bic"] - choice["delta_bic"] < BIC_AMBIGUOUS]
        steps.append({"selected_before": list(selected), "cv_rmse_before": current.cv_rmse,
                      "rmse_before": current.rmse, "candidates": rows,
                      "added": choice["effect"] if choice else None,
                      "alternatives": alternatives})
        if choice is None or len(selected) >= max_effects:
            break
        selected = (*selected, choice["effect"])
        current = choice["fit"]
        # the other forms of the effect just added are no longer candidates
        form = (forms or {}).get(choice["effect"], choice["effect"])
        remaining = [r for r in remaining
                     if r != choice["effect"] and (forms or {}).get(r, r) != form]
        if not remaining:
            break
        say(f"added {choice['effect']}; refitting {len(remaining)} candidates on top")
        if refresh is not None:
            refresh(current)
        fits = evaluate([(*selected, c) for c in remaining])
    dropped = []
    while selected:
        say(f"backward check of {', '.join(selected)}")
        reduced = [tuple(e for e in selected if e != r) for r in selected]
        # A library effect is judged without the generic covariates added after it: such a
        # term may absorb it (a smooth function of the contraction holds a sensor offset's
        # a4·δ·κ) and would then name in another form what the library models. It keeps
        # those added before it, the context it was added in: with no other change, the
        # backward judge repeats the forward verdict (nothing is added and then dropped).
        judged = [_context(selected, i) for i in range(len(selected))]
        wanted = list(dict.fromkeys(
            [*reduced, *(s for pair in judged for s in pair if s is not None)]))
        todo = [s for s in wanted if s]
        fitted = dict(zip(todo, evaluate(todo), strict=True)) if todo else {}
        fitted[()] = baseline
        fitted[tuple(selected)] = current
        fits = [fitted[r] for r in reduced]
        refs = [fitted[a] if a is not None else current for a, _ in judged]
        bad = [unphysical(current, r) if unphysical is not None else None for r in selected]
        # the judge of the forward step: the fit without the effect against the fit with it
        verdicts = [judge(fitted[b], ref, why)
                    for (_, b), ref, why in zip(judged, refs, bad, strict=True)]
        weak = [i for i, v in enumerate(verdicts) if not v["supported"]]
        if not weak:
            break
        weakest = max(weak, key=lambda i: (np.nan_to_num(verdicts[i]["cv_p_value"], nan=0.0),
                                           verdicts[i]["delta_bic"]))
        weakest = next((i for i in weak if bad[i] is not None), weakest)
        v = verdicts[weakest]
        dropped.append({"effect": selected[weakest], "delta_bic_without": -v["delta_bic"],
                        "delta_bic_without_independent": -v["delta_bic_independent"],
                        "n_eff": v["n_eff"], "cv_p_value": v["cv_p_value"],
                        "cv_gain": v["cv_gain"], "decided_by": v["decided_by"],
                        "unphysical": bad[weakest]})
        selected, current = reduced[weakest], fits[weakest]
    return {"baseline": baseline, "final": current, "selected": list(selected),
            "steps": steps, "dropped": dropped,
            "selection": {"bic_threshold": BIC_THRESHOLD, "cv_p": CV_P,
                          "cv_min_units": CV_MIN_UNITS, "cv_share": CV_SHARE,
                          "n": np.asarray(baseline.n, float).tolist(),
                          "rho1_baseline": _listed(baseline.rho1),
                          "tau_baseline": _listed(baseline.tau),
                          "n_eff_baseline": baseline.n_eff.tolist(),
                          "rho1_final": _listed(current.rho1),
                          "tau_final": _listed(current.tau),
                          "n_eff_final": current.n_eff.tolist()}}


def _context(selected: tuple[str, ...], i: int) -> tuple[tuple[str, ...] | None,
                                                          tuple[str, ...]]:
    """The backward judge's pair for the ``i``-th selected effect: (the set with it, or None
    for every selected effect; that set without it). Every other effect stays, except the
    generic covariates added after a library effect (``forward_select``'s backward pass)."""
    name = selected[i]
    with_it = selected if _generic(name) else tuple(
        e for j, e in enumerate(selected) if not (_generic(e) and j > i))
    without = tuple(e for e in with_it if e != name)
    return (None if with_it == selected else with_it), without


def _listed(values) -> list[float] | None:
    return None if values is None else np.asarray(values, float).tolist()


def _generic(name: str) -> bool:
    """A generic ``covariate:<column>`` effect rather than a library effect."""
    return name.startswith("covariate:")


def _choose(rows: list[dict]) -> dict | None:
    significant = [r for r in rows if r["significant"]]
    library = [r for r in significant if not _generic(r["effect"])]
    if library:
        return library[0]
    return significant[0] if significant else None
