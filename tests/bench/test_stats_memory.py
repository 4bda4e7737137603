"""Intervals over many episodes are drawn in blocks: bounded memory, the same figures."""

from __future__ import annotations

import numpy as np

from clonedrive.bench import stats


def _one_draw_bootstrap(values, seed=0):
    data = np.asarray(values, dtype=float)
    draws = np.random.default_rng(seed).integers(0, data.size, size=(stats.RESAMPLES, data.size))
    return np.mean(data[draws], axis=1)


def test_blocks_give_the_interval_one_draw_gives(monkeypatch):
    values = np.random.default_rng(3).normal(size=301)
    whole = stats.bootstrap_ci(values)
    monkeypatch.setattr(stats, "MAX_DRAWN_VALUES", 1000)  # blocks of 3 resamples
    assert stats.bootstrap_ci(values) == whole
    spread = _one_draw_bootstrap(values)
    assert whole["low"] == round(float(np.percentile(spread, 2.5)), 4)  # as before blocks


def test_a_pooled_ratio_in_blocks_is_the_same(monkeypatch):
    rng = np.random.default_rng(4)
    top, bottom = rng.poisson(1.0, 500).astype(float), rng.uniform(0.5, 2.0, 500)
    whole = stats.ratio_ci(top, bottom)
    monkeypatch.setattr(stats, "MAX_DRAWN_VALUES", 700)
    assert stats.ratio_ci(top, bottom) == whole


def test_no_block_holds_more_than_the_cap():
    sizes = [block.size for block in stats._draws(0, stats.RESAMPLES, 250_000)]
    assert max(sizes) <= stats.MAX_DRAWN_VALUES and sum(sizes) == stats.RESAMPLES * 250_000
