"""Outputs never replace an input, and a bad output place is said in one line before any
computing (exit 2), for every command that writes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from pamid._cli import main

BUNDLED = Path(__file__).resolve().parents[1] / "pamid" / "data" / "sarosi_dmsp20_400_virtual.csv"


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("pamid: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_an_input_named_like_a_plot_is_not_replaced_by_the_plot(tmp_path, capsys):
    """`pamid fit DIR/fit_muscle.png --out DIR` exited 0 and replaced the input (a CSV
    that carried a plot's name) with a PNG."""
    data = tmp_path / "fit_muscle.png"  # a file without muscle column: its plot's name
    lines = BUNDLED.read_text().splitlines()
    header = lines[0].split(",")
    keep = [j for j, name in enumerate(header) if name != "muscle"]
    data.write_text("\n".join(",".join(line.split(",")[j] for j in keep) for line in lines)
                    + "\n")
    before = data.read_bytes()
    code = main(["fit", str(data), "--out", str(tmp_path), "--intervals", "wald"])
    assert code == 2
    assert "it is the input file" in _one_error_line(capsys)
    assert data.read_bytes() == before


@pytest.mark.parametrize("command", [
    ["fit", str(BUNDLED)],
    ["diagnose", str(BUNDLED)],
    ["simulate", "lifting-mass", "--pressure-kPa", "400", "--mass-kg", "50", "--x0-mm", "50"],
])
def test_out_naming_a_file_is_refused_before_computing(tmp_path, capsys, command):
    target = tmp_path / "results"
    target.write_text("not a folder")
    code = main([*command, "--out", str(target)])
    assert code == 2
    assert "is a file, not a folder" in _one_error_line(capsys)
    assert target.read_text() == "not a folder"


def test_out_under_a_file_is_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["fit", str(BUNDLED), "--out", str(blocker / "sub" / "dir")]) == 2
    assert "no folder can be made there" in _one_error_line(capsys)


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_a_read_only_folder_is_refused(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert main(["fit", str(BUNDLED), "--out", str(ro)]) == 2
        assert "no permission" in _one_error_line(capsys)
    finally:
        ro.chmod(0o700)


def test_an_output_file_that_is_a_folder_is_one_line(tmp_path, capsys):
    (tmp_path / "fit.json").mkdir()
    code = main(["fit", str(BUNDLED), "--out", str(tmp_path), "--intervals", "wald"])
    assert code == 2
    assert "it is a folder" in _one_error_line(capsys)


def test_sigterm_while_writing_leaves_the_old_results_as_they_were(tmp_path, pamid_cli):
    """A kill during plotting left hidden 0-byte .fit_M1.png.XXXX.tmp files behind, and a
    killed re-run into a folder of results a new plot beside the old fit.json."""
    import signal
    import subprocess
    import sys

    import pandas as pd

    out = tmp_path / "out"
    many, fewer = tmp_path / "many.csv", tmp_path / "fewer.csv"
    frame = pd.read_csv(BUNDLED)
    frames = [frame.assign(muscle=f"M{i}") for i in range(40)]  # 81 plots: seconds
    pd.concat(frames).to_csv(many, index=False)
    pd.concat(f.iloc[:-40] for f in frames[:2]).to_csv(fewer, index=False)  # other plots
    assert pamid_cli(["fit", many, "--intervals", "wald", "--json"]).returncode == 0  # cache
    assert pamid_cli(["fit", fewer, "--intervals", "wald", "--out", out]).returncode == 0
    (out / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pamid._cli", "fit", str(many), "--intervals", "wald",
         "--max-plots", "40", "--out", str(out)], stderr=subprocess.PIPE, text=True,
        env={**os.environ, "JAX_PLATFORMS": "cpu"})
    for line in proc.stderr:  # wait until it writes
        if "writing plots" in line:
            break
    proc.send_signal(signal.SIGTERM)
    rest = proc.stderr.read()
    assert proc.wait(timeout=120) == 143, rest
    assert "pamid: terminated" in rest and "Traceback" not in rest
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fewer.csv", "many.csv", "out"]
