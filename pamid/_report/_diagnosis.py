"""A :class:`pamid.Diagnosis` as a person reads it: the text report ``pamid diagnose``
prints, and the residual before and after the selected effects, against each covariate and
in time order. Figures are written atomically (:func:`pamid._io.save_figure_atomic`)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .._io import save_figure_atomic


def _p(p) -> str:
    if p is None or not np.isfinite(p):
        return "—"
    return f"{p:.1e}" if p < 1e-3 else f"{p:.3f}"


#: What refused a candidate (``decided_by`` of :func:`pamid._diagnose._select.judge`), as
#: the report's "significant" column says it.
_REFUSED_BY = {"not_converged": "no (refit not converged)", "unphysical": "no (not physical)",
               "bic": "no (ΔBIC)", "held_out_share": "no (held-out gain too small)",
               "held_out_test": "no (held-out units not better)"}


def _verdict(r: dict) -> str:
    if r["significant"]:
        return "yes"
    if r.get("unphysical"):
        return _REFUSED_BY["unphysical"]
    return _REFUSED_BY.get(r.get("decided_by"), "no")


def _judge_lines(sel: dict) -> list[str]:
    """How the candidates were judged, with the selection's own thresholds and the
    baseline residual's effective sample size (:mod:`pamid._diagnose._select`)."""
    from .._diagnose._select import BIC_THRESHOLD

    bic = sel.get("bic_threshold", BIC_THRESHOLD)
    share = sel.get("cv_share")
    lines = ["2. Candidate effects, each refitted against the baseline; significant = ΔBIC < "
             f"−{bic:g} on the effective sample size n_eff (rows over the residual's "
             "autocorrelation time)"
             + (f", held-out error lower by ≥ {100 * share:g} %" if share is not None else "")
             + (f" and held-out units predicted better (Wilcoxon p < {sel['cv_p']:g}, ≥ "
                f"{sel['cv_min_units']} units)" if "cv_p" in sel else "") + ":"]
    n, n_eff = sel.get("n"), sel.get("n_eff_baseline")
    if n and n_eff:
        lines.append(f"     baseline residual: n_eff = {sum(n_eff):.0f} of {sum(n):.0f} rows")
    return lines


def constant_text(c: dict) -> str:
    """A diagnosed constant as text: its value and unit, then its 95 % interval, or why it
    has none (held on its physical bound by the fit, as a slip element at 0 is: absent;
    chosen over a grid, as the transient's τ is); an interval cut at the constant's physical
    bound says so."""
    value = f"{c['value']:.4g} {c['unit']}"
    if c.get("held_at_bound"):
        return f"{value}  (held at its bound: no interval)"
    if c.get("chosen_over") == "grid":
        return f"{value}  (chosen over a grid: no interval)"
    lo, hi = c["ci95"]
    cut = "  (cut at its physical bound)" if c.get("ci95_cut_at_bound") else ""
    return f"{value}  [{lo:.4g}, {hi:.4g}]{cut}"


