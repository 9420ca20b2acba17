"""What counts as a small batch: one definition for the size classes of packed batches
(:mod:`._batch`) and the compiler's options of the programs kept on disk
(:mod:`._export_cache`), which :mod:`._batch` imports."""

from __future__ import annotations

#: A batch (or a compiled call's largest array) of at most this many numbers, lanes × rows:
#: a lab's file of one or a few muscles. Compiling is nearly all of its time and its
#: arithmetic next to nothing: its rows and lanes are padded to wide classes (powers of
#: two), and its programs are compiled without LLVM's optimisation.
SMALL_BATCH_SAMPLES = 16384
