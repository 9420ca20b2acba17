"""``pamid simulate positioning``: Sárosi's linear positioning rig under sliding-mode control.

:func:`add_positioning_parser` adds the ``positioning`` system to the ``simulate``
subparsers that ``pamid._commands.dynamics.register`` creates; :func:`cmd_positioning` is
its command function (parsed namespace in, exit code out; bad options raise ValueError,
which the main command turns into one line and exit code 2). ``--json`` prints exactly one
JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from ._common import MAX_SEED, allow_negative_numbers, count, finite

#: Travel the linear rig's pair allows either side of its middle (pre-contraction 20 mm).
MAX_TARGET_MM = 20.0


def add_positioning_parser(systems_subparsers) -> None:
    """Add ``positioning`` to the subparsers of ``pamid simulate``."""
    ps = systems_subparsers.add_parser(
        "positioning",
        help="Sárosi's linear positioning rig: sliding-mode control of two DMSP-20-200N "
        "(Sections 2.4, 3.3; Fig. 3-7)",
        description="Simulate the antagonistic pair of DMSP-20-200N muscles on a 5/3 "
        "proportional valve (600 kPa) under Sárosi's single-surface sliding-mode "
        "controller (gradient 0.35, voltages 4/4.65/5/5.35/6 V, precision zone), "
        "sampled every 10 ms with a 0.01 mm encoder, from rest at 0 mm to the "
        "target; report the settling time, overshoot and steady-state error.",
    )
    ps.add_argument(
        "--target-mm",
        type=float,
        required=True,
        dest="target_mm",
        help=f"target position in mm (within ±{MAX_TARGET_MM:g}; Fig. 3-7: 15)",
    )
    ps.add_argument(
        "--fit",
        help="muscle constants from the JSON of `pamid fit --json` (default: Sárosi Table 3-1)",
    )
    ps.add_argument(
        "--muscle", type=int, default=0, help="index of the muscle in the --fit file (default 0)"
    )
    ps.add_argument(
        "--draws",
        type=int,
        default=0,
        help="also simulate N draws of the constants from their Wald intervals "
        "(one batched call) and report the spread (default 0)",
    )
    ps.add_argument("--seed", type=int, default=0, help="PRNG seed for --draws (default 0)")
    ps.add_argument(
        "--temperature-C",
        type=float,
        default=20.0,
        dest="temperature_C",
        help="muscle temperature in °C (default 20)",
    )
    ps.add_argument(
        "--duration-s",
        type=float,
        default=4.0,
        dest="duration_s",
        help="simulated time in s (default 4)",
    )
    ps.add_argument(
        "--plain-switching",
        action="store_true",
        dest="plain_switching",
        help="drop the precision zone (the chattering controller)",
    )
    ps.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    ps.add_argument("--out", help="folder for positioning.png and positioning.json")
    ps.set_defaults(func=cmd_positioning, outputs=("positioning.json", "positioning.png"))
    allow_negative_numbers(ps)


def _stage(message: str, quiet: bool) -> None:
    if not quiet:
        print(f"[pamid] {message}", file=sys.stderr, flush=True)


def _num(x, digits: int | None = None) -> float | None:
    x = float(x)
    if not math.isfinite(x):
        return None
    return round(x, digits) if digits is not None else x


def cmd_positioning(args) -> int:
    import jax
    import numpy as np

    from .._control._positioning import (
        linear_rig,
        positioning_metrics,
        sarosi_from_fit_json,
        simulate_positioning,
        wald_draws,
    )
    from .._control._sliding_mode import LINEAR_GRADIENT, SlidingModeController, plain_switching
    from .._io import final_place, write_text_atomic
    from .._models._sarosi import table_3_1, table_3_1_fit_json

    quiet = args.json
    t_start = time.perf_counter()
    target = finite("--target-mm", args.target_mm, low=-MAX_TARGET_MM, high=MAX_TARGET_MM,
                     unit="mm")
    temperature = finite("--temperature-C", args.temperature_C, low=-40.0, high=100.0,
                          unit="°C")
    duration = finite("--duration-s", args.duration_s, low=0.05, high=120.0, unit="s")
    count("--draws", args.draws, high=100_000)
    count("--seed", args.seed, high=MAX_SEED)
    count("--muscle", args.muscle)
    if args.fit:
        try:
            fit = json.loads(Path(args.fit).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"--fit {args.fit}: cannot read a JSON object ({exc})") from exc
        try:
            muscle, se = sarosi_from_fit_json(fit, args.muscle)
        except ValueError as exc:
            raise ValueError(f"--fit {args.fit}: {exc}") from None
        source = f"{args.fit} (muscle {args.muscle})"
    else:
        muscle = table_3_1()
        fit = table_3_1_fit_json()
        _, se = sarosi_from_fit_json(fit)
        source = "Sárosi Table 3-1 (DMSP-20-400N constants, taken for the DMSP-20-200N)"

    controller = SlidingModeController.for_encoder(0.01, LINEAR_GRADIENT)
    if args.plain_switching:
        controller = plain_switching(controller)
    rig = linear_rig(muscle, temperature_C=temperature)
    _stage(f"simulating {duration:g} s of positioning to {target:g} mm (10 ms samples, RK4)", quiet)
    run = simulate_positioning(rig, controller, target, duration_s=duration)
    if not np.all(np.isfinite(np.asarray(run.position))):
        raise ValueError(f"the simulation diverged (non-finite state) with the constants of "
                         f"{source}; check them")
    m = {k: float(v) for k, v in positioning_metrics(run, 0.0, 0.01).items()}
    payload = {
        "system": "positioning",
        "rig": "Sárosi Fig. 2-4: two DMSP-20-200N, MPYE 5/3 valve, 600 kPa, 10 ms, 0.01 mm",
        "controller": "plain switching (no precision zone)"
        if args.plain_switching
        else "sliding mode with precision zone (gradient 0.35)",
        "constants": source,
        "target_mm": target,
        "temperature_C": temperature,
        "duration_s": duration,
        "reach_time_s": _num(m["reach_time_s"], 6),
        "settling_time_s": _num(m["settling_time_s"], 6),
        "settling_time_2pct_s": _num(m["settling_time_2pct_s"], 6),
        "overshoot_mm": m["overshoot"],
        "overshoot_reading_mm": m["overshoot_reading"],
        "steady_state_error_mm": m["steady_state_error"],
        "steady_state_error_reading_mm": m["steady_state_error_reading"],
        "valve_switches_after_settling": int(m["valve_switches_settled"]),
        "settled": math.isfinite(m["settling_time_s"]),
    }
    if args.draws:
        _stage(f"simulating {args.draws} draws of the constants (Wald, independent)", quiet)
        draws = wald_draws(jax.random.key(args.seed), muscle, se, args.draws)
        dm = positioning_metrics(
            simulate_positioning(
                linear_rig(draws, temperature_C=temperature),
                controller,
                target,
                duration_s=duration,
            ),
            0.0,
            0.01,
        )
        summary = {}
        for key, name in (
            ("settling_time_s", "settling_time_s"),
            ("overshoot", "overshoot_mm"),
            ("steady_state_error", "steady_state_error_mm"),
        ):
            v = np.asarray(dm[key])
            ok = v[np.isfinite(v)]
            summary[name] = {
                "median": _num(np.median(ok)) if ok.size else None,
                "p5": _num(np.percentile(ok, 5)) if ok.size else None,
                "p95": _num(np.percentile(ok, 95)) if ok.size else None,
                "not_settled" if key == "settling_time_s" else "n_nan": int(v.size - ok.size),
            }
        payload["draws"] = {
            "n": args.draws,
            "seed": args.seed,
            "method": "independent normals from the Wald intervals",
            "n_diverged": int(np.sum(~np.isfinite(np.asarray(dm["steady_state_error"])))),
            **summary,
        }
    if args.out:
        out = Path(args.out)
        _stage(f"writing the plot to {final_place(out)}", quiet)
        _plot(run, payload, out / "positioning.png")
        payload["plots"] = ["positioning.png"]
    payload["seconds"] = round(time.perf_counter() - t_start, 3)
    if args.out:
        write_text_atomic(Path(args.out) / "positioning.json", json.dumps(payload, indent=2) + "\n")
    if args.json:
        print(json.dumps(payload))
    else:
        print(_text(payload))
    return 0


def _fmt(v, unit: str = "") -> str:
    return "—" if v is None else f"{v:.4g}" + (f" {unit}" if unit else "")


def _text(d: dict) -> str:
    settle = (
        f"{d['settling_time_s']:.2f} s (within one encoder count to the end)"
        if d["settled"]
        else "not settled within one count by the end of the run"
    )
    lines = [
        f"Positioning to {d['target_mm']:g} mm — {d['rig']}",
        f"  controller: {d['controller']}; constants: {d['constants']}",
        f"  reached (1 count)   {_fmt(d['reach_time_s'], 's')} (first within one count)",
        f"  settling time       {settle}",
        f"  2 % settling time   {_fmt(d['settling_time_2pct_s'], 's')}",
        f"  overshoot           {d['overshoot_mm']:.4f} mm true, "
        f"{d['overshoot_reading_mm']:.2f} mm on the encoder",
        f"  steady-state error  {d['steady_state_error_mm']:.4f} mm true, "
        f"{d['steady_state_error_reading_mm']:.2f} mm on the encoder",
        f"  valve switches after settling: {d['valve_switches_after_settling']}",
    ]
    if "draws" in d:
        dr = d["draws"]
        if dr.get("n_diverged"):
            lines.append(f"  {dr['n_diverged']} of {dr['n']} draws diverged (non-finite "
                         "state): left out of the statistics below")
        for key in ("settling_time_s", "overshoot_mm", "steady_state_error_mm"):
            s = dr[key]
            lines.append(
                f"  {dr['n']} draws, {key}: median {_fmt(s['median'])}, 90 % range "
                f"[{_fmt(s['p5'])}, {_fmt(s['p95'])}]"
            )
    return "\n".join(lines)


def _plot(run, d: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .._io import save_figure_atomic

    t = np.asarray(run.time_s)
    fig, axes = plt.subplots(
        3, 1, figsize=(7.5, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.5, 1.5]}
    )
    ax = axes[0]
    ax.plot(t, np.asarray(run.position), lw=1.2, label="position (true)")
    ax.step(t, np.asarray(run.reading), where="post", lw=0.8, color="C1", label="encoder (0.01 mm)")
    ax.axhline(d["target_mm"], color="k", lw=0.8, ls="--", label=f"target {d['target_mm']:g} mm")
    ax.set_ylabel("position [mm]")
    ax.set_title(f"Sliding-mode positioning to {d['target_mm']:g} mm (Sárosi Fig. 3-7 rig)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    axes[1].step(t, np.asarray(run.voltage_V), where="post", lw=1.0, color="C2")
    axes[1].set_ylabel("valve [V]")
    axes[1].grid(alpha=0.3)
    axes[2].plot(t, np.asarray(run.pressure_A_kPa), lw=1.0, label="muscle A")
    axes[2].plot(t, np.asarray(run.pressure_B_kPa), lw=1.0, label="muscle B")
    axes[2].set_ylabel("pressure [kPa]")
    axes[2].set_xlabel("time [s]")
    axes[2].legend(fontsize=8)
    axes[2].grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
