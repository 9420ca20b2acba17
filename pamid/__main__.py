"""``python -m pamid``: the ``pamid`` command, for a Python that has pamid but no script on
its PATH (benchmarks run a given interpreter this way)."""

from ._cli import console_main

console_main()
