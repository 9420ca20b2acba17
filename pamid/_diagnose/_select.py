"""Forward selection of effects by BIC and cross-validated error, for any model family.

The family supplies ``evaluate(sets)``: for every candidate set of effect names it fits the
model with those effects, on all data and on each cross-validation fold, and returns a
:class:`SetFit` each. Selection (Schwarz's BIC, 1978, summed over muscles or trials, each
with its own constants):

    BIC = Σ_m [ n_m·ln(SSE_m / n_m) + k_m·ln n_m ]

A candidate is significant when adding it lowers the BIC by more than
:data:`BIC_THRESHOLD` ("very strong" evidence on Kass and Raftery's scale, 1995) and lowers
the cross-validated RMSE on held-out curves. The best significant candidate (lowest BIC) is
added and the rest are refitted on top of it, until none is significant. Library effects,
which have a physical reading, come first: a generic ``covariate:<column>`` effect is added
only when no library effect is significant any more, so that it names what the library
cannot model rather than a library effect in another form. A backward pass then drops,
one at a time, any selected effect that, given the others, no longer lowers the BIC by
:data:`BIC_THRESHOLD` or no longer predicts the held-out curves better curve by curve (a
one-sided Wilcoxon signed-rank test on each curve's held-out error, p < :data:`CV_P`).

A candidate whose fitted constants land at or past a physical bound (a negative compliance,
a hysteresis loop run backwards: :mod:`pamid._effects._definitions`) is never significant,
however much it lowers the BIC; its row says what it would have needed (``unphysical``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

BIC_THRESHOLD = 10.0
#: Significant candidates within this BIC of the one added are reported as alternatives
#: the data cannot rule out (Kass and Raftery: a difference below 6 is not strong evidence).
BIC_AMBIGUOUS = 6.0
#: One-sided p-value of the paired test on held-out curves that a candidate must beat.
CV_P = 0.05
#: Fewest held-out units for the paired test; with fewer, the CV RMSE alone decides.
CV_MIN_UNITS = 6


def held_out_p_value(current: SetFit, candidate: SetFit) -> float:
    """Wilcoxon signed-rank test (one-sided) that the candidate predicts held-out curves
    better than the current model, curve by curve; NaN when there are too few curves.

    The BIC counts every sample as independent; a leftover that is constant along a curve
    (a sweep at its own temperature, say) makes any effect that varies from sweep to sweep
    look significant in-sample. Held-out curves are the independent units here.
    """
    from scipy import stats

    if current.cv_unit_sse is None or candidate.cv_unit_sse is None:
        return math.nan
    diff = np.asarray(current.cv_unit_sse) - np.asarray(candidate.cv_unit_sse)
    diff = diff[np.isfinite(diff) & (diff != 0)]
    if len(diff) < CV_MIN_UNITS:
        return math.nan
    return float(stats.wilcoxon(diff, alternative="greater").pvalue)


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

    @property
    def bic(self) -> float:
        n = np.asarray(self.n, float)
        sse = np.maximum(np.asarray(self.sse, float), 1e-300)
        return float(np.sum(n * np.log(sse / n) + np.asarray(self.k) * np.log(n)))

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
            d_bic = fit.bic - current.bic
            p_cv = held_out_p_value(current, fit)
            supported = (
                bool(np.all(fit.converged))
                and d_bic < -BIC_THRESHOLD
                and fit.cv_rmse < current.cv_rmse
            )
            why = unphysical(fit, name) if unphysical is not None else None
            rows.append({"effect": name, "covariate": covariate_of.get(name, name),
                         "delta_bic": d_bic, "cv_rmse": fit.cv_rmse, "cv_p_value": p_cv,
                         "rmse": fit.rmse, "significant": supported and why is None,
                         "unphysical": why, "fit": fit})
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
        # A library effect is judged among the library effects alone: a generic covariate
        # added after it may absorb it (a smooth function of the contraction holds a sensor
        # offset's a4·δ·κ), and would then name in another form what the library models.
        library = tuple(e for e in selected if not _generic(e))
        judged = [(library, tuple(e for e in library if e != r))
                  if not _generic(r) and len(library) < len(selected) else (None, red)
                  for r, red in zip(selected, reduced, strict=True)]
        wanted = list(dict.fromkeys(
            [*reduced, *(s for pair in judged for s in pair if s is not None)]))
        todo = [s for s in wanted if s]
        fitted = dict(zip(todo, evaluate(todo), strict=True)) if todo else {}
        fitted[()] = baseline
        fitted[tuple(selected)] = current
        fits = [fitted[r] for r in reduced]
        refs = [fitted[a] if a is not None else current for a, _ in judged]
        support = [fitted[b].bic - ref.bic for (_, b), ref in zip(judged, refs, strict=True)]
        p_cv = [held_out_p_value(fitted[b], ref) for (_, b), ref in zip(judged, refs,
                                                                        strict=True)]
        bad = [unphysical(current, r) if unphysical is not None else None for r in selected]
        weak = [i for i in range(len(selected))
                if support[i] < BIC_THRESHOLD or p_cv[i] >= CV_P or bad[i] is not None]
        if not weak:
            break
        weakest = max(weak, key=lambda i: (np.nan_to_num(p_cv[i], nan=0.0), -support[i]))
        weakest = next((i for i in weak if bad[i] is not None), weakest)
        dropped.append({"effect": selected[weakest], "delta_bic_without": support[weakest],
                        "cv_p_value": p_cv[weakest], "unphysical": bad[weakest]})
        selected, current = reduced[weakest], fits[weakest]
    return {"baseline": baseline, "final": current, "selected": list(selected),
            "steps": steps, "dropped": dropped}


def _generic(name: str) -> bool:
    """A generic ``covariate:<column>`` effect rather than a library effect."""
    return name.startswith("covariate:")


def _choose(rows: list[dict]) -> dict | None:
    significant = [r for r in rows if r["significant"]]
    library = [r for r in significant if not _generic(r["effect"])]
    if library:
        return library[0]
    return significant[0] if significant else None