def diagnosis_report(d) -> str:
    """The diagnosis ``d`` as ``pamid diagnose`` prints it (and writes to report.txt): the
    baseline's residual and its dependence on each covariate, the candidate effects, the
    forward selection with the constants found (95 % intervals), the error before and after
    (N for bench files, rad for decays), and what stays unexplained."""
    unit = "rad" if d.kind == "decay" else "N"
    what = "trials" if d.kind == "decay" else "muscles"
    lines = [f"pamid diagnose {d.path}",
             f"model: {d.model}; {d.n_groups} {what}, {d.n} samples"]
    if getattr(d, "subsample", None):
        lines.append(f"subsample (--max-rows): {d.rows_used} of the file's {d.rows_total} "
                     f"rows diagnosed — {d.subsample}")
    shape = getattr(d, "force_law_shape", None)
    if shape:
        kept = shape["selected_on_model"]
        lines.append(
            f"the force law's shape: {shape['model']} leaves structure in its own inputs "
            f"({', '.join(shape['suspects'])}); {shape['law']} alone fits this file better "
            f"(BIC {shape['bic_law']:.1f}, CV RMSE {shape['cv_rmse_law_N']:.4g} N) than "
            f"{shape['model']} with its best effect ({shape['best_effect']}: BIC "
            f"{shape['bic_model_with_best_effect']:.1f}, CV RMSE "
            f"{shape['cv_rmse_model_with_best_effect_N']:.4g} N)"
            + (f" or with the effects its selection kept ({', '.join(kept)}, CV RMSE "
               f"{shape['cv_rmse_model_with_selected_N']:.4g} N)" if kept else "")
            + f": the misfit is the force law's shape, not an effect. The effects below are "
            f"diagnosed on top of {shape['law']}.")
        lines.append("   force laws compared as pamid compare ranks them (CV RMSE N, BIC): "
                     + ", ".join(f"{law['model']} {law['cv_rmse_N']:.4g}, {law['bic']:.1f}"
                                 for law in shape["laws"]))
    for f in getattr(d, "muscles_flagged", []):
        what = ("fitted within bounds and diagnosed with the others, that constant held "
                "(its value is the bound, not a finding)" if f["diagnosed"]
                else "left out of the diagnosis (its residual would mean nothing)")
        lines.append(f"flagged: muscle {f['muscle']}: {f['why']}; {what}")
    lines.append("")
    b = d.residual_before
    lines.append(f"1. Residual of the baseline: RMSE {d.rmse_before:.4g} {unit}, "
                 f"max {d.max_error_before:.4g} {unit}; runs test p = {_p(b['runs']['p_value'])}, "
                 f"Ljung–Box p = {_p(b['ljung_box']['p_value'])}")
    lines.append("   dependence on each covariate (F test; share of the residual variance a "
                 "smooth function of it explains):")
    for c, dep in sorted(b["covariates"].items(), key=lambda kv: (kv[1]["p_value"] or 1.0)):
        share = dep.get("explained_fraction", math.nan)
        lines.append(f"     {c:<24} p = {_p(dep['p_value']):>8}   {100 * share:5.1f} %")
    lines.append("")
    lines += _judge_lines(getattr(d, "selection", {}) or {})
    ew = max([28] + [len(r["effect"]) for r in d.candidates])
    cw = max([20] + [len(r["covariate"]) for r in d.candidates])
    lines.append(f"     {'effect':<{ew}} {'covariate':<{cw}} {'ΔBIC':>10} {'n_eff':>8} "
                 f"{'CV RMSE':>10}  significant")
    for r in d.candidates:
        n_eff = r.get("n_eff")
        n_eff = f"{n_eff:>8.0f}" if n_eff is not None and np.isfinite(n_eff) else f"{'—':>8}"
        lines.append(f"     {r['effect']:<{ew}} {r['covariate']:<{cw}} {r['delta_bic']:>10.1f} "
                     f"{n_eff} {r['cv_rmse']:>10.4g}  {_verdict(r)}")
    # Effects the data would support but whose constants are past a physical bound.
    seen = set()
    for s in d.steps:
        for r in s["candidates"]:
            if r.get("unphysical") and r["delta_bic"] < -10 and r["effect"] not in seen:
                seen.add(r["effect"])
                lines.append(f"     {r['unphysical']}; not selected")
    lines.append("")
    lines.append("3. Forward selection:")
    for s in d.steps:
        added = s["added"]
        if added is None:
            lines.append(f"     from {s['selected_before'] or ['baseline']}: nothing significant "
                         "left")
        else:
            best = next(r for r in s["candidates"] if r["effect"] == added)
            lines.append(f"     + {added} (ΔBIC {best['delta_bic']:.1f}, CV RMSE "
                         f"{s['cv_rmse_before']:.4g} → {best['cv_rmse']:.4g} {unit})")
            if s.get("alternatives"):
                lines.append("       ambiguous: the data explain this almost as well with "
                             + ", ".join(s["alternatives"]) + " (ΔBIC within 6)")
    for r in d.dropped:
        lines.append(f"     − {r['effect']} dropped in the backward check (given the others: "
                     f"ΔBIC without it {r['delta_bic_without']:+.1f}, held-out curves p = "
                     f"{_p(r['cv_p_value'])})")
        if r.get("unphysical"):
            lines.append(f"       {r['unphysical']}")
    for r in getattr(d, "forms", []):
        lines.append(f"     form: {r['why']}")
    lines.append(f"   selected: {', '.join(d.selected) if d.selected else 'none'}")
    if d.selected:
        lines.append("   constants with 95 % intervals:")
        for g in d.constants[:10]:
            group = g.get("muscle", g.get("trial", ""))
            for name, consts in g["effects"].items():
                held = [pname for pname, c in consts.items() if c.get("held_at_bound")]
                width = max([12] + [len(pname) for pname in consts])
                for pname, c in consts.items():
                    if pname not in held:
                        lines.append(f"     {group:<10} {name:<22} {pname:<{width}} "
                                     f"{constant_text(c)}")
                if held:
                    lines.append(f"     {group:<10} {name:<22} on its bound by the fit "
                                 "(0: absent): " + ", ".join(held))
        if len(d.constants) > 10:
            lines.append(f"     … and {len(d.constants) - 10} more (see --json)")
    lines.append("")
    a = d.residual_after
    lines.append(f"4. Error before → after: RMSE {d.rmse_before:.4g} → {d.rmse_after:.4g} {unit}, "
                 f"max {d.max_error_before:.4g} → {d.max_error_after:.4g} {unit}, CV RMSE "
                 f"{d.cv_rmse_before:.4g} → {d.cv_rmse_after:.4g} {unit}")
    lines.append(f"   final residual: runs test p = {_p(a['runs']['p_value'])}, Ljung–Box p = "
                 f"{_p(a['ljung_box']['p_value'])}, lag-1 autocorrelation "
                 f"{a['ljung_box']['lag1_autocorrelation']:+.3f}")
    if d.kind == "decay":
        lines.append("   (the encoder's step holds the residual's sign near each turning point, "
                     "so the runs test is not used for decays; Ljung–Box is)")
    lines.append("   RMSE per covariate bin, before → after:")
    for c in b["covariates"]:
        bins_b, bins_a = b["covariates"][c]["bins"], a["covariates"][c]["bins"]
        cells = [f"{_range(x)}: {x['rmse']:.3g}→{y['rmse']:.3g}"
                 for x, y in zip(bins_b, bins_a, strict=False)]
        lines.append(f"     {c:<20} " + "; ".join(cells))
    lines.append("")
    in_time = getattr(d, "order_is_time", True)
    if d.unexplained:
        why = ("or a lag-1 autocorrelation of at least 0.1 for the time order" if in_time
               else "or, for a residual not white in the map's row order, the covariate that "
               "carries it: the largest share of its variance, p < 0.01")
        lines.append("5. Unexplained: the final residual still depends on "
                     + ", ".join(d.unexplained) + " (p < 0.001, and at least 2 % of its "
                     f"variance, {why}); no library effect removes it.")
    elif in_time:
        lines.append("5. Unexplained: nothing material — no covariate explains 2 % of the "
                     "final residual's variance at p < 0.001, and its time order shows no "
                     "lag-1 autocorrelation of 0.1 or more at p < 0.001.")
    else:
        lines.append("5. Unexplained: nothing material — no covariate explains 2 % of the "
                     "final residual's variance at p < 0.001, nor carries a structure of the "
                     "residual in the map's row order at p < 0.01.")
    if not in_time:
        lines.append("   The rows are a map sorted by its inputs, with no time: the runs test "
                     "and Ljung–Box read them in that order, and structure there is named by "
                     "the covariate that carries it, never by a time order.")
    for c in getattr(d, "covariates_not_used", []):
        lines.append(f"   Not used as a covariate: {c['column']} ({c['why']}).")
    return "\n".join(lines)


