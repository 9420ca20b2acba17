"""Curves, direction and trials of a bench file: the one definition every step uses.

A *curve* is a run of samples in which one input of the muscle is held while the other
moves in one direction, inside one trial:

* in Sárosi's quasi-static sweeps the pressure is held and the contraction moves
  (``moving == 0``); a curve is one contracting or one extending sweep at one pressure;
* in isometric tests (the AARL 10 mm file, most force-pressure benches) the length is
  clamped and the pressure moves (``moving == 1``); a curve is one inflation or one
  deflation at one contraction level.

"Held" means held within the input's own sensor noise, which is estimated from the data:
the robust spread of second differences of each input within each trial (for Gaussian
noise of standard deviation σ, a second difference has standard deviation √6·σ, and
1.4826·median|x| is σ for a normal variable). A logged pressure that wanders by ±1 kPa
around its set point is therefore one held level, not a new curve per sample.

Direction is the sign of the moving input's change in time order, measured over a lag
long enough to rise above the noise, and **+1 where the muscle is driven to contract**:
contraction rising in a sweep, pressure rising at a held length. A pause (no change beyond
the noise: a dwell at the top of a ramp, a motor that waits) keeps the direction of the
motion before it. A recorded ``direction`` column wins wherever it has a value; blank
cells (NaN) are derived. The trial's *repeat index* is its order among the earlier trials
of the same muscle with the same setting (the same moving input and the same held levels);
without a ``trial`` column, the ``cycle`` column plays that part.

Everything is vectorised over all muscles and trials of a file at once (cumulative sums,
clamped index arithmetic and grouped medians; no Python loop over rows or muscles), so
that a file of 10,000 muscles or one muscle of 100,000 rows costs time in proportion to
its rows.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._columns import Columns, factorize

__all__ = ["Curves", "find_curves"]

#: A change larger than this many noise standard deviations is motion, not noise.
NOISE_SIGMAS = 5.0
#: Floor of the tolerance, relative to the input's scale (|median| + range): exact data.
RELATIVE_FLOOR = 1e-6
#: Samples over which the typical step of the moving input is measured.
STEP_SPAN = 16
#: The longest lag (in samples) used to see motion through noise.
MAX_LAG = 64
#: A reversal of the moving input must retrace this fraction of the trial's range.
MIN_RETRACE = 0.05
#: Trials are the same setting when their held levels agree within this fraction of the
#: muscle's range of that input (or the noise tolerance, if larger).
SETTING_FRACTION = 0.02

MOVING_NAMES = ("contraction", "pressure")


@dataclasses.dataclass(frozen=True, eq=False)
class Curves:
    """Curve structure of a bench table; every array is aligned with the table's rows.

    Attributes:
        curve: curve id of each row, dense within its muscle (0, 1, 2, … in time order).
        direction: +1 where the muscle is driven to contract (contraction rising in a
            sweep, pressure rising at a held length), −1 where it is let extend; the
            recorded direction wherever the file has one.
        direction_recorded: True where ``direction`` comes from the file.
        moving: 0 where the contraction moves at a held pressure (a sweep), 1 where the
            pressure moves at a held contraction (an isometric test).
        level: the held input's level of the row's curve: pressure in kPa for sweeps, the
            contraction (in ``contraction_column``'s unit) for isometric curves.
        trial: index of the row's trial within its muscle, in file order (0 when the file
            has no trial column).
        repeat: the trial's order among the earlier trials of its muscle with the same
            setting (0, 1, 2, …); from ``cycle`` when there is no trial column.
        rate: rate of change of the moving input in its unit per second (kPa/s or %/s or
            mm/s), NaN without time.
        elapsed_s: time since the muscle's first sample, continuous across trials whose
            clock restarts (each trial is placed one sampling interval after the previous
            one ends); NaN without time.
        noise: the estimated noise standard deviation of each row's trial, per input
            (``noise["pressure_kPa"]``, ``noise[contraction_column]``).
        contraction_column: the contraction column the structure was found on.
    """

    curve: np.ndarray
    direction: np.ndarray
    direction_recorded: np.ndarray
    moving: np.ndarray
    level: np.ndarray
    trial: np.ndarray
    repeat: np.ndarray
    rate: np.ndarray
    elapsed_s: np.ndarray
    noise: dict[str, np.ndarray]
    contraction_column: str

    def __len__(self) -> int:
        return len(self.curve)

    def take(self, rows) -> Curves:
        """The structure of a subset of the rows (a boolean mask or integer indices)."""
        return dataclasses.replace(
            self,
            **{f.name: getattr(self, f.name)[rows] for f in dataclasses.fields(self)
               if f.name not in ("noise", "contraction_column")},
            noise={k: v[rows] for k, v in self.noise.items()},
        )

    def summary(self) -> dict:
        """Counts for messages and JSON: curves, sweeps and isometric curves, trials."""
        return {
            "rows": len(self.curve),
            "isometric_rows": int(np.sum(self.moving == 1)),
            "sweep_rows": int(np.sum(self.moving == 0)),
            "direction_derived_rows": int(np.sum(~self.direction_recorded)),
        }


# --------------------------------------------------------------------------------------
# Grouped primitives: rows sorted so that every group is one contiguous block
# --------------------------------------------------------------------------------------


class _Blocks:
    """Contiguous groups of a sorted array: start and end (exclusive) of each row's group."""

    def __init__(self, codes: np.ndarray):
        n = len(codes)
        new = np.ones(n, dtype=bool)
        new[1:] = codes[1:] != codes[:-1]
        self.block = np.cumsum(new) - 1  # dense block id per row
        starts = np.flatnonzero(new)
        ends = np.append(starts[1:], n)
        self.starts, self.ends = starts, ends
        self.start = starts[self.block]
        self.end = ends[self.block]  # exclusive
        self.size = (ends - starts)[self.block]
        self.n_blocks = len(starts)
        self.new = new
        self.idx = np.arange(n)
        self._diffs: dict[int, tuple] = {}

    def count(self, mask: np.ndarray) -> np.ndarray:
        """Rows of each block where ``mask`` holds."""
        return np.bincount(self.block[mask], minlength=self.n_blocks)

    def min_max(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Smallest and largest value of each block."""
        if not len(values):
            return np.zeros(0), np.zeros(0)
        return np.minimum.reduceat(values, self.starts), np.maximum.reduceat(values, self.starts)

    def per_block(self, values: np.ndarray) -> np.ndarray:
        """A per-block array spread to its rows."""
        return values[self.block]

    def median(self, values: np.ndarray, valid: np.ndarray, default: float = 0.0) -> np.ndarray:
        """Median of ``values`` over each block's ``valid`` rows (``default`` if none)."""
        out = np.full(self.n_blocks, default, dtype=np.float64)
        if valid.any():
            groups, med = _grouped_median(self.block[valid], values[valid])
            out[groups] = med
        return out

    def running_mean(self, x: np.ndarray, half: np.ndarray) -> np.ndarray:
        """Mean of ``x`` over rows i − half … i + half, clipped to the row's block."""
        if not np.any(half > 0):
            return x.copy()
        base = x[self.start]  # precision: sum deviations from the block's first value
        c = np.concatenate([[0.0], np.cumsum(x - base)])
        lo = np.maximum(self.idx - half, self.start)
        hi = np.minimum(self.idx + half, self.end - 1)
        return base + (c[hi + 1] - c[lo]) / (hi - lo + 1)

    def shifted(self, idx_offset: np.ndarray) -> np.ndarray:
        """Row index moved by ``idx_offset`` rows, clipped to the row's block."""
        return np.minimum(np.maximum(self.idx + idx_offset, self.start), self.end - 1)


def _grouped_median(groups: np.ndarray, values: np.ndarray):
    """``(ids, medians)``: the median of ``values`` over each group id present, ids
    ascending; NaN values left out (a group of NaN only has median NaN). The mean of the two
    middle values of an even count, ``(a + b) / 2``, as pandas' grouped median has it."""
    order = np.lexsort((values, groups))
    g, v = groups[order], values[order]
    new = np.ones(len(g), dtype=bool)
    new[1:] = g[1:] != g[:-1]
    starts = np.flatnonzero(new)
    # NaN sorts last within its group: count the others
    valid = np.add.reduceat((~np.isnan(v)).astype(np.int64), starts)
    lower = starts + np.maximum(valid - 1, 0) // 2
    upper = starts + np.maximum(valid, 1) // 2
    med = np.where(valid % 2 == 1, v[lower], (v[lower] + v[upper]) / 2.0)
    return g[starts], np.where(valid > 0, med, np.nan)


def _first_of_max(groups: np.ndarray, values: np.ndarray) -> np.ndarray:
    """For each group id in ascending order, the position (into ``values``) of its largest
    value, the first one where several are largest (as a grouped ``idxmax``)."""
    order = np.lexsort((np.arange(len(values)), -values, groups))
    g = groups[order]
    first = np.ones(len(g), dtype=bool)
    first[1:] = g[1:] != g[:-1]
    return order[first]


def _ffill_within(values: np.ndarray, known: np.ndarray, blocks: _Blocks) -> np.ndarray:
    """Each unknown row takes the last known value before it in its block, else the first
    known value after it; a block with none known gets +1."""
    n = len(values)
    idx = np.where(known, np.arange(n), -1)
    last = np.maximum.accumulate(idx)
    ok = last >= blocks.start
    out = np.where(ok, values[np.maximum(last, 0)], np.nan)
    # rows before the first known value of the block: the next known value
    idx_next = np.where(known, np.arange(n), n)
    nxt = np.minimum.accumulate(idx_next[::-1])[::-1]
    ok_next = nxt < blocks.end
    back = np.where(ok_next, values[np.minimum(nxt, n - 1)], 1.0)
    return np.where(ok, out, back)


# --------------------------------------------------------------------------------------
# The curve finder
# --------------------------------------------------------------------------------------


@dataclasses.dataclass
class _Input:
    """One input (pressure or contraction) of every row, with its noise and motion."""

    raw: np.ndarray
    sigma: np.ndarray  # per block
    tol: np.ndarray  # per block
    lag: np.ndarray  # per block
    smooth: np.ndarray  # per row
    back: np.ndarray  # per row: smooth[i] − smooth[i − lag]
    fwd: np.ndarray  # per row: smooth[i + lag] − smooth[i]
    events: np.ndarray  # per block: rows moving beyond the tolerance
    span: np.ndarray  # per block: max − min


def _differences(u: np.ndarray, blocks: _Blocks):
    """First differences (the step into each row) and second differences (centred on each
    row), with masks of the rows where they stay inside one block; kept on ``blocks``."""
    cached = blocks._diffs.get(id(u))
    if cached is not None and cached[0] is u:
        return cached[1]
    n = len(u)
    d1 = np.zeros(n)
    np.subtract(u[1:], u[:-1], out=d1[1:])
    has_prev = ~blocks.new
    d2 = np.zeros(n)
    np.subtract(d1[2:], d1[1:-1], out=d2[1:-1])
    valid2 = np.zeros(n, dtype=bool)
    np.logical_and(has_prev[1:-1], has_prev[2:], out=valid2[1:-1])
    out = (d1, has_prev, d2, valid2)
    blocks._diffs[id(u)] = (u, out)
    return out


def _exact(u: np.ndarray, blocks: _Blocks) -> np.ndarray:
    """Per block: written at exact set points — most steps exactly zero, and the changes
    not flickering back and forth as a quantised noisy reading does."""
    d1, has_prev, _, _ = _differences(u, blocks)
    steps = blocks.count(has_prev)
    change = has_prev & (d1 != 0)
    n_changes = blocks.count(change)
    idx = np.flatnonzero(change)
    flicker = np.zeros(blocks.n_blocks)
    if len(idx) > 1:
        same = blocks.block[idx[1:]] == blocks.block[idx[:-1]]
        a, b = d1[idx[:-1]], d1[idx[1:]]
        back = same & (np.sign(a) != np.sign(b)) & (
            np.abs(a + b) <= 0.5 * np.maximum(np.abs(a), np.abs(b)))
        flicker = np.bincount(blocks.block[idx[:-1]], weights=back.astype(float),
                              minlength=blocks.n_blocks)
    zero_frac = 1.0 - n_changes / np.maximum(steps, 1)
    return (zero_frac >= 0.5) & (flicker <= 0.2 * np.maximum(n_changes, 1))


def _noise(u: np.ndarray, blocks: _Blocks, exact: np.ndarray,
           steady: np.ndarray | None = None) -> np.ndarray:
    """Noise standard deviation of ``u`` per block (0 for ``exact`` blocks).

    1.4826·median|Δ²u| / √6 is σ for white Gaussian noise, and ignores the few large second
    differences at set-point jumps and valve pulses. ``steady`` restricts it to rows where
    the other input holds its level (in a sparse map the other input's jumps would
    otherwise be taken for noise), where at least 5 such rows exist in the block.
    """
    _, _, d2, valid2 = _differences(u, blocks)
    valid2 = valid2 & ~blocks.per_block(exact)
    sigma = 1.4826 * blocks.median(np.abs(d2), valid2) / np.sqrt(6.0)
    # Fewer than 5 second differences say nothing about noise (a table of a few rows): the
    # values are taken as they are written.
    sigma = np.where(blocks.count(valid2) >= 5, sigma, 0.0)
    if steady is not None:
        use = valid2 & steady
        enough = blocks.count(use) >= 5
        if enough.any():
            use &= blocks.per_block(enough)
            sigma = np.where(enough, 1.4826 * blocks.median(np.abs(d2), use) / np.sqrt(6.0),
                             sigma)
    return np.where(exact, 0.0, sigma)


def _analyse(u: np.ndarray, blocks: _Blocks, sigma: np.ndarray) -> _Input:
    """Tolerance, lag, smoothed signal and lagged differences of one input per block."""
    d1, has_prev, _, _ = _differences(u, blocks)
    lo, hi = blocks.min_max(u)
    scale = np.maximum(np.abs(lo), np.abs(hi))
    tol = np.maximum(NOISE_SIGMAS * sigma, RELATIVE_FLOOR * np.maximum(scale, 1e-300))
    # The lag at which a typical step of motion clears the noise twice over. The step is
    # measured over STEP_SPAN samples (the mean |u[i + 16] − u[i]| / 16), where noise adds
    # only ~0.1 σ per sample: at a fast sampling rate a one-sample step is mostly noise.
    ahead = np.minimum(blocks.idx + STEP_SPAN, blocks.end - 1)
    span_rows = np.maximum(ahead - blocks.idx, 1)
    step = np.bincount(blocks.block, weights=np.abs(u[ahead] - u) / span_rows,
                       minlength=blocks.n_blocks) / np.maximum(blocks.size[blocks.starts], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lag = np.where(step > 0, np.ceil(2.0 * tol / step), 1.0)
    lag = np.clip(np.nan_to_num(lag, nan=1.0), 1, MAX_LAG).astype(np.int64)
    lag_rows = blocks.per_block(lag)
    smooth = blocks.running_mean(u, lag_rows // 2)
    back = smooth - smooth[blocks.shifted(-lag_rows)]
    fwd = smooth[blocks.shifted(lag_rows)] - smooth
    tol_rows = blocks.per_block(tol)
    moving_row = (np.abs(back) > tol_rows) | (np.abs(fwd) > tol_rows)
    events = blocks.count(moving_row)
    return _Input(u, sigma, tol, lag, smooth, back, fwd, events, hi - lo)


def _steady(u: np.ndarray, blocks: _Blocks, sigma: np.ndarray) -> np.ndarray:
    """Rows whose second difference of the *other* input spans no step of ``u`` beyond
    its tolerance (``u`` holds its level at the row and on both sides)."""
    d1, has_prev, _, _ = _differences(u, blocks)
    tol = blocks.per_block(np.maximum(NOISE_SIGMAS * sigma, 0.0))
    flat = np.abs(d1) <= tol
    out = np.zeros(len(u), dtype=bool)
    out[:-1] = flat[:-1] & flat[1:]
    return out


def _level_starts(jump, held_raw, tol, exact, blocks: _Blocks) -> np.ndarray:
    """First row of each new level of the held input. ``jump`` flags rows near a change of
    level (smoothing spreads a step over several rows). In every run of them, an input at
    exact set points (``exact`` rows) starts a level at each row whose step clears the
    tolerance (a sparse map: one level per row); a noisy input starts one level per run, at
    its largest step (a noise spike beside a real step is not a level of its own)."""
    starts = np.zeros(len(jump), dtype=bool)
    if not jump.any():
        return starts
    d1, has_prev, _, _ = _differences(held_raw, blocks)
    big = jump & has_prev & exact & (np.abs(d1) > tol)
    run_start = np.zeros(len(jump), dtype=bool)
    run_start[0] = jump[0]
    run_start[1:] = jump[1:] & (~jump[:-1] | blocks.new[1:])
    run = np.cumsum(run_start) - 1
    rows = np.flatnonzero(jump)
    has_big = np.bincount(run[rows], weights=big[rows].astype(float)) > 0
    size = np.where(has_prev[rows], np.abs(d1[rows]), -1.0)
    best = _first_of_max(run[rows], size)
    best = best[~has_big[np.unique(run[rows])]]
    starts[rows[best]] = True
    starts |= big
    return starts


def _direction_of(inp: _Input, blocks: _Blocks, span: np.ndarray) -> np.ndarray:
    """+1 / −1 from the time order of a moving input: the step that led to a sample when
    it clears the noise; pauses keep the motion before. The step that led to a sample is
    measured on samples up to it only (the smoothed input ``lag // 2`` samples back), so
    that a hold does not turn before the input leaves it (the top of an isometric ramp or
    stairs). A pause of at most ``lag`` samples between two motions (a sweep's turning
    point, sampled again as the first point of the return) takes the motion after it, as
    do the samples before a block's first motion. A reversal that retraces less than
    :data:`MIN_RETRACE` of the trial's range (a valve pulse's overshoot in a ramp) is not
    a reversal."""
    tol = blocks.per_block(inp.tol)
    lag = blocks.per_block(inp.lag)
    back = inp.back[blocks.shifted(-(lag // 2))]  # causal: nothing after the sample
    d = np.where(np.abs(back) > tol, np.sign(back), 0.0)
    # Runs of pause rows: their length, and whether motion came before them in the block.
    pause = d == 0
    run_start = pause & (blocks.new | np.r_[True, ~pause[:-1]])
    run_id = np.cumsum(run_start) - 1
    run_len = np.bincount(run_id[pause], minlength=max(int(run_id.max()) + 1, 1))
    short = np.zeros(len(d), dtype=bool)
    short[pause] = (run_len[run_id[pause]] <= lag[pause]) & ~blocks.new[
        np.flatnonzero(run_start)[run_id[pause]]]
    fill = short & (np.abs(inp.fwd) > tol)
    d[fill] = np.sign(inp.fwd[fill])
    d = _ffill_within(d, d != 0, blocks)
    retrace = np.maximum(3.0 * inp.tol, MIN_RETRACE * span)
    causal = inp.smooth[blocks.shifted(-(lag // 2))]  # the runs' values, as ``back`` saw them
    return _merge_short_runs(d, causal, blocks, blocks.per_block(retrace))


def _merge_short_runs(d, smooth, blocks: _Blocks, retrace):
    """A zigzag filter on runs of one direction: the direction changes only where the
    moving input retraces more than ``retrace`` from the extreme it reached, and the change
    is placed at that extreme. Runs that retrace less (a valve pulse's overshoot and the
    dip after it) take the direction around them.

    Runs are found vectorised; only blocks that hold a short run are walked run by run.
    """
    n = len(d)
    start = blocks.new.copy()
    start[1:] |= d[1:] != d[:-1]
    rs = np.flatnonzero(start)
    re = np.append(rs[1:], n) - 1
    before = np.where(blocks.new[rs], rs, rs - 1)
    disp = np.abs(smooth[re] - smooth[before])
    short = (disp < retrace[rs]) & ~(blocks.new[rs] & np.append(blocks.new[rs[1:]], True))
    if not short.any():
        return d
    run_block = blocks.block[rs]
    suspect = np.zeros(blocks.n_blocks, dtype=bool)
    suspect[run_block[short]] = True
    run_dir = d[rs].copy()
    end_value = smooth[re]
    start_value = smooth[blocks.starts]
    for blk in np.flatnonzero(suspect):
        runs = np.flatnonzero(run_block == blk)
        r_tol = retrace[rs[runs[0]]]
        out = list(run_dir[runs])
        # Until the input has moved by ``r_tol`` one way, the direction is open; the runs
        # before that take the first confirmed direction.
        lo = hi = start_value[blk]
        cur, first = 0.0, len(runs)
        for j, r in enumerate(runs):
            v = end_value[r]
            lo, hi = min(lo, v), max(hi, v)
            if v - lo >= r_tol or hi - v >= r_tol:
                cur = 1.0 if v - lo >= r_tol else -1.0
                first = j
                break
        if cur == 0.0:  # never moved by r_tol: keep the runs as found
            continue
        out[: first + 1] = [cur] * (first + 1)
        extreme, at = end_value[runs[first]], first
        for j in range(first + 1, len(runs)):
            r = runs[j]
            v = end_value[r]
            if run_dir[r] == cur:
                if (v - extreme) * cur > 0:
                    extreme, at = v, j
                out[j] = cur
            elif abs(v - extreme) >= r_tol:  # a confirmed reversal, from the extreme on
                cur = run_dir[r]
                out[at + 1 : j + 1] = [cur] * (j - at)
                extreme, at = v, j
            else:
                out[j] = cur
        run_dir[runs] = out
    run_of_row = np.cumsum(start) - 1
    return run_dir[run_of_row]


def find_curves(frame, *, contraction_column: str | None = None) -> Curves:
    """Find curves, direction, trials and repeats in a bench table (all muscles at once).

    Args:
        frame: rows of a bench table in file order (``BenchData.frame``, a pandas
            DataFrame, or ``BenchData.columns``) with
            ``pressure_kPa`` and a contraction column, and optionally ``muscle``,
            ``trial``, ``time_s``, ``direction`` (NaN where not recorded) and ``cycle``.
            Within a muscle and trial the rows must be in time order (the loader checks).
        contraction_column: ``"contraction_pct"`` or ``"contraction_mm"``; by default the
            first of them in the frame.

    Returns:
        The :class:`Curves` of the table, aligned with its rows.
    """
    n = len(frame)
    if contraction_column is None:
        contraction_column = next(
            (c for c in ("contraction_pct", "contraction_mm") if c in frame), None)
        if contraction_column is None:
            raise ValueError("find_curves needs contraction_pct or contraction_mm")
    muscle = _codes(frame, "muscle") if "muscle" in frame else np.zeros(n, dtype=np.int64)
    if "trial" in frame:
        trial_code = _pair_codes(muscle, _codes(frame, "trial"))
    else:
        trial_code = muscle.copy()
    cycle = np.asarray(frame["cycle"]) if "cycle" in frame else None

    # Sort rows so that every muscle is one block and, within it, every trial one block,
    # in order of first appearance; the rows of a trial keep their file (time) order.
    first_of_trial = np.zeros(trial_code.max() + 1 if n else 0, dtype=np.int64)
    first_of_trial[trial_code[::-1]] = np.arange(n)[::-1]
    first_of_muscle = np.zeros(muscle.max() + 1 if n else 0, dtype=np.int64)
    first_of_muscle[muscle[::-1]] = np.arange(n)[::-1]
    key_m = first_of_muscle[muscle]
    key_t = first_of_trial[trial_code]
    if n and np.all(np.diff(key_m) >= 0) and np.all(np.diff(key_t) >= 0):
        order = None  # the usual layout: already grouped
    else:
        order = np.lexsort((np.arange(n), key_t, key_m))

    def sort(a):
        return a if order is None or a is None else a[order]

    trials = _Blocks(sort(key_t))
    muscles = _Blocks(sort(key_m))
    p = sort(np.asarray(frame["pressure_kPa"], dtype=np.float64))
    k = sort(np.asarray(frame[contraction_column], dtype=np.float64))
    t = sort(np.asarray(frame["time_s"], dtype=np.float64)) if "time_s" in frame else None
    cycle = sort(cycle)

    exact_p, exact_k = _exact(p, trials), _exact(k, trials)
    sigma_p, sigma_k = _noise(p, trials, exact_p), _noise(k, trials, exact_k)
    # Again, each on the rows where the other input holds: in a sparse map (a few rows per
    # level) the other input's jumps would be taken for noise.
    if not exact_p.all():
        sigma_p = _noise(p, trials, exact_p, _steady(k, trials, sigma_k))
    if not exact_k.all():
        sigma_k = _noise(k, trials, exact_k, _steady(p, trials, sigma_p))
    pin, kin = _analyse(p, trials, sigma_p), _analyse(k, trials, sigma_k)
    # The input that moves is the one with more rows in motion (ties: the contraction,
    # Sárosi's sweeps); decided per trial, so a file may mix sweeps and isometric tests.
    moving_block = (pin.events > kin.events).astype(np.int8)
    moving = trials.per_block(moving_block)
    iso = moving == 1

    # Where the held input changes level (a step beyond its noise), a new segment starts.
    held_raw = np.where(iso, k, p)
    held_tol = np.where(iso, trials.per_block(kin.tol), trials.per_block(pin.tol))
    jump = ((np.abs(np.where(iso, kin.back, pin.back)) > held_tol)
            | (np.abs(np.where(iso, kin.fwd, pin.fwd)) > held_tol))
    held_exact = np.where(iso, trials.per_block(exact_k), trials.per_block(exact_p))
    seg_start = trials.new | _level_starts(jump, held_raw, held_tol, held_exact, trials)
    if cycle is not None:
        seg_start[1:] |= cycle[1:] != cycle[:-1]
    segments = _Blocks(np.cumsum(seg_start))

    # Direction of the moving input, within each segment: the step across a change of the
    # held level (a sweep's return to zero contraction at the next pressure) is no motion.
    moving_raw = np.where(iso, p, k)
    sigma_seg = np.where(iso, trials.per_block(sigma_p), trials.per_block(sigma_k))
    mov = _analyse(moving_raw, segments, sigma_seg[segments.starts])
    trial_of_seg = trials.block[segments.starts]
    span = np.where(moving_block == 1, pin.span, kin.span)[trial_of_seg]
    given = (sort(np.asarray(frame["direction"], dtype=np.float64)) if "direction" in frame
             else None)
    recorded = np.isfinite(given) if given is not None else np.zeros(n, dtype=bool)
    if recorded.all():
        direction = given
    else:
        derived = _direction_of(mov, segments, span)
        direction = np.where(recorded, given, derived) if given is not None else derived

    # A new curve starts with a segment (trial, cycle, held level) or a change of direction.
    start = seg_start.copy()
    start[1:] |= direction[1:] != direction[:-1]
    curve_global = np.cumsum(start) - 1
    curve = curve_global - curve_global[muscles.start]

    # The level of a curve: the mean of its held input (the noise averages out).
    level_raw = held_raw
    level = (np.bincount(curve_global, weights=level_raw)
             / np.bincount(curve_global))[curve_global]

    trial_index = trials.block - trials.block[muscles.start]
    repeat = _repeats(trials, muscles, moving_block, level_raw, iso, pin, kin, cycle,
                      has_trials="trial" in frame)

    rate = np.full(n, np.nan)
    elapsed = np.full(n, np.nan)
    if t is not None:
        mv = mov.smooth
        lag = segments.per_block(mov.lag)
        ahead, behind = segments.shifted(lag), segments.shifted(-lag)
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = (mv[ahead] - mv[behind]) / (t[ahead] - t[behind])
        rate = np.where(np.isfinite(rate), rate, np.nan)
        elapsed = _elapsed(t, trials, muscles)

    noise_p = trials.per_block(pin.sigma)
    noise_k = trials.per_block(kin.sigma)
    out = Curves(
        curve=curve.astype(np.int64),
        direction=direction.astype(np.float64),
        direction_recorded=recorded,
        moving=moving.astype(np.int8),
        level=level,
        trial=trial_index.astype(np.int64),
        repeat=repeat.astype(np.int64),
        rate=rate,
        elapsed_s=elapsed,
        noise={"pressure_kPa": noise_p, contraction_column: noise_k},
        contraction_column=contraction_column,
    )
    if order is not None:  # back to the file's row order
        inverse = np.empty(n, dtype=np.int64)
        inverse[order] = np.arange(n)
        out = out.take(inverse)
    return out


def _codes(frame, name: str) -> np.ndarray:
    """A label column's codes in order of first appearance: from :class:`Columns` as the
    reader coded it, else (a DataFrame's text) by ``pd.factorize``."""
    if isinstance(frame, Columns):
        return frame.codes(name)[0]
    import pandas as pd  # a DataFrame: pandas is there

    codes = pd.factorize(frame[name], sort=False, use_na_sentinel=False)[0]  # NaN: a label
    return codes.astype(np.int64, copy=False)


def _pair_codes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Codes of the pairs ``(a[i], b[i])`` of two code arrays (values ≥ 0), in order of
    first appearance."""
    if not len(a):
        return np.zeros(0, dtype=np.int64)
    return factorize(a.astype(np.int64) * (int(b.max()) + 1) + b)[0]


def _elapsed(t: np.ndarray, trials: _Blocks, muscles: _Blocks) -> np.ndarray:
    """Time since the muscle's first sample, trials laid end to end: each trial starts
    one (median) sampling interval after the previous trial of the muscle ends."""
    dt = np.diff(t)
    same = ~trials.new[1:]
    good = same & np.isfinite(dt) & (dt > 0)
    interval = float(np.median(dt[good])) if good.any() else 0.0
    tmin, tmax = trials.min_max(t)  # time increases within a trial: first and last row
    if not np.isfinite(t).all():  # blank times: the first and last recorded ones
        t_lo = np.where(np.isfinite(t), t, np.inf)
        t_hi = np.where(np.isfinite(t), t, -np.inf)
        tmin, tmax = trials.min_max(t_lo)[0], trials.min_max(t_hi)[1]
    span = np.nan_to_num(tmax - tmin, nan=0.0) + interval
    # offset of each trial: the spans of the muscle's earlier trials
    block_muscle = muscles.block[trials.starts]
    csum = np.cumsum(span) - span
    first_block_of_muscle = np.zeros(block_muscle.max() + 1, dtype=np.int64)
    first_block_of_muscle[block_muscle[::-1]] = np.arange(len(block_muscle))[::-1]
    offset = csum - csum[first_block_of_muscle[block_muscle]]
    return t - trials.per_block(tmin) + trials.per_block(offset)


def _repeats(trials, muscles, moving_block, level_raw, iso, pin, kin, cycle, has_trials):
    """Repeat index of every row: the order of its trial among the muscle's earlier trials
    with the same setting (same moving input, held levels within tolerance). Without a
    trial column, the rank of the row's cycle within its muscle (0 without cycles)."""
    n = len(level_raw)
    if not has_trials:
        if cycle is None:
            return np.zeros(n, dtype=np.int64)
        codes = _pair_codes(muscles.block, factorize(cycle)[0])
        first = np.zeros(codes.max() + 1, dtype=np.int64)
        first[codes[::-1]] = np.arange(n)[::-1]
        new = np.zeros(n, dtype=bool)
        new[first] = True
        rank = np.cumsum(new) - 1
        return rank - rank[muscles.start]
    # Setting of a trial: which input moves, and the held input's median, min and max.
    med = _grouped_median(trials.block, level_raw)[1]
    lo, hi = trials.min_max(level_raw)
    tol = np.where(moving_block == 1, kin.tol, pin.tol)
    block_muscle = muscles.block[trials.starts]
    # per trial: the largest range of a trial of its muscle, and its muscle's range of medians
    of_muscle = _Blocks(block_muscle)  # a muscle's trials are one block
    span = of_muscle.per_block(np.maximum.reduceat(hi - lo, of_muscle.starts))
    med_lo, med_hi = of_muscle.min_max(med)
    span = np.maximum(span, of_muscle.per_block(med_hi - med_lo))
    tolerance = np.maximum(SETTING_FRACTION * span, 3.0 * tol)
    repeat_block = np.zeros(len(med), dtype=np.int64)
    # A loop over trials (not rows): files hold tens to thousands of trials.
    seen: dict[int, list[int]] = {}
    for b in range(len(med)):
        m = int(block_muscle[b])
        earlier = seen.setdefault(m, [])
        same = [e for e in earlier
                if moving_block[e] == moving_block[b]
                and abs(med[e] - med[b]) <= max(tolerance[e], tolerance[b])
                and abs(lo[e] - lo[b]) <= max(tolerance[e], tolerance[b])
                and abs(hi[e] - hi[b]) <= max(tolerance[e], tolerance[b])]
        repeat_block[b] = len(same)
        earlier.append(b)
    return trials.per_block(repeat_block)

