"""The public fitting entry point and its result."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pandas as pd

from .._data._bench import BenchData
from . import _intervals
from ._batch import FitData, pack_rows
from ._least_squares import solve, statistics
from ._spec import ModelSpec, get_model

INTERVAL_KINDS = ("wald", "profile", "bootstrap")


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult:
    """Fitted constants of one model for every muscle of a batch, with 95% intervals.

    Arrays have a leading muscle axis; constants follow ``param_names``. ``ci95`` holds the
    Wald interval (the one the CLI table shows); ``ci95_profile`` and ``ci95_bootstrap`` are
    None unless asked for. ``converged`` is False for a muscle whose solve did not meet its
    tolerance within the step budget: its constants are still reported, never dropped.
    """

    model: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    muscles: tuple[str | None, ...]
    theta: np.ndarray
    se: np.ndarray
    ci95: np.ndarray  # (M, p, 2), Wald with Student-t
    ci95_profile: np.ndarray | None
    ci95_bootstrap: np.ndarray | None
    covariance: np.ndarray  # (M, p, p) = s²·(JᵀJ)⁻¹
    n: np.ndarray
    dof: np.ndarray
    sse: np.ndarray
    rmse_N: np.ndarray
    r: np.ndarray
    converged: np.ndarray
    n_steps: np.ndarray
    solver: str
    profile_ok: np.ndarray | None = None
    bootstrap_converged: np.ndarray | None = None
    spec: ModelSpec | None = None
    messages: tuple[str | None, ...] = ()  # per muscle: why it did not converge, else None

    def message(self, i: int) -> str | None:
        """Why muscle ``i`` is not reported as converged (None when it is)."""
        return self.messages[i] if i < len(self.messages) else None

    @property
    def n_muscles(self) -> int:
        return self.theta.shape[0]

    def params(self, i: int = 0):
        """The constants of muscle ``i`` as the model's parameter object (Sarosi, Cullinan)."""
        return self.spec.make(self.theta[i])

    def to_dict(self) -> dict:
        """The JSON shape of ``pamid fit --json``."""
        # Whole arrays to Python lists at once (10,000 muscles: element by element took most
        # of a second).
        theta, se, ci = _json_values(self.theta), _json_values(self.se), _json_values(self.ci95)
        optional = [
            (key, _json_values(arr))
            for key, arr in (("ci95_profile", self.ci95_profile),
                             ("ci95_bootstrap", self.ci95_bootstrap))
            if arr is not None
        ]
        units = [self.param_units[name] for name in self.param_names]
        rmse, r = _json_values(self.rmse_N), _json_values(self.r)
        n, converged = self.n.tolist(), np.asarray(self.converged, dtype=bool).tolist()
        muscles = []
        for i, muscle in enumerate(self.muscles):
            params = {}
            for j, name in enumerate(self.param_names):
                entry = {"value": theta[i][j], "ci95": ci[i][j], "se": se[i][j], "unit": units[j]}
                for key, values in optional:
                    entry[key] = values[i][j]
                params[name] = entry
            muscles.append(
                {
                    "muscle": muscle,
                    "n": int(n[i]),
                    "rmse_N": rmse[i],
                    "r": r[i],
                    "converged": converged[i],
                    "message": self.message(i),
                    "params": params,
                }
            )
        return {
            "model": self.model,
            "equation": self.spec.source,
            "units": dict(self.spec.units),
            "solver": self.solver,
            "interval": "wald-t",
            "muscles": muscles,
        }


def _reasons(spec, n, solver_ok, full_rank, se, converged, steps) -> tuple[str | None, ...]:
    """Per muscle, why a fit is not reported as converged, in words (None where it is)."""
    p = spec.n_params
    out = []
    for i in range(len(n)):
        if converged[i]:
            out.append(None)
        elif n[i] <= p:
            out.append(f"too few rows: {int(n[i])} for the {p} constants of {spec.source} "
                       f"(at least {p + 1} are needed to estimate them and their error)")
        elif not full_rank[i]:
            out.append(f"the data cannot determine all {p} constants of {spec.source} "
                       "(rank-deficient Jacobian): too few distinct pressures or "
                       "contractions for this model, or rows that repeat one point")
        elif not solver_ok[i]:
            out.append(f"the solver stopped after {int(steps[i])} steps without meeting "
                       "its tolerance; the constants shown are its last accepted point")
        else:
            bad = [spec.param_names[j] for j in np.flatnonzero(~np.isfinite(se[i]))]
            out.append(f"no finite standard error for {', '.join(bad)}: those constants "
                       "are not determined by the data")
    return tuple(out)


def _json_values(a) -> list:
    """An array as (nested) lists of floats, NaN and ±inf as None: :func:`_num` for every
    element at once."""
    a = np.asarray(a, dtype=np.float64)
    return np.where(np.isfinite(a), a, None).tolist()


def _num(x):
    """A float for JSON: NaN and ±inf (not valid JSON) become null."""
    return float(x) if np.isfinite(x) else None


def _pair(v):
    return [_num(x) for x in v]


