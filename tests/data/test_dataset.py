"""build_dataset: the same samples, report and summary every time; bad rows and images reported;
no cache file left behind, whatever happens."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.batches import ImageCache, read_rgb
from clonedrive.data.dataset import CACHE_FILE, DatasetConfig, build_dataset
from clonedrive.data.driving_log import read_driving_log
from clonedrive.data.recipe import default_recipe_for
from clonedrive.model.train_config import TrainConfig

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"
MOUNTAIN = FIXTURES / "mountain_windows_paths"
SAMPLE_FIELDS = ("image_index", "camera", "steering", "flip", "recording", "row", "time_s",
                 "weight", "target_speed_mph", "recorded_speed_mph")


def _config(**changes) -> DatasetConfig:
    return TrainConfig(**changes).dataset_config()


def _build(tmp_path: Path, name: str, config: DatasetConfig, folders=(LAKE, MOUNTAIN)):
    out = tmp_path / name
    out.mkdir()
    return build_dataset(default_recipe_for(list(folders)), config, out, progress=False)


def _same_samples(first, second) -> None:
    assert first.unique_paths == second.unique_paths
    for name in SAMPLE_FIELDS:
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name), err_msg=name)


@pytest.fixture
def damaged(tmp_path: Path) -> Path:
    """A copy of the lake recording with one row's center image missing and one left image cut
    to a third of its bytes."""
    folder = tmp_path / "damaged"
    shutil.copytree(LAKE, folder)
    rows = read_driving_log(folder).rows
    rows[5].center.unlink()
    data = rows[9].left.read_bytes()
    rows[9].left.write_bytes(data[: len(data) // 3])
    return folder


@pytest.mark.parametrize("changes", [
    {},
    {"balance": False, "split": "recording", "augment": False},
    {"speed_head": True, "speed_headroom": 1.3, "split": "blocks", "cache": "memory"},
])
def test_building_twice_gives_the_same_data_set(tmp_path: Path, changes: dict) -> None:
    config = _config(**changes)
    first = _build(tmp_path, "first", config)
    second = _build(tmp_path, "second", config)
    try:
        _same_samples(first.train, second.train)
        _same_samples(first.val, second.val)
        assert first.report == second.report
        assert first.summary == second.summary.replace(str(tmp_path / "second"),
                                                       str(tmp_path / "first"))
        np.testing.assert_array_equal(np.asarray(first.cache.frames),
                                      np.asarray(second.cache.frames))
    finally:
        first.close()
        second.close()
    assert (tmp_path / "first" / "steering_before.png").is_file()
    # Without balancing there is no "after": one histogram of the labels.
    assert (tmp_path / "first" / "steering_after.png").is_file() == config.balance


def test_the_report_counts_what_was_used(tmp_path: Path) -> None:
    dataset = _build(tmp_path, "run", _config(cache="memory"))
    dataset.close()
    report = dataset.report
    rows = sum(len(read_driving_log(folder).rows) for folder in (LAKE, MOUNTAIN))
    assert report["rows_read"] == rows and report["skipped_rows"] == {}
    assert report["samples_before_balance"] == rows * 3 * 2  # three cameras, flipped copies
    assert report["train_samples"] == len(dataset.train) > 0
    assert report["val_samples"] == len(dataset.val) > 0
    assert report["train_samples"] + report["val_samples"] == report["samples_after_balance"]
    assert report["images_cached"] == len(dataset.cache)
    assert [entry["name"] for entry in report["recordings"]] == [LAKE.name, MOUNTAIN.name]
    assert list(report)[-3:] == ["train_samples", "val_samples", "images_cached"]
    assert dataset.summary.splitlines()[0] == (
        f"2 recording(s), {rows} usable rows, {rows * 6} samples")
    assert dataset.summary.splitlines()[-1] == (
        f"training on {len(dataset.train)} samples, validating on {len(dataset.val)}")


def test_a_bad_row_and_a_bad_image_are_reported_as_skipped(tmp_path: Path, damaged: Path
                                                           ) -> None:
    dataset = _build(tmp_path, "run", _config(cache="memory", balance=False),
                     folders=(damaged,))
    dataset.close()
    report = dataset.report
    assert report["skipped_rows"] == {"image_missing": 1}
    assert len(report["skipped_row_details"]) == 1
    assert report["skipped_row_details"][0].startswith("damaged: ")
    assert report["skipped_images"] == {"image_corrupt": 1}
    assert report["skipped_image_samples"] == 2  # the image and its flipped copy (kept: no
    # balancing)
    lines = dataset.summary.splitlines()
    assert "skipped rows: 1 image_missing" in lines
    assert "skipped images: 1 image_corrupt (2 samples)" in lines
    for samples in (dataset.train, dataset.val):  # every image left decodes
        for index in np.unique(samples.image_index):
            read_rgb(samples.unique_paths[int(index)])


def test_a_memmap_cache_lives_in_the_run_folder_until_closed(tmp_path: Path) -> None:
    dataset = _build(tmp_path, "run", _config(cache="memmap"))
    assert (tmp_path / "run" / CACHE_FILE).is_file()
    assert f"memmap {tmp_path / 'run' / CACHE_FILE}" in dataset.summary
    dataset.close()
    assert not (tmp_path / "run" / CACHE_FILE).exists()


def test_a_handoff_gives_the_next_data_set_the_same_images_only(tmp_path: Path,
                                                                  damaged: Path) -> None:
    from clonedrive.data.dataset import ImageHandoff

    handoff = ImageHandoff()
    config = _config(cache="memmap")
    first = _build(tmp_path, "one", config, folders=(damaged, MOUNTAIN))
    handoff.keep(first.cache)
    again = build_dataset(default_recipe_for([damaged, MOUNTAIN]), config, tmp_path / "one",
                          progress=False, handoff=handoff)
    assert again.cache is first.cache and "reused" in again.summary
    assert again.report == first.report  # the bad image is skipped and counted as before
    # Another crop needs other rows: the kept cache is deleted and a new one decoded.
    handoff.keep(again.cache)
    (tmp_path / "two").mkdir()
    other = build_dataset(default_recipe_for([damaged, MOUNTAIN]),
                          dataclasses.replace(config, crop_top_px=config.crop_top_px + 10),
                          tmp_path / "two", progress=False, handoff=handoff)
    assert other.cache is not first.cache and "reused" not in other.summary
    assert not (tmp_path / "one" / CACHE_FILE).exists()
    handoff.keep(other.cache)
    handoff.close()
    assert not (tmp_path / "two" / CACHE_FILE).exists()


@pytest.mark.parametrize("where", ["__init__", "fill"])
def test_an_interrupted_build_leaves_no_cache_file(tmp_path: Path, monkeypatch, where: str
                                                   ) -> None:
    original = getattr(ImageCache, where)

    def interrupted(self, *args, **kwargs):
        original(self, *args, **kwargs)  # the memmap file exists by now
        assert (tmp_path / "run" / CACHE_FILE).is_file()
        raise KeyboardInterrupt

    monkeypatch.setattr(ImageCache, where, interrupted)
    with pytest.raises(KeyboardInterrupt):
        _build(tmp_path, "run", _config(cache="memmap"))
    assert not (tmp_path / "run" / CACHE_FILE).exists()


def test_no_usable_sample_is_an_error(tmp_path: Path, damaged: Path) -> None:
    for path in (damaged / "IMG").glob("center_*"):
        path.unlink()
    with pytest.raises(ValueError, match="no usable samples in .*image_missing"):
        _build(tmp_path, "run", _config(cache="memory"), folders=(damaged,))


def test_the_data_set_settings_come_from_the_training_settings() -> None:
    train_config = TrainConfig(seed=4, balance_bins=9, crop_top_px=60, cache="memmap")
    config = train_config.dataset_config()
    for field in dataclasses.fields(DatasetConfig):
        assert getattr(config, field.name) == getattr(train_config, field.name)
    with pytest.raises(ValueError, match="cache 'disk'; expected one of"):
        TrainConfig(cache="disk")
    with pytest.raises(ValueError, match="split 'halves'; expected one of"):
        dataclasses.replace(config, split="halves")