def _range(b: dict) -> str:
    if b["low"] == b["high"]:
        return f"{b['low']:.4g}"
    return f"{b['low']:.3g}–{b['high']:.3g}"


def _strata(d) -> np.ndarray:
    """A key per row of the diagnosis table whose every-k-th subsample keeps points of
    every curve (bench files: :func:`pamid._data._curves.find_curves`) of every group."""
    t = d.table
    group = pd.factorize(t["group"])[0].astype(np.int64)
    col = next((c for c in ("contraction_pct", "contraction_mm") if c in t), None)
    if d.kind != "bench" or "pressure_kPa" not in t or col is None:
        return group
    from .._data._curves import find_curves

    curve = find_curves(t, contraction_column=col).curve
    return group * (int(curve.max()) + 1) + curve


def _subject(d) -> str:
    """Model and what was diagnosed, for titles."""
    what = "trial" if d.kind == "decay" else "muscle"
    if d.n_groups == 1:
        return f"{d.model}, {what} {d.groups[0]}"
    return f"{d.model}, {d.n_groups} {what}s"


def plot_diagnosis_residuals(d, path=None, max_panels: int = 9):
    """Residual [N, or rad for decays] against each covariate (the ``max_panels`` most
    significant), before (grey) and after (blue) the selected effects.

    Big tables are drawn from every k-th sample of each curve (at most
    :data:`pamid._report._plot.MAX_POINTS` points per panel, before and after together).
    Writes ``path`` (PNG) atomically unless it is None, and returns the figure.
    """
    from matplotlib.figure import Figure

    from ._plot import MAX_POINTS, axis_label, every_kth, shown, wrap

    unit = "rad" if d.kind == "decay" else "N"
    covs = list(d.residual_before["covariates"])
    covs.sort(key=lambda c: d.residual_before["covariates"][c]["p_value"] or 1.0)
    covs = covs[:max_panels]
    n = len(covs)
    ncol = min(3, n)
    nrow = math.ceil(n / ncol)
    keep, k = every_kth(_strata(d), MAX_POINTS // 2)
    table = d.table.iloc[keep]
    fig = Figure(figsize=(4.2 * ncol, 3.2 * nrow + 0.6), layout="constrained")
    axes = fig.subplots(nrow, ncol, squeeze=False)
    before, after = f"residual_before_{unit}", f"residual_after_{unit}"
    for ax, c in zip(axes.ravel(), covs, strict=False):
        x = table[c].to_numpy(float)
        jitter = 0.0
        if c == "direction":
            jitter = 0.08 * (np.random.default_rng(0).random(len(x)) - 0.5)
        ax.plot(x + jitter, table[before], ".", ms=2.5, color="0.6", label="before")
        ax.plot(x - jitter, table[after], ".", ms=2.5, color="tab:blue", label="after")
        ax.axhline(0.0, color="k", lw=0.6)
        pb = d.residual_before["covariates"][c]["p_value"]
        pa = d.residual_after["covariates"][c]["p_value"]
        ax.set_title(f"{c}: p {_p(pb)} → {_p(pa)}", fontsize=9)
        ax.set_xlabel(axis_label(c) if d.kind == "bench" else c)
        ax.set_ylabel(f"residual [{unit}]")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=8, markerscale=3)
    sel = ", ".join(d.selected) if d.selected else "no effect"
    note = shown(k, len(d.table))
    fig.suptitle(wrap(f"{_subject(d)}: residual before and after ({sel}), RMSE "
                      f"{d.rmse_before:.3g} → {d.rmse_after:.3g} {unit}", 45 * ncol)
                 + (f"\n{note}" if note else ""), fontsize=11)
    if path is not None:
        save_figure_atomic(fig, path, dpi=110)
    return fig


