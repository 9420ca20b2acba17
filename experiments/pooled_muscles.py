#!/usr/bin/env python
"""Predicting a muscle nobody has tested (issue #31): pooled models on the measured files.

1. The AARL 10 mm file (``../shared/data/aarl_festo10mm_isometric.csv``: six cut-tube
   muscles, l0 = 83–382 mm, their lengths at 620 kPa logged): every pooled model of
   ``pamid.compare_pooled`` (Sárosi eq. 2.1 with one set of constants, constants smooth in
   ln l0, the nearest tested length's constants; the Bolen et al. 2026 normalized law fitted
   and at the Hunt lab code's 10 mm coefficients), each muscle predicted from the other
   five: LOMO RMSE per muscle and overall, and the share of the held-out muscle's rows
   inside its 95 % predictive interval (calibrated on the other muscles).
2. The Martens & Boblan DMSP-10-250 map (``../shared/data/martens_dmsp10_250.csv``: one
   catalogue muscle, 250 mm, with fittings; one muscle, so no LOMO of its own): predicted by
   each AARL pooled model from l0 = 250 mm alone (ε_max from the AARL muscles' line in
   ln l0): RMSE and coverage of its 40 uncensored points. Cut tube against a catalogue
   muscle: a test of how far a pooled law carries, not an expected match.

3. ``--coverage R``: R virtual populations of the Bolen law (8 tested muscles of
   l0 = 80–400 mm, each muscle's force × exp(0.05·z), 3 N noise; 4 new muscles of each, of
   lengths log-uniform in 90–380 mm): the share of the new muscles' rows inside the 95 %
   interval of the least-squares pooled fit and of the hierarchical Bayesian fit (all R
   populations sampled as stacked ensembles in one call). No measured file needed.

    .venv/bin/python experiments/pooled_muscles.py [--out DIR] [--quick] [--bayes]
    .venv/bin/python experiments/pooled_muscles.py --coverage 30

``--quick``: every 10th row of the AARL file; ``--bayes``: also the hierarchical Bayesian
Bolen law on the AARL file. Prints "skipped: file absent" and exits 0 when the AARL file is
absent.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
import pandas as pd

import pamid
import pamid.engine
import pamid.report

ROOT = Path(__file__).resolve().parents[1]
AARL = ROOT.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
MARTENS = ROOT.parent / "shared" / "data" / "martens_dmsp10_250.csv"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bayes", action="store_true")
    ap.add_argument("--coverage", type=int, default=0, metavar="R")
    args = ap.parse_args(argv)
    if args.coverage:
        return _coverage(args.coverage)
    if not AARL.is_file():
        print("skipped: file absent")
        return 0
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = AARL
        if args.quick:
            path = Path(tmp) / "aarl_every_10th.csv"
            pd.read_csv(AARL).iloc[::10].to_csv(path, index=False)
        bench = pamid.load_bench(path)
        bayes = jax.random.key(0) if args.bayes else None
        result = pamid.compare_pooled(bench, bayes=bayes, progress=lambda m: print(
            f"[{time.perf_counter() - t0:6.1f} s] {m}", file=sys.stderr))
    print(pamid.report.pooled_table(result))
    payload = result.to_dict()
    martens = _martens(payload) if MARTENS.is_file() else None
    if martens is not None:
        print("\nThe DMSP-10-250 map (Martens & Boblan 2017) predicted from the AARL muscles "
              "(l0 = 250 mm):")
        print(f"{'model':<22} {'RMSE [N]':>9} {'inside 95 %':>12} {'n':>4}")
        for row in martens:
            print(f"{row['model']:<22} {row['rmse_N']:>9.3g} {100 * row['coverage_95']:>11.3g}% "
                  f"{row['n']:>4}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        pamid.report.plot_pooled_lomo(result, args.out / "pooled_lomo.png")
        best = pamid.predict_muscle(payload["pooled"][0], l0_mm=350.0)
        pamid.report.plot_prediction(best, args.out / "predicted_350mm.png")
        (args.out / "pooled.json").write_text(json.dumps(
            payload | {"martens": martens}, indent=2) + "\n")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


def _martens(payload) -> list[dict]:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pamid.CensoredRowsWarning)
        frame = pamid.load_bench(MARTENS, l0_mm=250.0).frame
    y = frame["force_N"].to_numpy()
    out = []
    for entry in payload["pooled"]:
        pred = pamid.predict_muscle(entry, l0_mm=250.0, descriptors={"diameter_mm": 10.0},
                                    pressure_kPa=frame["pressure_kPa"].to_numpy(),
                                    contraction_pct=frame["contraction_pct"].to_numpy(),
                                    points=True)
        out.append({"model": entry["model"],
                    "rmse_N": float(np.sqrt(np.mean((pred.force_N - y) ** 2))),
                    "coverage_95": float(np.mean((y >= pred.low_N) & (y <= pred.high_N))),
                    "n": int(y.size)})
    return out


def _coverage(n_populations: int) -> int:
    t0 = time.perf_counter()
    names = ("a_N", "b_per_m", "a0", "a1", "a3")
    lower = np.array([pamid.Bolen2026.bounds[n][0] for n in names])
    upper = np.array([pamid.Bolen2026.bounds[n][1] for n in names])
    l0_train = np.geomspace(80.0, 400.0, 8)
    rng = np.random.default_rng(7)
    ls_inside, data, new, entries = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(n_populations):
            l0_new = np.exp(rng.uniform(np.log(90.0), np.log(380.0), 4))
            frame = pamid.simulate_population_bench(jax.random.key(1000 + r),
                                                    (*l0_train, *l0_new), spread=0.05,
                                                    noise_N=3.0)
            muscles = sorted(frame["muscle"].unique())
            train = frame[frame["muscle"].isin(muscles[:8])]
            path = Path(tmp) / "train.csv"
            train.to_csv(path, index=False)
            entry = pamid.compare_pooled(pamid.load_bench(path), kinds=()).model(
                "bolen2026").to_dict()
            entries.append(entry)
            held = frame[frame["muscle"].isin(muscles[8:])]
            new.append(held)
            for _, rows in held.groupby("muscle"):
                pred = pamid.predict_muscle(entry, l0_mm=rows["l0_mm"].iloc[0],
                                            pressure_kPa=rows["pressure_kPa"].to_numpy(),
                                            contraction_pct=rows["contraction_pct"].to_numpy(),
                                            points=True)
                y = rows["force_N"].to_numpy()
                ls_inside.append(np.mean((y >= pred.low_N) & (y <= pred.high_N)))
            code = pd.Categorical(train["muscle"], categories=muscles[:8]).codes
            data.append(((train["pressure_kPa"].to_numpy(),
                          train["contraction_pct"].to_numpy() / 100.0,
                          train["l0_mm"].to_numpy(),
                          1.0 - train["l620_mm"].to_numpy() / train["l0_mm"].to_numpy()),
                         train["force_N"].to_numpy(), code,
                         [entry["constants"][n] for n in names]))
    print(f"least squares: {n_populations} populations fitted in "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    x = tuple(np.stack([d[0][j] for d in data]) for j in range(4))
    post = pamid.engine.fit_hierarchical(
        jax.random.key(0), x, np.stack([d[1] for d in data]), np.stack([d[2] for d in data]),
        8, np.stack([d[3] for d in data]), lower=lower, upper=upper)
    bayes_inside = []
    for r, (entry, held) in enumerate(zip(entries, new, strict=True)):
        draws = {"theta": post.theta[r], "tau": post.tau[r], "sigma_N": post.sigma_N[r]}
        law = entry["emax_law"]
        for _, rows in held.groupby("muscle"):
            l0 = rows["l0_mm"].to_numpy()
            emax = (law["e0_pct"] + law["e1_pct"] * np.log(l0 / law["l0_ref_mm"])) / 100.0
            _, low, high = pamid.engine.hierarchical_predictive(
                jax.random.key(r), draws, rows["pressure_kPa"].to_numpy(),
                rows["contraction_pct"].to_numpy() / 100.0, l0, emax)
            y = rows["force_N"].to_numpy()
            bayes_inside.append(np.mean((y >= low) & (y <= high)))
    print(f"{len(ls_inside)} new virtual muscles ({n_populations} populations): rows inside "
          f"the 95 % interval — least squares {100 * np.mean(ls_inside):.1f} %, "
          f"hierarchical Bayes {100 * np.mean(bayes_inside):.1f} % "
          f"(acceptance {post.acceptance:.2f}); {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
