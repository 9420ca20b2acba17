"""Figures a person would rather look at than read: data against model, and residuals.

The drawing of one muscle's rows (a bench frame, a model and its constants), shared by the
fit's figures (:mod:`._fit`), the comparison's (:mod:`._compare`) and the diagnosis's
(:mod:`._diagnosis`, which takes its subsampling and labels from here).

Every bench file gives figures a person can read, whatever its size or noise:

* the data are drawn per curve, as :func:`pamid._data._curves.find_curves` defines them:
  force against contraction at each held pressure for sweeps, force against pressure at
  each held contraction for isometric tests; a file that holds both gets both panels;
* where the curves' levels do not hold their input (a map logged by hand: the length held
  within a few mm while the pressure goes up and down, no time column), the view is chosen
  by the data (:func:`choose_view`): force against the other input at the levels one input
  keeps in the data, else force against pressure per contraction bin, so that every point
  has its model line;
* beside them, measured against predicted force for every file;
* samples taken while the muscle is driven to contract (direction +1: contraction rising
  in a sweep, pressure rising at a held length) are filled markers, the others open ones,
  explained once in the legend;
* up to :data:`MAX_LISTED` held levels are listed in the legend; more are coloured by a
  colour bar, and the model is drawn at no more than :data:`MAX_LINES` levels (neighbouring
  levels binned together);
* an axes shows at most :data:`MAX_POINTS` samples: every k-th sample of each curve, so
  that every curve keeps points, and the figure says so.
"""

from __future__ import annotations

import functools
import math
import textwrap
from dataclasses import dataclass
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.colors import ListedColormap, Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from .._io import save_figure_atomic  # noqa: E402

#: Most samples drawn in one axes; bigger files are drawn from every k-th sample per curve.
MAX_POINTS = 20_000
#: Most model lines per panel; more held levels are binned.
MAX_LINES = 20
#: Most held levels (or trials) listed in a legend; more get a colour bar instead.
MAX_LISTED = 5
#: Up to this many samples per axes are drawn on top of the model lines, more beneath.
SPARSE_POINTS = 2_000
#: Points along the moving input at which a model line is evaluated.
GRID_POINTS = 120
#: Held levels closer than this fraction of their range are drawn as one level.
LEVEL_MERGE_FRACTION = 0.02
#: A view holds an input when each of its levels' samples (5th–95th percentile) span at most
#: this fraction of the input's range in the panel.
HELD_SPREAD = 0.2
#: Levels found in the data: sorted values part where they leave a gap wider than this
#: fraction of the input's range.
LEVEL_GAP = 0.04
#: Contraction bins of a map where neither input is held (the samples scattered).
CONTRACTION_BINS = 4

_LABELS = {
    "contraction_pct": "contraction κ [%]",
    "contraction_mm": "contraction y [mm]",
    "pressure_kPa": "pressure p [kPa]",
    "force_N": "force F [N]",
    "elapsed_s": "elapsed time [s]",
    "time_s": "time [s]",
    "direction": "direction (+1 contracting, −1 extending)",
}
_UNITS = {"contraction_pct": "%", "contraction_mm": "mm", "pressure_kPa": "kPa"}
# viridis without its palest yellow, which vanishes on a white background
_CMAP = ListedColormap(matplotlib.colormaps["viridis"](np.linspace(0.0, 0.88, 256)),
                       name="viridis_dark")
_DPI = 110
# a dark edge keeps a model line visible on top of its own level's samples
_HALO = [patheffects.Stroke(linewidth=3.6, foreground="black"), patheffects.Normal()]


# --------------------------------------------------------------------------------------
# Rows, model and subsampling
# --------------------------------------------------------------------------------------


def _grid(ax) -> None:
    """A light grid at up to six ticks per axis (matplotlib's default chooses up to ~9 on
    these panels; every tick is an object to lay out and draw: 5 instead cut ~15 % of the
    CPU time of ``pamid fit --out``'s figures, benchmarks/README.md)."""
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
    ax.grid(alpha=0.3)


