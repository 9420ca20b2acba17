"""``pamid check-decays``: simulate a fitted decay model against recorded decays.

:func:`register` adds the command to the ``pamid`` command's subparsers. It reads a model
(the JSON that ``pamid damping --json`` writes, or a bare ``{"zeta", "natural_frequency_Hz"}``
or ``{"stiffness_Nm_per_rad", "damping_Nms_per_rad"}`` object) and a decay file; every trial
is simulated in ONE batched call of the linear oscillator
(:func:`pamid.simulate_oscillator`, J·β̈ + c·β̇ + k·(β − β_eq) = 0, Cullinan section VI),
started from the trial's own recorded state at its first usable extremum (angle as
recorded, rate 0) and about the trial's own equilibrium (the fixed point of its extrema,
as ``pamid damping`` estimates it), so that the check tests the model's ζ and ω_n and not
the start. Per trial it reports the RMS angle error over the usable window (first to
last usable extremum, as the trajectory fit uses), the frequency error (model's damped
frequency minus the recorded one, from the extremum times) and the damping error (model ζ
minus the recorded ζ of eq. 9–10), and plots recorded and simulated angles.

Which model a trial gets: with ``--pooled`` (or when the JSON has no per-trial models of
the same names) the pooled model; otherwise the trial's own. Within a block the trajectory
fit's ζ and f_n are used when present (``--source fit``, the default), else the decrement's
(``--source decrement``). A model given as k and c needs J (``--inertia``) for ζ and ω_n;
one given as ζ and f_n does not (J only scales the reported k and c).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from .._io import safe_file_names
from ._common import (
    MAX_SEED,
    NonNegative,
    allow_negative_numbers,
    count,
    finite,
    plot_unit,
    stage,
)

#: Most posterior draws per trial that ``--posterior-draws`` simulates (one batched call).
MAX_POSTERIOR_DRAWS = 100_000


def register(subparsers) -> None:
    """Add ``check-decays`` to ``subparsers``."""
    chk = subparsers.add_parser(
        "check-decays",
        help="simulate a fitted decay model against recorded decays (RMS, f and ζ errors)",
        description="Simulate every recorded trial with the fitted linear oscillator (one "
                    "batched call), from the trial's recorded state at its first usable "
                    "extremum, and report the angle RMS error, the frequency error and the "
                    "damping-ratio error per trial.",
    )
    chk.add_argument("decay", help="decay file (CSV or Parquet), as for `pamid damping`")
    chk.add_argument("--model-json", required=True, dest="model_json", metavar="FIT.json",
                     help="the JSON of `pamid damping --json` (or damping.json), or an object "
                          "with zeta and natural_frequency_Hz")
    chk.add_argument("--inertia", type=float, required=True, metavar="J",
                     help="moment of inertia of the arm about the pivot in kg·m² (eq. 12)")
    chk.add_argument("--pooled", action="store_true",
                     help="use the pooled model for every trial (default: each trial's own)")
    chk.add_argument("--source", choices=("fit", "decrement"), default="fit",
                     help="take ζ and f_n from the trajectory fit (default, when present) or "
                          "from the logarithmic decrement")
    chk.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    chk.add_argument("--out", help="folder for check_<trial>.png and check_decays.json")
    chk.add_argument("--max-plots", type=int, action=NonNegative, default=12,
                     help="trials to plot (default 12)")
    chk.add_argument("--posterior-draws", type=int, default=0, dest="posterior_draws",
                     metavar="N",
                     help="also sample the posterior of every trial (MCMC) and simulate N "
                          "draws per trial in one batched call: 95%% predictive band and "
                          "its coverage of the recording (default 0: off)")
    chk.add_argument("--seed", type=int, default=0, help="PRNG seed for the posterior draws")
    chk.set_defaults(func=cmd_check_decays,
                     outputs=("check_decays.json", "check_*.png", "predictive_*.png"))
    allow_negative_numbers(chk)


#: The keys of a model block that ``check-decays`` reads (ζ and f_n, or k and c).
MODEL_KEYS = ("zeta", "natural_frequency_Hz", "stiffness_Nm_per_rad", "damping_Nms_per_rad")


def _modal(block: dict, source: str, inertia: float, path: str = "", where: str = "") -> dict:
    """ζ and f_n (Hz) of one model block, from ζ/f_n or from k/c; None if it has neither.

    A key that is there but holds no finite number (NaN, Infinity, text) is an error naming
    the key (``where`` is the block's place in the JSON, ``path`` the file); null counts as
    absent (``pamid damping`` writes null where it has no estimate).
    """
    for key in MODEL_KEYS:
        value = block.get(key)
        if value is not None and not _number(value):
            what = ("NaN (not a number)" if isinstance(value, float) and math.isnan(value)
                    else f"{'-' if value < 0 else ''}Infinity (not a finite number)"
                    if isinstance(value, float) else
                    f"{json.dumps(value)} ({type(value).__name__}, not a number)")
            raise ValueError(f"--model-json: {path}: {where}{key} is {what}; the model needs a "
                             "finite number there")
    if source == "fit" and isinstance(block.get("trajectory_fit"), dict):
        fitted = _modal(block["trajectory_fit"], "decrement", inertia, path,
                        f"{where}trajectory_fit.")
        if fitted is not None:
            return {**fitted, "source": "trajectory fit"}
    zeta, f_n = block.get("zeta"), block.get("natural_frequency_Hz")
    if _number(zeta) and _number(f_n):
        return {"zeta": float(zeta), "natural_frequency_Hz": float(f_n),
                "source": "log decrement" if "log_decrement" in block else "given"}
    k, c = block.get("stiffness_Nm_per_rad"), block.get("damping_Nms_per_rad")
    if _number(k) and _number(c) and k > 0:
        omega = math.sqrt(k / inertia)
        return {"zeta": c / (2.0 * inertia * omega),  # c = 2·ζ·√(k·J) = 2·ζ·J·ω_n
                "natural_frequency_Hz": omega / (2.0 * math.pi), "source": "k and c"}
    return None


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _load_models(path: str, source: str, inertia: float, trials, pooled: bool) -> list[dict]:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"--model-json: file not found: {path}")
    try:
        model = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"--model-json: {path} is not JSON ({exc})") from None
    if not isinstance(model, dict):
        raise ValueError(f"--model-json: {path} must hold one JSON object")
    blocks = {}
    if isinstance(model.get("trials"), list):
        blocks = {str(b.get("trial")): (i, b) for i, b in enumerate(model["trials"])
                  if isinstance(b, dict)}
    has_pooled = isinstance(model.get("pooled"), dict)
    fallback = model["pooled"] if has_pooled else model
    use_own = not pooled and all(t in blocks for t in trials)
    out = []
    for t in trials:
        if use_own:
            i, block = blocks[t]
            where = f"trials[{i}]."
        else:
            block, where = fallback, "pooled." if has_pooled else ""
        m = _modal(block, source, inertia, path, where)
        if m is None:
            raise ValueError(f"--model-json: {path} gives neither zeta and "
                             "natural_frequency_Hz nor stiffness_Nm_per_rad and "
                             f"damping_Nms_per_rad for {'trial ' + t if use_own else 'the model'}")
        if not (0.0 <= m["zeta"] < 1.0 and m["natural_frequency_Hz"] > 0):
            raise ValueError(f"--model-json: the model needs 0 ≤ ζ < 1 and f_n > 0; got ζ = "
                             f"{m['zeta']:g}, f_n = {m['natural_frequency_Hz']:g} Hz")
        out.append({**m, "model": f"trial {t}" if use_own else "pooled"})
    return out


def check_decays(data, models: list[dict], inertia: float) -> tuple[list[dict], dict]:
    """Simulate every trial in one batched call and compare (see the module docstring).

    Returns the per-trial rows and the arrays for plotting ({trial: (t, recorded, sim)}).
    """
    import jax.numpy as jnp
    import numpy as np

    from .._decays._analysis import analyze_decays, angle_unit
    from .._sim._oscillator import DampedOscillator, simulate_oscillator

    report = analyze_decays(data, inertia, fit=False)
    starts, equilibria, windows, rates = [], [], [], []
    for i, trial in enumerate(report.trials):
        t, _ = data.arrays(trial)
        times, values, _ = report.extrema[i].used
        starts.append(float(values[0]))
        equilibria.append(report.decrement[i].equilibrium_rad)
        windows.append((float(times[0]), float(times[-1])))
        rates.append((len(t) - 1) / (t[-1] - t[0]))
    rate = float(max(rates))
    for m in models:
        if m["natural_frequency_Hz"] >= rate / 2.0:
            raise ValueError(
                f"--model-json: the model's f_n = {m['natural_frequency_Hz']:g} Hz ({m['model']}) "
                f"is at or above the recordings' Nyquist frequency {rate / 2.0:g} Hz: the "
                "recording cannot show it")
    duration = max(w1 - w0 for w0, w1 in windows)
    zeta = jnp.array([m["zeta"] for m in models])
    f_n = jnp.array([m["natural_frequency_Hz"] for m in models])
    # Simulated in a unit (a power of two) that keeps the angles, and the rates ω·β, far
    # from overflow; the decay is linear in the state and J cancels out of it.
    unit = angle_unit(np.concatenate([data.arrays(trial)[1] for trial in report.trials]))
    # (Divided in NumPy: XLA flushes subnormal numbers such as 1e-320 to zero.)
    osc = DampedOscillator.from_modal(zeta, f_n, 1.0, jnp.array(np.divide(equilibria, unit)))
    run = simulate_oscillator(osc, jnp.array(np.divide(starts, unit)), 0.0, duration_s=duration,
                              sample_rate_Hz=rate, with_rate=False)  # one batched call
    sim_t = np.asarray(run.time_s)
    sim = np.asarray(run.angle_rad)  # in unit
    rows, curves = [], {}
    for i, trial in enumerate(report.trials):
        t, y = data.arrays(trial)
        w0, w1 = windows[i]
        inside = (t >= w0) & (t <= w1)
        resid = np.interp(t[inside] - w0, sim_t, sim[i]) - y[inside] / unit
        m, dec = models[i], report.decrement[i]
        f_d = m["natural_frequency_Hz"] * math.sqrt(1.0 - m["zeta"] ** 2)
        wn = 2.0 * math.pi * m["natural_frequency_Hz"]
        rows.append({
            "trial": trial,
            "model": m["model"], "model_source": m["source"],
            "rms_error_rad": _rms(resid) * unit,
            "max_abs_error_rad": float(np.max(np.abs(resid))) * unit,
            "frequency_error_Hz": f_d - dec.frequency_Hz,
            "zeta_error": m["zeta"] - dec.zeta,
            "model_zeta": m["zeta"], "model_natural_frequency_Hz": m["natural_frequency_Hz"],
            "model_frequency_Hz": f_d,
            "model_stiffness_Nm_per_rad": inertia * wn**2,
            "model_damping_Nms_per_rad": 2.0 * m["zeta"] * inertia * wn,
            "recorded_zeta": dec.zeta, "recorded_zeta_ci95": dec.zeta_ci95,
            "recorded_frequency_Hz": dec.frequency_Hz,
            "recorded_frequency_Hz_ci95": dec.frequency_Hz_ci95,
            "recorded_interval_notes": dec.interval_notes,
            "zeta_within_recorded_ci95": (None if dec.zeta_ci95 is None else
                                          bool(dec.zeta_ci95[0] <= m["zeta"]
                                               <= dec.zeta_ci95[1])),
            "recorded_stable": not dec.grows, "recorded_stability": dec.stability,
            "angle0_rad": starts[i], "equilibrium_rad": equilibria[i],
            "window_s": [w0, w1], "n_samples": int(inside.sum()),
            "encoder_step_rad": report.extrema[i].quantum_rad,
        })
        curves[trial] = (t, y, w0, sim_t + w0, sim[i] * unit, w1)
    return rows, curves


def _rms(x) -> float:
    """Root mean square, scaled by the largest |x| first so that no square under- or
    overflows (residuals of angles of 1e-300 or 1e300 rad)."""
    import numpy as np

    top = float(np.max(np.abs(x))) if len(x) else 0.0
    if top == 0.0 or not np.isfinite(top):
        return top
    return top * float(np.sqrt(np.mean((np.asarray(x) / top) ** 2)))


def cmd_check_decays(args) -> int:
    from .._data._decay_file import load_decay
    from .._io import final_place, json_ready, write_text_atomic

    quiet = args.json
    t_start = time.perf_counter()
    inertia = finite("--inertia", args.inertia, positive=True, unit="kg·m²")
    count("--posterior-draws", args.posterior_draws, high=MAX_POSTERIOR_DRAWS)
    count("--seed", args.seed, high=MAX_SEED)
    data = load_decay(args.decay)
    models = _load_models(args.model_json, args.source, inertia, list(data.trials), args.pooled)
    stage(f"simulating {len(data.trials)} trial(s) in one batched call", quiet)
    rows, curves = check_decays(data, models, inertia)
    payload = {"source": str(args.decay), "model_json": str(args.model_json),
               "inertia_kg_m2": inertia, "n_trials": len(rows),
               "simulator": "linear oscillator (Cullinan section VI), exact sampled solution",
               "trials": rows}
    posterior = pred = None
    if args.posterior_draws:
        import jax

        from .._decays._posterior import fit_decay_mcmc

        stage(f"sampling the posterior of {len(data.trials)} trial(s), then "
               f"{args.posterior_draws} draws per trial through the simulator", quiet)
        k_fit, k_pred = jax.random.split(jax.random.key(args.seed))
        try:
            posterior = fit_decay_mcmc(data, key=k_fit, progress=not quiet)
        except ValueError as exc:
            raise ValueError(f"--posterior-draws: {args.decay}: {exc}") from None
        pred = posterior.predictive(k_pred, n_draws=args.posterior_draws)
        coverage = pred.coverage()
        for row, post, cov in zip(rows, posterior.intervals(inertia), coverage, strict=True):
            row["posterior"] = {
                "draws": args.posterior_draws,
                "band95_coverage": float(cov),
                "zeta": post["zeta"],
                "natural_frequency_Hz": post["natural_frequency_Hz"],
                "converged": post["converged"],
            }
    if args.out:
        out = Path(args.out)
        stage(f"writing plots to {final_place(out)}", quiet)
        owners = _plot(curves, rows, out, args.max_plots)
        if pred is not None:
            from .._report._decays import plot_decay_predictive

            names = safe_file_names(posterior.trials)
            for i, trial in enumerate(posterior.trials[: args.max_plots]):
                name = f"predictive_{names[i]}.png"
                plot_decay_predictive(posterior, pred, i, path=out / name,
                                      title=f"Posterior predictive, trial {trial}")
                owners[name] = trial
        payload["plots"] = list(owners)
        payload["trial_of_file"] = owners
    payload["seconds"] = round(time.perf_counter() - t_start, 3)
    payload = json_ready(payload)  # JSON has no NaN: null
    text = json.dumps(payload)
    if args.out:
        write_text_atomic(Path(args.out) / "check_decays.json",
                          json.dumps(payload, indent=2) + "\n")
    if args.json:
        print(text)
    else:
        print(_text(payload))
    growing = [r["trial"] for r in rows if not r["recorded_stable"]]
    if growing:  # the recording is no decay: the comparison with a decay model is void
        if not args.json:
            print(f"UNSTABLE: the recorded oscillation grows in trial(s) {', '.join(growing)} "
                  "(negative damping): the decay model does not apply")
        return 1
    return 0


def _g(value, spec: str) -> str:
    """``value`` formatted by ``spec``, or "—" (padded alike) where JSON holds null."""
    if value is None:
        return format("—", spec.replace("+", "").rstrip("gef").split(".")[0] or "")
    return format(value, spec)


def _text(d: dict) -> str:
    lines = [f"Model {d['model_json']} against {d['source']}: {d['n_trials']} trial(s), "
             f"J = {d['inertia_kg_m2']:g} kg·m²",
             "  trial  model          RMS [rad]   f error [Hz]   ζ error    ζ model / recorded"]
    for r in d["trials"]:
        lines.append(f"  {r['trial']:<6} {r['model']:<14} {_g(r['rms_error_rad'], '<11.3g')} "
                     f"{_g(r['frequency_error_Hz'], '<+14.3g')} {_g(r['zeta_error'], '<+10.3g')} "
                     f"{_g(r['model_zeta'], '.4g')} / {_g(r['recorded_zeta'], '.4g')}")
    posts = [r for r in d["trials"] if "posterior" in r]
    if posts:
        lines.append(f"posterior ({posts[0]['posterior']['draws']} draws per trial, simulated "
                     "in one batched call):")
        lines.append("  trial  inside 95% band   ζ 95% (posterior)      f_n 95% [Hz]")
        for r in posts:
            p = r["posterior"]
            z, f = p["zeta"]["eti95"], p["natural_frequency_Hz"]["eti95"]
            lines.append(f"  {r['trial']:<6} {p['band95_coverage']:<17.1%} "
                         f"[{z[0]:.4g}, {z[1]:.4g}]      [{f[0]:.5g}, {f[1]:.5g}]")
    return "\n".join(lines)


def _plot(curves, rows, out: Path, max_plots: int) -> dict:
    """``check_<trial>.png`` for the first ``max_plots`` trials; returns {file name: trial}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure_atomic

    written = {}
    names = safe_file_names(row["trial"] for row in rows)
    for row, piece in zip(rows[:max(max_plots, 0)], names):
        t, y, w0, st, sy, w1 = curves[row["trial"]]
        keep = st <= w1
        fig, (ax, ax_r) = plt.subplots(2, 1, figsize=(8.0, 5.5), sharex=True,
                                       gridspec_kw={"height_ratios": [3, 1.3]})
        unit, unit_label = plot_unit(y)
        ax.plot(t, y / unit, lw=0.8, color="0.4", label="recorded angle")
        ax.plot(st[keep], sy[keep] / unit, lw=1.0, color="C0", alpha=0.85,
                label=f"simulated ({row['model']}), ζ = {row['model_zeta']:.4f}, "
                      f"f_n = {row['model_natural_frequency_Hz']:.4g} Hz")
        ax.axvspan(w0, w1, color="0.93", zorder=0)
        ax.set_ylabel(f"angle β [{unit_label}]")
        ax.set_title(f"Trial {row['trial']}: RMS {row['rms_error_rad']:.3g} rad, "
                     f"Δf {row['frequency_error_Hz']:+.3g} Hz, Δζ {row['zeta_error']:+.3g}")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(alpha=0.3)
        inside = (t >= w0) & (t <= w1)
        ax_r.plot(t[inside], (np.interp(t[inside], st, sy) - y[inside]) / unit, lw=0.8,
                  color="C3")
        ax_r.set_ylabel(f"simulated −\nrecorded [{unit_label}]")
        ax_r.set_xlabel("time [s]")
        ax_r.grid(alpha=0.3)
        fig.tight_layout()
        name = f"check_{piece}.png"
        save_figure_atomic(fig, out / name, dpi=110)
        plt.close(fig)
        written[name] = row["trial"]
    return written

