"""Mistakes a newcomer makes get one line that names the flag or file, with a hint."""

from __future__ import annotations

from pathlib import Path

import pytest

from clonedrive.cli import main


@pytest.mark.parametrize(("argv", "said"), [
    (["record", "--track", "lake", "--speed", "300", "--out", "x"],
     "clonedrive record: --speed must be a speed in (0, 30] mph (the car's top speed), got 300.0"),
    (["evaluate", "m.keras", "--speed", "15", "--speed", "nan"],
     "clonedrive evaluate: --speed must be a speed in (0, 30] mph"),
    (["evaluate", "m.keras", "--unseen", "1", "--unseen-speed", "-5"],
     "clonedrive evaluate: --unseen-speed must be a speed in (0, 30] mph"),
    (["autonomous", "--speed", "31"], "clonedrive autonomous: --speed must be a speed in"),
])
def test_a_speed_out_of_range_is_refused_naming_its_flag(argv, said, tmp_path: Path, capsys,
                                                         monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(said) and len(err.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())  # refused before anything was made


def test_a_misspelt_track_gets_a_guess(tmp_path: Path, capsys):
    assert main(["record", "--track", "lakee", "--out", str(tmp_path / "d")]) == 2
    assert "unknown track 'lakee': did you mean 'lake'?" in capsys.readouterr().err


def test_a_missing_model_is_named_with_what_a_model_is(tmp_path: Path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["evaluate", "nonexistent.keras", "--track", "lake"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("clonedrive evaluate: nonexistent.keras: no such model file (a .keras, .h5 "
                   "or .onnx file, such as runs/demo/train/model.keras)")
    assert "Errno" not in err and not (tmp_path / "eval").exists()


def test_a_run_folder_given_as_the_model_points_at_its_model(tmp_path: Path, capsys):
    run = tmp_path / "demo"
    (run / "train").mkdir(parents=True)
    (run / "train" / "model.keras").write_bytes(b"not read")
    assert main(["evaluate", str(run), "--track", "lake"]) == 2
    assert f"a folder, not a model file; did you mean {run / 'train' / 'model.keras'}?" in \
        capsys.readouterr().err
