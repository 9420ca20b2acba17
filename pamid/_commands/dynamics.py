"""The dynamics commands: ``pamid simulate lifting-mass`` and ``pamid damping``.

:func:`register` adds both to the ``pamid`` command's subparsers. Each command function
takes the parsed namespace and returns the exit code; bad files raise
:class:`~pamid.BenchDataError` and bad options :class:`ValueError`, which the main command
turns into a one-line message and exit code 2. ``--json`` prints exactly one JSON object on
stdout; progress goes to stderr.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from pathlib import Path

from .._io import safe_file_names
from ._common import (
    NonNegative,
    allow_negative_numbers,
    finite,
    plot_unit,
    stage,
)

#: Accepted nominal lengths of the muscle, mm (a PAM of 1 cm to 10 m).
MIN_L0_MM, MAX_L0_MM = 10.0, 10_000.0
#: Accepted initial rate of shortening, ±mm/s (10 m/s, beyond any PAM's).
MAX_V0_MM_S = 1e4
#: Most RK4 steps one lifting-mass run may take (about 10 s of CPU).
MAX_RK4_STEPS = 20_000_000

#: Sárosi's reported end state of the Fig. 3-6 run (400 kPa, 50 kg, x0 = 50 mm).
FIG_3_6 = {"pressure_kPa": 400.0, "mass_kg": 50.0, "x0_mm": 50.0,
           "force_N": 493.0, "displacement_mm": 49.8}


def register(subparsers) -> None:
    """Add ``simulate`` (with ``lifting-mass``) and ``damping`` to ``subparsers``."""
    sim = subparsers.add_parser("simulate", help="simulate a dynamic system with a PAM")
    systems = sim.add_subparsers(dest="system", required=True)
    lm = systems.add_parser(
        "lifting-mass",
        help="Sárosi's PAM lifting a hanging mass (eq. 2.2, Fig. 2-3 and 3-6)",
        description="Simulate Sárosi eq. 2.2, m·s̈ = F_spring(κ) − c(κ)·ṡ − m·g, for a "
                    "DMSP-20-400N muscle with the constants of Table 3-1 at constant "
                    "pressure; s is the muscle's shortening (Sárosi's displacement).",
    )
    lm.add_argument("--pressure-kPa", type=float, required=True, dest="pressure_kPa",
                    help="constant gauge pressure in kPa (Table 3-1 covers 0–500)")
    lm.add_argument("--mass-kg", type=float, required=True, dest="mass_kg",
                    help="the hanging mass in kg")
    lm.add_argument("--x0-mm", type=float, required=True, dest="x0_mm",
                    help="initial shortening of the muscle in mm (released from rest)")
    lm.add_argument("--v0-mm-s", type=float, default=0.0, dest="v0_mm_s",
                    help="initial rate of shortening in mm/s (default 0)")
    lm.add_argument("--duration-s", type=float, default=10.0, dest="duration_s",
                    help="simulated time in s (default 10)")
    lm.add_argument("--sample-rate-Hz", type=float, default=1000.0, dest="sample_rate_Hz",
                    help="output samples per second (default 1000; one RK4 step each)")
    damping = lm.add_mutually_exclusive_group()
    damping.add_argument("--zeta", type=float,
                         help="constant damping ratio ζ of eq. 2.10 (default: from the "
                              "hysteresis loop, eq. 2.3–2.5)")
    damping.add_argument("--hysteresis-N-per-bar", type=float, dest="hysteresis_N_per_bar",
                         help="half height of the hysteresis loop in N per bar, for ζ by "
                              "eq. 2.3–2.5 (default 3: the loop of pamid's bundled data set)")
    lm.add_argument("--l0-mm", type=float, default=400.0, dest="l0_mm",
                    help="nominal muscle length in mm (default 400, Table 3-1's muscle)")
    lm.add_argument("--gravity", type=float, default=9.81,
                    help="g in m/s² (default 9.81)")
    lm.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    lm.add_argument("--out", help="folder for lifting_mass.png and lifting_mass.json")
    lm.set_defaults(func=cmd_lifting_mass, outputs=("lifting_mass.json", "lifting_mass.png"))
    allow_negative_numbers(lm)

    from .positioning import add_positioning_parser

    add_positioning_parser(systems)

    dmp = subparsers.add_parser(
        "damping",
        help="damping and stiffness from free decays (Cullinan section VI, eq. 8–11)",
        description="Logarithmic decrement (Cullinan eq. 8 and 9), damping ratio (eq. 10), "
                    "frequencies, stiffness k = J·ω_n² and damping coefficient (eq. 11) of "
                    "each decay in the file and pooled, with 95%% intervals; and a fit of "
                    "the linear damped oscillator to the recorded trajectories.",
    )
    dmp.add_argument("decay", help="decay file (CSV or Parquet): time_s, angle_rad or "
                                   "angle_deg, optional trial, pressure1_kPa, pressure2_kPa, "
                                   "temperature_C")
    dmp.add_argument("--inertia", type=float, required=True, metavar="J",
                     help="moment of inertia of the arm about the pivot in kg·m² "
                          "(Cullinan eq. 12; 0.46 with two 1.2 kg weights)")
    dmp.add_argument("--no-fit", action="store_true",
                     help="skip the trajectory fit (decrement estimates only)")
    dmp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    dmp.add_argument("--out", help="folder for plots (PNG) and damping.json")
    dmp.add_argument("--max-plots", type=int, action=NonNegative, default=6,
                     help="trials to plot (default 6)")
    dmp.set_defaults(func=cmd_damping, outputs=("damping.json", "decay_*.png", "decrement.png"))
    allow_negative_numbers(dmp)


# --------------------------------------------------------------------------------------
# pamid simulate lifting-mass
# --------------------------------------------------------------------------------------


def cmd_lifting_mass(args) -> int:
    import numpy as np

    from .._io import final_place, write_text_atomic
    from .._models._sarosi import table_3_1
    from .._sim._lifting_mass import (
        DEFAULT_HYSTERESIS_N_PER_BAR,
        LiftingMass,
        default_zeta,
        lifting_mass_damping,
        lifting_mass_equilibrium,
        lifting_mass_force,
        lifting_mass_stiffness,
        lifting_mass_substeps,
        loop_range_pct,
        settling,
        simulate_lifting_mass,
    )
    from .._units import KPA_PER_BAR

    quiet = args.json
    t_start = time.perf_counter()
    p = finite("--pressure-kPa", args.pressure_kPa, low=0.0, high=1000.0, unit="kPa")
    m = finite("--mass-kg", args.mass_kg, positive=True, unit="kg")
    l0_mm = finite("--l0-mm", args.l0_mm, low=MIN_L0_MM, high=MAX_L0_MM, unit="mm")
    x0_mm = finite("--x0-mm", args.x0_mm, low=-0.1 * l0_mm, high=0.5 * l0_mm,
                    unit=f"mm (−10 … 50 % of l0 = {l0_mm:g} mm)")
    v0 = finite("--v0-mm-s", args.v0_mm_s, low=-MAX_V0_MM_S, high=MAX_V0_MM_S, unit="mm/s")
    duration = finite("--duration-s", args.duration_s, positive=True, high=3600.0, unit="s")
    rate = finite("--sample-rate-Hz", args.sample_rate_Hz, positive=True, high=1e5, unit="Hz")
    g = finite("--gravity", args.gravity, positive=True, unit="m/s²")
    if duration * rate > 5e6:
        raise ValueError(f"{duration:g} s at {rate:g} Hz is {duration * rate:.3g} samples; "
                         "the limit is 5e6 (shorten --duration-s or lower --sample-rate-Hz)")
    if round(duration * rate) < 1:
        raise ValueError(f"--duration-s {duration:g} at --sample-rate-Hz {rate:g} gives fewer "
                         f"than 2 samples; the duration must be at least 1/rate = "
                         f"{1 / rate:g} s")
    if args.zeta is not None:
        zeta = finite("--zeta", args.zeta, low=0.0, high=10.0)
    h = None
    if args.zeta is None and args.hysteresis_N_per_bar is not None:
        h = finite("--hysteresis-N-per-bar", args.hysteresis_N_per_bar, low=0.0, unit="N/bar")
    if p > 500.0:
        warnings.warn(f"{p:g} kPa is above the 0–500 kPa that Table 3-1 was fitted on; "
                      "eq. 2.1 is extrapolated", stacklevel=2)

    muscle = table_3_1()
    if args.zeta is not None:
        zeta_source = "given (--zeta)"
        loop = None
    else:
        h = DEFAULT_HYSTERESIS_N_PER_BAR if h is None else h
        kappa_max = float(loop_range_pct(muscle, p))
        zeta = float(default_zeta(muscle, p, per_bar_N=h))
        if zeta > 1.0:
            # ζ = ΔU/U0 = 2·h·p·Δκ/(I + h·p·Δκ) (eq. 2.3–2.5, I = ∫F dκ of Table 3-1 over
            # the loop): ζ > 1 means a contracting branch with less than no energy, a muscle
            # that pushes. The largest loop is h = I/(p·Δκ), the mean force per bar.
            from .._models._hysteresis import sarosi_force_integral

            p_bar = p / KPA_PER_BAR
            h_max = float(sarosi_force_integral(muscle, p_bar, 0.0, kappa_max)) / (
                p_bar * kappa_max)
            raise ValueError(
                f"--hysteresis-N-per-bar {h:g} gives ζ = ΔU/U0 = {zeta:.3g} > 1 at {p:g} kPa "
                f"(Sárosi eq. 2.3–2.5): the contracting branch would hold less than no "
                f"energy; at {p:g} kPa the loop must be at most {h_max:.4g} N/bar")
        zeta_source = (f"hysteresis loop ±{h:g} N/bar around Table 3-1, Sárosi eq. 2.3–2.5, "
                       f"over κ = 0–{kappa_max:.3g} % at {p:g} kPa")
        loop = {"half_height_N_per_bar": h, "kappa_min_pct": 0.0, "kappa_max_pct": kappa_max}
    model = LiftingMass(muscle, p, m, zeta, l0_mm / 1000.0, g)

    eq = float(lifting_mass_equilibrium(model))
    if not math.isfinite(eq):
        f_max = float(lifting_mass_force(model, -0.1 * l0_mm / 1000.0))
        raise ValueError(
            f"no static equilibrium: at {p:g} kPa the muscle cannot hold {m:g} kg anywhere "
            "between −10 % and 50 % contraction (Sárosi eq. 2.1 with Table 3-1): it holds at "
            f"most {f_max / g:.4g} kg under --gravity {g:g} m/s² (lower --mass-kg or raise "
            "--pressure-kPa)")
    if eq < 0:
        warnings.warn(f"the static solution is at {100 * eq / (l0_mm / 1000):.3g} % "
                      "contraction: the muscle would be stretched beyond l0, outside the "
                      "range Table 3-1 was fitted on", stacklevel=2)
    substeps, fastest = lifting_mass_substeps(model, x0_mm / 1000.0, v0 / 1000.0, rate)
    n_steps = substeps * round(duration * rate)
    if n_steps > MAX_RK4_STEPS:
        raise ValueError(
            f"at {m:g} kg the fastest rate of the linearised motion is {fastest:.4g} 1/s "
            f"(ω_n = √(k/m), Sárosi eq. 2.9); RK4 needs "
            f"{f'{substeps:.3g}' if math.isfinite(substeps) else 'more than 1e15'} steps per "
            f"sample at {rate:g} Hz to follow it, {n_steps:.3g} steps in all over "
            f"{duration:g} s, above the limit {MAX_RK4_STEPS:.0e} (shorten --duration-s or "
            "raise --mass-kg)")
    stage(f"simulating {duration:g} s at {rate:g} Hz (RK4, Sárosi eq. 2.2), ζ = {zeta:.4g}",
           quiet)
    run = simulate_lifting_mass(model, x0_mm / 1000.0, v0 / 1000.0, duration_s=duration,
                                sample_rate_Hz=rate, substeps=substeps)
    t = np.asarray(run.time_s)
    s = np.asarray(run.contraction_m)
    force = np.asarray(run.force_N)
    c = np.asarray(run.damping_Ns_per_m)
    if not np.all(np.isfinite(s)):
        raise ValueError("the simulation diverged (non-finite state) although RK4 took "
                         f"{substeps} step(s) per sample; check the inputs")
    _check_reach(s, l0_mm, x0_mm, v0)
    k_eq = float(lifting_mass_stiffness(model, eq))
    c_eq = float(lifting_mass_damping(model, eq))
    wn = math.sqrt(k_eq / m)
    settle = settling(t, s, eq, band_fraction=0.02, floor_m=0.0)
    payload = {
        "system": "lifting-mass",
        "model": "Sárosi eq. 2.2 with F_spring from eq. 2.1 (Table 3-1) and c(κ) = "
                 "ζ·2·√(k(κ)·m) (eq. 2.6, 2.9, 2.10); displacement = muscle shortening",
        "pressure_kPa": p, "mass_kg": m, "x0_mm": x0_mm, "v0_mm_s": v0, "l0_mm": l0_mm,
        "gravity_m_per_s2": g, "duration_s": duration, "sample_rate_Hz": rate,
        "integrator": f"RK4, fixed step, {substeps} step(s) per output sample",
        "rk4_steps_per_sample": substeps,
        "zeta": zeta, "zeta_source": zeta_source, "hysteresis_loop": loop,
        "final_displacement_mm": float(s[-1] * 1e3),
        "final_force_N": float(force[-1]),
        "final_velocity_mm_s": float(np.asarray(run.velocity_m_per_s)[-1] * 1e3),
        "equilibrium_displacement_mm": eq * 1e3,
        "equilibrium_contraction_pct": 100.0 * eq / (l0_mm / 1000.0),
        "equilibrium_force_N": m * g,
        "final_minus_equilibrium_mm": float((s[-1] - eq) * 1e3),
        "stiffness_at_equilibrium_N_per_m": k_eq,
        "damping_at_equilibrium_Ns_per_m": c_eq,
        "damping_range_Ns_per_m": [float(c.min()), float(c.max())],
        "natural_frequency_Hz": wn / (2 * math.pi),
        "damped_frequency_Hz": wn * math.sqrt(max(1 - zeta**2, 0.0)) / (2 * math.pi),
        "settling": {
            "band_mm": settle["band_m"] * 1e3,
            "band": "±2 % of the initial distance from the static solution",
            "settling_time_s": settle["settling_time_s"],
            "settled": settle["settled"],
            "overshoot_mm": settle["overshoot_m"] * 1e3,
        },
    }
    if (p, m, x0_mm) == (FIG_3_6["pressure_kPa"], FIG_3_6["mass_kg"], FIG_3_6["x0_mm"]):
        payload["sarosi_fig_3_6"] = {"force_N": FIG_3_6["force_N"],
                                     "displacement_mm": FIG_3_6["displacement_mm"]}
    if args.out:
        out = Path(args.out)
        stage(f"writing the plot to {final_place(out)}", quiet)
        _plot_lifting_mass(t, s, force, c, eq, m * g, settle, payload, out / "lifting_mass.png")
        payload["plots"] = ["lifting_mass.png"]
    payload["seconds"] = round(time.perf_counter() - t_start, 3)
    if args.out:
        write_text_atomic(Path(args.out) / "lifting_mass.json",
                          json.dumps(payload, indent=2) + "\n")
    if args.json:
        print(json.dumps(payload))
    else:
        print(_lifting_mass_text(payload))
    return 0


def _check_reach(s, l0_mm: float, x0_mm: float, v0_mm_s: float) -> None:
    """A run must keep the muscle's length between 0 and 2·l0 (κ in −100 … 100 %): beyond,
    the numbers describe no muscle; outside −10 … 50 % eq. 2.1 is extrapolated (a warning)."""
    import numpy as np

    kappa = 100.0 * np.asarray(s) / (l0_mm / 1000.0)
    lo, hi = float(kappa.min()), float(kappa.max())
    if lo < -100.0 or hi > 100.0:
        raise ValueError(
            f"from --x0-mm {x0_mm:g} at --v0-mm-s {v0_mm_s:g} the run reaches κ = "
            f"{lo if lo < -100.0 else hi:.4g} % (l0 = {l0_mm:g} mm): a muscle length "
            f"{'above 2·l0' if lo < -100.0 else 'below 0'}, which no muscle reaches; start "
            "nearer the static solution or slower")
    if lo < -10.0 or hi > 50.0:
        warnings.warn(f"the run spans κ = {lo:.3g} … {hi:.3g} %, beyond the −10 … 50 % where "
                      "eq. 2.1 with Table 3-1 holds (extrapolated; the muscle goes slack "
                      "above the contraction where its force reaches 0)", stacklevel=2)


def _lifting_mass_text(d: dict) -> str:
    st = d["settling"]
    settle = (f"settles into ±{st['band_mm']:.3g} mm after {st['settling_time_s']:.3g} s"
              if st["settled"] else f"not yet inside ±{st['band_mm']:.3g} mm at the end")
    lines = [
        f"PAM lifting a mass (Sárosi eq. 2.2): {d['pressure_kPa']:g} kPa, {d['mass_kg']:g} kg, "
        f"x0 = {d['x0_mm']:g} mm, l0 = {d['l0_mm']:g} mm, {d['duration_s']:g} s",
        f"  damping ratio ζ = {d['zeta']:.4g} ({d['zeta_source']})",
        f"  end of run:       displacement {d['final_displacement_mm']:.4f} mm, "
        f"F_spring {d['final_force_N']:.2f} N",
        f"  static solution:  displacement {d['equilibrium_displacement_mm']:.4f} mm "
        f"(κ = {d['equilibrium_contraction_pct']:.4g} %), F_spring = m·g = "
        f"{d['equilibrium_force_N']:.2f} N",
        f"  at equilibrium:   k = {d['stiffness_at_equilibrium_N_per_m']:.5g} N/m (eq. 2.9), "
        f"c = {d['damping_at_equilibrium_Ns_per_m']:.4g} N·s/m (eq. 2.10), "
        f"f_n = {d['natural_frequency_Hz']:.4g} Hz",
        f"  {settle}; overshoot {st['overshoot_mm']:.3g} mm",
    ]
    if "sarosi_fig_3_6" in d:
        ref = d["sarosi_fig_3_6"]
        lines.append(f"  Sárosi Fig. 3-6 reports F_spring ≈ {ref['force_N']:g} N and "
                     f"displacement ≈ {ref['displacement_mm']:g} mm")
    return "\n".join(lines)


def _plot_lifting_mass(t, s, force, c, eq, weight, settle, d, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .._io import save_figure_atomic

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.0), sharex=True,
                             gridspec_kw={"height_ratios": [3, 3, 1.6]})
    ax = axes[0]
    ax.plot(t, s * 1e3, lw=1.2, color="C0", label="simulation (RK4)")
    ax.axhline(eq * 1e3, color="k", lw=0.8, ls="--", label=f"static solution {eq * 1e3:.3f} mm")
    band = settle["band_m"] * 1e3
    ax.axhspan(eq * 1e3 - band, eq * 1e3 + band, color="0.85", zorder=0,
               label=f"±{band:.2g} mm (2 %)")
    if "sarosi_fig_3_6" in d:
        ax.axhline(d["sarosi_fig_3_6"]["displacement_mm"], color="C3", lw=0.8, ls=":",
                   label="Sárosi Fig. 3-6: 49.8 mm")
    ax.set_ylabel("displacement (shortening) s [mm]")
    ax.set_title(f"PAM lifting a mass, Sárosi eq. 2.2: {d['pressure_kPa']:g} kPa, "
                 f"{d['mass_kg']:g} kg, x0 = {d['x0_mm']:g} mm, ζ = {d['zeta']:.3g}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[1]
    ax.plot(t, force, lw=1.2, color="C1", label="F_spring (eq. 2.1)")
    ax.axhline(weight, color="k", lw=0.8, ls="--", label=f"m·g = {weight:.1f} N")
    if "sarosi_fig_3_6" in d:
        ax.axhline(d["sarosi_fig_3_6"]["force_N"], color="C3", lw=0.8, ls=":",
                   label="Sárosi Fig. 3-6: 493 N")
    ax.set_ylabel("F_spring [N]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[2]
    ax.plot(t, c, lw=1.0, color="C2")
    ax.set_ylabel("c(κ) [N·s/m]\n(eq. 2.10)")
    ax.set_xlabel("time t [s]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------------------
# pamid damping
# --------------------------------------------------------------------------------------


def cmd_damping(args) -> int:
    from .._data._decay_file import load_decay
    from .._decays._analysis import analyze_decays
    from .._io import final_place, write_text_atomic

    quiet = args.json
    t_start = time.perf_counter()
    inertia = finite("--inertia", args.inertia, positive=True, unit="kg·m²")
    data = load_decay(args.decay)
    stage(f"loaded {len(data)} samples, {len(data.trials)} trial(s) from {args.decay}", quiet)
    stage("peaks and troughs, logarithmic decrement (Cullinan eq. 8–11)"
           + ("" if args.no_fit else "; trajectory fit (batched Levenberg–Marquardt)"), quiet)
    report = analyze_decays(data, inertia, fit=not args.no_fit)
    payload = report.to_dict()
    if args.out:
        out = Path(args.out)
        stage(f"writing plots to {final_place(out)}", quiet)
        owners = _plot_decays(data, report, out, args.max_plots)
        payload["plots"] = list(owners)
        payload["trial_of_file"] = {name: trial for name, trial in owners.items()
                                    if trial is not None}
    payload["seconds"] = round(time.perf_counter() - t_start, 3)
    if args.out:
        write_text_atomic(Path(args.out) / "damping.json", json.dumps(payload, indent=2) + "\n")
    if args.json:
        print(json.dumps(payload))
    else:
        print(_damping_text(report))
    code = 0
    if not report.stable:  # a growing oscillation: the decay model does not apply
        if not args.json:
            print(f"UNSTABLE: {_unstable_text(report)}")
        code = 1
    if report.fits is not None and not all(f.converged for f in report.fits):
        if not args.json:
            bad = [tr for tr, f in zip(report.trials, report.fits) if not f.converged]
            print(f"WARNING: the trajectory fit did not converge for trial(s) {bad}")
        code = 1
    return code


def _unstable_text(report) -> str:
    grows = report.growing_trials
    which = (f"trial(s) {', '.join(grows)}" if grows else "the pooled estimate")
    return (f"the oscillation grows in {which}: negative damping; the decay model does not "
            "apply")


def _fmt(v, ci=None, digits=4):
    if v is None or not math.isfinite(v):
        return "—"
    text = f"{v:.{digits}g}"
    if ci is not None and all(x is not None and math.isfinite(x) for x in ci):
        text += f" ({ci[0]:.{digits}g}, {ci[1]:.{digits}g})"
    return text


_ROWS = (
    ("log decrement δ", "log_decrement"),
    ("ζ (eq. 10)", "zeta"),
    ("f_d [Hz]", "frequency_Hz"),
    ("f_n [Hz]", "natural_frequency_Hz"),
    ("k = J·ω_n² [N·m/rad]", "stiffness_Nm_per_rad"),
    ("c (eq. 11) [N·m·s/rad]", "damping_Nms_per_rad"),
)


def _comparison(dec: dict, fit: dict | None) -> list[str]:
    head = ["", "log decrement (eq. 9)"] + (["trajectory fit"] if fit is not None else [])
    rows = [head]
    for label, key in _ROWS:
        row = [label, _fmt(dec.get(key), dec.get(key + "_ci95"))]
        if fit is not None:
            row.append(_fmt(fit.get(key), fit.get(key + "_ci95")))
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return ["  " + "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)) for r in rows]


def _amplitude_lines(a: dict) -> list[str]:
    if a.get("amplitude_dependent") is None:
        return [f"  amplitude dependence: {a.get('note', 'not tested')}"]
    lines = [
        f"  amplitude dependence: δ early {_fmt(a.get('log_decrement_early'))}, late "
        f"{_fmt(a.get('log_decrement_late'))} (p = {_fmt(a.get('early_late_p_value'), None, 2)})"
        f"; slope of δ_j on amplitude {_fmt(a.get('slope_per_rad'))} /rad "
        f"(p = {_fmt(a.get('slope_p_value'), None, 2)})",
        f"  Coulomb friction (viscous + Coulomb half-cycle map): T_c = "
        f"{_fmt(a.get('coulomb_Nm'), a.get('coulomb_Nm_ci95'), 3)} N·m "
        f"(p = {_fmt(a.get('coulomb_p_value'), None, 2)}), viscous ζ = "
        f"{_fmt(a.get('zeta_viscous'))}",
        f"  → {a['note']}",
    ]
    return lines


def _damping_text(report) -> str:
    d = report.to_dict()
    lines = [f"Free decays of {d['source']}: {d['n_trials']} trial(s), J = "
             f"{d['inertia_kg_m2']:g} kg·m² (Cullinan section VI)", ""]
    for tr in d["trials"]:
        lines.append(
            f"trial {tr['trial']}: {tr['n_samples']} samples, {tr['n_extrema']} extrema used "
            f"(of {tr['n_extrema_detected']} found), encoder step {_fmt(tr['encoder_step_rad'])} "
            f"rad, noise {_fmt(tr['noise_rad'])} rad")
        if not tr["stable"]:
            lines.append(f"  {tr['stability']}")
            lines.append(f"  ζ = {_fmt(tr['zeta'], tr['zeta_ci95'])}, δ = "
                         f"{_fmt(tr['log_decrement'], tr['log_decrement_ci95'])}, f_d = "
                         f"{_fmt(tr['frequency_Hz'])} Hz (95 % intervals)")
            lines.append("")
            continue
        if tr["stability"] != "decays":
            lines.append(f"  note: {tr['stability']}")
        lines += _comparison(tr, tr.get("trajectory_fit"))
        lines.append(
            f"  eq. 8: δ = {_fmt(tr['log_decrement_eq8'], tr['log_decrement_eq8_ci95'])} about "
            f"β_eq = {_fmt(tr['equilibrium_rad'])} rad; printed two-point forms: eq. 8 "
            f"{_fmt(tr['log_decrement_eq8_endpoints'])}, eq. 9 "
            f"{_fmt(tr['log_decrement_eq9_endpoints'])}")
        lines += _amplitude_lines(tr["amplitude_dependence"])
        fit = tr.get("trajectory_fit")
        if fit is not None:
            lines.append(f"  fit: {fit['n_samples']} samples, RMSE {_fmt(fit['rmse_rad'])} rad, "
                         f"{'converged' if fit['converged'] else 'NOT CONVERGED'} "
                         f"({fit['n_steps']} steps)")
        lines.append("")
    pooled = d["pooled"]
    lines.append(f"pooled over {d['n_trials']} trial(s) (common slopes, per-trial intercepts; "
                 "fit: inverse-variance weighted mean):")
    if pooled["stable"]:
        lines += _comparison(pooled, pooled.get("trajectory_fit"))
        lines += _amplitude_lines(pooled["amplitude_dependence"])
    else:
        lines.append(f"  {pooled['stability']}")
    notes = _interval_notes(d)
    if notes:
        lines.append("")
        lines.append("Intervals not given (—):")
        lines += [f"  {where}: {why}" for where, why in notes]
    lines.append("")
    lines.append("Intervals: 95 %. Decrement: Student-t on the regression of ln(travel) on the "
                 "half-cycle index, propagated (delta method); fit: Wald.")
    return "\n".join(lines)


def _interval_notes(d: dict) -> list[tuple[str, str]]:
    """(where, why) of every interval that the damping JSON ``d`` leaves out."""
    out = []
    blocks = [(f"trial {tr['trial']}", tr) for tr in d["trials"]] + [("pooled", d["pooled"])]
    for where, block in blocks:
        if not block.get("stable", True):
            continue
        parts = [("", block), (" (fit)", block.get("trajectory_fit") or {}),
                 (" (amplitude)", block.get("amplitude_dependence") or {})]
        for suffix, part in parts:
            for key, why in (part.get("interval_notes") or {}).items():
                out.append((f"{where}{suffix} {key}", why))
    return out


def _plot_decays(data, report, out: Path, max_plots: int) -> dict:
    """``decay_<trial>.png`` for the first ``max_plots`` trials and ``decrement.png``;
    returns {file name: trial} (None for the figure of every trial)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure_atomic
    from .._sim._oscillator import DampedOscillator, oscillator_response

    written = {}
    names = safe_file_names(report.trials)
    for i, trial in enumerate(report.trials[:max_plots]):
        t, y = data.arrays(trial)
        e = report.extrema[i]
        dec = report.decrement[i]
        fig, ax = plt.subplots(figsize=(8.0, 4.5))
        unit, unit_label = plot_unit(y)  # matplotlib cannot scale an axis of 1e-300 rad
        ax.plot(t, y / unit, lw=0.8, color="0.4", label="recorded angle")
        n = e.n_used
        ax.plot(e.time_s[:n], e.angle_rad[:n] / unit, "o", color="C3", ms=4,
                label=f"peaks/troughs used ({n})")
        if len(e.time_s) > n:
            ax.plot(e.time_s[n:], e.angle_rad[n:] / unit, "o", mfc="none", color="C3", ms=4,
                    label="below the noise floor (not used)")
        ax.axhline(dec.equilibrium_rad / unit, color="k", lw=0.7, ls="--",
                   label="β_eq (eq. 8)")
        if report.fits is not None:
            f = report.fits[i]
            p = f.params
            tt = np.linspace(f.t0_s, f.t1_s, 2000)
            osc = DampedOscillator(1.0, p["omega_n_rad_s"] ** 2,
                                   2 * p["zeta"] * p["omega_n_rad_s"], p["equilibrium_rad"])
            fitted = np.asarray(oscillator_response(osc, p["angle0_rad"], p["rate0_rad_s"],
                                                    tt - f.t0_s)[0])
            ax.plot(tt, fitted / unit, lw=1.0, color="C0", alpha=0.8,
                    label=f"trajectory fit, ζ = {p['zeta']:.4f}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"angle β [{unit_label}]")
        ax.set_title(f"Free decay, trial {trial}: δ = {dec.log_decrement:.4f}, "
                     f"ζ = {dec.zeta:.4f} (Cullinan eq. 9, 10)")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        name = f"decay_{names[i]}.png"
        save_figure_atomic(fig, out / name, dpi=110)
        plt.close(fig)
        written[name] = trial

    fig, ax = plt.subplots(figsize=(7.0, 4.5))
    for i, trial in enumerate(report.trials):
        a = report.extrema[i].travels_rad
        j = np.arange(len(a))
        line, = ax.plot(j, np.log(a), "o", ms=4, label=f"trial {trial}")
        slope = -report.decrement[i].log_decrement / 2
        ax.plot(j, np.mean(np.log(a)) + slope * (j - j.mean()), "-", lw=0.8,
                color=line.get_color())
    ax.set_xlabel("half cycle j")
    ax.set_ylabel("ln(peak-to-trough travel a_j / rad)")
    ax.set_title("Cullinan eq. 9 as a regression: slope = −δ/2 per half cycle")
    ax.grid(alpha=0.3)
    if len(report.trials) <= 12:
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, out / "decrement.png", dpi=110)
    plt.close(fig)
    written["decrement.png"] = None
    return written
