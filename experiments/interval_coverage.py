#!/usr/bin/env python
"""Coverage of pamid's 95 % intervals when the residuals are correlated.

Virtual files of realistic designs — Sárosi's sweeps (:class:`pamid.SarosiProtocol`, 5
pressures × 2 directions × 30 points, 10 curves) and AARL-like isometric stairs
(:func:`pamid.virtual_lab_file`, 4 levels × 3 trials, 24 curves) — are simulated without
noise; the truth is Sárosi's Table 3-1 for the Sárosi model and, for Cullinan's eq. 3, the
Cullinan constants closest to that force map (their predictions are the true force).
Noise is then added per replicate muscle, independent between curves:

* ``ar0``, ``ar0.5``, ``ar0.8``: a stationary AR(1) inside every curve, φ = 0, 0.5, 0.8,
  standard deviation σ (2 N sweeps, 3 N isometric);
* ``smooth``: a misfit-like residual, a random smooth curve per curve (cosines of 0–3
  half-periods over the curve, total sd σ) plus white noise of σ/2.

Every setting's replicate muscles are fitted in one batched call, and every interval is
computed for all of them at once: Wald (t, n − p), HAC within trials (Bartlett, Andrews'
AR(1) bandwidth, and 2× and 4× it), HAC within curves, cluster-robust CR1 / CR2 / CR3 by
curve (t, G − 1), CR2 / CR3 by trial (isometric), and the whole-curve bootstrap
(percentile; on the first ``--boot-muscles`` replicates). Coverage = share of converged
replicates whose interval holds the true constant, averaged over the constants (and the
worst constant). Where the real AARL 10 mm file is present (``--real``), pamid's fit with
its cluster and HAC intervals is run on it too: the residual's lag-1 autocorrelation and
the widths of those intervals against Wald's.

    .venv/bin/python experiments/interval_coverage.py [--n-muscles 1000] [--quick]

Results (table and command) in experiments/README.md, section 7.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pamid  # noqa: E402
from pamid import FitData  # noqa: E402
from pamid import engine as eng  # noqa: E402
from pamid.engine import find_curves, get_model, solve, statistics  # noqa: E402
from pamid.io import write_text_atomic  # noqa: E402
from pamid.sarosi import table_3_1  # noqa: E402

jax.config.update("jax_enable_x64", True)

NOISES = ("ar0", "ar0.5", "ar0.8", "smooth")
DESIGNS = ("sweeps", "isometric")
MODELS = ("sarosi", "cullinan")
HAC_MULTIPLIERS = (2.0, 4.0)  # Andrews' bandwidth times these, to choose the bandwidth
SIGMA_N = {"sweeps": 2.0, "isometric": 3.0}


def design_frame(design: str, rows: int):
    """A noise-free file of one muscle (truth: Table 3-1) and its curve structure."""
    key = jax.random.key(7)
    if design == "sweeps":
        frame = pamid.simulate_sarosi_bench(
            key, table_3_1(),
            pamid.SarosiProtocol(noise_sd_N=0.0, force_resolution_N=0.0,
                                 length_resolution_mm=0.0))
    else:
        frame = pamid.virtual_lab_file(
            key, "isometric_stairs", rows, force_noise_N=0.0, pressure_noise_kPa=0.0,
            contraction_noise_pct=0.0, transient_N_per_kPa=0.0, hysteresis_N_at_3_bar=0.0,
            pressure_offset_kPa=0.0, force_resolution_N=0.0, pressure_resolution_kPa=0.0,
            length_resolution_mm=0.0)
    frame = frame.copy()
    frame["contraction_mm"] = frame["l0_mm"] - frame["length_mm"]
    curves = find_curves(frame)
    return frame, curves


def truth(model: str, frame):
    """(spec, x, true θ, true force) for one muscle."""
    spec = get_model(model)
    x = spec.x_from_frame(frame)
    if model == "sarosi":
        theta = np.asarray(table_3_1().to_vector(), float)
    else:  # the Cullinan constants closest to the Sárosi force map
        one = FitData(x=tuple(jnp.asarray(a)[None] for a in x),
                      y=jnp.asarray(frame["force_N"].to_numpy(float))[None],
                      w=jnp.ones((1, len(frame))), curve=jnp.zeros((1, len(frame)), int))
        theta = solve(spec, one)[0][0]
    y = np.asarray(spec.predict(jnp.asarray(theta), tuple(jnp.asarray(a) for a in x)))
    return spec, x, theta, y


def noise(key, kind: str, curve: np.ndarray, m: int, sigma: float) -> np.ndarray:
    """(m, n) noise, independent between curves (rows of a curve are contiguous)."""
    if kind.startswith("ar"):
        return eng.ar1_noise(key, curve, m, sigma, float(kind[2:]))
    # smooth: Σ_k c_k cos(π k u) per curve, u the position within the curve (0 … 1)
    n = len(curve)
    start = np.r_[True, curve[1:] != curve[:-1]]
    ids = np.cumsum(start) - 1
    first = np.flatnonzero(start)
    length = np.diff(np.r_[first, n])
    u = (np.arange(n) - first[ids]) / np.maximum(length[ids] - 1, 1)
    k1, k2 = jax.random.split(key)
    coef = np.asarray(jax.random.normal(k1, (m, len(first), 4))) * sigma / 2.0  # sd σ
    basis = np.cos(np.pi * np.arange(4) * u[:, None])  # (n, 4)
    smooth = np.einsum("mnk,nk->mn", coef[:, ids, :], basis)
    return smooth + 0.5 * sigma * np.asarray(jax.random.normal(k2, (m, n)))


def coverage(lower, upper, theta_true, ok):
    hit = (lower <= theta_true) & (theta_true <= upper)
    hit = hit[ok]
    per = hit.mean(axis=0)
    return float(per.mean()), float(per.min()), int(ok.sum())


def run_setting(design, model, kind, m, n_boot, boot_m, seed, cache):
    frame, curves = cache[design]
    spec, x, theta_true, y_true = truth(model, frame)
    curve = curves.curve
    trial = curves.trial
    n = len(frame)
    y = y_true[None] + noise(jax.random.key(seed), kind, curve, m, SIGMA_N[design])
    data = FitData(x=tuple(jnp.asarray(np.broadcast_to(a, (m, n))) for a in x),
                   y=jnp.asarray(y), w=jnp.ones((m, n)),
                   curve=jnp.asarray(np.broadcast_to(curve, (m, n))))
    t0 = time.perf_counter()
    theta, conv, _ = solve(spec, data)
    sse, jtj_inv, _, n_rows, full = statistics(spec, theta, data)
    ok = np.asarray(conv) & np.asarray(full)
    res = {}
    _, lo, hi, _, _ = eng.wald_intervals(theta, jtj_inv, sse, n_rows)
    res["wald"] = coverage(lo, hi, theta_true, ok)
    jac_r = eng.jacobian_residuals(spec, theta, data)
    trials = np.broadcast_to(trial, (m, n))
    curves_b = np.broadcast_to(curve, (m, n))
    rho, _, _ = eng.lag1_autocorrelation(jac_r[1], curves_b)
    hac = eng.correlated_intervals(spec, data, theta, "hac", trials, jac_r=jac_r)
    res["hac_trial"] = coverage(hac["lower"], hac["upper"], theta_true, ok)
    bandwidth = float(np.median(hac["bandwidth"]))
    s_x = hac["bandwidth"]
    for mult in HAC_MULTIPLIERS:
        cov, _ = eng.hac_covariance(*jac_r, trials, bandwidth=mult * s_x)
        _, lo_m, hi_m = eng.sandwich_intervals(theta, cov, hac["dof"])
        res[f"hac_trial_x{mult:g}"] = coverage(lo_m, hi_m, theta_true, ok)
    hac_c = eng.correlated_intervals(spec, data, theta, "hac", curves_b, jac_r=jac_r)
    res["hac_curve"] = coverage(hac_c["lower"], hac_c["upper"], theta_true, ok)
    for k in eng.CLUSTER_KINDS:
        out = eng.correlated_intervals(spec, data, theta, "cluster", curves_b, kind=k,
                                       jac_r=jac_r)
        res[f"{k}_curve"] = coverage(out["lower"], out["upper"], theta_true, ok)
    if trial.max() > 1:
        for k in ("CR2", "CR3"):
            out = eng.correlated_intervals(spec, data, theta, "cluster", trials, kind=k,
                                           jac_r=jac_r)
            res[f"{k}_trial"] = coverage(out["lower"], out["upper"], theta_true, ok)
    if n_boot:
        sub = FitData(*(tuple(a[:boot_m] for a in f) if isinstance(f, tuple) else f[:boot_m]
                        for f in data))
        blo, bhi, _, _ = eng.bootstrap_intervals(spec, sub, theta[:boot_m],
                                                 jax.random.key(seed), n_boot)
        res["bootstrap"] = coverage(blo, bhi, theta_true, ok[:boot_m])
    return {
        "design": design, "model": model, "noise": kind, "rows": n,
        "curves": int(curve.max() + 1), "trials": int(trial.max() + 1),
        "lag1_residual": float(np.median(rho)), "hac_bandwidth_median": bandwidth,
        "coverage": res, "seconds": time.perf_counter() - t0,
    }


def real_file(path: Path) -> dict | None:
    """On the real AARL 10 mm file (if present): Sárosi per muscle, the residual's lag-1
    autocorrelation within curves and the widths of the honest intervals against Wald's."""
    if not path.exists():
        print(f"{path} not found: the real-file check is skipped")
        return None
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bench = pamid.load_bench(path)
    fit = pamid.fit_least_squares(bench, "sarosi", intervals=("wald", "cluster", "hac"))
    wald = np.diff(fit.ci95, axis=-1)[..., 0]
    out = {"muscles": list(fit.muscles), "rows": fit.n.tolist(),
           "lag1_residual": fit.residual_lag1.round(3).tolist(),
           "curves": fit.cluster_groups.tolist(),
           "hac_bandwidth": fit.hac_bandwidth.round(1).tolist()}
    for kind in ("cluster", "hac"):
        width = np.diff(getattr(fit, f"ci95_{kind}"), axis=-1)[..., 0]
        out[f"width_ratio_{kind}_median"] = np.median(width / wald, axis=1).round(2).tolist()
    print("real file", path.name)
    for key, values in out.items():
        print(f"  {key}: {values}")
    print(f"  note of the first muscle: {fit.interval_notes[0]}")
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n-muscles", type=int, default=1000)
    parser.add_argument("--n-boot", type=int, default=200)
    parser.add_argument("--boot-muscles", type=int, default=300)
    parser.add_argument("--isometric-rows", type=int, default=1200)
    parser.add_argument("--designs", default=",".join(DESIGNS))
    parser.add_argument("--models", default=",".join(MODELS))
    parser.add_argument("--noises", default=",".join(NOISES))
    parser.add_argument("--real", type=Path, default=Path(__file__).resolve().parents[2]
                        / "shared" / "data" / "aarl_festo10mm_isometric.csv",
                        help="the real AARL 10 mm file (skipped where absent)")
    parser.add_argument("--quick", action="store_true", help="200 muscles, 50 bootstrap draws")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).resolve().parent / "out" / "interval_coverage")
    args = parser.parse_args(argv)
    if args.quick:
        args.n_muscles, args.n_boot, args.boot_muscles = 200, 50, 100
    cache = {d: design_frame(d, args.isometric_rows) for d in args.designs.split(",")}
    rows = []
    seed = 0
    for design in args.designs.split(","):
        for model in args.models.split(","):
            for kind in args.noises.split(","):
                seed += 1
                r = run_setting(design, model, kind, args.n_muscles, args.n_boot,
                                min(args.boot_muscles, args.n_muscles), seed, cache)
                rows.append(r)
                cov = "  ".join(f"{k} {v[0]:.3f}/{v[1]:.3f}" for k, v in r["coverage"].items())
                print(f"{design:9s} {model:8s} {kind:6s} n={r['rows']} G={r['curves']} "
                      f"lag1={r['lag1_residual']:+.2f} S={r['hac_bandwidth_median']:.1f} "
                      f"({r['seconds']:.0f} s)\n    {cov}", flush=True)
    real = real_file(args.real)
    args.out.mkdir(parents=True, exist_ok=True)
    result = {"command": " ".join(["experiments/interval_coverage.py", *sys.argv[1:]]),
              "n_muscles": args.n_muscles, "n_boot": args.n_boot,
              "boot_muscles": args.boot_muscles, "settings": rows, "real_file": real}
    write_text_atomic(args.out / "interval_coverage.json", json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out / 'interval_coverage.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
