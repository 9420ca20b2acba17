#!/usr/bin/env python
"""Every registered static force model on the measured files: ``pamid compare`` in Python.

Data (next to the repository, skipped when absent; never copied into it):

* ``../shared/data/martens_dmsp10_250.csv``: the DMSP-10-250 force map of Martens & Boblan
  2017 (Appendix A, table A2), read with l0 = 250 mm so that models in mm (Cullinan) can
  take it; no trials, so whole curves (sweeps at a held pressure) are held out;
* ``../shared/data/aarl_festo10mm_isometric.csv``: the AARL isometric tests of cut Festo
  10 mm tube, 6 muscles × 12 trials; whole trials are held out.

For each file every model of ``pamid.engine.model_names()`` (whatever is registered when
the script runs) is fitted to every muscle in one batched solve per model, with its
cross-validation refits as weighted lanes (:func:`pamid.compare_models`), and
ranked per muscle by CV RMSE and by BIC = n·ln(SSE/n) + p·ln n. Writes, per file,
``compare.json``, one PNG of every model against the data per muscle and ``cv_rmse.png``,
and for all files ``table.md`` (the table of experiments/README.md) and ``summary.json``.

    .venv/bin/python experiments/compare_models.py [--out DIR] [--folds K]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import pamid
from pamid import compare_models
from pamid.engine import model_names
from pamid.io import write_text_atomic
from pamid.report import comparison_table, write_comparison_plots

NAME = "compare_models"
ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
FILES = (
    ("martens_dmsp10_250.csv", {"l0_mm": 250.0}),
    ("aarl_festo10mm_isometric.csv", {}),
)


def _f(x, digits=3) -> str:
    if x is None:
        return "—"
    return f"{x:.{digits}g}" if abs(x) < 1e5 else f"{x:.2e}"


def markdown(results: dict) -> str:
    """Per file and muscle: the models best first, with RMSE, CV RMSE and BIC."""
    lines = []
    for name, d in results.items():
        for mu in d["muscles"]:
            lines.append(f"**{name}, {mu['muscle']}** — n = {mu['models'][0]['n']}, CV on "
                         f"held-out whole {mu['cv']} ({mu['cv_folds']} folds of "
                         f"{mu['cv_units']}); best: **{mu['best']}**")
            lines.append("")
            lines.append("| rank | model | p | RMSE [N] | CV RMSE [N] | max error [N] | "
                         "folds converged | BIC | status |")
            lines.append("|---|---|---|---|---|---|---|---|---|")
            for k, m in enumerate(mu["models"], start=1):
                lines.append(f"| {k} | {m['model']} | {m['n_params']} | {_f(m['rmse_N'])} | "
                             f"{_f(m['cv_rmse_N'])} | {_f(m['max_abs_error_N'])} | "
                             f"{m['cv_folds_converged']}/"
                             f"{mu['cv_folds']} | {_f(m['bic'], 6)} | {m['status']} |")
            lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "experiments" / "out" / NAME)
    parser.add_argument("--folds", type=int, default=5)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    print(f"registered models: {', '.join(model_names())}")
    results, seconds = {}, {}
    for filename, options in FILES:
        path = DATA / filename
        if not path.is_file():
            print(f"{path} not found: skipped")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pamid.CensoredRowsWarning)
            bench = pamid.load_bench(path, **options)
        t1 = time.perf_counter()
        progress(f"{filename}: {len(bench.frame)} rows, {len(bench.muscles)} muscle(s)")
        result = compare_models(bench, n_folds=args.folds, progress=progress)
        seconds[filename] = round(time.perf_counter() - t1, 1)
        d = result.to_dict()
        d["source"] = filename
        d["seconds"] = seconds[filename]
        out = args.out / Path(filename).stem
        d["plots"] = write_comparison_plots(result, bench, out, max_plots=len(bench.muscles))
        write_text_atomic(out / "compare.json", json.dumps(d, indent=2) + "\n")
        results[filename] = d
        print(f"\n{filename} ({seconds[filename]} s for the fits)\n")
        print(comparison_table(result))
    if not results:
        print("no measured data found: nothing to compare")
        return 0
    table = markdown(results)
    write_text_atomic(args.out / "table.md", table + "\n")
    summary = {"models": list(model_names()), "seconds": seconds,
               "files": {k: {"muscles": v["muscles"], "skipped": v["skipped"]}
                         for k, v in results.items()}}
    write_text_atomic(args.out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"\nwrote {args.out}/table.md, summary.json and per-file compare.json and PNGs "
          f"({time.perf_counter() - t0:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
