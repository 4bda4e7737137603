"""``train --consistency``: each sample beside its next frame, the pair augmented alike, and a
loss that penalises the part of their prediction change the labels do not explain."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import keras
import numpy as np
import pytest

from clonedrive.data.augment import augment_batch
from clonedrive.data.batches import DrivingBatches, ImageCache
from clonedrive.data.neighbours import next_frames
from clonedrive.data.recipe import default_recipe_for, expand
from clonedrive.data.recorder import RecordConfig, record
from clonedrive.drivers.policy import load_policy
from clonedrive.model.consistency import ConsistentMSE
from clonedrive.model.train import train
from clonedrive.model.train_config import TrainConfig


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("consistency") / "expert"
    record(RecordConfig(track="lake", seconds=2.0, speed_mph=30.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), folder, progress=False)
    return folder


def test_next_frames_links_the_next_line_of_the_same_camera_and_mirroring(recording) -> None:
    samples = expand(default_recipe_for([recording]))
    partner = next_frames(samples)
    rows = samples.row.max()
    for index in range(len(samples)):
        other = partner[index]
        same = (samples.recording[other], samples.camera[other], samples.flip[other])
        assert same == (samples.recording[index], samples.camera[index], samples.flip[index])
        if samples.row[index] == rows:  # the last line has no next frame: itself
            assert other == index
        else:
            assert samples.row[other] == samples.row[index] + 1
    # A subset that lost some rows pairs the samples before the gap with themselves.
    keep = np.flatnonzero(samples.row != 5)
    subset = samples.subset(keep)
    partner = next_frames(subset)
    before_gap = np.flatnonzero(subset.row == 4)
    assert len(before_gap) and np.all(partner[before_gap] == before_gap)
    assert np.all(subset.row[partner[subset.row == 3]] == 4)


def test_pairs_are_augmented_alike() -> None:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, size=(3, 160, 320, 3), dtype=np.uint8)
    images = np.concatenate([frames, frames])
    labels = np.array([0.1, -0.2, 0.3, 0.1, -0.2, 0.3], np.float32)
    out, out_labels = augment_batch(images, labels, np.random.default_rng(5), pairs=True)
    np.testing.assert_array_equal(out[:3], out[3:])
    np.testing.assert_array_equal(out_labels[:3], out_labels[3:])
    assert not np.array_equal(out[0], out[1])  # ...while the samples of a batch differ
    # Without pairs the same frames get their own draws.
    single, _ = augment_batch(images, labels, np.random.default_rng(5))
    assert not np.array_equal(single[:3], single[3:])
    with pytest.raises(ValueError, match="even number"):
        augment_batch(images[:5], labels[:5], np.random.default_rng(5), pairs=True)


def test_batches_with_partners_hold_each_sample_then_its_next_frame(recording) -> None:
    samples = expand(default_recipe_for([recording]))
    cache = ImageCache(samples.unique_paths)
    partner = next_frames(samples)
    batches = DrivingBatches(samples, cache, batch_size=4, partners=partner)
    images, labels = batches[1]
    chosen = batches.batch_indices(1)
    assert images.shape[0] == labels.shape[0] == 8
    np.testing.assert_allclose(labels, samples.steering[np.concatenate([chosen,
                                                                        partner[chosen]])])
    with pytest.raises(ValueError, match="partners"):
        DrivingBatches(samples, cache, batch_size=4, partners=partner[:-1])


def test_the_loss_adds_the_weighted_squared_difference_of_each_pairs_errors() -> None:
    y_true = np.array([0.1, 0.2, 0.1, 0.3], np.float32)  # pairs (0, 2) and (1, 3)
    y_pred = np.array([[0.2], [0.2], [0.1], [0.1]], np.float32)
    per_sample = keras.ops.convert_to_numpy(ConsistentMSE(3.0).call(y_true, y_pred))
    errors = y_pred[:, 0] - y_true  # 0.1, 0, 0, -0.2
    pair = np.array([(0.1 - 0.0) ** 2, (0.0 + 0.2) ** 2])
    np.testing.assert_allclose(per_sample, errors**2 + 3.0 * np.concatenate([pair, pair]),
                               atol=1e-7)
    # A change the labels explain costs nothing beyond the MSE.
    shifted = np.array([[0.1], [0.2], [0.1], [0.3]], np.float32) + 0.05
    per_sample = keras.ops.convert_to_numpy(ConsistentMSE(3.0).call(y_true, shifted))
    np.testing.assert_allclose(per_sample, np.full(4, 0.0025), atol=1e-7)
    assert ConsistentMSE.from_config(ConsistentMSE(2.5).get_config()).weight == 2.5


@pytest.mark.slow
def test_a_consistency_run_trains_resumes_and_drives(recording, tmp_path) -> None:
    config = TrainConfig(model="fast", batch_size=16, epochs=1, learning_rate=1e-3,
                         speed_head=True, export_h5=False, consistency=5.0)
    first = train(config, [recording], tmp_path / "run", progress=False)
    assert np.isfinite(first.best_val_loss)
    resumed = train(dataclasses.replace(config, epochs=2), [recording], tmp_path / "run",
                    resume=True, progress=False)
    assert resumed.epochs_done == 2
    # The plain steering MSE is logged apart from the loss, which carries the penalty.
    assert all(row["loss"] >= row["mse"] - 1e-6 for row in resumed.history)
    policy = load_policy(resumed.model_path, set_speed_mph=30.0)
    steering = policy.predict_steering(np.zeros((2, 160, 320, 3), np.uint8))
    assert steering.shape == (2,) and np.all(np.isfinite(steering))
    # The write-up's training settings say what the loss was.
    from clonedrive.report.writeup import write_report

    shutil.move(tmp_path / "run", tmp_path / "folder" / "train")
    markdown = write_report(tmp_path / "folder").markdown_path.read_text(encoding="utf-8")
    assert ("mse on the steering label, plus 5 x the squared difference of neighbouring "
            "frames' errors (consistency)") in markdown


def test_consistency_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="consistency must be >= 0"):
        TrainConfig(consistency=-1.0)
    with pytest.raises(ValueError, match="consistency must be >= 0"):
        TrainConfig(consistency=float("nan"))
    with pytest.raises(ValueError, match="adds to the mse loss"):
        TrainConfig(consistency=1.0, loss="mae")
