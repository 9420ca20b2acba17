"""A posterior (:class:`pamid.McmcResult`) written out: each muscle's ArviZ DataTree as
NetCDF, and its figures (traces, pair plot, posterior predictive) as ``pamid fit --method
mcmc --out`` writes them.

NetCDF: a DataTree with groups needs a NetCDF-4 engine (h5netcdf or netCDF4). Where neither
is installed, :func:`save_netcdf` writes one NetCDF-3 file per group into a folder (SciPy's
writer; list-valued attributes as JSON text, :func:`pamid._sampling._arviz.encode_attrs`)
and warns; :func:`pamid.load_inference_data` reads either form. The DataTree itself is
built by :func:`pamid._sampling._arviz.to_inference_data`. Every file is written
atomically (:func:`pamid._io.write_atomic`).
"""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._io import safe_file_names, save_figure_atomic, write_atomic
from .._sampling._arviz import (
    encode_attrs,
    input_names,
    observed,
    predictive_bands,
    to_inference_data,
)

# --------------------------------------------------------------------------------------
# NetCDF.


def netcdf_engine() -> str | None:
    """The NetCDF-4 engine xarray can use here, or None."""
    for module, engine in (("h5netcdf", "h5netcdf"), ("netCDF4", "netcdf4")):
        if importlib.util.find_spec(module) is not None:
            return engine
    return None


def muscle_file_stem(result, i: int) -> str:
    """Muscle ``i``'s name in file names: its name made safe, unique among the result's
    muscles (:func:`pamid._io.safe_file_names`), or "muscle" ("muscle<i>" among several
    unnamed ones)."""
    m = result.muscles[i]
    if m is None:
        return "muscle" if result.n_muscles == 1 else f"muscle{i}"
    return safe_file_names(result.muscles)[i]


def save_netcdf(result, directory, muscles=None, *, owners: dict | None = None) -> list[str]:
    """Write each muscle's DataTree (posterior, sample_stats, log_likelihood,
    posterior_predictive, observed_data, constant_data; units in the attributes) to
    ``directory``/``mcmc_<muscle>.nc``, atomically; without a NetCDF-4 engine a folder
    ``mcmc_<muscle>.nc3`` of NetCDF-3 files instead, with a warning. ``muscles``: indices
    (default all). Returns the names written; :func:`pamid.load_inference_data` reads them.
    ``owners``, a dict, gets {name written: muscle}."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for i in range(result.n_muscles) if muscles is None else muscles:
        dt = to_inference_data(result, i)
        written.append(write_datatree(dt, directory / f"mcmc_{muscle_file_stem(result, i)}.nc"))
        if owners is not None:
            owners[written[-1]] = result.muscles[i]
    return written


def write_datatree(dt, path) -> str:
    """Write a DataTree as NetCDF-4 to ``path``, or, without a NetCDF-4 engine, as one
    NetCDF-3 file per group in the folder ``path`` + ``3`` (with a warning). Returns the
    name written."""
    path = Path(path)
    engine = netcdf_engine()
    if engine is not None:
        write_atomic(path, lambda tmp: dt.to_netcdf(tmp, engine=engine))
        return path.name
    folder = path.with_suffix(path.suffix + "3")
    warnings.warn(f"no NetCDF-4 engine (install h5netcdf): wrote {folder.name}/, one "
                  "NetCDF-3 file per group; read it with pamid's load_inference_data",
                  stacklevel=3)
    folder.mkdir(parents=True, exist_ok=True)
    for name, node in dt.children.items():
        ds = node.to_dataset()
        ds.attrs = encode_attrs(ds.attrs)
        for v in ds.variables.values():
            v.attrs = encode_attrs(v.attrs)
        write_atomic(folder / f"{name}.nc",
                     lambda tmp, ds=ds: ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT"))
    return folder.name


# --------------------------------------------------------------------------------------
# Figures.


def _finish(fig, path, dpi=100):
    """Save (atomically) and close the pyplot figure if ``path`` is given, returning None;
    else return it (a notebook shows it)."""
    import matplotlib.pyplot as plt

    if path is None:
        return fig
    save_figure_atomic(fig, path, dpi=dpi)
    plt.close(fig)
    return None


def plot_trace(result, i: int = 0, path=None, title: str | None = None):
    """Muscle ``i``'s trace and marginal density of every constant and of the noise σ [N]
    (ArviZ; walkers as chains, burn-in dropped). Saved to ``path`` (PNG) if given, else the
    matplotlib figure is returned."""
    import arviz as az

    dt = to_inference_data(result, i, predictive=False)
    pc = az.plot_trace_dist(dt, backend="matplotlib", compact=True, combined=True)
    fig = pc.get_viz("figure")
    fig.suptitle(title or f"MCMC traces — {result.spec.source}", y=1.0)
    return _finish(fig, path)


def plot_pair(result, i: int = 0, path=None, title: str | None = None):
    """Muscle ``i``'s pair plot of the constants (ArviZ: posterior draws two by two, with
    the marginals), in the model's units. Saved to ``path`` if given, else returned."""
    import arviz as az

    dt = to_inference_data(result, i, predictive=False)
    size = 1.7 * len(result.param_names) + 1.0
    pm = az.plot_pair(dt, var_names=list(result.param_names), backend="matplotlib",
                      figure_kwargs={"figsize": (size, size)},
                      visuals={"scatter": {"alpha": 0.15, "s": 2}})
    fig = pm.get_viz("figure")
    fig.suptitle(title or f"Posterior of the constants — {result.spec.source}")
    for ax in fig.axes:  # long tick labels of neighbouring panels must not collide
        ax.tick_params(labelsize=7)
        ax.tick_params(axis="x", labelrotation=30)
    if not fig.get_constrained_layout():
        fig.subplots_adjust(wspace=0.45, hspace=0.45)
    return _finish(fig, path)


