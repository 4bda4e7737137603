"""bench with students' Lambda models (--trust-model) and ONNX models (--runtime)."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.student_models import student_model, write_keras2_h5

from clonedrive.bench.driving import BatchTask, drive_batch
from clonedrive.bench.run import BenchConfig, offline_mse, offline_rows
from clonedrive.bench.suite import EpisodeSpec
from clonedrive.sim.conditions import Conditions

FIXTURE = Path(__file__).parents[1] / "fixtures" / "udacity" / "lake_posix_mixed_columns"


def test_a_students_model_is_benched_only_with_trust(tmp_path: Path) -> None:
    path = str(write_keras2_h5(tmp_path / "model.h5", student_model(seed=2)))
    rows = offline_rows((str(FIXTURE),))[:16]
    with pytest.raises(ValueError, match="--trust-model"):
        offline_mse(path, rows)
    trusted = offline_mse(path, rows, trust=True)
    # The same network rebuilt without its Lambda (a safe .keras file) scores the same.
    from clonedrive.network.legacy_keras import rebuild

    safe = tmp_path / "rebuilt.keras"
    rebuild(path, normalisation=(1 / 255.0, -0.5)).save(safe)
    assert 0.0 < trusted == pytest.approx(offline_mse(str(safe), rows), rel=1e-5)
    spec = EpisodeSpec(split="a", index=0, track="lake", speed_mph=10.0, family="clear", seed=0,
                       conditions=Conditions(), laps=1)
    task = BatchTask(kind="model", model=path, scenery=False, max_seconds=1.0,
                     trust_model=True, episodes=(spec,))
    [result] = drive_batch(task)
    assert result["distance_m"] > 0.0
    with pytest.raises(ValueError, match="runtime 'tpu'"):
        BenchConfig(models=(path,), runtime="tpu")