def bench_to_fit_data(bench: BenchData, model: str | ModelSpec = "sarosi", *,
                      curves: bool = True) -> FitData:
    """Pack a loaded bench file into a batch, one lane per muscle, with the model's inputs.

    Straight from the frame's columns (no per-muscle frames): muscle codes by one
    ``pd.factorize``, then :func:`~pamid._fit._batch.pack_rows`. The curve of every sample
    (the bootstrap's resampling unit) is the file's one curve definition,
    ``bench.curves`` (:func:`pamid._data._curves.find_curves`); ``curves=False`` puts
    every sample of a muscle in curve 0, for fits that resample nothing.
    """
    spec = get_model(model, bench.frame)
    frame = bench.frame
    codes = pd.factorize(frame["muscle"], sort=False)[0]
    x = spec.x_from_frame(frame, bench.path)
    y = frame["force_N"].to_numpy(dtype=np.float64)
    curve = bench.curves.curve if curves else np.zeros(len(frame), dtype=np.int64)
    return pack_rows(codes, x, y, curve, n_muscles=len(bench.muscles))


def fit_least_squares(
    data: BenchData | FitData,
    model: str | ModelSpec = "sarosi",
    *,
    solver: str = "gauss-newton",
    intervals: tuple[str, ...] = ("wald",),
    n_bootstrap: int = 1000,
    key: jax.Array | None = None,
    bounds=None,
    level: float = 0.95,
    muscles: tuple[str | None, ...] | None = None,
) -> FitResult:
    """Fit a static force model to every muscle of ``data`` in one batched solve.

    Args:
        data: a loaded bench file (:func:`pamid.load_bench`) or a packed :class:`FitData`.
        model: "sarosi" (Sárosi eq. 2.1), "cullinan" (Cullinan eq. 3: A–E from static
            data, and G too when the data carry ``velocity_mm_s``), or a ModelSpec.
        solver: "gauss-newton" (default; for the Sárosi model the written-out batched
            Gauss–Newton of ``_gauss_newton.py`` with its own start, otherwise
            optimistix's), "levenberg-marquardt", "variable-projection",
            "jaxopt-levenberg-marquardt".
        intervals: any of "wald" (always computed), "profile", "bootstrap".
        n_bootstrap: bootstrap replicates per muscle (whole curves resampled).
        key: PRNG key, required for the bootstrap.
        bounds: optional (lower, upper) arrays of the constants; uses jaxopt's L-BFGS-B.
        level: coverage of the intervals (0.95).
    """
    frame = data.frame if isinstance(data, BenchData) else None
    spec = get_model(model, frame)
    unknown = set(intervals) - set(INTERVAL_KINDS)
    if unknown:
        raise ValueError(f"unknown interval kinds {sorted(unknown)}; choose from {INTERVAL_KINDS}")
    if isinstance(data, BenchData):
        names = tuple(m if data.has_muscle_column else None for m in data.muscles)
        data = bench_to_fit_data(data, spec, curves="bootstrap" in intervals)
    else:
        names = muscles if muscles is not None else tuple([None] * data.n_muscles)

    theta, converged, steps = solve(spec, data, solver=solver, bounds=bounds)
    sse, jtj_inv, corr, n, full_rank = statistics(spec, theta, data)
    se, lo, hi, s2, dof = _intervals.wald(theta, jtj_inv, sse, n, level)
    # A fit whose constants are not all determined by the data (rank-deficient Jacobian, or
    # no degrees of freedom left) is not reported as converged, whatever the solver says.
    solver_ok = np.asarray(converged, dtype=bool)
    converged = converged & full_rank & np.all(np.isfinite(se), axis=-1)
    messages = _reasons(spec, np.asarray(n), solver_ok, np.asarray(full_rank),
                        np.asarray(se), np.asarray(converged), np.asarray(steps))

    ci_profile = profile_ok = None
    if "profile" in intervals:
        plo, phi, profile_ok = _intervals.profile(spec, data, theta, se, s2, sse, dof, level,
                                                  jtj_inv=jtj_inv)
        ci_profile = np.stack([plo, phi], axis=-1)
    ci_boot = boot_ok = None
    if "bootstrap" in intervals:
        if key is None:
            raise ValueError("the bootstrap needs a PRNG key: pass key=jax.random.key(...)")
        blo, bhi, _, boot_ok = _intervals.bootstrap(spec, data, theta, key, n_bootstrap, level)
        ci_boot = np.stack([blo, bhi], axis=-1)

    with np.errstate(invalid="ignore"):  # NaN where the data do not determine a constant
        covariance = s2[:, None, None] * jtj_inv
    return FitResult(
        model=spec.name,
        param_names=spec.param_names,
        param_units=spec.param_units,
        muscles=names,
        theta=theta,
        se=se,
        ci95=np.stack([lo, hi], axis=-1),
        ci95_profile=ci_profile,
        ci95_bootstrap=ci_boot,
        covariance=covariance,
        n=n.astype(int),
        dof=dof,
        sse=sse,
        rmse_N=np.sqrt(sse / n),
        r=corr,
        converged=converged,
        n_steps=steps,
        solver=solver if bounds is None else "jaxopt-lbfgsb",
        profile_ok=profile_ok,
        bootstrap_converged=boot_ok,
        spec=spec,
        messages=messages,
    )
