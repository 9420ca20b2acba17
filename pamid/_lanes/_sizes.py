"""What counts as a small batch, and the size classes of packed batches: one definition
for :mod:`._batch` (which packs them) and :mod:`._export_cache` (the compiler's options of
the programs kept on disk, and the kind of run whose programs are read ahead), which
:mod:`._batch` imports. Without JAX: a command names its kind of run while JAX may still
be starting on another thread."""

from __future__ import annotations

import numpy as np

#: A batch (or a compiled call's largest array) of at most this many numbers, lanes × rows:
#: a lab's file of one or a few muscles. Compiling is nearly all of its time and its
#: arithmetic next to nothing: its rows and lanes are padded to wide classes (powers of
#: two), and its programs are compiled without LLVM's optimisation.
SMALL_BATCH_SAMPLES = 16384


#: Row counts of packed batches: at least ``ROWS_MIN``; then, for a batch of few samples in
#: all (lanes × rows ≤ ``SMALL_BATCH_SAMPLES``: a lab's file of one or a few muscles), the
#: powers of two; for larger batches a geometric grid of ``ROW_BUCKETS_PER_OCTAVE`` sizes
#: per doubling (each a multiple of 8). A file of a row count never seen before packs to a
#: size that an earlier file of nearby length had, so the programs compiled (and kept on
#: disk) for that one serve it. In a small batch compilation is nearly all of the time and
#: the arithmetic of the padding (weight 0) next to nothing, so the classes are wide; in a
#: large one the arithmetic counts, and the padding costs at most 2^(1/4) − 1 = 19 %
#: (benchmarks/README.md, "Shape classes").
ROWS_MIN = 64
ROW_BUCKETS_PER_OCTAVE = 4


def padded_rows(n: int, lanes: int = 1) -> int:
    """The number of columns a batch of ``lanes`` muscles, the largest of ``n`` rows, is
    packed to (module constants above); 0 for no rows."""
    if n <= 0:
        return 0
    if n <= ROWS_MIN:
        return ROWS_MIN
    if n * max(lanes, 1) <= SMALL_BATCH_SAMPLES:
        return 1 << (n - 1).bit_length()
    steps = ROW_BUCKETS_PER_OCTAVE
    k = max(0, int(np.floor(steps * np.log2(n / ROWS_MIN))) - 1)
    while True:  # from just below, so that float rounding cannot skip a size
        size = -(-int(np.ceil(ROWS_MIN * 2.0 ** (k / steps))) // 8) * 8
        if size >= n:
            return size
        k += 1