def plot_diagnosis_time_order(d, path=None):
    """The residual in time order, before and after the selected effects: what the
    whiteness tests (runs, Ljung–Box) look at.

    Big tables are drawn from every k-th sample of each curve. Writes ``path`` (PNG)
    atomically unless it is None, and returns the figure.
    """
    from matplotlib.figure import Figure

    from ._plot import MAX_POINTS, every_kth, shown, wrap

    unit = "rad" if d.kind == "decay" else "N"
    keep, k = every_kth(_strata(d), MAX_POINTS)
    t = d.table.iloc[keep]
    fig = Figure(figsize=(10, 5.4), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True, sharey=True)
    for ax, col, label in ((axes[0], f"residual_before_{unit}", "baseline"),
                           (axes[1], f"residual_after_{unit}", "with " + (
                               ", ".join(d.selected) or "no effect"))):
        ax.plot(keep, t[col], lw=0.6, color="tab:blue")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"residual [{unit}]")
        ax.set_title(label, fontsize=10)
    what = "trials" if d.kind == "decay" else "muscles"
    axes[1].set_xlabel(f"sample, in time order ({what} one after another)")
    note = shown(k, len(d.table))
    fig.suptitle(wrap(f"{_subject(d)}: residual in time order", 90)
                 + (f"\n{note}" if note else ""), fontsize=11)
    if path is not None:
        save_figure_atomic(fig, path, dpi=110)
    return fig