def plot_predictive(result, i: int = 0, path=None, title: str | None = None):
    """Muscle ``i``'s data against the posterior, per pressure level. Top: data [N],
    posterior-mean force and the 95% posterior-predictive band. Bottom, relative to the
    posterior mean (where the bands are visible at all): residuals, the 95% predictive band
    (dashed) and the 95% credible band of the model force (filled). Saved to ``path`` if
    given, else returned."""
    import matplotlib.pyplot as plt

    spec = result.spec
    x, y, _, _ = observed(result, i)
    names = input_names(spec)
    p_in, k_in = x[0], x[1]
    levels = np.unique(np.round(p_in, 6))
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, max(len(levels), 1)))
    mean_at_data = np.asarray(spec.predict(jnp.asarray(result.theta_mean[i]),
                                           tuple(jnp.asarray(a) for a in x)))
    p_unit = names[0].split("_", 1)[1] if "_" in names[0] else ""
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(7.5, 8.0), sharex=True,
                                  gridspec_kw={"height_ratios": [2.2, 1.6]})
    for level, color in zip(levels, colors):
        sel = np.round(p_in, 6) == level
        grid = np.linspace(k_in[sel].min(), k_in[sel].max(), 120)
        mean, band, pband = predictive_bands(result, i, level, grid)
        ax.fill_between(grid, *pband, color=color, alpha=0.25, lw=0)
        ax.plot(grid, mean, "-", color=color, lw=1.2, label=f"{level:.3g} {p_unit}")
        ax.plot(k_in[sel], y[sel], "o", ms=3.5, mfc="none", color=color)
        for edge in pband:
            axr.plot(grid, edge - mean, "--", color=color, lw=0.9)
        axr.fill_between(grid, band[0] - mean, band[1] - mean, color=color, alpha=0.5, lw=0)
        axr.plot(k_in[sel], (y - mean_at_data)[sel], "o", ms=3, mfc="none", color=color)
    axr.axhline(0.0, color="k", lw=0.8)
    ax.set_ylabel("force F [N]")
    ax.set_title(title or f"Posterior predictive — {spec.source}")
    ax.legend(title=f"{names[0].split('_')[0]} (band: 95% predictive)", fontsize=7,
              title_fontsize=8, loc="upper right", ncol=2 if len(levels) > 8 else 1)
    ax.grid(alpha=0.3)
    axr.set_xlabel(names[1].replace("_pct", " [%]").replace("_mm", " [mm]"))
    axr.set_ylabel("data − posterior mean [N]")
    axr.set_title("dashed: 95% predictive band (noise included); band: 95% credible band "
                  "of the model force", fontsize=8)
    axr.grid(alpha=0.3)
    fig.tight_layout()
    return _finish(fig, path, dpi=110)


def write_mcmc_plots(result, bench, folder, n_muscles: int, *,
                     owners: dict | None = None) -> list[str]:
    """What ``pamid fit --method mcmc --out`` draws for its first ``n_muscles`` muscles:
    ``mcmc_trace_<muscle>.png``, ``mcmc_pair_<muscle>.png`` and
    ``mcmc_predictive_<muscle>.png``, each written atomically into ``folder``; ``bench``
    (the file sampled) names an unnamed muscle in the titles. Returns the names written;
    ``owners``, a dict, gets {file name: muscle}."""
    folder = Path(folder)
    written = []
    for i in range(n_muscles):
        stem = muscle_file_stem(result, i)
        label = result.muscles[i] if result.muscles[i] is not None else Path(bench.path).name
        src = result.spec.source
        for kind, plot, title in (
            ("trace", plot_trace, f"MCMC traces — {src} — {label}"),
            ("pair", plot_pair, f"Posterior of the constants — {src} — {label}"),
            ("predictive", plot_predictive, f"Posterior predictive — {src} — {label}"),
        ):
            name = f"mcmc_{kind}_{stem}.png"
            plot(result, i, folder / name, title)
            written.append(name)
            if owners is not None:
                owners[name] = result.muscles[i]
    return written
