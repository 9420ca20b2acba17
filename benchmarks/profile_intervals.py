"""Profile-likelihood intervals: the current implementation against an earlier one.

    .venv/bin/python benchmarks/profile_intervals.py                      # 300 muscles
    .venv/bin/python benchmarks/profile_intervals.py --n 300 --noise 2 20 --rev 383407b

For each noise level, N virtual muscles (Sárosi Table 3-1 × (1 + 0.03·normal), Sárosi's
protocol, load-cell noise ``--noise`` N) are fitted once; then the profile intervals of
``pamid.engine.profile_intervals`` (this tree; ``profile`` of ``pamid/_fit/_intervals.py``)
and of the same function at git revision ``--rev`` (that file read with ``git show``, run
beside this tree's solver) are computed on the same fit. Printed: the largest |difference|
of an interval end relative to the width of that interval (and the median), how many ends
each left unconverged, and the time of each (first call after ``jax.clear_caches()``,
compilation included, and the median of ``--repeats`` warm calls).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import types
from pathlib import Path

import jax
import numpy as np

import pamid
from pamid import fit_least_squares
from pamid.engine import profile_intervals

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from run import _time_pamid  # noqa: E402

TABLE_3_1 = np.asarray(pamid.sarosi.table_3_1().to_vector(), dtype=float)


def old_profile(rev: str):
    """``profile`` of ``pamid/_fit/_intervals.py`` at git revision ``rev``."""
    src = subprocess.run(
        ["git", "show", f"{rev}:pamid/_fit/_intervals.py"],
        capture_output=True, text=True, check=True, cwd=HERE.parent,
    ).stdout
    name = "pamid._fit._intervals_at_" + rev.replace("~", "_").replace("^", "_")
    module = types.ModuleType(name)
    module.__package__ = "pamid._fit"
    sys.modules[name] = module
    exec(compile(src, f"{rev}:pamid/_fit/_intervals.py", "exec"), module.__dict__)
    return module.profile


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300, help="muscles per noise level")
    parser.add_argument("--noise", type=float, nargs="+", default=[2.0, 20.0],
                        help="load-cell noise levels in N (default 2 20)")
    parser.add_argument("--rev", default="383407b", help="git revision of the reference")
    parser.add_argument("--repeats", type=int, default=2, help="warm calls timed")
    args = parser.parse_args(argv)
    old = old_profile(args.rev)
    print(f"profile intervals, this tree against {args.rev}; {args.n} muscles per noise level")
    print(f"{'noise N':>8} {'max |Δ|/width':>14} {'median':>9} {'NaN new':>8} {'NaN old':>8} "
          f"{'new first':>10} {'new warm':>9} {'old first':>10} {'old warm':>9}")
    for noise in args.noise:
        key_p, key_n = jax.random.split(jax.random.key(20261124 + args.n))
        z = np.asarray(jax.random.normal(key_p, (args.n, 6)))
        thetas = TABLE_3_1 * (1.0 + 0.03 * z)
        protocol = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=noise)
        frame = pamid.simulate_sarosi_bench(key_n, pamid.Sarosi.from_vector(thetas), protocol)
        groups = [
            ((g["pressure_kPa"].to_numpy() / 100.0, g["contraction_pct"].to_numpy()),
             g["force_N"].to_numpy())
            for _, g in frame.groupby("muscle", sort=False)
        ]
        data = pamid.pack_muscles(groups)
        fit = fit_least_squares(data)
        s2 = fit.sse / np.maximum(fit.dof, 1)
        jtj_inv = fit.covariance / s2[:, None, None]
        t_new, new = _time_pamid(
            lambda: profile_intervals(fit.spec, data, fit.theta, fit.se, s2, fit.sse, fit.dof,
                                      jtj_inv=jtj_inv), args.repeats)
        t_old, ref = _time_pamid(
            lambda: old(fit.spec, data, fit.theta, fit.se, s2, fit.sse, fit.dof), args.repeats)
        (new_first, new_warm), (old_first, old_warm) = (
            (t["first_s"], t["pamid_s"]) for t in (t_new, t_old))
        new_ci = np.stack(new[:2], -1)
        old_ci = np.stack(ref[:2], -1)
        width = (old_ci[..., 1] - old_ci[..., 0])[..., None]
        rel = np.abs(new_ci - old_ci) / width
        both = np.isfinite(rel)
        print(f"{noise:8g} {np.max(rel[both]):14.2e} {np.median(rel[both]):9.2e} "
              f"{int(np.sum(~np.isfinite(new_ci))):8d} {int(np.sum(~np.isfinite(old_ci))):8d} "
              f"{new_first:9.2f}s {new_warm:8.3f}s {old_first:9.2f}s {old_warm:8.3f}s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
