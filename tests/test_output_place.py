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


# -- every output name unique, bounded, and traceable to its muscle or trial --------------------


def test_file_names_of_names_that_read_alike_differ_and_stay_short():
    from pamid._io import safe_file_names

    names = ["A/B", "A_B", "A B", "M" * 300, "é" * 200, "Festo10mm_lc40cm", "m1", "M1"]
    pieces = safe_file_names(names)
    assert len({p.casefold() for p in pieces}) == len(names)
    assert pieces[1] == "A_B" and pieces[5] == "Festo10mm_lc40cm"  # ordinary names as they are
    assert pieces[0].startswith("A_B-") and pieces[3].startswith("MMM")
    assert all(len(p.encode()) <= 160 for p in pieces)
    assert safe_file_names(names) == pieces  # stable
    # a name written like another's hashed piece still gets a file of its own
    assert len(set(safe_file_names(["A/B", pieces[0]]))) == 2


@pytest.mark.parametrize("command", [["fit", "--intervals", "wald"],
                                     ["compare", "--models", "sarosi"]])
def test_muscles_whose_names_read_alike_each_get_their_own_plots(tmp_path, capsys, command):
    """Muscles `A/B`, `A_B` and `A B` all wrote fit_A_B.png (exit 0; fit.json listed it three
    times), and a muscle name over 255 bytes ended in exit 3 (OSError: File name too long)
    after the whole fit."""
    import json

    import pandas as pd

    frame = pd.read_csv(BUNDLED)
    names = ["A/B", "A_B", "A B", "M" * 300, "Festo10mm_lc40cm"]
    data = tmp_path / "names.csv"
    pd.concat(frame.assign(muscle=m) for m in names).to_csv(data, index=False)
    out = tmp_path / "out"
    assert main([command[0], str(data), *command[1:], "--out", str(out), "--json"]) == 0
    doc = json.loads((out / f"{command[0]}.json").read_text())
    owners = doc["muscle_of_file"]
    per_muscle = 2 if command[0] == "fit" else 1
    assert sorted(owners.values()) == sorted(names * per_muscle)
    assert len(set(doc["plots"])) == len(doc["plots"]) == len(owners) + 1
    assert set(doc["plots"]) <= {p.name for p in out.iterdir()}
    assert all(len(name.encode()) < 255 for name in doc["plots"])
    _written_as_declared(out, [command[0], "x.csv"])
    kind = "fit" if command[0] == "fit" else "models"
    assert owners[f"{kind}_A_B.png"] == "A_B"
    assert owners[f"{kind}_Festo10mm_lc40cm.png"] == "Festo10mm_lc40cm"


def test_trials_whose_names_read_alike_each_get_their_own_plot(tmp_path, capsys):
    """`pamid damping` wrote one decay_a_b.png for the trials `a/b` and `a_b`."""
    import json

    import jax

    import pamid

    osc = pamid.DampedOscillator.from_modal(0.05, 2.0, 0.46, equilibrium_rad=0.0123)
    frame = pamid.simulate_decays(jax.random.key(1), osc, pamid.DecayProtocol(
        n_trials=2, deflections_deg=(9.0, 6.0), hold_s=0.3))
    frame["trial"] = frame["trial"].map(dict(zip(frame["trial"].unique(), ["a/b", "a_b"])))
    data = tmp_path / "decay.csv"
    frame.to_csv(data, index=False)
    out = tmp_path / "out"
    assert main(["damping", str(data), "--inertia", "0.46", "--out", str(out), "--json"]) == 0
    doc = json.loads((out / "damping.json").read_text())
    assert doc["trial_of_file"]["decay_a_b.png"] == "a_b"
    assert sorted(doc["trial_of_file"].values()) == ["a/b", "a_b"]
    assert sorted(doc["plots"]) == sorted([*doc["trial_of_file"], "decrement.png"])
    assert set(doc["plots"]) <= {p.name for p in out.iterdir()}
    _written_as_declared(out, ["damping", "d.csv", "--inertia", "1"])


def _written_as_declared(out, argv):
    """Every file the command wrote has a name it declares (``outputs``: what is checked
    against its input files before any work)."""
    import fnmatch

    from pamid._cli import _parser

    declared = _parser().parse_args(argv).outputs
    for path in out.iterdir():
        if path.name != ".pamid-outputs.json":
            assert any(fnmatch.fnmatchcase(path.name, p) for p in declared), path.name


# -- caught before any computing ----------------------------------------------------------------


def test_out_as_a_dangling_symlink_is_refused_before_computing(tmp_path, capsys):
    """`--out LINK` to a folder that does not exist ran the whole fit, then said "cannot
    move the results into LINK: No such file or directory"."""
    link = tmp_path / "results"
    link.symlink_to(tmp_path / "gone" / "results")
    assert main(["fit", str(BUNDLED), "--intervals", "wald", "--out", str(link)]) == 2
    err = capsys.readouterr().err
    assert "fitting" not in err and "loaded" not in err  # nothing read, nothing computed
    assert [line for line in err.splitlines() if line.startswith("pamid: error:")] == [
        f"pamid: error: --out {link} is a symbolic link to {tmp_path / 'gone' / 'results'}, "
        "which does not exist; make that folder or name another"]
    assert link.is_symlink() and not (tmp_path / "gone").exists()


@pytest.mark.parametrize(("command", "name"), [
    (["fit", "--intervals", "wald"], "fit.json"),
    (["compare", "--models", "sarosi"], "compare.json"),
    (["diagnose"], "diagnosis.json"),
])
def test_an_input_named_like_an_output_is_refused_before_computing(tmp_path, capsys, command,
                                                                   name):
    """`pamid fit DIR/fit.json --out DIR` (a bench file under the name of an output) read
    the file and ran the whole fit before it refused to replace it."""
    data = tmp_path / name
    data.write_bytes(BUNDLED.read_bytes())
    assert main([command[0], str(data), *command[1:], "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "loaded" not in err and "diagnosing" not in err  # nothing read, nothing computed
    assert [line for line in err.splitlines() if line.startswith("pamid: error:")] == [
        f"pamid: error: refusing to write {data}: it is the input file {data}; choose "
        "another output path"]
    assert data.read_bytes() == BUNDLED.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
