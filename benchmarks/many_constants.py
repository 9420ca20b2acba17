"""User models of many constants: `pamid fit --intervals wald --json` as the count grows.

    .venv/bin/python benchmarks/many_constants.py                  # 5, 10, 20, 50 constants
    .venv/bin/python benchmarks/many_constants.py --sizes 50 --rows 300 --rounds 2

For each count n, a model file (written to a temporary folder) holds ``ManyN``, a
``pamid.ForceModel`` that is a sum of simple terms: n products of Chebyshev polynomials of
the scaled pressure (degree 0–4) and contraction, linear in every constant; with
``--nonlinear``, n − 2 of them and ``g·p·exp(−κ/τ)``, τ nonlinear (so the start searches
trial values). ``--source DIR`` runs the pamid package in DIR (another commit's tree, from
``git archive``) in place of this one. A one-muscle file of ``--rows`` rows,
pressures and contractions spread over 1–6 bar and 0–30 %, holds the model's force at
known constants plus 2 N of noise. Each command is a process of its own with a compilation
cache of the benchmark's own: the first round of each n starts from an empty cache (what a
new model costs), the later rounds are warm. Printed per n: wall time of each round, the
command's own "seconds", whether the fit converged, and the RMSE.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAMID = [sys.executable, "-m", "pamid"]


def terms(n: int, nonlinear: bool) -> list[tuple[int, int]]:
    """(degree in pressure, degree in contraction) of the linear terms."""
    return [(a, b) for b in range(n) for a in range(5)][: n - 2 if nonlinear else n]


def model_source(n: int, nonlinear: bool = False) -> str:
    """The text of a model file with class ``Many{n}``: n constants, all linear, or (with
    ``nonlinear``) n − 2 linear ones and an exponential term ``g·p·exp(−κ/τ)``."""
    lines = ["import jax.numpy as jnp", "import pamid", "", "",
             "def chebyshev(x, degree):",
             "    out = [jnp.ones_like(x), x]",
             "    while len(out) <= degree:",
             "        out.append(2 * x * out[-1] - out[-2])",
             "    return out", "", "",
             f"class Many{n}(pamid.ForceModel):",
             f'    """A sum of simple terms: {n} constants."""', ""]
    linear = terms(n, nonlinear)
    lines += [f"    c{i}: float = 0.0" for i in range(len(linear))]
    units = {f"c{i}": "N" for i in range(len(linear))}
    if nonlinear:
        lines += ["    g: float = 1.0", "    tau: float = 5.0"]
        units |= {"g": "N/bar", "tau": "%"}
    lines += [f"    units = {units!r}", '    inputs = ("pressure_bar", "contraction_pct")', "",
              "    def __call__(self, pressure_bar, contraction_pct):",
              "        tp = chebyshev((pressure_bar - 3.5) / 2.5, 4)",
              f"        tk = chebyshev((contraction_pct - 15.0) / 15.0, {n})",
              "        return (0.0"]
    if nonlinear:
        lines += ["                + self.g * pressure_bar * jnp.exp(-contraction_pct / self.tau)"]
    lines += [f"                + self.c{i} * tp[{a}] * tk[{b}]" for i, (a, b) in enumerate(linear)]
    lines[-1] += ")"
    return "\n".join(lines) + "\n"


def bench_file(n: int, rows: int, nonlinear: bool = False, seed: int = 0) -> str:
    """A one-muscle CSV of ``rows`` rows whose force is ``Many{n}`` at known constants."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(1.0, 6.0, rows)
    k = rng.uniform(0.0, 30.0, rows)
    tp = np.polynomial.chebyshev.chebvander((p - 3.5) / 2.5, 4)
    tk = np.polynomial.chebyshev.chebvander((k - 15.0) / 15.0, n)
    force = 40.0 * p * np.exp(-k / 8.0) if nonlinear else np.zeros(rows)
    for a, b in terms(n, nonlinear):
        force += rng.normal(0.0, 20.0 / (1 + a + b)) * tp[:, a] * tk[:, b]
    force += rng.normal(0.0, 2.0, rows)
    lines = ["muscle,pressure_bar,contraction_pct,force_N"]
    lines += [f"M1,{pi:.6f},{ki:.6f},{fi:.6f}" for pi, ki, fi in zip(p, k, force)]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="5,10,20,50")
    parser.add_argument("--rows", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--nonlinear", action="store_true",
                        help="n − 2 linear constants and the exponential term g·p·exp(−κ/τ)")
    parser.add_argument("--source", type=Path, default=ROOT,
                        help="the folder holding the pamid package to run (another commit's "
                             "tree, from `git archive`)")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per command")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="pamid-many-") as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, PAMID_CACHE_DIR=str(tmp / "cache"),
                   PYTHONPATH=os.pathsep.join([str(args.source.resolve()),
                                               os.environ.get("PYTHONPATH", "")]))
        for n in (int(s) for s in args.sizes.split(",")):
            (tmp / f"many{n}.py").write_text(model_source(n, args.nonlinear))
            (tmp / f"many{n}.csv").write_text(bench_file(n, args.rows, args.nonlinear))
            cmd = PAMID + ["fit", str(tmp / f"many{n}.csv"), "--model",
                           f"{tmp / f'many{n}.py'}:Many{n}", "--intervals", "wald", "--json"]
            for r in range(args.rounds):
                start = time.perf_counter()
                try:
                    out = subprocess.run(cmd, capture_output=True, text=True, env=env,
                                         cwd=tmp, timeout=args.timeout)
                except subprocess.TimeoutExpired:
                    print(f"{n:3d} constants, {args.rows} rows: not done in {args.timeout:.0f} s",
                          flush=True)
                    break
                wall = time.perf_counter() - start
                try:
                    res = json.loads(out.stdout)
                    m = res["muscles"][0]
                    info = (f"pamid seconds {res['seconds']:.2f}, converged {m['converged']}, "
                            f"rmse {m['rmse_N']:.3f} N")
                except (ValueError, KeyError, IndexError):
                    info = f"exit {out.returncode}: {out.stderr.strip()[-300:]}"
                cache = "empty cache" if r == 0 else "warm cache"
                print(f"{n:3d} constants, {args.rows} rows, {cache}: {wall:6.2f} s wall ({info})",
                      flush=True)


if __name__ == "__main__":
    main()