def _save(fig, path) -> None:
    """Write ``fig`` to ``path`` atomically at :data:`_DPI`; PNG unless the extension says
    else. Without a ``path`` (None) nothing is written: the figure is only returned.

    A PNG is laid out once, then drawn once: ``savefig`` lays a figure with a layout engine
    out in a dry-run draw and again in the real one, measuring every text twice (most of a
    figure's time); here the constrained layout runs once on an Agg canvas and the engine is
    then dropped, so that ``savefig`` draws the figure as laid out (the same pixels). zlib's
    fastest level encodes it (files ~10 % larger). The 13 figures of ``pamid fit --out`` on
    the AARL file, with :func:`_grid`'s ticks: 2.6 → 2.0 s of CPU (benchmarks/README.md)."""
    if path is None:
        return
    if Path(path).suffix.lower() not in ("", ".png"):
        save_figure_atomic(fig, path, dpi=_DPI)
        return
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)  # the renderer the layout measures text with
    fig.set_dpi(_DPI)
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine(None)  # laid out: savefig draws it once, as it is
    save_figure_atomic(fig, path, dpi=_DPI, pil_kwargs={"compress_level": 1})


@functools.cache
def _jitted(predict):
    return jax.jit(predict)


def _predict(spec, theta, x) -> np.ndarray:
    """``spec.predict`` compiled once per length bucket: the inputs are padded to the next
    power of two (at least 256), so that muscles and grids of any size reuse a few
    programs instead of compiling every operation for every length."""
    n = len(x[0])
    if n == 0:
        return np.zeros(0)
    m = max(256, 1 << (n - 1).bit_length())
    xp = tuple(np.pad(np.asarray(a, np.float64), (0, m - n), mode="edge") for a in x)
    return np.asarray(_jitted(spec.predict)(np.asarray(theta, np.float64), xp))[:n]


def _model_on_rows(spec, theta, frame):
    return _predict(spec, theta, spec.x_from_frame(frame))


def _model_curve(spec, theta, p_kpa, contraction):
    """The model at rest (velocities zero) at the given pressures and contractions
    (arrays or scalars, broadcast together): lines along either input."""
    p_kpa, contraction = np.broadcast_arrays(np.asarray(p_kpa, np.float64),
                                             np.asarray(contraction, np.float64))
    cols = {c: np.zeros_like(contraction) for c in spec.columns}
    cols["pressure_kPa"] = p_kpa
    cols[spec.contraction_column] = contraction
    return _predict(spec, theta, spec.to_x(*(cols[c] for c in spec.columns)))


def _dense(groups) -> np.ndarray:
    """Dense 0-based codes of any array of group keys."""
    return np.unique(np.asarray(groups), return_inverse=True)[1].ravel()


