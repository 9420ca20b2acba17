"""Every notebook runs top to bottom."""

from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
#: Notebooks another test module runs, and checks what they write: a notebook that runs an
#: experiment is run once in the suite, not once here and once more for its checks.
RUN_ELSEWHERE = {"04_close_the_loop.ipynb": "tests/test_close_the_loop_aarl.py"}


def test_every_notebook_is_run_by_the_suite():
    root = Path(__file__).resolve().parents[1]
    for name, module in RUN_ELSEWHERE.items():
        assert (root / "notebooks" / name).is_file()
        assert f'"{name}"' in (root / module).read_text(encoding="utf-8")


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in NOTEBOOKS if p.name not in RUN_ELSEWHERE],
                         ids=lambda p: p.name)
def test_notebook_runs(path, tmp_path, run_notebook):
    run_notebook(path, tmp_path)  # raises CellExecutionError, with the failing cell, on any error
