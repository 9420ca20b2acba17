"""Writing results as pamid's commands write them: each file appears whole or not at all
(written beside its place, then renamed), and an input is never overwritten. For scripts
and notebooks that save what they compute (the ``experiments/`` do)."""

from ._io import (
    json_ready,
    refuse_overwrite_input,
    save_figure_atomic,
    write_bytes_atomic,
    write_frame_atomic,
    write_text_atomic,
)

__all__ = [
    "json_ready", "refuse_overwrite_input", "save_figure_atomic", "write_bytes_atomic",
    "write_frame_atomic", "write_text_atomic",
]