def every_kth(groups, max_points: int = MAX_POINTS) -> tuple[np.ndarray, int]:
    """Rows to draw: every k-th row of each group, counted from the group's first row.

    ``groups`` holds one key per row (a curve id, say). ``k`` is the smallest stride that
    keeps at most ``max_points`` rows while every group keeps its first row; when there
    are too many groups for that, every k-th row of the whole table. Returns the kept row
    indices (ascending) and ``k`` (1 when every row is kept).
    """
    n = len(groups)
    if n <= max_points:
        return np.arange(n), 1
    codes = _dense(groups)
    sizes = np.bincount(codes)
    if len(sizes) > max_points // 2:
        k = math.ceil(n / max_points)
        return np.arange(0, n, k), k

    def kept(k: int) -> int:
        return int(np.sum(-(-sizes // k)))

    lo, hi = math.ceil(n / max_points), math.ceil(n / (max_points - len(sizes)))
    while lo < hi:  # the smallest k with kept(k) <= max_points (kept falls as k grows)
        mid = (lo + hi) // 2
        if kept(mid) <= max_points:
            hi = mid
        else:
            lo = mid + 1
    order = np.argsort(codes, kind="stable")
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n) - np.repeat(starts, sizes)
    return np.flatnonzero(rank % lo == 0), lo


def _ordinal(k: int) -> str:
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def axis_label(column: str) -> str:
    """A column's name as an axis shows it: quantity and unit where pamid knows them."""
    return _LABELS.get(column, column)


def shown(k: int, n: int) -> str:
    """The note a subsampled figure carries ("every 5th of 100,000 samples shown")."""
    return "" if k == 1 else f"every {_ordinal(k)} of {n:,} samples shown"


def _curves_of(frame, spec, curves):
    if curves is not None:
        return curves
    from .._data._curves import find_curves

    return find_curves(frame, contraction_column=spec.contraction_column)


class _Rows:
    """One muscle's samples as the plots need them."""

    def __init__(self, frame, spec, theta, curves):
        self.spec = spec
        self.col = spec.contraction_column
        self.n = len(frame)
        self.p = frame["pressure_kPa"].to_numpy(np.float64)
        self.c = frame[self.col].to_numpy(np.float64)
        self.f = frame["force_N"].to_numpy(np.float64)
        self.model = _model_on_rows(spec, theta, frame)
        self.resid = self.f - self.model
        self.curves = _curves_of(frame, spec, curves)
        self.trial_names = (frame["trial"].astype(str).to_numpy() if "trial" in frame
                            else None)


def _level_groups(level: np.ndarray, max_groups: int = MAX_LINES):
    """Group rows by held level: each group starts at the lowest level not yet grouped and
    takes every level within :data:`LEVEL_MERGE_FRACTION` of the range above it (a set
    point read through sensor noise; no chaining, so evenly spread levels still part);
    more than ``max_groups`` groups are binned into ``max_groups`` runs of neighbouring
    groups. Returns the group of each row and the number of groups."""
    u = np.unique(level)
    if len(u) == 0:
        return np.zeros(0, dtype=np.int64), 0
    tol = LEVEL_MERGE_FRACTION * (u[-1] - u[0])
    starts = [0]  # one step per group: at most 1 / LEVEL_MERGE_FRACTION + 1 of them
    while (nxt := int(np.searchsorted(u, u[starts[-1]] + tol, side="right"))) < len(u):
        starts.append(nxt)
    new = np.zeros(len(u), dtype=bool)
    new[starts] = True
    cluster = np.cumsum(new) - 1
    n = len(starts)
    if n > max_groups:
        cluster = _dense(cluster * max_groups // n)
        n = int(cluster.max()) + 1
    return cluster[np.searchsorted(u, level)], n


def _norm(values) -> Normalize:
    lo, hi = float(np.min(values)), float(np.max(values))
    if hi <= lo:
        lo, hi = lo - 1.0, hi + 1.0
    return Normalize(lo, hi)


def _level_names(values, unit: str) -> list[str]:
    """Levels as a legend lists them: to about a hundredth of their range (3 significant
    digits for a single level), so that 0 reads "0.0 %", not "-6.25e-05 %"."""
    values = np.asarray(values, np.float64)
    span = float(np.ptp(values)) if len(values) > 1 else 0.0
    scale = span if span > 0 else float(np.max(np.abs(values))) or 1.0
    decimals = min(6, max(0, 2 - math.floor(math.log10(scale))))
    return [f"{np.round(v, decimals) + 0.0:.{decimals}f} {unit}" for v in values]


def _points(ax, x, y, code, palette, direction, layers: int = 4, over_lines=False):
    """Samples as markers, one colour per ``code`` (``palette[code]``): filled where the
    muscle is driven to contract, open elsewhere. One marker line per colour, direction
    and layer: Agg stamps those far faster than a collection coloured point by point. The
    rows are dealt into ``layers`` interleaved layers (every ``layers``-th row), drawn
    layer by layer, so that no colour is hidden under all the others. ``over_lines``:
    bigger markers, drawn over the model lines and outlined so that they stand out on a
    line of their own colour (filled: a dark edge; open: a white face)."""
    up = direction == 1.0
    layer = np.arange(len(x)) % layers
    for ell in range(layers):
        for g in np.unique(code):
            for filled in (True, False):
                s = (layer == ell) & (code == g) & (up if filled else ~up)
                if not s.any():
                    continue
                if over_lines:
                    ax.plot(x[s], y[s], ls="none", marker="o", ms=5, mew=1.0 if filled else 1.3,
                            color=palette[g], mec="0.1" if filled else palette[g],
                            mfc=palette[g] if filled else "white", zorder=4)
                else:
                    ax.plot(x[s], y[s], ls="none", marker="o", ms=3.2, mew=0.7,
                            color=palette[g], mfc=palette[g] if filled else "none",
                            alpha=0.75, zorder=2)


def _direction_handles(direction, names):
    handles = []
    for d, name in zip((1.0, -1.0), names):
        if np.any(direction == d if d > 0 else direction != 1.0):
            handles.append(Line2D([], [], ls="none", marker="o", ms=5, color="0.3",
                                  mfc="0.3" if d > 0 else "none", label=name))
    return handles


def wrap(title: str, width: int) -> str:
    """A title broken into lines of at most ``width`` characters (long muscle names)."""
    return "\n".join(textwrap.wrap(title, width)) or title


# --------------------------------------------------------------------------------------
# Data against model
# --------------------------------------------------------------------------------------

_KINDS = {
    # moving == 0: the contraction moves at a held pressure; moving == 1: the reverse
    0: {"title": "sweeps: force against contraction at held pressures",
        "directions": ("contracting (filled)", "extending (open)")},
    1: {"title": "isometric tests: force against pressure at held contractions",
        "directions": ("inflating (filled)", "deflating (open)")},
}


@dataclass(frozen=True)
class View:
    """How one panel draws its rows: force against the ``moving`` input (0: the
    contraction, lines at held pressures; 1: the pressure, lines at held contractions),
    grouped by ``level`` (each row's held level), as ``kind`` found it: ``"curves"``, the
    curves of :func:`pamid._data._curves.find_curves` (the protocol); ``"levels"``, levels
    the held input keeps in the data; ``"bins"``, bins of the contraction where neither
    input is held. ``direction``: +1 where the moving input is driven up (filled markers)."""

    moving: int
    level: np.ndarray
    kind: str
    direction: np.ndarray
    title: str


def _spread(held: np.ndarray, group: np.ndarray, n: int) -> float:
    """The widest level's spread of a held input (5th–95th percentile of its samples) as a
    fraction of the input's range; 0 for an input with one value."""
    span = float(np.ptp(held)) if len(held) else 0.0
    if span == 0.0:
        return 0.0
    widest = 0.0
    for g in range(n):
        values = held[group == g]
        if len(values) > 1:
            lo, hi = np.percentile(values, [5.0, 95.0])
            widest = max(widest, float(hi - lo))
    return widest / span


def _gap_levels(values: np.ndarray) -> tuple[np.ndarray, int]:
    """Levels of an input found in the data: its sorted values part wherever they leave a gap
    wider than :data:`LEVEL_GAP` of their range. Returns each row's level and their number."""
    u = np.unique(values)
    span = float(u[-1] - u[0]) if len(u) else 0.0
    if span == 0.0:
        return np.zeros(len(values), dtype=np.int64), 1
    tops = u[:-1][np.diff(u) > LEVEL_GAP * span]
    return np.searchsorted(tops, values, side="left"), len(tops) + 1


def _held_in_data(held: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, int] | None:
    """Levels at which ``held`` is held while ``other`` moves, found in the data: levels
    parted by gaps (:func:`_gap_levels`) no narrower than the widest level (so that samples
    scattered evenly, whose gaps are random, make no levels), each spanning at most
    :data:`HELD_SPREAD` of the range, three samples or more per level on average, and
    ``other`` covering a third of its range or more within a typical level. None where the
    data hold no such levels."""
    group, n = _gap_levels(held)
    if n < 2 or n * 3 > len(held):
        return None
    spread = _spread(held, group, n)
    lows = np.array([held[group == g].min() for g in range(n)])
    highs = np.array([held[group == g].max() for g in range(n)])
    if spread > HELD_SPREAD or np.min(lows[1:] - highs[:-1]) < spread * np.ptp(held):
        return None
    span = float(np.ptp(other))
    moves = [float(np.ptp(other[group == g])) for g in range(n) if np.any(group == g)]
    if span == 0.0 or np.median(moves) < span / 3:
        return None
    return group, n


def _driven_up(x: np.ndarray, group: np.ndarray, recorded: np.ndarray,
               recorded_direction: np.ndarray) -> np.ndarray:
    """+1 where the moving input rises from the previous sample of its level to the next
    (file order), −1 where it falls; the recorded direction wherever the file has one."""
    direction = np.ones(len(x))
    for g in np.unique(group):
        at = np.flatnonzero(group == g)
        if len(at) > 1:
            direction[at] = np.where(np.gradient(x[at]) < 0.0, -1.0, 1.0)
    return np.where(recorded, recorded_direction, direction)


def choose_view(r: _Rows, rows: np.ndarray, moving: int) -> View:
    """The view of one kind of curve's rows, chosen by the data: the curves' own (force
    against the moving input at each held level) where their levels hold the held input
    (:data:`HELD_SPREAD`); else levels that one input keeps in the data while the other moves
    (a hand-logged isometric map: length held within a few mm while the pressure goes up and
    down), the fewer levels first; else force against pressure per contraction bin."""
    cv = r.curves
    p, c = r.p[rows], r.c[rows]
    level = cv.level[rows]
    group, n = _level_groups(level)
    held = p if moving == 0 else c
    if _spread(held, group, n) <= HELD_SPREAD:
        return View(moving, level, "curves", cv.direction[rows], _KINDS[moving]["title"])
    found = []
    for view_moving, held, other in ((1, c, p), (0, p, c)):
        levels = _held_in_data(held, other)
        if levels is not None:
            found.append((levels[1], view_moving, levels[0], held))
    recorded = cv.direction_recorded[rows]
    if found:
        _, view_moving, group, held = min(found, key=lambda f: f[0])
        medians = np.array([np.median(held[group == g]) for g in range(group.max() + 1)])
        x = c if view_moving == 0 else p
        half = float(np.max(np.abs(held - medians[group])))
        what = ("force against contraction at held pressures" if view_moving == 0 else
                "force against pressure at held contractions")
        unit = "kPa" if view_moving == 0 else _UNITS[r.col]
        title = f"{what} (levels in the data, each held within ±{half:.2g} {unit})"
        return View(view_moving, medians[group], "levels",
                    _driven_up(x, group, recorded, cv.direction[rows]), title)
    edges = np.unique(np.quantile(c, np.linspace(0.0, 1.0, CONTRACTION_BINS + 1))[1:-1])
    group = np.searchsorted(edges, c, side="right")
    medians = np.array([np.median(c[group == g]) if np.any(group == g) else np.nan
                        for g in range(len(edges) + 1)])
    title = ("force against pressure per contraction bin (neither input held: lines at "
             "each bin's median contraction)")
    return View(1, medians[group], "bins", _driven_up(p, group, recorded, cv.direction[rows]),
                title)


def _fit_panel(fig, ax, axr, r: _Rows, rows: np.ndarray, moving: int, theta):
    """One kind of curve, drawn as :func:`choose_view` decides: data coloured by held level,
    model at the (binned) levels, the residual below. Returns the rows drawn, their colour
    codes and the palette (for the measured-against-predicted panel)."""
    spec = r.spec
    view = choose_view(r, rows, moving)
    moving = view.moving
    x_all, held_all = (r.c, r.p) if moving == 0 else (r.p, r.c)
    x_name, held_name = ((r.col, "pressure_kPa") if moving == 0 else ("pressure_kPa", r.col))
    held_label, held_unit = _LABELS[held_name], _UNITS[held_name]
    if view.kind == "bins":
        held_label = f"{held_label}, bin median"
    level = view.level
    direction = view.direction
    group, n_groups = _level_groups(level)
    rep = np.array([np.median(level[group == g]) for g in range(n_groups)])
    listed = n_groups <= MAX_LISTED
    norm = _norm(level)
    palette = _CMAP(norm(rep))

    # model lines: at each group's held value (median of its samples), across the range
    # of the moving input its samples cover, evaluated on a grid in one call
    held_vals, xs = [], []
    for g in range(n_groups):
        s = group == g
        held_vals.append(np.median(held_all[rows][s]))
        xs.append(np.linspace(x_all[rows][s].min(), x_all[rows][s].max(), GRID_POINTS))
    held_grid = np.repeat(held_vals, GRID_POINTS)
    x_grid = np.concatenate(xs)
    p_grid, c_grid = (held_grid, x_grid) if moving == 0 else (x_grid, held_grid)
    f_grid = _model_curve(spec, theta, p_grid, c_grid).reshape(n_groups, GRID_POINTS)

    keep, k = every_kth(r.curves.curve[rows])
    sub = rows[keep]
    # a few samples are drawn over the model lines, a dense cloud under them
    _points(ax, x_all[sub], r.f[sub], group[keep], palette, direction[keep],
            over_lines=len(keep) <= SPARSE_POINTS)
    _points(axr, x_all[sub], r.resid[sub], group[keep], palette, direction[keep])
    for g in range(n_groups):
        if xs[g][-1] > xs[g][0]:
            ax.plot(xs[g], f_grid[g], "-", lw=1.8, color=palette[g], zorder=3,
                    path_effects=_HALO)
        else:  # the level's samples sit at one value of the moving input: a tick there
            ax.plot(xs[g][:1], f_grid[g][:1], "_", ms=12, mew=1.8, color=palette[g], zorder=3,
                    path_effects=_HALO)

    handles = []
    if listed:
        handles += [Line2D([], [], color=palette[g], marker="o", ms=4, ls="none", label=name)
                    for g, name in enumerate(_level_names(rep, held_unit))]
    handles += _direction_handles(direction, _KINDS[moving]["directions"])
    handles.append(Line2D([], [], color="0.6", lw=1.8, path_effects=_HALO,
                          label=f"model: {spec.source}"))
    if listed:  # the levels' names: beside the panel
        ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                  borderaxespad=0.0, title=held_label, title_fontsize=8)
    else:
        # Two or three entries, the levels in the colour bar: inside the panel where it
        # hides least. Beside it, the legend's width was kept free down the whole column,
        # a wide empty band between the panels and the colour bar.
        ax.legend(handles=handles, fontsize=8, loc="best", framealpha=0.85)
    if not listed:
        cbar = fig.colorbar(ScalarMappable(norm, _CMAP), ax=[ax, axr], location="right",
                            aspect=35, pad=0.02)
        binned = len(np.unique(level)) > n_groups
        cbar.set_label(held_label + (f" ({n_groups} bins of levels)" if binned else ""),
                       fontsize=8)
        cbar.ax.tick_params(labelsize=8)
    note = shown(k, len(rows))
    ax.set_title(wrap(view.title, 70) + (f"\n{note}" if note else ""), fontsize=9)
    ax.set_ylabel("force F [N]")
    _grid(ax)
    axr.axhline(0.0, color="k", lw=0.8)
    axr.set_xlabel(_LABELS[x_name])
    axr.set_ylabel("residual [N]\n(data − model)")
    _grid(axr)
    return sub, group[keep], palette, direction[keep]


def _measured_panel(ax, r: _Rows, drawn) -> None:
    """Measured force against the model's force on the same rows (every input the model
    takes), coloured as the panels beside it, with the line of perfect agreement."""
    for sub, code, palette, direction in drawn:
        _points(ax, r.model[sub], r.f[sub], code, palette, direction,
                over_lines=len(sub) <= SPARSE_POINTS)
    lo = float(min(r.model.min(), r.f.min()))
    hi = float(max(r.model.max(), r.f.max()))
    pad = 0.04 * (hi - lo or 1.0)
    ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], "--", color="0.25", lw=1.0, zorder=5)
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_aspect("equal", adjustable="box")
    rmse = float(np.sqrt(np.mean(r.resid**2)))
    ax.text(0.03, 0.97, f"n = {r.n:,}\nRMSE = {rmse:.3g} N\n– – measured = model",
            transform=ax.transAxes, va="top", fontsize=8,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.7"})
    ax.set_title("measured against predicted", fontsize=9)
    ax.set_xlabel("model force F̂ [N]")
    ax.set_ylabel("measured force F [N]")
    _grid(ax)


def plot_fit(frame, spec, theta, path, title: str, *, curves=None) -> Figure:
    """Force against the moving input per held level, data and fitted model, residuals
    below; one column of panels per kind of curve in the file (sweeps, isometric tests),
    each drawn as :func:`choose_view` decides; last, measured against predicted force.

    ``frame`` is one muscle's rows of a bench table; ``spec`` the fitted model
    (``pamid._fit._spec.ModelSpec``) and ``theta`` its constants; ``curves`` the rows'
    :class:`pamid._data._curves.Curves` (found here when not given). Model lines are drawn
    at rest (zero velocity); residuals use every column the model takes. Writes ``path``
    atomically (unless it is None) and returns the figure (for inspection; it is not
    shown).
    """
    r = _Rows(frame, spec, theta, curves)
    kinds = [m for m in (0, 1) if np.any(r.curves.moving == m)]
    fig = Figure(figsize=(8.2 * len(kinds) + 4.6, 7.2), layout="constrained")
    gs = fig.add_gridspec(2, len(kinds) + 1, height_ratios=[3, 1.3],
                          width_ratios=[8.2] * len(kinds) + [4.6])
    drawn = []
    for j, moving in enumerate(kinds):
        ax = fig.add_subplot(gs[0, j])
        axr = fig.add_subplot(gs[1, j], sharex=ax)
        ax.tick_params(labelbottom=False)
        rows = np.flatnonzero(r.curves.moving == moving)
        drawn.append(_fit_panel(fig, ax, axr, r, rows, moving, theta))
    _measured_panel(fig.add_subplot(gs[:, -1]), r, drawn)
    fig.suptitle(wrap(title, 70 * len(kinds) + 40), fontsize=11)
    _save(fig, path)
    return fig


# --------------------------------------------------------------------------------------
# Residuals
# --------------------------------------------------------------------------------------


def _direction_names(moving: np.ndarray) -> tuple[str, str]:
    if np.all(moving == 1):
        return _KINDS[1]["directions"]
    if np.all(moving == 0):
        return _KINDS[0]["directions"]
    return ("contracting / inflating (filled)", "extending / deflating (open)")


def _residual_colors(r: _Rows, direction: np.ndarray, moving: np.ndarray):
    """Colour code of each row, its palette, the legend handles and an optional colour
    bar: the direction for one trial, the trial for a few, the repeat when many trials
    repeat a few settings, else the trial's order (binned) with a colour bar.
    ``direction`` and ``moving``: each row's, as the fit figure draws them."""
    cv = r.curves
    trials = np.unique(cv.trial)
    repeats = np.unique(cv.repeat)
    tab = matplotlib.colormaps["tab10"]
    if len(trials) <= 1:
        code = (direction != 1.0).astype(np.int64)
        names = _direction_names(moving)
        handles = [Line2D([], [], ls="none", marker="o", ms=5, color=tab(3 * i),
                          mfc=tab(0) if i == 0 else "none", label=names[i])
                   for i in (0, 1) if np.any(code == i)]
        return code, [tab(0), tab(3)], handles, None, None
    handles = _direction_handles(direction, _direction_names(moving))
    if len(trials) <= MAX_LISTED:
        for i, t in enumerate(trials):
            first = np.flatnonzero(cv.trial == t)[0]
            name = r.trial_names[first] if r.trial_names is not None else f"{t + 1}"
            handles.append(Line2D([], [], ls="none", marker="o", ms=5, color=tab(i % 10),
                                  label=f"trial {name}"))
        return _dense(cv.trial), [tab(i % 10) for i in range(len(trials))], handles, None, None
    if 1 < len(repeats) <= MAX_LISTED:
        handles += [Line2D([], [], ls="none", marker="o", ms=5, color=tab(i % 10),
                           label=f"repeat {rep + 1} of a setting")
                    for i, rep in enumerate(repeats)]
        return (_dense(cv.repeat), [tab(i % 10) for i in range(len(repeats))], handles,
                None, None)
    number = cv.trial + 1.0
    code, n = _level_groups(number)
    norm = _norm(number)
    palette = _CMAP(norm([np.median(number[code == g]) for g in range(n)]))
    return code, palette, handles, norm, "trial, in file order"


def plot_residuals(frame, spec, theta, path, title: str, *, curves=None) -> Figure:
    """Residuals against the moving input, the held level, the elapsed time (trials end
    to end) and the fitted force. A file that mixes sweeps and isometric tests has no one
    moving input: its first panels are the contraction and the pressure as measured.

    Arguments as :func:`plot_fit`; writes ``path`` atomically (unless it is None) and
    returns the figure.
    """
    r = _Rows(frame, spec, theta, curves)
    cv = r.curves
    keep, k = every_kth(cv.curve)
    direction, moving_of = cv.direction, cv.moving
    if np.all(cv.moving == cv.moving[0]):
        view = choose_view(r, np.arange(r.n), int(cv.moving[0]))  # as the fit figure draws
        moving = view.moving
        direction, moving_of = view.direction, np.full(r.n, moving)
        x_name, held_name = ((r.col, "pressure_kPa") if moving == 0 else ("pressure_kPa", r.col))
        of = {"curves": "level of the curve", "levels": "level in the data",
              "bins": "bin median"}[view.kind]
        first = [(r.c if moving == 0 else r.p, _LABELS[x_name] + " (moving)"),
                 (view.level, f"held {_LABELS[held_name]} ({of})")]
    else:
        first = [(r.c, _LABELS[r.col]), (r.p, _LABELS["pressure_kPa"])]
    if np.all(np.isfinite(cv.elapsed_s)):
        end = float(np.max(cv.elapsed_s, initial=0.0))
        per, unit = (3600.0, "h") if end > 7200 else (60.0, "min") if end > 600 else (1.0, "s")
        when = (cv.elapsed_s / per, f"elapsed time [{unit}] (trials end to end)")
    else:
        when = (np.arange(r.n, dtype=np.float64), "sample, in file order")
    panels = [*first, when, (r.model, "fitted force [N]")]
    code, palette, handles, norm, cbar_label = _residual_colors(r, direction, moving_of)

    fig = Figure(figsize=(10, 7.2), layout="constrained")
    axes = fig.subplots(2, 2, sharey=True)
    for ax, (xv, label) in zip(axes.ravel(), panels):
        _points(ax, xv[keep], r.resid[keep], code[keep], palette, direction[keep])
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(label)
        _grid(ax)
    for ax in axes[:, 0]:
        ax.set_ylabel("residual [N] (data − model)")
    if norm is not None:
        cbar = fig.colorbar(ScalarMappable(norm, _CMAP), ax=axes, location="right",
                            aspect=30)
        cbar.set_label(cbar_label, fontsize=9)
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
               fontsize=8)
    note = shown(k, r.n)
    fig.suptitle(wrap(title, 90) + (f"\n{note}" if note else ""), fontsize=11)
    _save(fig, path)
    return fig


def plot_rmse_histogram(rmse, path, title: str) -> Figure:
    """Distribution of the fit RMSE [N] across many muscles; written to ``path`` (unless it
    is None) and returned."""
    fig = Figure(figsize=(6.5, 4), layout="constrained")
    ax = fig.subplots()
    ax.hist(np.asarray(rmse), bins=min(60, max(10, len(rmse) // 20)), color="tab:blue")
    ax.set_xlabel("RMSE of the fit [N]")
    ax.set_ylabel("muscles")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(wrap(title, 70))
    ax.grid(alpha=0.3)
    _save(fig, path)
    return fig
