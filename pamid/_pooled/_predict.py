"""The force map of a muscle nobody has tested, from a pooled model, with 95 % intervals.

:func:`predict_muscle` reads one entry of the ``"pooled"`` list that ``pamid compare
--pooled`` writes (:meth:`._lomo.PooledModel.to_dict`; the whole compare.json works too),
evaluates the pooled law at the new muscle's descriptors on a grid of pressures and
contractions, and gives each point the predictive interval of that entry's ``"spread"``
(F̂ ± √((z·σ)² + (t·√(1 + 1/M)·τ·F̂)²), calibrated on the held-out muscles' residuals: the
spread of muscles about the law and the noise within one). The hierarchical Bayesian model
(``bolen2026_hierarchical``) gives the median and the 2.5/97.5 % quantiles of its posterior
predictive instead: each stored posterior draw's law times a new muscle's factor
exp(τ·z), plus noise. A model with per-muscle constants predicts with their mean;
``<base>_nearest`` with the constants of the tested muscle nearest in ln l0; the Bolen law
with ε_max from its line in ln l0 (``"emax_law"``) unless it is given. A descriptor the
fitted muscles did not vary (their one diameter) must match: the fit says nothing of another
value of it. Where the law gives a negative force the muscle is slack: 0 N.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._fit._spec import get_model
from ._descriptors import EMAX
from ._hierarchical import predictive_interval
from ._lomo import bolen_spec, half_width
from ._spec import mean_per_muscle, pooled_spec

#: The pressures of the predicted map by default (kPa).
DEFAULT_PRESSURES_KPA = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0)
#: Contraction points per pressure of the default map, from 0 to the model's range.
N_CONTRACTIONS = 21


@dataclasses.dataclass(frozen=True)
class MusclePrediction:
    """A predicted force map (every array one value per grid point).

    Attributes:
        model: the pooled model; ``descriptors`` the new muscle's (l0_mm, …; emax_pct where
            the model uses it, with ``emax_source`` saying where it came from).
        pressure_kPa, contraction_pct, force_N, low_N, high_N: the map and its 95 %
            predictive interval.
        notes: what the prediction assumes (extrapolation beyond the fitted lengths, …).
    """

    model: str
    descriptors: dict[str, float]
    emax_source: str | None
    pressure_kPa: np.ndarray
    contraction_pct: np.ndarray
    force_N: np.ndarray
    low_N: np.ndarray
    high_N: np.ndarray
    notes: tuple[str, ...]
    level: float = 0.95

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame({"pressure_kPa": self.pressure_kPa,
                             "contraction_pct": self.contraction_pct,
                             "force_N": self.force_N, "low_N": self.low_N,
                             "high_N": self.high_N})

    def to_dict(self) -> dict:
        return {"model": self.model, "descriptors": dict(self.descriptors),
                "emax_source": self.emax_source, "level": self.level,
                "notes": list(self.notes),
                "points": [{k: float(v) for k, v in row.items()}
                           for row in self.to_frame().to_dict(orient="records")]}


def pick_entry(payload: dict, model: str | None = None) -> dict:
    """The entry of ``model`` in a pooled comparison's JSON (``{"pooled": [...]}``), or the
    first (best LOMO RMSE) converged one."""
    entries = payload.get("pooled") if isinstance(payload, dict) else None
    if not entries:
        raise ValueError("the file holds no pooled models: write it with "
                         "`pamid compare DATA --pooled --out DIR` (DIR/compare.json)")
    if model is None:
        ok = [e for e in entries if e.get("converged")]
        return (ok or entries)[0]
    for e in entries:
        if e["model"] == model:
            return e
    raise ValueError(f"no pooled model {model!r} in the file; it holds "
                     f"{', '.join(e['model'] for e in entries)}")


def predict_muscle(entry: dict, *, l0_mm: float, descriptors: dict[str, float] | None = None,
                   pressure_kPa=DEFAULT_PRESSURES_KPA, contraction_pct=None,
                   points: bool = False, key=None) -> MusclePrediction:
    """Predict the force map of a new muscle of resting length ``l0_mm`` (module text).

    Args:
        entry: one model of a pooled comparison (:func:`pick_entry`).
        l0_mm: the new muscle's resting length.
        descriptors: its other descriptors, e.g. ``{"diameter_mm": 10, "emax_pct": 16.5}``.
        pressure_kPa: pressures of the map.
        contraction_pct: contractions of the map (default: 0 to ε_max for the Bolen law,
            else to the fitted data's largest contraction, :data:`N_CONTRACTIONS` points).
        points: predict at the pairs (pressure_kPa[i], contraction_pct[i]) instead of on
            their grid (to score a measured muscle's rows).
        key: PRNG key of the posterior predictive's draws (a hierarchical model only;
            default ``jax.random.key(0)``).

    Raises:
        ValueError: a descriptor the model needs is missing or not positive, or one the
            fitted muscles held fixed is given another value.
    """
    key = jax.random.key(0) if key is None else key
    given = {"l0_mm": float(l0_mm), **{k: float(v) for k, v in (descriptors or {}).items()
                                        if v is not None}}
    for name, value in given.items():
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, not {value:g}")
    d = entry["descriptors"]
    notes = []
    for name, value in d["constant"].items():
        if name in given and not math.isclose(given[name], value, rel_tol=1e-9):
            raise ValueError(f"every muscle of the fitted file has {name} = {value:g}; the "
                             f"pooled model says nothing of {name} = {given[name]:g}")
    l0_fit = np.asarray(d["muscle_values"]["l0_mm"], np.float64)
    if not l0_fit.min() <= given["l0_mm"] <= l0_fit.max():
        notes.append(f"l0 = {given['l0_mm']:g} mm is outside the fitted muscles' "
                     f"{l0_fit.min():g}–{l0_fit.max():g} mm: an extrapolation")
    emax_source = None
    emax = given.get(EMAX)
    if entry.get("emax_law") is not None or EMAX in d["used"]:
        if emax is None:
            if entry.get("emax_law") is None:
                raise ValueError(f"the model uses {EMAX} (the maximal contraction at 620 kPa): "
                                 "give it")
            law = entry["emax_law"]
            emax = law["e0_pct"] + law["e1_pct"] * math.log(given["l0_mm"] / law["l0_ref_mm"])
            emax_source = "the fitted muscles' line in ln l0"
        else:
            emax_source = "given"
        given[EMAX] = float(emax)
    missing = [u for u in d["used"] if u not in given]
    if missing:
        raise ValueError(f"the model {entry['model']} depends on {', '.join(missing)}: give "
                         "the new muscle's value")
    p = np.asarray(pressure_kPa, np.float64)
    if contraction_pct is None:
        top = emax if emax is not None else entry.get("contraction_max_pct") or 0.0
        contraction_pct = np.linspace(0.0, float(top), N_CONTRACTIONS)
    k = np.asarray(contraction_pct, np.float64)
    if not points:
        p, k = (a.ravel() for a in np.meshgrid(p, k, indexing="ij"))
    elif p.shape != k.shape:
        raise ValueError("points=True takes one pressure per contraction")
    if entry.get("posterior") is not None:  # hierarchical Bayes: the posterior predictive
        raw, low, high = predictive_interval(
            key, entry["posterior"], p, k / 100.0, np.full(p.shape, given["l0_mm"]),
            np.full(p.shape, given[EMAX] / 100.0),
            level=float(entry["spread"].get("level", 0.95)))
    else:
        raw = _evaluate(entry, given, p, k)
        half = half_width(entry["spread"], raw)
        low, high = raw - half, raw + half
    # A braided muscle pulls; where the law gives less than 0 it is slack: 0 N.
    force, low, high = (np.maximum(v, 0.0) for v in (raw, low, high))
    if np.any(raw < 0):
        notes.append("where the law gives a negative force the muscle is slack: shown as 0 N")
    shown = {name: given[name] for name in ("l0_mm", *d["used"], *d["constant"], EMAX)
             if name in given}
    for name, value in d["constant"].items():
        shown.setdefault(name, value)
    return MusclePrediction(model=entry["model"], descriptors=shown, emax_source=emax_source,
                            pressure_kPa=p, contraction_pct=k, force_N=force,
                            low_N=low, high_N=high, notes=tuple(notes),
                            level=float(entry["spread"].get("level", 0.95)))


def _inputs(spec, pressure_kPa, contraction_pct, l0_mm):
    frame = pd.DataFrame({"pressure_kPa": pressure_kPa, "contraction_pct": contraction_pct,
                          "l0_mm": np.full_like(pressure_kPa, l0_mm),
                          "length_mm": l0_mm * (1.0 - contraction_pct / 100.0),
                          "contraction_mm": l0_mm * contraction_pct / 100.0})
    return tuple(jnp.asarray(v) for v in spec.x_from_frame(frame))


def _evaluate(entry: dict, given: dict, p, k) -> np.ndarray:
    kind = entry["kind"]
    theta = np.asarray([np.nan if v is None else v for v in entry["constants"].values()],
                       np.float64)
    if kind in ("bolen", "bolen_lab_code"):
        spec = bolen_spec()
        x = (jnp.asarray(p), jnp.asarray(k / 100.0), jnp.full(p.shape, given["l0_mm"]),
             jnp.full(p.shape, given[EMAX] / 100.0))
        return np.asarray(spec.predict(jnp.asarray(theta), x))
    base = get_model(entry["base"])
    x = _inputs(base, p, k, given["l0_mm"])
    if kind == "nearest":
        values = entry["descriptors"]["muscle_values"]
        l0 = np.asarray(values["l0_mm"], np.float64)
        # The nearest length among the tested muscles of the new one's diameter (and other
        # descriptors given), as the comparison scored it.
        same = np.ones(l0.size, bool)
        for name, tested in values.items():
            if name in ("l0_mm", "l620_mm", EMAX) or name not in given:
                continue
            same &= np.isclose(np.asarray(tested, np.float64), given[name], rtol=1e-9)
        if not same.any():
            asked = ", ".join(f"{n} = {given[n]:g}" for n in values
                              if n not in ("l0_mm", "l620_mm", EMAX) and n in given)
            raise ValueError(f"no tested muscle has {asked}: the nearest tested muscle's "
                             "constants say nothing of it (a smooth pooled model may)")
        i = int(np.argmin(np.where(same, np.abs(np.log(l0 / given["l0_mm"])), np.inf)))
        row = list(entry["constants_per_muscle"].values())[i]
        return np.asarray(base.predict(jnp.asarray([row[n] for n in base.param_names]), x))
    d = entry["descriptors"]
    used = tuple(d["used"])
    roles = tuple(entry["roles"][n] for n in base.param_names)
    m = len(d["muscle_values"]["l0_mm"])
    spec = pooled_spec(base, roles, used, m)
    theta = mean_per_muscle(theta, base, roles, used, m, 0, np.arange(m))
    g = [np.full(p.shape, math.log(given[u] / d["ref"][u])) for u in used]
    xs = (*x, jnp.zeros(p.shape), *(jnp.asarray(v) for v in g))
    return np.asarray(spec.predict(jnp.asarray(theta), xs))
