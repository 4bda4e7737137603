"""A shared run folder whose model.keras declares a huge layer: the report leaves the network
section out, saying why, instead of letting Keras allocate the layer."""

from __future__ import annotations

from pathlib import Path

from support.hostile_files import keras_with_huge_dense

from clonedrive.report.writeup import write_report

#: 8 inputs x 160 million outputs x 4 bytes: 5.1 GB declared in a file of a few KB.
HUGE_UNITS = 160_000_000


def test_the_network_section_refuses_a_model_declaring_a_huge_layer(
        tiny_model_path: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    keras_with_huge_dense(tiny_model_path, run / "model.keras", HUGE_UNITS)
    (run / "history.csv").write_text("epoch,loss,val_loss\n0,0.5,0.6\n", encoding="utf-8")
    result = write_report(run, tmp_path / "out")
    refused = [note for note in result.notes if note.startswith("`model.keras` refused: ")]
    assert len(refused) == 1
    assert f"{run / 'model.keras'}: its layer configuration declares 5." in refused[0]
