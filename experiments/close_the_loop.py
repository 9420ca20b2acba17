"""Close the loop (issue #5): hidden effects in virtual data, then the measured DMSP-10 map.

For every scenario the virtual bench (Sárosi's protocol, Table 3-1 constants, 2 N noise,
5 repeats averaged: noise level 0.894 N) hides one or more effects in a file that does not
mention them; ``pamid.diagnose`` must find, name and remove them. Then the same diagnosis
runs on ../shared/data/martens_dmsp10_250.csv (skipped when absent).

    .venv/bin/python experiments/close_the_loop.py [--out experiments/out/close_the_loop]

Prints a before/after table and writes summary.json, the Martens report and its residual
plots into the output folder.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import jax

import pamid
from pamid.io import write_text_atomic

ROOT = Path(__file__).resolve().parents[1]
MARTENS = ROOT.parent / "shared" / "data" / "martens_dmsp10_250.csv"
NOISE_N = 2.0 / math.sqrt(5.0)
SPEEDS = (1.0, 3.0, 2.0, 1.5)

SCENARIOS = [
    ("control (no effect)", (), {}),
    ("hysteresis, linear in p", (pamid.InjectedHysteresis(9.0),), {}),
    ("hysteresis ∝ √p", (pamid.InjectedHysteresis(9.0, form="sqrt"),), {}),
    ("hysteresis constant", (pamid.InjectedHysteresis(9.0, form="constant"),), {}),
    ("hysteresis ∝ p²", (pamid.InjectedHysteresis(9.0, form="quadratic"),), {}),
    ("temperature, linear", (pamid.InjectedTemperature(),), {}),
    ("temperature, quadratic", (pamid.InjectedTemperature(form="quadratic"),), {}),
    ("drift 30 N/h, linear", (pamid.InjectedDrift(30.0),), {}),
    ("drift, exponential settling", (pamid.InjectedDrift(60.0, form="exponential"),), {}),
    ("compliance 0.002 mm/N", (pamid.InjectedCompliance(0.002),), {}),
    ("viscous 2 N·s/mm, 4 speeds", (pamid.InjectedViscousDamping(2.0),),
     {"sweep_seconds_per_point": SPEEDS}),
    ("humidity (outside the library)", (pamid.InjectedCovariate("humidity_pct"),), {}),
    ("humidity, sine form", (pamid.InjectedCovariate("humidity_pct", form="sine"),), {}),
    ("hysteresis + temperature", (pamid.InjectedHysteresis(9.0), pamid.InjectedTemperature()),
     {}),
    ("drift + compliance", (pamid.InjectedDrift(30.0), pamid.InjectedCompliance(0.002)), {}),
]


def run_scenario(name, effects, protocol, seed, folder):
    proto = pamid.SarosiProtocol(min_force_N=10.0, effects=effects, **protocol)
    frame = pamid.simulate_sarosi_bench(jax.random.key(seed), pamid.sarosi.table_3_1(), proto)
    path = Path(folder) / f"scenario_{seed}.csv"
    frame.to_csv(path, index=False)
    t0 = time.perf_counter()
    d = pamid.diagnose(path)
    return {"scenario": name, "hidden": [type(e).__name__.replace("Injected", "") for e in effects],
            "selected": d.selected, "rmse_before_N": d.rmse_before, "rmse_after_N": d.rmse_after,
            "max_error_before_N": d.max_error_before, "max_error_after_N": d.max_error_after,
            "cv_rmse_before_N": d.cv_rmse_before, "cv_rmse_after_N": d.cv_rmse_after,
            "unexplained": d.unexplained, "seconds": time.perf_counter() - t0}


def false_positives(n: int) -> dict:
    """Diagnose ``n`` clean virtual-bench files (no hidden effect; seeds 0 … n−1)."""
    selected, unexplained = {}, {}
    proto = pamid.SarosiProtocol(min_force_N=10.0)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(n):
            frame = pamid.simulate_sarosi_bench(jax.random.key(seed), pamid.sarosi.table_3_1(),
                                                proto)
            path = Path(tmp) / f"control_{seed}.csv"
            frame.to_csv(path, index=False)
            d = pamid.diagnose(path)
            if d.selected:
                selected[seed] = d.selected
            if d.unexplained:
                unexplained[seed] = d.unexplained
    return {"n": n, "n_selected": len(selected), "n_unexplained": len(unexplained),
            "selected": selected, "unexplained": unexplained}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "experiments" / "out" / "close_the_loop"))
    ap.add_argument("--control-seeds", type=int, default=100,
                    help="clean data sets (seeds 0 … N−1) for the false-positive count")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, effects, protocol) in enumerate(SCENARIOS):
            rows.append(run_scenario(name, effects, protocol, 100 + i, tmp))
            r = rows[-1]
            print(f"  {name}: {', '.join(r['selected']) or 'nothing'} ({r['seconds']:.1f} s)",
                  file=sys.stderr)
    print(f"Virtual bench, noise level {NOISE_N:.3f} N (2 N per reading, 5 repeats averaged)")
    head = (f"{'scenario':<32} {'selected':<36} {'RMSE before':>11} {'after':>7} "
            f"{'max before':>10} {'after':>7}  unexplained")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['scenario']:<32} {', '.join(r['selected']) or '—':<36} "
              f"{r['rmse_before_N']:>11.3f} {r['rmse_after_N']:>7.3f} "
              f"{r['max_error_before_N']:>10.2f} {r['max_error_after_N']:>7.2f}  "
              f"{', '.join(r['unexplained']) or '—'}")
    summary = {"noise_level_N": NOISE_N, "scenarios": rows}
    if args.control_seeds:
        summary["control"] = false_positives(args.control_seeds)
        c = summary["control"]
        print(f"\nControl: {c['n_selected']} of {c['n']} clean data sets (seeds 0–{c['n'] - 1}) "
              f"selected an effect, {c['n_unexplained']} listed something as unexplained")
    if MARTENS.is_file():
        d = pamid.diagnose(MARTENS)
        report = pamid.report.diagnosis_report(d)
        write_text_atomic(out / "martens_report.txt", report + "\n")
        pamid.report.plot_diagnosis_residuals(d, out / "martens_residuals_before_after.png")
        pamid.report.plot_diagnosis_time_order(d, out / "martens_residual_time_order.png")
        summary["martens"] = d.to_dict()
        print(f"\nMeasured: {MARTENS.name} ({d.n} uncensored points)")
        print(f"  selected: {', '.join(d.selected) or 'nothing'}; RMSE {d.rmse_before:.3f} → "
              f"{d.rmse_after:.3f} N, max {d.max_error_before:.2f} → {d.max_error_after:.2f} N, "
              f"CV RMSE {d.cv_rmse_before:.3f} → {d.cv_rmse_after:.3f} N; unexplained: "
              f"{', '.join(d.unexplained) or 'nothing'}")
    else:
        print(f"\n{MARTENS} not found: measured-data part skipped")
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"\nwrote {out}/summary.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
