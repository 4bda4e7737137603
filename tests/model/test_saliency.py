"""VisualBackProp: masks from the conv layers' averaged feature maps, mapped back to the frame;
`clonedrive saliency` writes overlays for images and logs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.udacity_spec import IMAGE_SHAPE
from clonedrive.cli import main
from clonedrive.model.architectures import build_model
from clonedrive.model.saliency import VisualBackProp, _spread, overlay
from clonedrive.network.crop import CROP_BOTTOM_PX, CROP_TOP_PX

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"


def test_spread_is_the_transposed_convolution_with_ones() -> None:
    mask = np.array([[[1.0, 2.0]]], dtype=np.float32)  # 1x2 map
    # kernel 3x3, stride 2: output 3x5, the two patches overlap in column 2.
    out = _spread(mask, (3, 3), (2, 2))
    assert out.shape == (1, 3, 5)
    np.testing.assert_array_equal(out[0, 0], [1, 1, 3, 2, 2])
    np.testing.assert_array_equal(out[0, 2], [1, 1, 3, 2, 2])


def bright_stripe_frames() -> np.ndarray:
    """Grey frames with one bright vertical stripe in the cropped band (a road line)."""
    frames = np.full((2, *IMAGE_SHAPE), 90, dtype=np.uint8)
    frames[0, :, 100:108] = 255
    frames[1, :, 220:228] = 255
    return frames


@pytest.mark.parametrize("name", ["fast", "seed", "pilotnet"])
def test_masks_cover_the_cropped_band_and_follow_the_features(name) -> None:
    model = build_model(name, seed=2, data_format="channels_last")
    saliency = VisualBackProp(model)
    # The frozen RGB->YUV 1x1 convolution of pilotnet is not a feature layer.
    assert all(stage.kernel != (1, 1) for stage in saliency.stages)
    masks = saliency.masks(bright_stripe_frames())
    assert masks.shape == (2, 160, 320) and masks.dtype == np.float32
    assert masks.min() >= 0.0 and masks.max() == pytest.approx(1.0)
    assert not masks[:, :CROP_TOP_PX].any() and not masks[:, 160 - CROP_BOTTOM_PX:].any()
    # Same weights, channels first or last: the same masks.
    first = VisualBackProp(build_model(name, seed=2, data_format="channels_first"))
    np.testing.assert_allclose(first.masks(bright_stripe_frames()), masks, atol=1e-4)


def test_a_model_without_convolutions_is_refused() -> None:
    import keras

    inputs = keras.Input(shape=IMAGE_SHAPE)
    outputs = keras.layers.Dense(1)(keras.layers.GlobalAveragePooling2D()(inputs))
    with pytest.raises(ValueError, match="no convolutional layer"):
        VisualBackProp(keras.Model(inputs, outputs))


def test_overlay_paints_the_mask_green() -> None:
    image = np.full(IMAGE_SHAPE, 100, np.uint8)
    mask = np.zeros(IMAGE_SHAPE[:2], np.float32)
    mask[:, :10] = 1.0
    painted = overlay(image, mask)
    assert painted[0, 0, 1] > 200 and painted[0, 0, 0] < 100  # green where the mask is
    assert tuple(painted[0, 200]) == (70, 70, 70)  # darkened elsewhere


def test_saliency_command_on_images_and_logs(tmp_path, capsys) -> None:
    model = build_model("fast", seed=0, speed_head=True)
    model.save(tmp_path / "model.keras")
    log = FIXTURES / "lake_posix_mixed_columns"
    image = sorted((log / "IMG").glob("center_*.jpg"))[0]
    out = tmp_path / "saliency"
    code = main(["saliency", str(tmp_path / "model.keras"), str(image), str(log),
                 "--frames-per-log", "3", "--out", str(out)])
    assert code == 0
    report = json.loads((out / "saliency.json").read_text())
    assert len(report["frames"]) == 4 and report["layers"] == ["conv1", "conv2", "conv3"]
    names = [frame["overlay"] for frame in report["frames"]]
    assert len(set(names)) == 4 and all((out / name).is_file() for name in names)
    assert all("target_speed_mph" in frame for frame in report["frames"])
    # Bad input: one clear line, nothing written outside --out.
    assert main(["saliency", str(tmp_path / "model.keras"), str(tmp_path / "nothing.jpg"),
                 "--out", str(tmp_path / "bad")]) == 2
    assert "nothing.jpg" in capsys.readouterr().err


def test_evaluate_video_can_show_where_the_network_looks(tmp_path) -> None:
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate
    from clonedrive.evaluate.video import read_stills

    policy = NetworkPolicy(build_model("fast", seed=0))
    greens = {}
    for painted in (False, True):
        out = tmp_path / str(painted)
        config = EvalConfig(tracks=("lake",), laps=1, max_seconds=2.0, video=True,
                            video_saliency=painted, scenery=False, expert_reference=False)
        report = evaluate(policy, config, out, progress=False)
        (_, frame), = read_stills(out / report["runs"][0]["video"], count=1)
        band = frame[2 * 90:2 * 130].astype(int)  # the HUD frame is the camera at 2x
        greens[painted] = float(np.mean(band[..., 1] - band[..., 0]))
    assert greens[True] > greens[False] + 10.0  # the mask is painted green


def test_a_model_cropping_less_has_masks_from_its_own_top_row() -> None:
    model = build_model("fast", seed=1, crop_top_px=60, speed_head=True)
    masks = VisualBackProp(model).masks(bright_stripe_frames())
    assert not masks[:, :60].any() and masks[:, 60:80].any()
    with pytest.raises(ValueError, match="crop_top_px"):
        build_model("fast", crop_top_px=120)


@pytest.mark.slow
def test_saliency_videos_from_worker_processes_load_the_keras_model(tmp_path) -> None:
    """Workers normally run the model's traces without Keras; VisualBackProp needs the Keras
    model, so with --video-saliency they load the model file."""
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    model = build_model("fast", seed=0)
    model.save(tmp_path / "model.keras")
    config = EvalConfig(tracks=("lake",), speeds_mph=(15.0, 20.0), laps=1, max_seconds=1.0,
                        video=True, video_saliency=True, scenery=False,
                        expert_reference=False, workers=2)
    report = evaluate(NetworkPolicy(model), config, tmp_path / "out", progress=False,
                      model_path=str(tmp_path / "model.keras"))
    assert report["complete"] and len(report["runs"]) == 2
    assert all((tmp_path / "out" / run["video"]).is_file() for run in report["runs"])
