"""Train/validation splits: random by row, contiguous time blocks, whole recordings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.recipe import default_recipe_for, expand
from clonedrive.data.split import split_samples

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"
MOUNTAIN = FIXTURES / "mountain_windows_paths"


@pytest.fixture(scope="module")
def samples():
    return expand(default_recipe_for([LAKE, MOUNTAIN]))


def _rows(samples, indices) -> set[tuple[int, int]]:
    return set(zip(samples.recording[indices].tolist(), samples.row[indices].tolist(), strict=True))


def _check_partition(samples, split) -> None:
    assert np.intersect1d(split.train, split.val).size == 0
    np.testing.assert_array_equal(np.union1d(split.train, split.val), np.arange(len(samples)))


def test_random_split_keeps_each_row_on_one_side(samples) -> None:
    split = split_samples(samples, "random", np.random.default_rng(0))
    _check_partition(samples, split)
    train_rows, val_rows = _rows(samples, split.train), _rows(samples, split.val)
    assert not train_rows & val_rows  # a frame's cameras and flips never straddle the split
    assert len(val_rows) == 28  # 20 % of 140 rows
    assert split.kind == "random" and "split 'random'" in split.description
    again = split_samples(samples, "random", np.random.default_rng(0))
    np.testing.assert_array_equal(split.val, again.val)
    other = split_samples(samples, "random", np.random.default_rng(1))
    assert not np.array_equal(split.val, other.val)


def test_block_split_keeps_time_blocks_whole(samples) -> None:
    split = split_samples(samples, "blocks", np.random.default_rng(0), block_s=5.0)
    _check_partition(samples, split)

    def blocks(indices):
        block = np.floor(samples.time_s[indices] / 5.0).astype(int)
        return set(zip(samples.recording[indices].tolist(), block.tolist(), strict=True))

    assert not blocks(split.train) & blocks(split.val)
    val_share = len(_rows(samples, split.val)) / 140
    assert 0.2 <= val_share < 0.5
    assert "contiguous 5 s blocks" in split.description


def test_recording_split_holds_out_whole_recordings(samples) -> None:
    split = split_samples(samples, "recording", np.random.default_rng(0))
    _check_partition(samples, split)
    assert len(set(samples.recording[split.val].tolist())) == 1
    assert not set(samples.recording[split.val].tolist()) & set(
        samples.recording[split.train].tolist()
    )
    single = expand(default_recipe_for([LAKE]))
    with pytest.raises(ValueError, match="at least two of a recording"):
        split_samples(single, "recording", np.random.default_rng(0))


def test_split_rejects_bad_arguments(samples) -> None:
    with pytest.raises(ValueError, match="unknown split 'time'"):
        split_samples(samples, "time", np.random.default_rng(0))
    with pytest.raises(ValueError, match="val_fraction"):
        split_samples(samples, "random", np.random.default_rng(0), val_fraction=1.0)
