"""``replay`` and ``web`` hold their output as the other writers do: a second writer into the
same folder is refused with the first one's PID, and an output inside an input (a LOG_DIR, the
model) is refused before anything is read or written."""

from __future__ import annotations

import shutil
from pathlib import Path

from support.cli_process import refused, run_clonedrive

from clonedrive.data.output_lock import claim_output

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "udacity" / "stationary"


def listing(folder: Path) -> list[str]:
    return sorted(str(path.relative_to(folder)) for path in folder.rglob("*"))


def test_replay_refuses_an_output_inside_a_log_folder(tmp_path: Path,
                                                      tiny_model_path: Path) -> None:
    log = tmp_path / "log"
    shutil.copytree(FIXTURE.parent / "mountain_windows_paths", log)  # replay drives it
    before = listing(log)
    result = run_clonedrive("replay", tiny_model_path, log, "--out", log / "replay")
    message = refused(result, "replay", 1)
    assert "is inside the input" in message and str(log) in message
    assert listing(log) == before


def test_replay_refuses_a_folder_another_writer_holds(tmp_path: Path,
                                                      tiny_model_path: Path) -> None:
    out = tmp_path / "replay"
    with claim_output("replay", out):
        result = run_clonedrive("replay", tiny_model_path, FIXTURE, "--out", out)
    message = refused(result, "replay", 1)
    assert "another clonedrive replay" in message and "is writing there" in message


def test_web_refuses_an_output_over_its_model(tmp_path: Path, tiny_model_path: Path) -> None:
    model = tmp_path / "tiny.keras"
    shutil.copy(tiny_model_path, model)
    result = run_clonedrive("web", "--model", model, "--port", "0", "--no-scenery",
                            "--out", model)
    assert "is the input" in refused(result, "web", 1)
    assert model.read_bytes() == tiny_model_path.read_bytes()


def test_web_refuses_a_folder_another_web_records_into(tmp_path: Path) -> None:
    out = tmp_path / "takeovers"
    with claim_output("web", out):
        result = run_clonedrive("web", "--port", "0", "--no-scenery", "--out", out)
    assert "another clonedrive web" in refused(result, "web", 1)
