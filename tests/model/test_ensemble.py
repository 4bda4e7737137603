"""Ensembles: several models as one file predicting their mean, built, saved, loaded and driven."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.cli import main
from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.model.architectures import build_model
from clonedrive.model.ensemble import build_ensemble
from clonedrive.network.contract import has_speed_head
from clonedrive.network.model_file import load_model


def frames(count: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (count, 160, 320, 3), dtype=np.uint8)


def test_ensemble_predicts_the_members_mean_and_drives(tmp_path: Path) -> None:
    members = [build_model("fast", seed=seed, speed_head=True, crop_top_px=crop)
               for seed, crop in ((1, 80), (2, 60), (3, 80))]
    images = frames(5, 0)
    outputs = [member.predict_on_batch(images.astype(np.float32)) for member in members]
    ensemble = build_ensemble(members)
    assert has_speed_head(ensemble)
    ensemble.save(tmp_path / "ensemble.keras")
    loaded = load_model(tmp_path / "ensemble.keras")  # safe mode: no Lambda
    policy = NetworkPolicy(loaded)
    steering, speed = policy.predict(images)
    # Each frame is predicted alone: from the second frame on, the checked trace of one frame.
    assert policy.forward.traced_shapes == [(1, *images.shape[1:])]
    again, _ = policy.predict(images)
    np.testing.assert_array_equal(again, steering)
    want_steering = np.mean([out[0][:, 0] for out in outputs], axis=0)
    want_speed = np.mean([out[1][:, 0] for out in outputs], axis=0)
    np.testing.assert_allclose(steering, np.clip(want_steering, -1, 1), atol=1e-6)
    np.testing.assert_allclose(speed / policy_speed_scale(), np.clip(want_speed, 0, 1), atol=1e-6)
    # The members really differ: the mean is none of them.
    assert not np.allclose(outputs[0][0], outputs[1][0], atol=1e-3)


def policy_speed_scale() -> float:
    from clonedrive.network.contract import TARGET_SPEED_SCALE_MPH

    return float(TARGET_SPEED_SCALE_MPH)


def test_ensemble_refuses_mixed_or_too_few_members() -> None:
    headed = build_model("fast", seed=1, speed_head=True)
    plain = build_model("fast", seed=2)
    with pytest.raises(ValueError, match="models 2 have a speed head"):
        build_ensemble([plain, headed])
    with pytest.raises(ValueError, match="at least 2"):
        build_ensemble([plain])
    one_output = build_ensemble([plain, build_model("seed", seed=3)])
    assert not has_speed_head(one_output) and one_output.output_names == ["steering"]


def test_ensemble_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    for seed in (1, 2):
        build_model("fast", seed=seed).save(tmp_path / f"m{seed}.keras")
    build_model("fast", seed=3, speed_head=True).save(tmp_path / "headed.keras")
    out = tmp_path / "runs" / "ensemble.keras"
    models = [str(tmp_path / "m1.keras"), str(tmp_path / "m2.keras")]
    assert main(["ensemble", *models, "--out", str(out)]) == 0
    assert "the mean steering of 2 models" in capsys.readouterr().out
    images = frames(3, 4).astype(np.float32)
    want = np.mean([load_model(path).predict_on_batch(images) for path in models], axis=0)
    np.testing.assert_allclose(load_model(out).predict_on_batch(images), want, atol=1e-6)
    # Bad input: a clear message, exit 2, nothing written.
    bad = tmp_path / "bad.keras"
    assert main(["ensemble", *models, "--out", str(tmp_path / "e.h5")]) == 2
    assert main(["ensemble", models[0], str(tmp_path / "headed.keras"), "--out", str(bad)]) == 2
    assert main(["ensemble", models[0], str(tmp_path / "missing.keras"), "--out", str(bad)]) == 2
    assert main(["ensemble", models[0], "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "must end in .keras" in err and "speed head" in err and "missing.keras" in err
    assert "at least 2" in err and "Traceback" not in err
    assert not bad.exists() and not (tmp_path / "e.h5").exists()
