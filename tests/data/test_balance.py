"""Steering balancing: the write-up's 20-bin method, exactly, and its histograms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.balance import balance_steering, bin_of, save_balance_plots


def _skewed(rng: np.random.Generator) -> np.ndarray:
    """Mostly straight driving: 3000 zeros, 600 small angles, 400 spread over [-1, 1]."""
    return np.concatenate(
        [np.zeros(3000), rng.normal(0.0, 0.05, 600), rng.uniform(-1.0, 1.0, 400)]
    ).astype(np.float32)


def test_balance_is_the_writeups_method_exactly() -> None:
    steering = _skewed(np.random.default_rng(1))
    result = balance_steering(steering, np.random.default_rng(7))

    counts, edges = np.histogram(steering.astype(np.float64), bins=20)
    np.testing.assert_array_equal(result.counts_before, counts)
    np.testing.assert_array_equal(result.bin_edges, edges)
    assert result.target == len(steering) / 20 == 200.0
    # The same decision by hand: one uniform draw per sample, kept if below target / bin size.
    draws = np.random.default_rng(7).random(len(steering))
    sample_bin = np.digitize(steering, edges[1:-1])
    probability = np.minimum(1.0, 200.0 / counts[sample_bin])
    np.testing.assert_array_equal(result.keep, np.flatnonzero(draws < probability))
    np.testing.assert_array_equal(
        result.counts_after, np.bincount(sample_bin[result.keep], minlength=20)
    )


def test_balance_keeps_small_bins_whole_and_cuts_big_bins_to_the_target() -> None:
    steering = _skewed(np.random.default_rng(2))
    result = balance_steering(steering, np.random.default_rng(3))
    small = result.counts_before <= result.target
    np.testing.assert_array_equal(result.counts_after[small], result.counts_before[small])
    np.testing.assert_allclose(result.expected_after[~small], result.target)
    # Binomial(count, target / count): within 4 standard deviations of the target.
    big = np.flatnonzero(~small)
    assert big.size >= 1
    for index in big:
        p = result.target / result.counts_before[index]
        sigma = np.sqrt(result.counts_before[index] * p * (1 - p))
        assert abs(result.counts_after[index] - result.target) <= 4 * sigma
    assert result.counts_after.sum() == len(result.keep)
    assert "balancing: 4000 ->" in result.summary()


def test_balance_is_seeded() -> None:
    steering = _skewed(np.random.default_rng(4))
    first = balance_steering(steering, np.random.default_rng(9)).keep
    again = balance_steering(steering, np.random.default_rng(9)).keep
    other = balance_steering(steering, np.random.default_rng(10)).keep
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_bin_of_matches_numpy_histogram_at_the_edges() -> None:
    values = np.array([-1.0, -0.9, -0.1, 0.0, 0.1, 0.9, 1.0])
    counts, edges = np.histogram(values, bins=20)
    np.testing.assert_array_equal(np.bincount(bin_of(values, edges), minlength=20), counts)
    assert bin_of(np.array([1.0]), edges)[0] == 19  # the last bin is closed


def test_balance_edge_cases() -> None:
    empty = balance_steering(np.zeros(0), np.random.default_rng(0))
    assert empty.keep.size == 0 and empty.counts_before.sum() == 0
    same = balance_steering(np.zeros(100), np.random.default_rng(0))
    assert same.counts_before.max() == 100 and same.target == 5.0
    with pytest.raises(ValueError, match="1-D"):
        balance_steering(np.zeros((2, 2)), np.random.default_rng(0))


def test_histogram_pngs(tmp_path: Path) -> None:
    import matplotlib.image

    result = balance_steering(_skewed(np.random.default_rng(5)), np.random.default_rng(6))
    before, after = save_balance_plots(result, tmp_path / "before.png", tmp_path / "after.png")
    for path in (before, after):
        image = matplotlib.image.imread(path)
        assert image.shape[0] > 100 and image.shape[1] > 100
    assert sorted(item.name for item in tmp_path.iterdir()) == ["after.png", "before.png"]
