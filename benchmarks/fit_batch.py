"""Batched fitting benchmark: pamid (JAX, one vmapped solve) against SciPy loops.

    .venv/bin/python benchmarks/fit_batch.py                 # full run (N = 1, 100, 1000, 10000)
    .venv/bin/python benchmarks/fit_batch.py --quick         # N up to 1000, fewer repeats
    .venv/bin/python benchmarks/fit_batch.py --json out.json # also write every number as JSON

What is measured (see benchmarks/README.md for a recorded run):

1. Data. For N muscles, per-muscle constants = Sárosi Table 3-1 × (1 + 0.03·normal), and
   Sárosi's protocol on the virtual bench (5 pressures 100–500 kPa, 30 points per sweep,
   contracting and extending, 5 repeats averaged, load-cell noise 2 N, sweeps end where the
   force falls to 10 N): 300 samples per muscle. Generated once per N with fixed keys.
2. Fit time for N = 1, 100, 1000, 10000:
   - pamid ``solve`` (the bare batched solve; for the Sárosi model the default solver is the
     written-out Gauss–Newton of ``pamid/_solvers/_sarosi.py``: a coarse variable-
     projection scan on a subsample of each muscle as start, then Gauss–Newton, Newton near
     the optimum),
   - pamid ``fit_least_squares`` (the public path: the same solve + statistics + Wald
     intervals), both from a packed ``FitData``;
   - a loop of ``scipy.optimize.least_squares`` with the ANALYTIC Jacobian, x_scale="jac",
     method "trf" and "lm" (the faster one is the baseline), started from the Table 3-1
     constants. The muscles are Table 3-1 ± 3 %, so this start is within a few percent of
     every optimum: the most favourable start SciPy could get. (A fixed generic start is
     measured too, in section 4.)
   - a loop of ``scipy.optimize.curve_fit`` (numerical Jacobian, default settings), from
     the same Table 3-1 start: what most users write.
   pamid: "first" is the first call after ``jax.clear_caches()`` (tracing + compilation +
   one run; the persistent compilation cache is switched off in this process), "steady" the
   median of warm calls; results are converted to NumPy inside the timed call. Warm calls
   of all contenders at one N are interleaved round by round, so that the load of other
   processes on a shared machine falls on all of them alike. SciPy loops
   larger than ``--scipy-max`` muscles are timed on the first ``--scipy-max`` muscles and
   extrapolated linearly (marked ``*``).
3. Check: pamid's constants against the SciPy least_squares optimum, muscle by muscle
   (max relative difference of any constant, relative SSE difference, and which is lower
   where they differ).
4. Solvers at N = 1000: every pamid solver; the previous default (optimistix Gauss–Newton
   from the 24-point variable-projection start); optimistix LM/GN and pamid's Gauss–Newton
   from a fixed generic start (no scan), and SciPy from the same generic start.
5. Ratios (SciPy time / pamid time), and the targets: ≥ 20× faster than the analytic-Jacobian
   SciPy loop at N = 1000, steady state (issue #2); at N = 10000, 0.1 s or less and ≥ 25×
   (issue #7).
6. End to end: ``pamid fit FILE --json`` as a subprocess on an N-muscle CSV against
   ``benchmarks/baseline_curve_fit_script.py`` (pandas + curve_fit), and the one-muscle CLI
   call with a cold and a warm compilation cache (``PAMID_CACHE_DIR``). One call each;
   ``benchmarks/end_to_end.py`` repeats the comparison in rounds (medians, CPU times) and
   adds the measured AARL file with plots.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

# Compile times are part of what is measured: no persistent compilation cache in this
# process (the CLI's cache is measured separately, in section 6).
jax.config.update("jax_enable_compilation_cache", False)

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.optimize import curve_fit, least_squares  # noqa: E402

import pamid  # noqa: E402
from pamid.engine import (  # noqa: E402
    get_model,
    sarosi_fast_start,
    sarosi_variable_projection_start,
    solve,
)
from pamid.io import write_text_atomic  # noqa: E402

HERE = Path(__file__).resolve().parent
SAROSI = get_model("sarosi")
# The Sárosi model without its written-out kernels (``written_out=False``): solve() runs
# optimistix's Gauss–Newton for it, the previous default path.
SAROSI_OPTIMISTIX = dataclasses.replace(SAROSI, written_out=False)
PROTOCOL = pamid.SarosiProtocol(min_force_N=10.0)
TABLE_3_1 = np.asarray(pamid.sarosi.table_3_1().to_vector(), dtype=float)
# A fixed generic start, not adapted to the data or to Table 3-1: 100 N and 100 N/bar with
# an exponential decaying over 10 % of contraction, no bilinear term, no offset. SciPy
# (trf and lm) and optimistix LM converge from it on every muscle of this data.
GENERIC_START = np.array([0.0, 100.0, -0.1, 0.0, 100.0, 0.0])
SOLVERS = (
    "gauss-newton",
    "levenberg-marquardt",
    "variable-projection",
    "jaxopt-levenberg-marquardt",
)
TARGET_RATIO = 20.0
TARGET_N = 1000
# Issue #7: 10,000 static fits in 0.1 s or less, and ≥ 25× the analytic-Jacobian SciPy loop.
TARGET7_N, TARGET7_S, TARGET7_RATIO = 10000, 0.1, 25.0


# --------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------


def clock(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - t0, time.process_time() - c0, out


def first_call(fn):
    """The first call after ``jax.clear_caches()``: tracing + compilation + one run."""
    jax.clear_caches()
    wall, cpu, out = clock(fn)
    return {"first_s": wall, "first_cpu_s": cpu}, out


def interleaved(fns, rounds):
    """Warm every function once, then run them in turn for ``rounds`` rounds.

    Interleaving spreads the load of other processes over all contenders alike, so that
    their ratios are fairer than back-to-back measurements on a shared machine. Returns,
    per name, the median and minimum wall time, the median CPU time and the samples, and
    the last output of each function.
    """
    outs = {name: fn() for name, fn in fns.items()}
    walls = {name: [] for name in fns}
    cpus = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            wall, cpu, outs[name] = clock(fn)
            walls[name].append(wall)
            cpus[name].append(cpu)
    stats = {
        name: {
            "steady_s": statistics.median(walls[name]),
            "steady_min_s": min(walls[name]),
            "steady_cpu_s": statistics.median(cpus[name]),
            "samples_s": walls[name],
        }
        for name in fns
    }
    return stats, outs


# --------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------


def make_data(n_muscles: int):
    """Virtual-bench data for ``n_muscles`` muscles: (frame, groups, FitData, true thetas)."""
    key_params, key_noise = jax.random.split(jax.random.key(20261121 + n_muscles))
    z = np.asarray(jax.random.normal(key_params, (n_muscles, 6), dtype=jax.numpy.float64))
    thetas = TABLE_3_1 * (1.0 + 0.03 * z)
    frame = pamid.simulate_sarosi_bench(key_noise, pamid.Sarosi.from_vector(thetas), PROTOCOL)
    t0 = time.perf_counter()
    groups = [
        (
            (rows["pressure_kPa"].to_numpy() / 100.0, rows["contraction_pct"].to_numpy()),
            rows["force_N"].to_numpy(),
        )
        for _, rows in frame.groupby("muscle", sort=False)
    ]
    data = pamid.pack_muscles(groups)
    pack_s = time.perf_counter() - t0
    return frame, groups, data, thetas, pack_s


# --------------------------------------------------------------------------------------
# SciPy baselines
# --------------------------------------------------------------------------------------


def sarosi_np(theta, p, k):
    a1, a2, a3, a4, a5, a6 = theta
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def residual(theta, p, k, y):
    return sarosi_np(theta, p, k) - y


def jacobian(theta, p, k, y):
    """Analytic Jacobian of eq. 2.1 with respect to (a1, …, a6)."""
    a1, a2, a3 = theta[0], theta[1], theta[2]
    e = np.exp(a3 * k)
    return np.stack([p * e, e, (a1 * p + a2) * k * e, k * p, p, np.ones_like(p)], axis=1)


def curve_fit_model(x, a1, a2, a3, a4, a5, a6):
    p, k = x
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def scipy_ls_loop(groups, start, method, tol):
    theta = np.empty((len(groups), 6))
    nfev = np.empty(len(groups), dtype=int)
    ok = np.empty(len(groups), dtype=bool)
    for i, ((p, k), y) in enumerate(groups):
        res = least_squares(
            residual,
            start,
            jac=jacobian,
            args=(p, k, y),
            method=method,
            x_scale="jac",
            ftol=tol,
            xtol=tol,
            gtol=tol,
        )
        theta[i], nfev[i], ok[i] = res.x, res.nfev, res.success
    return theta, nfev, ok


def curve_fit_loop(groups, start):
    theta = np.empty((len(groups), 6))
    for i, ((p, k), y) in enumerate(groups):
        theta[i] = curve_fit(curve_fit_model, (p, k), y, p0=start)[0]
    return theta


def sse_np(theta, data):
    """Per-muscle weighted SSE, in NumPy float64."""
    p, k = (np.asarray(a) for a in data.x)
    y, w = np.asarray(data.y), np.asarray(data.w)
    with np.errstate(all="ignore"):  # a diverged solver's constants may overflow
        model = sarosi_np(tuple(theta[:, j][:, None] for j in range(6)), p, k)
        return np.sum(w * (model - y) ** 2, axis=1)


def compare(theta, theta_ref, data_sub):
    """Max relative difference (any constant, any muscle), SSE difference, who is lower."""
    with np.errstate(all="ignore"):
        rel = np.abs(theta - theta_ref) / np.abs(theta_ref)
        sse, sse_ref = sse_np(theta, data_sub), sse_np(theta_ref, data_sub)
        dsse = (sse - sse_ref) / sse_ref
    bad = np.max(rel, axis=1) > 1e-6
    return {
        "max_rel_diff": float(np.max(rel)),
        "max_rel_diff_per_constant": dict(
            zip(SAROSI.param_names, map(float, np.max(rel, axis=0)), strict=True)
        ),
        "max_abs_rel_sse_diff": float(np.max(np.abs(dsse))),
        "max_rel_sse_excess": float(np.max(dsse)),  # > 0: this one worse than the reference
        "n_muscles": int(len(theta)),
        "n_differ_1e-6": int(bad.sum()),
        "n_differ_lower_sse_here": int(np.sum(bad & (sse < sse_ref))),
        "n_differ_lower_sse_ref": int(np.sum(bad & (sse > sse_ref))),
        "all_within_1e-6": bool(not bad.any()),
    }


def subset(data, n):
    return pamid.FitData(
        x=tuple(a[:n] for a in data.x), y=data.y[:n], w=data.w[:n], curve=data.curve[:n]
    )


# --------------------------------------------------------------------------------------
# Output helpers
# --------------------------------------------------------------------------------------


def fmt_s(seconds, star=False):
    if seconds is None or not np.isfinite(seconds):
        return "—"
    if seconds < 1e-3:
        text = f"{seconds * 1e6:.0f} µs"
    elif seconds < 1.0:
        text = f"{seconds * 1e3:.1f} ms"
    else:
        text = f"{seconds:.2f} s"
    return text + ("*" if star else "")


def fmt_x(ratio):
    if ratio is None or not np.isfinite(ratio):
        return "—"
    return f"{ratio:.1f}×" if ratio < 100 else f"{ratio:.0f}×"


def table(headers, rows, aligns=None):
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    aligns = aligns or ["<"] + [">"] * (len(headers) - 1)

    def line(cells):
        return "  ".join(f"{str(c):{a}{w}}" for c, a, w in zip(cells, aligns, widths, strict=True))

    out = [line(headers), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in rows]
    return "\n".join(out)


def say(text=""):
    print(text, flush=True)


# --------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------


def bench_size(n, data, groups, args):
    """Sections 2 and 3 for one N: first calls, then interleaved rounds of every contender."""
    rec = {"n_muscles": n}
    n_fit = min(n, args.scipy_max)
    scale = n / n_fit
    sub_groups = groups[:n_fit]
    sub_data = subset(data, n_fit)
    rec["scipy_subset"] = n_fit
    rec["scipy_extrapolated"] = n_fit < n
    if n >= 10000:
        rounds = max(3, args.repeats // 2)
    elif n >= 1000:
        rounds = args.repeats
    else:
        rounds = max(args.repeats, args.scipy_repeats_small)
    rec["rounds"] = rounds

    contenders = {
        "pamid_solve": lambda: solve(SAROSI, data),
        "pamid_fit_least_squares": lambda: pamid.fit_least_squares(data),
        "scipy_least_squares_trf": lambda: scipy_ls_loop(sub_groups, TABLE_3_1, "trf", args.tol),
        "scipy_least_squares_lm": lambda: scipy_ls_loop(sub_groups, TABLE_3_1, "lm", args.tol),
        "scipy_curve_fit": lambda: curve_fit_loop(sub_groups, TABLE_3_1),
    }
    firsts = {
        name: first_call(contenders[name]) for name in ("pamid_solve", "pamid_fit_least_squares")
    }
    timings, outs = interleaved(contenders, rounds)
    for name, (first, _) in firsts.items():
        timings[name].update(first)
    for name, t in timings.items():
        t["time_s"] = t["steady_s"] * (scale if name.startswith("scipy") else 1.0)
        rec[name] = t

    theta, converged, steps = outs["pamid_solve"]
    fit = outs["pamid_fit_least_squares"]
    rec["pamid_solve"].update(
        converged_fraction=float(converged.mean()), max_steps=int(steps.max())
    )
    rec["pamid_fit_least_squares"].update(converged_fraction=float(fit.converged.mean()))
    rec["fit_vs_solve_max_rel_diff"] = float(np.max(np.abs(fit.theta - theta) / np.abs(theta)))
    for method in ("trf", "lm"):
        th, nfev, ok = outs[f"scipy_least_squares_{method}"]
        rec[f"scipy_least_squares_{method}"].update(
            max_nfev=int(nfev.max()),
            success_fraction=float(ok.mean()),
            check_vs_pamid=compare(theta[:n_fit], th, sub_data),
        )
    best = min(("trf", "lm"), key=lambda m: rec[f"scipy_least_squares_{m}"]["time_s"])
    rec["scipy_least_squares_best_method"] = best
    rec["scipy_least_squares_best_s"] = rec[f"scipy_least_squares_{best}"]["time_s"]
    # Same optimum? (compare() also says which SSE is lower where they differ.)
    rec["check"] = rec[f"scipy_least_squares_{best}"]["check_vs_pamid"]
    rec["scipy_curve_fit"]["check_vs_pamid"] = compare(
        theta[:n_fit], outs["scipy_curve_fit"], sub_data
    )
    return rec, theta, outs[f"scipy_least_squares_{best}"][0]


def bench_solvers(n, data, groups, theta_ref, args):
    """Section 4: every solver at one N (first calls, then interleaved warm rounds)."""
    ref_data = subset(data, len(theta_ref))
    generic0, table0 = np.tile(GENERIC_START, (n, 1)), np.tile(TABLE_3_1, (n, 1))
    configs = {
        "gauss-newton (default; own start)": ("gauss-newton", None),
        "levenberg-marquardt (VP start)": ("levenberg-marquardt", None),
        "variable-projection": ("variable-projection", None),
        "jaxopt-levenberg-marquardt (VP start)": ("jaxopt-levenberg-marquardt", None),
        "previous default: optimistix GN (VP start)": ("optimistix-gauss-newton", "vp"),
        "gauss-newton, generic start (no scan)": ("gauss-newton", generic0),
        "optimistix LM, generic start (no VP)": ("levenberg-marquardt", generic0),
        "optimistix GN, generic start (no VP)": ("optimistix-gauss-newton", generic0),
        "optimistix LM, Table 3-1 start (no VP)": ("levenberg-marquardt", table0),
    }

    def optimistix_gn(theta0):
        # The previous default path: optimistix Gauss–Newton (solve() now sends
        # "gauss-newton" for the Sárosi model to its written-out kernels, which
        # SAROSI_OPTIMISTIX has not), 100 steps, tolerances 1e-10.
        if isinstance(theta0, str):
            theta0 = sarosi_variable_projection_start(data.x, data.y, data.w)
        return solve(SAROSI_OPTIMISTIX, data, solver="gauss-newton", theta0=theta0)

    fns = {
        label: (
            (lambda t=theta0: optimistix_gn(t))
            if solver == "optimistix-gauss-newton"
            else (lambda s=solver, t=theta0: solve(SAROSI, data, solver=s, theta0=t))
        )
        for label, (solver, theta0) in configs.items()
    }
    # The starts on their own: the 24-point variable-projection start (what every VP-start
    # solver pays first) and the default Gauss–Newton's coarse scan on a subsample.
    fns["variable-projection start alone"] = lambda: jax.block_until_ready(
        sarosi_variable_projection_start(data.x, data.y, data.w)
    )
    fns["gauss-newton's start alone"] = lambda: jax.block_until_ready(
        sarosi_fast_start(data.x, data.y, data.w)
    )
    firsts = {label: first_call(fn)[0] for label, fn in fns.items()}
    timings, outs = interleaved(fns, args.repeats)
    out = []
    for label, t in timings.items():
        t.update(firsts[label], label=label)
        if label in configs:
            theta, ok, steps = outs[label]
            t.update(
                solver=configs[label][0],
                converged_fraction=float(ok.mean()),
                max_steps=int(steps.max()),
                median_steps=float(np.median(steps)),
                check_vs_scipy=compare(theta[: len(theta_ref)], theta_ref, ref_data),
            )
        else:
            t["solver"] = "(start only)"
        out.append(t)
    # The CLI's default intervals include the profile likelihood: its cost at this N.
    fn = lambda: pamid.fit_least_squares(data, intervals=("wald", "profile"))  # noqa: E731
    first, _ = first_call(fn)
    timing, _ = interleaved({"p": fn}, max(1, args.repeats // 2))
    timing = timing["p"]
    timing.update(first, label="fit_least_squares + profile intervals", solver="gauss-newton")
    out.append(timing)
    # SciPy from the same generic start, for a like-for-like "no good start" comparison.
    n_fit = min(n, args.scipy_max)
    scipy_fns = {
        m: (lambda m=m: scipy_ls_loop(groups[:n_fit], GENERIC_START, m, args.tol))
        for m in ("trf", "lm")
    }
    scipy_generic, scipy_outs = interleaved(scipy_fns, 1)
    for method, timing in scipy_generic.items():
        th, nfev, ok = scipy_outs[method]
        timing["time_s"] = timing["steady_s"] * n / n_fit
        timing.update(
            max_nfev=int(nfev.max()),
            success_fraction=float(ok.mean()),
            check_vs_scipy_table31_start=compare(th[: len(theta_ref)], theta_ref, ref_data),
        )
    return out, scipy_generic


def run_cmd(cmd, env=None, timeout=None):
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"cmd": cmd, "timed_out": True, "wall_s": time.perf_counter() - t0}
    wall = time.perf_counter() - t0
    rec = {
        "cmd": cmd,
        "rc": proc.returncode,
        "wall_s": wall,
        "timed_out": False,
        "stderr_tail": proc.stderr[-1500:],
    }
    try:
        rec["json"] = json.loads(proc.stdout)
        if isinstance(rec["json"], dict) and "seconds" in rec["json"]:
            # The command's own clock (after imports): load + fit + intervals.
            rec["reported_seconds"] = rec["json"]["seconds"]
    except json.JSONDecodeError:
        rec["json"] = None
        rec["stdout_tail"] = proc.stdout[-500:]
    return rec


def values_of(doc):
    """(muscle ids, theta (M, 6)) from a pamid --json or baseline JSON document."""
    muscles = doc["muscles"]
    theta = np.array([[m["params"][name]["value"] for name in SAROSI.param_names] for m in muscles])
    return [m.get("muscle") for m in muscles], theta


def bench_cli(frame_big, frame_one, n_big, args, tmp):
    """Section 6: end to end, as subprocesses."""
    rec = {"n_muscles": n_big}
    cli = Path(sys.executable).parent / "pamid"
    baseline = [sys.executable, str(HERE / "baseline_curve_fit_script.py")]
    one_csv, big_csv = tmp / "one_muscle.csv", tmp / f"bench_{n_big}.csv"
    frame_one.to_csv(one_csv, index=False)
    t0 = time.perf_counter()
    frame_big.to_csv(big_csv, index=False)
    rec["csv_write_s"] = time.perf_counter() - t0
    rec["csv_rows"] = len(frame_big)
    rec["csv_mb"] = big_csv.stat().st_size / 1e6
    say(f"  wrote {big_csv.name}: {len(frame_big)} rows, {rec['csv_mb']:.0f} MB")

    base = run_cmd(baseline + [str(big_csv)], timeout=args.cli_timeout)
    rec["baseline_big"] = {k: v for k, v in base.items() if k != "json"}
    say(f"  pandas + curve_fit script, {n_big} muscles: {fmt_s(base['wall_s'])}")
    base_one = run_cmd(baseline + [str(one_csv)], timeout=args.cli_timeout)
    rec["baseline_one"] = {k: v for k, v in base_one.items() if k != "json"}

    if not cli.exists():
        rec["skipped"] = f"{cli} does not exist"
        say(f"  SKIPPED pamid CLI: {rec['skipped']}")
        return rec
    env = dict(os.environ)
    cache_one = tmp / "cache_one"
    cache_one.mkdir()
    env["PAMID_CACHE_DIR"] = str(cache_one)
    cold = run_cmd([str(cli), "fit", str(one_csv), "--json"], env=env, timeout=args.cli_timeout)
    if cold.get("json") is None:
        why = (
            "timed out"
            if cold.get("timed_out")
            else (f"exit {cold.get('rc')}: {cold.get('stderr_tail', '').strip()[-300:]}")
        )
        rec["skipped"] = f"`pamid fit FILE --json` gave no JSON ({why})"
        rec["cli_one_cold"] = {k: v for k, v in cold.items() if k != "json"}
        say(f"  SKIPPED pamid CLI: {rec['skipped']}")
        return rec
    rec["cache_files_after_cold"] = sum(1 for p in cache_one.rglob("*") if p.is_file())
    warm = run_cmd([str(cli), "fit", str(one_csv), "--json"], env=env, timeout=args.cli_timeout)
    wald = run_cmd(
        [str(cli), "fit", str(one_csv), "--json", "--intervals", "wald"],
        env=env,
        timeout=args.cli_timeout,
    )
    rec["cli_one_cold"] = {k: v for k, v in cold.items() if k != "json"}
    rec["cli_one_warm"] = {k: v for k, v in warm.items() if k != "json"}
    rec["cli_one_warm_wald_only"] = {k: v for k, v in wald.items() if k != "json"}
    say(
        f"  pamid fit, 1 muscle: cold cache {fmt_s(cold['wall_s'])}, "
        f"warm cache {fmt_s(warm['wall_s'])} ({rec['cache_files_after_cold']} cache files), "
        f"warm with --intervals wald {fmt_s(wald['wall_s'])}"
    )

    cache_big = tmp / "cache_big"
    cache_big.mkdir()
    env["PAMID_CACHE_DIR"] = str(cache_big)
    runs = [("cli_big_cold", [])]
    big = None
    for name, extra in runs:
        big = run_cmd(
            [str(cli), "fit", str(big_csv), "--json", *extra], env=env, timeout=args.cli_timeout
        )
        rec[name] = {k: v for k, v in big.items() if k != "json"}
        state = "TIMED OUT after " if big.get("timed_out") else ""
        say(f"  pamid fit, {n_big} muscles ({name}): {state}{fmt_s(big['wall_s'])}")
        if big.get("json") is not None and base.get("json") is not None:
            ids_cli, th_cli = values_of(big["json"])
            ids_base, th_base = values_of(base["json"])
            if ids_cli == ids_base:
                rel = np.abs(th_cli - th_base) / np.abs(th_base)
                rec[name]["max_rel_diff_vs_curve_fit_script"] = float(np.max(rel))
        if (
            name == "cli_big_cold"
            and not big.get("timed_out")
            and big["wall_s"] < args.cli_timeout / 3
        ):
            runs.append(("cli_big_warm", []))
    return rec


# --------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=None,
        help="numbers of muscles (default 1 100 1000 10000; --quick: 1 100 1000)",
    )
    parser.add_argument("--quick", action="store_true", help="N up to 1000, fewer repeats")
    parser.add_argument("--json", metavar="PATH", help="also write all numbers as JSON")
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="warm calls per pamid measurement (default 5, --quick 3)",
    )
    parser.add_argument(
        "--scipy-max",
        type=int,
        default=1000,
        help="largest SciPy loop actually run; larger N are extrapolated",
    )
    parser.add_argument(
        "--scipy-repeats-small",
        type=int,
        default=None,
        help="repeats of small SciPy loops (default 15, --quick 5)",
    )
    parser.add_argument(
        "--tol",
        type=float,
        default=1e-12,
        help="ftol = xtol = gtol of scipy.optimize.least_squares",
    )
    parser.add_argument(
        "--solver-n", type=int, default=TARGET_N, help="N of the solver comparison (section 4)"
    )
    parser.add_argument("--skip-solvers", action="store_true")
    parser.add_argument("--skip-cli", action="store_true")
    parser.add_argument(
        "--cli-timeout",
        type=float,
        default=None,
        help="seconds per CLI subprocess (default 300, --quick 180)",
    )
    args = parser.parse_args(argv)
    if args.sizes is None:
        args.sizes = [1, 100, 1000] if args.quick else [1, 100, 1000, 10000]
    args.sizes = sorted(set(args.sizes))
    if args.repeats is None:
        args.repeats = 3 if args.quick else 5
    if args.scipy_repeats_small is None:
        args.scipy_repeats_small = 5 if args.quick else 15
    if args.cli_timeout is None:
        args.cli_timeout = 180.0 if args.quick else 300.0

    t_start = time.perf_counter()
    results = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "argv": sys.argv[1:],
        "machine": {
            "platform": platform.platform(),
            "cpu_count": os.cpu_count(),
            "jax_backend": jax.default_backend(),
            "jax_devices": [str(d) for d in jax.devices()],
            "loadavg_start": os.getloadavg(),
        },
        "pamid_revision": _revision(),
        "versions": {
            "python": platform.python_version(),
            "jax": jax.__version__,
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "pamid": pamid.__version__,
        },
        "settings": {
            "sizes": args.sizes,
            "repeats": args.repeats,
            "scipy_max": args.scipy_max,
            "scipy_tol": args.tol,
            "scipy_start": "Table 3-1 constants",
            "generic_start": GENERIC_START.tolist(),
            "protocol": {
                "pressures_kPa": PROTOCOL.pressures_kPa,
                "points_per_curve": PROTOCOL.points_per_curve,
                "repeats_averaged": PROTOCOL.repeats,
                "noise_sd_N": PROTOCOL.noise_sd_N,
                "min_force_N": PROTOCOL.min_force_N,
            },
        },
        "sizes": {},
    }
    say(f"pamid batched-fit benchmark — {results['date']}")
    say(
        f"{platform.platform()}; {os.cpu_count()} CPUs; JAX {jax.__version__} "
        f"({jax.default_backend()}), NumPy {np.__version__}, SciPy {scipy.__version__}; "
        f"load average at start {os.getloadavg()[0]:.2f}"
    )
    say(f"pamid {pamid.__version__} at {results['pamid_revision']}")
    say(
        "Timings are wall clock. pamid 'first' = first call after jax.clear_caches(); "
        "'steady' (and every SciPy time) = median of warm runs, all contenders interleaved "
        "round by round."
    )

    # ---- 1. data ----
    say("\n1. Data (virtual bench, Sárosi protocol, 300 samples per muscle)")
    datasets = {}
    for n in sorted(set(args.sizes) | ({args.solver_n} if not args.skip_solvers else set())):
        t0 = time.perf_counter()
        frame, groups, data, thetas, pack_s = make_data(n)
        gen_s = time.perf_counter() - t0 - pack_s
        datasets[n] = (frame, groups, data)
        results["sizes"].setdefault(str(n), {})["data"] = {
            "simulate_s": gen_s,
            "groupby_pack_s": pack_s,
            "rows": len(frame),
            "samples_per_muscle": int(np.asarray(data.w).sum(axis=1).max()),
        }
        say(f"  N={n}: {len(frame)} rows; simulate {fmt_s(gen_s)}, groupby+pack {fmt_s(pack_s)}")

    # ---- 2, 3. timings and check ----
    say("\n2./3. Fit time and check against SciPy")
    thetas_ref = {}
    for n in args.sizes:
        frame, groups, data = datasets[n]
        rec, theta, theta_ref = bench_size(n, data, groups, args)
        results["sizes"][str(n)].update(rec)
        thetas_ref[n] = theta_ref
        say(
            f"  N={n}: pamid solve steady {fmt_s(rec['pamid_solve']['steady_s'])}, "
            f"SciPy least_squares ({rec['scipy_least_squares_best_method']}) "
            f"{fmt_s(rec['scipy_least_squares_best_s'], rec['scipy_extrapolated'])}"
        )

    rows = []
    for n in args.sizes:
        r = results["sizes"][str(n)]
        star = r["scipy_extrapolated"]
        rows.append(
            [
                n,
                fmt_s(r["pamid_solve"]["first_s"]),
                fmt_s(r["pamid_solve"]["steady_s"]),
                fmt_s(r["pamid_fit_least_squares"]["first_s"]),
                fmt_s(r["pamid_fit_least_squares"]["steady_s"]),
                fmt_s(r["scipy_least_squares_trf"]["time_s"], star),
                fmt_s(r["scipy_least_squares_lm"]["time_s"], star),
                fmt_s(r["scipy_curve_fit"]["time_s"], star),
            ]
        )
    say("\nFit time (pamid: first call = trace + compile + run; steady = median warm call)")
    say(
        table(
            [
                "N",
                "solve first",
                "solve steady",
                "fit_ls first",
                "fit_ls steady",
                "SciPy LS trf",
                "SciPy LS lm",
                "curve_fit",
            ],
            rows,
        )
    )
    if any(results["sizes"][str(n)]["scipy_extrapolated"] for n in args.sizes):
        say(
            f"  * SciPy measured on the first {args.scipy_max} muscles and extrapolated "
            "linearly to N."
        )
    say(
        "  SciPy LS = scipy.optimize.least_squares, analytic Jacobian, x_scale='jac', "
        f"ftol=xtol=gtol={args.tol:g}; curve_fit = default settings (numerical Jacobian)."
    )
    say(
        "  SciPy start: Table 3-1 constants (every muscle is Table 3-1 ± 3 %: a near-optimal "
        "start); pamid: its own start (a coarse variable-projection scan), no user guess."
    )

    rows = []
    for n in args.sizes:
        r = results["sizes"][str(n)]
        ls_best = r["scipy_least_squares_best_s"]
        cf = r["scipy_curve_fit"]["time_s"]
        solve_s = r["pamid_solve"]["steady_s"]
        fit_s = r["pamid_fit_least_squares"]["steady_s"]
        best_rec = r[f"scipy_least_squares_{r['scipy_least_squares_best_method']}"]
        ls_cpu = best_rec["steady_cpu_s"] * n / r["scipy_subset"]
        r["ratios"] = {
            "ls_over_solve": ls_best / solve_s,
            "ls_over_fit": ls_best / fit_s,
            "cf_over_solve": cf / solve_s,
            "cf_over_fit": cf / fit_s,
            "ls_over_solve_first": ls_best / r["pamid_solve"]["first_s"],
            "ls_over_solve_cpu_time": ls_cpu / r["pamid_solve"]["steady_cpu_s"],
        }
        rows.append(
            [
                n,
                f"LS {r['scipy_least_squares_best_method']}",
                fmt_x(r["ratios"]["ls_over_solve"]),
                fmt_x(r["ratios"]["ls_over_fit"]),
                fmt_x(r["ratios"]["cf_over_solve"]),
                fmt_x(r["ratios"]["cf_over_fit"]),
                fmt_x(r["ratios"]["ls_over_solve_first"]),
                fmt_x(r["ratios"]["ls_over_solve_cpu_time"]),
            ]
        )
    say("\n5. Speed-up = SciPy time / pamid time (steady state; > 1 means pamid is faster)")
    say(
        table(
            [
                "N",
                "SciPy baseline",
                "LS/solve",
                "LS/fit_ls",
                "curve_fit/solve",
                "curve_fit/fit_ls",
                "LS/solve first call",
                "LS/solve CPU time",
            ],
            rows,
        )
    )
    say(
        "  CPU time = process CPU seconds (all threads), less sensitive than wall time to "
        "other processes on the machine."
    )

    rows = []
    for n in args.sizes:
        r = results["sizes"][str(n)]
        c = r["check"]
        cf = r["scipy_curve_fit"]["check_vs_pamid"]
        rows.append(
            [
                n,
                c["n_muscles"],
                f"{c['max_rel_diff']:.1e}",
                f"{c['max_abs_rel_sse_diff']:.1e}",
                f"{c['n_differ_1e-6']} ({c['n_differ_lower_sse_here']} pamid lower, "
                f"{c['n_differ_lower_sse_ref']} SciPy lower)",
                f"{r['pamid_solve']['converged_fraction']:.3f}",
                f"{cf['max_rel_diff']:.1e}",
            ]
        )
    say("\n3. Same optimum? pamid solve vs SciPy least_squares (analytic J), per muscle")
    say(
        table(
            [
                "N",
                "muscles",
                "max rel diff",
                "max |ΔSSE|/SSE",
                "muscles > 1e-6",
                "pamid converged",
                "curve_fit max rel diff",
            ],
            rows,
        )
    )

    # ---- 4. solvers ----
    if not args.skip_solvers:
        n = args.solver_n
        say(f"\n4. Solvers at N={n}")
        frame, groups, data = datasets[n]
        if n in thetas_ref:
            ref_method = results["sizes"][str(n)]["scipy_least_squares_best_method"]
        else:
            n_fit = min(n, args.scipy_max)
            ref_method = "trf"
            thetas_ref[n] = scipy_ls_loop(groups[:n_fit], TABLE_3_1, "trf", args.tol)[0]
        solver_recs, scipy_generic = bench_solvers(n, data, groups, thetas_ref[n], args)
        results["solvers"] = {
            "n_muscles": n,
            "reference": f"scipy least_squares {ref_method}, Table 3-1 start",
            "pamid": solver_recs,
            "scipy_generic_start": scipy_generic,
        }
        rows = []
        for s in solver_recs:
            chk = s.get("check_vs_scipy")
            rows.append(
                [
                    s["label"],
                    fmt_s(s["first_s"]),
                    fmt_s(s["steady_s"]),
                    s.get("max_steps", "—"),
                    f"{s['converged_fraction']:.3f}" if "converged_fraction" in s else "—",
                    f"{chk['max_rel_diff']:.1e}" if chk else "—",
                    f"{chk['max_rel_sse_excess']:+.1e}" if chk else "—",
                ]
            )
        for method, s in scipy_generic.items():
            chk = s["check_vs_scipy_table31_start"]
            rows.append(
                [
                    f"SciPy least_squares {method}, generic start",
                    "—",
                    fmt_s(s["time_s"], s["time_s"] != s["steady_s"]),
                    f"{s['max_nfev']} nfev",
                    f"{s['success_fraction']:.3f}",
                    f"{chk['max_rel_diff']:.1e}",
                    f"{chk['max_rel_sse_excess']:+.1e}",
                ]
            )
        say(
            table(
                [
                    "solver",
                    "first call",
                    "steady",
                    "max steps",
                    "converged",
                    "max rel diff",
                    "max SSE excess",
                ],
                rows,
            )
        )
        say(
            f"  generic start = {GENERIC_START.tolist()}; 'max rel diff' and 'SSE excess' are "
            f"against SciPy least_squares {ref_method} from Table 3-1 (SSE excess > 0: worse "
            "optimum)."
        )
        timed = [
            s
            for s in solver_recs
            if s["label"].endswith("(VP start)")
            or s["solver"] == "variable-projection"
            or s["label"].startswith("gauss-newton (default")
        ]
        ok = [
            s
            for s in timed
            if s["converged_fraction"] == 1.0 and s["check_vs_scipy"]["all_within_1e-6"]
        ]
        if ok:
            fastest = min(ok, key=lambda s: s["steady_s"])
            results["solvers"]["fastest_accurate"] = fastest["label"]
            say(
                f"  fastest pamid solver that converges on every muscle to the SciPy optimum "
                f"(1e-6): {fastest['label']} ({fmt_s(fastest['steady_s'])})"
            )

    # ---- 5. target ----
    if TARGET_N in args.sizes:
        r = results["sizes"][str(TARGET_N)]
        ratio = r["ratios"]["ls_over_solve"]
        ratio_fit = r["ratios"]["ls_over_fit"]
        met = ratio >= TARGET_RATIO
        results["target"] = {
            "n": TARGET_N,
            "required": TARGET_RATIO,
            "ratio_solve": ratio,
            "ratio_fit_least_squares": ratio_fit,
            "met": bool(met),
        }
        say(
            f"\nTARGET (N={TARGET_N}, steady state, ≥ {TARGET_RATIO:.0f}× faster than the "
            f"analytic-Jacobian SciPy loop): {'MET' if met else 'NOT MET'} — "
            f"solve {fmt_x(ratio)}, fit_least_squares {fmt_x(ratio_fit)}"
        )
    if TARGET7_N in args.sizes:
        r = results["sizes"][str(TARGET7_N)]
        t_solve = r["pamid_solve"]["steady_s"]
        ratio = r["ratios"]["ls_over_solve"]
        met = t_solve <= TARGET7_S and ratio >= TARGET7_RATIO
        results["target_issue7"] = {
            "n": TARGET7_N,
            "required_s": TARGET7_S,
            "required_ratio": TARGET7_RATIO,
            "solve_s": t_solve,
            "fit_least_squares_s": r["pamid_fit_least_squares"]["steady_s"],
            "ratio_solve": ratio,
            "met": bool(met),
        }
        say(
            f"TARGET issue #7 (N={TARGET7_N}, steady state, ≤ {TARGET7_S:g} s and ≥ "
            f"{TARGET7_RATIO:.0f}× the SciPy loop): {'MET' if met else 'NOT MET'} — solve "
            f"{fmt_s(t_solve)} ({fmt_x(ratio)}), fit_least_squares "
            f"{fmt_s(r['pamid_fit_least_squares']['steady_s'])}"
        )

    # ---- 6. end to end ----
    if not args.skip_cli:
        n_big = max(args.sizes)
        say(f"\n6. End to end (subprocesses; CSV with {n_big} muscles)")
        tmp = Path(tempfile.mkdtemp(prefix="pamid-bench-"))
        try:
            one_frame = datasets[min(args.sizes)][0]
            one_frame = one_frame[one_frame["muscle"] == one_frame["muscle"].iloc[0]]
            cli = bench_cli(datasets[n_big][0], one_frame, n_big, args, tmp)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        results["end_to_end"] = cli

        def own(c):
            return fmt_s(c["reported_seconds"]) if "reported_seconds" in c else "—"

        rows = []
        for name, label in (
            ("baseline_big", f"pandas + curve_fit script, {n_big} muscles"),
            ("baseline_one", "pandas + curve_fit script, 1 muscle"),
            ("cli_big_cold", f"pamid fit --json, {n_big} muscles, cold cache"),
            ("cli_big_warm", f"pamid fit --json, {n_big} muscles, warm cache"),
            ("cli_one_cold", "pamid fit --json, 1 muscle, cold cache"),
            ("cli_one_warm", "pamid fit --json, 1 muscle, warm cache"),
            ("cli_one_warm_wald_only", "pamid fit --json --intervals wald, 1 muscle, warm"),
        ):
            if name in cli:
                c = cli[name]
                wall = ("> " if c.get("timed_out") else "") + fmt_s(c["wall_s"])
                rows.append([label, wall, own(c), "—" if c.get("timed_out") else c.get("rc")])
        if "skipped" in cli:
            say(f"  pamid CLI skipped: {cli['skipped']}")
        else:
            base = cli["baseline_big"]["wall_s"]
            for name in ("cli_big_cold", "cli_big_warm"):
                if name in cli and not cli[name].get("timed_out"):
                    cli[name]["speedup_vs_curve_fit_script"] = base / cli[name]["wall_s"]
        say(table(["end to end", "wall", "own clock", "exit"], rows))
        say("  own clock = the 'seconds' each program reports in its JSON (after its imports).")
        for name in ("cli_big_cold", "cli_big_warm"):
            if name in cli and "speedup_vs_curve_fit_script" in cli[name]:
                diff = cli[name].get("max_rel_diff_vs_curve_fit_script")
                say(
                    f"  {name}: {fmt_x(cli[name]['speedup_vs_curve_fit_script'])} vs the "
                    "curve_fit script"
                    + (f"; max rel diff of the constants {diff:.1e}" if diff is not None else "")
                )

    results["machine"]["loadavg_end"] = os.getloadavg()
    results["total_s"] = time.perf_counter() - t_start
    say(
        f"\nTotal benchmark time {fmt_s(results['total_s'])}; load average at end "
        f"{os.getloadavg()[0]:.2f}."
    )
    if args.json:
        write_text_atomic(args.json, json.dumps(results, indent=2, default=_jsonable) + "\n")
        say(f"Wrote {args.json}")
    return 0


def _revision() -> str:
    """The git commit of the checkout, with "+dirty" when pamid/ has uncommitted changes."""
    root = HERE.parent
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "pamid"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown revision"
    return f"git {head}" + (" +dirty (uncommitted changes under pamid/)" if dirty else "")


def _jsonable(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(type(obj))


if __name__ == "__main__":
    raise SystemExit(main())
