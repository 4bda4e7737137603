"""Steering balancing, the write-up's method.

Driving data is dominated by straight-ahead steering. The write-up evens it out:

1. histogram the steering labels into 20 equal bins between the smallest and largest label;
2. the target is the average number of samples per bin (samples / bins);
3. in a bin holding more than the target, each sample is kept with probability
   target / (samples in the bin); bins at or below the target are kept whole.

One uniform number is drawn from the given ``numpy.random.Generator`` per sample, in input
order, so the same generator state always keeps the same samples.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.base.config import atomic_path

DEFAULT_BINS = 20


@dataclass(frozen=True)
class BalanceResult:
    """What balancing kept, with the histograms before and after."""

    keep: np.ndarray  # sorted indices of the kept samples
    bin_edges: np.ndarray  # (bins + 1,) steering, [-1, 1] units
    counts_before: np.ndarray  # (bins,) samples per bin before
    counts_after: np.ndarray  # (bins,) samples per bin after
    target: float  # average samples per bin before balancing
    keep_probability: np.ndarray  # (bins,) probability a sample of each bin is kept

    @property
    def expected_after(self) -> np.ndarray:
        """Expected samples per bin after balancing: min(count, target)."""
        return self.counts_before * self.keep_probability

    def summary(self) -> str:
        """A few lines for a person: totals and per-bin counts before -> after."""
        before, after = int(self.counts_before.sum()), int(self.counts_after.sum())
        lines = [
            f"balancing: {before} -> {after} samples ({len(self.counts_before)} bins, "
            f"target {self.target:.1f} per bin)"
        ]
        for low, high, count_before, count_after in zip(
            self.bin_edges[:-1], self.bin_edges[1:], self.counts_before, self.counts_after,
            strict=True,
        ):
            lines.append(f"  [{low:+.3f}, {high:+.3f}): {count_before:6d} -> {count_after:6d}")
        return "\n".join(lines)


def balance_steering(
    steering: np.ndarray, rng: np.random.Generator, *, bins: int = DEFAULT_BINS
) -> BalanceResult:
    """Balance ``steering`` labels ([-1, 1]) with the write-up's method (see module doc)."""
    steering = np.asarray(steering, dtype=np.float64)
    if steering.ndim != 1:
        raise ValueError(f"steering must be 1-D, got shape {steering.shape}")
    if bins < 1:
        raise ValueError(f"bins must be >= 1, got {bins}")
    if steering.size == 0:
        edges = np.linspace(-1.0, 1.0, bins + 1)
        zeros = np.zeros(bins, dtype=np.int64)
        return BalanceResult(np.zeros(0, np.int64), edges, zeros, zeros, 0.0, np.ones(bins))
    counts, edges = np.histogram(steering, bins=bins)
    target = steering.size / bins
    probability = np.where(counts > target, target / np.maximum(counts, 1), 1.0)
    sample_bin = bin_of(steering, edges)
    draws = rng.random(steering.size)
    keep = np.flatnonzero(draws < probability[sample_bin])
    counts_after = np.bincount(sample_bin[keep], minlength=bins)
    return BalanceResult(
        keep=keep,
        bin_edges=edges,
        counts_before=counts.astype(np.int64),
        counts_after=counts_after.astype(np.int64),
        target=float(target),
        keep_probability=probability,
    )


def bin_of(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The histogram bin of each value, as ``np.histogram`` counts it (last bin closed)."""
    index = np.searchsorted(edges, values, side="right") - 1
    return np.clip(index, 0, len(edges) - 2)


def plot_histogram(
    counts: np.ndarray, edges: np.ndarray, path: str | os.PathLike, *, title: str,
    target: float | None = None,
) -> Path:
    """Save a bar chart of a steering histogram as PNG (matplotlib Agg), atomically."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    path = Path(path)
    figure = Figure(figsize=(7, 4), dpi=100)
    axes = figure.add_subplot()
    axes.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="tab:blue",
             edgecolor="white")
    if target is not None:
        axes.axhline(target, color="tab:red", linestyle="--", label=f"target {target:.1f}")
        axes.legend()
    axes.set_xlabel("steering (wheel angle / 25 deg; + = right)")
    axes.set_ylabel("samples")
    axes.set_title(f"{title} ({int(np.sum(counts))} samples)")
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png")
    return path


def save_balance_plots(
    result: BalanceResult, before_path: str | os.PathLike, after_path: str | os.PathLike
) -> tuple[Path, Path]:
    """``steering_before.png`` / ``steering_after.png``-style histograms of ``result``."""
    return (
        plot_histogram(result.counts_before, result.bin_edges, before_path,
                       title="steering before balancing", target=result.target),
        plot_histogram(result.counts_after, result.bin_edges, after_path,
                       title="steering after balancing", target=result.target),
    )
