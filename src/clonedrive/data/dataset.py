"""The data set a training run learns from: recipe -> samples -> balance -> split -> cache.

:func:`build_dataset` expands a recipe into samples (:mod:`clonedrive.data.recipe`), continues
a speed head's labels at the top speed (headroom, :mod:`clonedrive.data.speed_labels`), balances
the steering histogram (:mod:`clonedrive.data.balance`; writes ``steering_before.png`` and
``steering_after.png`` into the run folder), splits training from validation samples
(:mod:`clonedrive.data.split`) and decodes every image used once into an
:class:`~clonedrive.data.batches.ImageCache` (in memory, or the memmap :data:`CACHE_FILE` in the
run folder), dropping the samples whose image does not decode. It returns a :class:`Dataset`:
both sample sets, the cache, the report that ``model.train`` writes as ``dataset.json`` and the
summary lines it prints.

Deterministic: balancing draws from ``numpy.random.default_rng([seed, 1])`` and splitting from
``[seed, 2]``; nothing else is random, so building twice gives the same samples in the same
order. Interrupted (Ctrl-C, SIGTERM) or failing while the cache is made or filled, it leaves no
cache file behind.

Two training stages in one process (a recipe's ``[finetune]``) share the decoded images through
an :class:`ImageHandoff`: the second stage reuses the first one's cache when it holds the same
images and rows, instead of decoding every image again.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from clonedrive.base.udacity_spec import IMAGE_HEIGHT
from clonedrive.data.recipe import Recipe, expand
from clonedrive.data.samples import Samples
from clonedrive.network.crop import CROP_BOTTOM_PX

if TYPE_CHECKING:
    from clonedrive.base.images import ImageDecodeError
    from clonedrive.data.balance import BalanceResult
    from clonedrive.data.batches import ImageCache
    from clonedrive.data.split import Split

logger = logging.getLogger(__name__)

CACHE_MODES = ("auto", "memory", "memmap")
#: With a speed head, balancing keeps every sample whose speed label is below this [mph]
#: (the expert slowing for a bend), whatever its steering.
SLOWING_LABEL_MPH = 28.5
#: The decoded-image memmap in the run folder.
CACHE_FILE = "image_cache.u8"


@dataclass(frozen=True)
class DatasetConfig:
    """The training settings that make the data set (their defaults and the checks of the
    other fields are :class:`clonedrive.model.train.TrainConfig`'s, which derives this)."""

    seed: int  # balancing draws from default_rng([seed, 1]), splitting from [seed, 2]
    balance: bool  # the write-up's steering histogram balancing
    balance_bins: int
    split: str  # random | blocks | recording (see data.split)
    val_fraction: float
    block_s: float  # block length of the "blocks" split, seconds
    augment: bool  # widens the cached rows by augmentation's vertical shift
    augment_looks: float  # > 0 (frames restyled) widens them by its blur's reach too
    crop_top_px: int  # rows the network cuts from the top
    speed_head: bool  # speed labels are reported and slowing samples kept back
    speed_headroom: float  # labels at the top speed rise up to this multiple of it
    cache: str  # memory | memmap | auto (CACHE_MODES)
    cache_memory_limit_mb: int  # "auto" uses a memmap above this size

    def __post_init__(self) -> None:
        from clonedrive.data.split import SPLIT_KINDS

        if self.split not in SPLIT_KINDS:
            raise ValueError(f"split {self.split!r}; expected one of: {', '.join(SPLIT_KINDS)}")
        if self.cache not in CACHE_MODES:
            raise ValueError(f"cache {self.cache!r}; expected one of: {', '.join(CACHE_MODES)}")


@dataclass
class Dataset:
    """What training learns from; :meth:`close` releases (and deletes) the image cache."""

    train: Samples
    val: Samples
    cache: ImageCache  # every image of train and val, decoded once
    report: dict  # what dataset.json holds
    summary: str  # the lines printed before training

    def close(self) -> None:
        self.cache.close(delete=True)


@dataclass(frozen=True)
class _Balanced:
    """The outcome of balancing, for the report."""

    result: BalanceResult  # for the histograms (keeps everything with balancing off)
    kept_for_speed: int  # samples kept back for the speed head
    raised: int  # speed labels raised by headroom before balancing


@dataclass(frozen=True)
class _Images:
    """The outcome of decoding: unusable images by reason and the samples they cost."""

    bad: dict[str, int]
    dropped_samples: int


class ImageHandoff:
    """Decoded images handed from one training stage to the next in the same process.

    A stage gives it its cache instead of deleting it (:meth:`keep`); the next stage takes it
    (:meth:`take`) when it needs the same images (in the same order) and rows, else it is
    deleted then. :meth:`close` deletes what is left (a memmap's file too)."""

    def __init__(self) -> None:
        self.cache: ImageCache | None = None

    def keep(self, cache: ImageCache) -> None:
        self.close()
        self.cache = cache

    def take(self, paths: list[Path], rows: tuple[int, int]) -> ImageCache | None:
        cache, self.cache = self.cache, None
        if cache is not None and cache.rows == tuple(rows) and cache.paths == list(paths):
            return cache
        if cache is not None:
            cache.close(delete=True)
        return None

    def close(self) -> None:
        if self.cache is not None:
            self.cache.close(delete=True)
            self.cache = None


def build_dataset(recipe: Recipe, config: DatasetConfig, out: Path, *, progress: bool,
                  handoff: ImageHandoff | None = None) -> Dataset:
    """expand -> speed-label headroom -> balance -> split -> decode the used images once
    (unusable ones skipped); see the module doc. ``out`` is the run folder: it gets the
    balancing histograms and, for a memmap cache, :data:`CACHE_FILE`. ``ValueError`` when no
    sample is usable, or when training or validation is left without one. ``handoff``: an
    earlier stage's decoded images, used when they are this data set's."""
    from clonedrive.data.split import split_samples

    out = Path(out)
    lines: list[str] = []
    samples = _expand(recipe, config, lines)
    samples, raised = _with_headroom(config, samples, lines)
    samples, result, kept_for_speed = _balance(config, samples, lines, out)
    balanced = _Balanced(result, kept_for_speed, raised)
    split = split_samples(
        samples, config.split, np.random.default_rng([config.seed, 2]),
        val_fraction=config.val_fraction, block_s=config.block_s,
    )
    lines.append(split.description)

    samples = samples.compact()
    cache, failed = _filled_cache(config, samples, out, lines, progress=progress,
                                  handoff=handoff)
    train_samples, dropped_train = samples.subset(split.train).drop_images(failed)
    val_samples, dropped_val = samples.subset(split.val).drop_images(failed)
    images = _Images(_count_reasons(failed), dropped_train + dropped_val)
    if failed:
        lines.append(f"skipped images: {_counts_text(images.bad)} "
                     f"({images.dropped_samples} samples)")
        for error in list(failed.values())[:5]:
            logger.warning("skipped image: %s", error)
    if len(train_samples) == 0 or len(val_samples) == 0:
        cache.close(delete=True)
        raise ValueError(
            f"after skipping unusable images, {len(train_samples)} training and "
            f"{len(val_samples)} validation samples remain; need at least one of each"
        )
    report = _report(recipe, config, samples, balanced, split, images)
    report.update(train_samples=len(train_samples), val_samples=len(val_samples),
                  images_cached=len(cache))
    lines.append(f"training on {len(train_samples)} samples, validating on {len(val_samples)}")
    return Dataset(train_samples, val_samples, cache, report, "\n".join(lines))


def discard_cache(out: Path) -> None:
    """Delete the run folder's image cache file, if any (a run interrupted while making it)."""
    (Path(out) / CACHE_FILE).unlink(missing_ok=True)


def cached_rows(config: DatasetConfig) -> tuple[int, int]:
    """The frame rows training reads: the network's crop, widened by augmentation's largest
    vertical shift (a shifted picture's visible rows come from up to that far away) and, where
    frames are restyled, the rows its blur reaches beyond them."""
    from clonedrive.data.augment import BLUR_MARGIN, AugmentConfig

    margin = 0
    if config.augment:
        margin = AugmentConfig().vertical_shift_max_px + (
            BLUR_MARGIN if config.augment_looks > 0 else 0)
    return (max(0, config.crop_top_px - margin),
            min(IMAGE_HEIGHT, IMAGE_HEIGHT - CROP_BOTTOM_PX + margin))


# --- the steps ------------------------------------------------------------------------------


def _expand(recipe: Recipe, config: DatasetConfig, lines: list[str]) -> Samples:
    """Every sample of ``recipe``, what was read said in ``lines``; ``ValueError`` if none."""
    samples = expand(recipe)
    if len(samples) == 0:
        raise ValueError(
            f"no usable samples in {', '.join(str(spec.path) for spec in recipe.recordings)}"
            + (f" (skipped rows: {samples.skipped})" if samples.skipped else "")
        )
    lines.append(
        f"{len(recipe.recordings)} recording(s), {samples.rows_read} usable rows, "
        f"{len(samples)} samples"
    )
    if samples.skipped:
        lines.append(f"skipped rows: {_counts_text(samples.skipped)}")
    if samples.side_images_missing:
        lines.append(f"{samples.side_images_missing} rows lack a side image: they train with "
                     "the cameras they have")
    if config.speed_head:
        lines.append(
            f"speed labels: the expert's target speed on {samples.rows_with_target_speed} rows, "
            f"the recorded speed on {samples.rows_read - samples.rows_with_target_speed}")
    return samples


def _with_headroom(config: DatasetConfig, samples: Samples, lines: list[str]
                   ) -> tuple[Samples, int]:
    """(the samples with a speed head's labels at the top speed raised, how many were).
    Headroom comes before balancing: the profile is counted back along whole recordings,
    before balancing drops any of their samples."""
    if not (config.speed_head and config.speed_headroom != 1.0):
        return samples, 0
    from clonedrive.data.speed_labels import with_headroom

    labels, raised = with_headroom(samples.target_speed_mph, samples.recording, samples.row,
                                   samples.time_s, samples.recorded_speed_mph,
                                   config.speed_headroom)
    lines.append(f"speed head: {raised} labels at the top speed continue the expert's "
                 f"braking profile up to {config.speed_headroom:g}x it (headroom, before "
                 "balancing)")
    return dataclasses.replace(samples, target_speed_mph=labels), raised


def _balance(config: DatasetConfig, samples: Samples, lines: list[str], out: Path
             ) -> tuple[Samples, BalanceResult, int]:
    """(the samples kept, the balancing result for the histograms, samples kept back for the
    speed head), the steps said in ``lines``; the histograms before and after written into
    ``out``."""
    from clonedrive.data.balance import balance_steering, plot_histogram, save_balance_plots

    balanced = balance_steering(samples.steering, np.random.default_rng([config.seed, 1]),
                                bins=config.balance_bins)
    kept_for_speed = 0
    if not config.balance:
        lines.append(f"balancing off: {len(samples)} samples")
        balanced = _unbalanced(balanced)
    else:
        keep = balanced.keep
        if config.speed_head:
            # Steering balancing thins out the straight-ahead samples, and with them the
            # braking zones before bends: the samples the speed head learns slowing from.
            slowing = np.flatnonzero(samples.target_speed_mph < SLOWING_LABEL_MPH)
            keep = np.union1d(keep, slowing)
            kept_for_speed = len(keep) - len(balanced.keep)
            lines.append(f"speed head: {kept_for_speed} samples where the "
                         f"expert slows below {SLOWING_LABEL_MPH:g} mph kept back")
        lines.append(balanced.summary())
        samples = samples.subset(keep)
    if config.balance:
        save_balance_plots(balanced, out / "steering_before.png", out / "steering_after.png")
    else:  # one histogram, no target: nothing was thinned out
        plot_histogram(balanced.counts_before, balanced.bin_edges, out / "steering_before.png",
                       title="steering labels, balancing off")
        (out / "steering_after.png").unlink(missing_ok=True)  # a resumed run's older one
    return samples, balanced, kept_for_speed


def _unbalanced(result: BalanceResult) -> BalanceResult:
    """A BalanceResult that keeps everything (balancing off), for the histograms."""
    return dataclasses.replace(
        result,
        keep=np.arange(int(result.counts_before.sum())),
        counts_after=result.counts_before.copy(),
        keep_probability=np.ones_like(result.keep_probability),
    )


def _filled_cache(config: DatasetConfig, samples: Samples, out: Path, lines: list[str], *,
                  progress: bool, handoff: ImageHandoff | None = None
                  ) -> tuple[ImageCache, dict[int, ImageDecodeError]]:
    """(the image cache holding every image of ``samples``, the images that failed to decode
    by index). Interrupted (Ctrl-C, SIGTERM) or failed, it leaves no cache file."""
    cache = None
    try:
        if handoff is not None:
            cache = handoff.take(samples.unique_paths, cached_rows(config))
        reused = cache is not None
        cache = cache or _open_cache(config, samples, out)
        lines.append(
            f"image cache: {len(cache)} images, rows {cache.rows[0]}-{cache.rows[1] - 1} of "
            f"each, {cache.nbytes / 1e6:.0f} MB "
            + (f"memmap {cache.memmap_path}" if cache.memmap_path else "in memory")
            + (" (the previous stage's, reused)" if reused else "")
        )
        return cache, cache.fill(workers=2, progress=progress)
    except BaseException:
        if cache is not None:
            cache.close(delete=True)
        discard_cache(out)  # interrupted while the cache was being made
        raise


def _open_cache(config: DatasetConfig, samples: Samples, out: Path) -> ImageCache:
    """The decoded-image cache ``config.cache`` asks for (memory, a memmap in ``out``, or
    memory up to the limit and a memmap above it), holding only the rows the network and its
    augmentation read (:func:`cached_rows`)."""
    from clonedrive.data.batches import ImageCache

    rows = cached_rows(config)
    if config.cache == "memory":
        return ImageCache(samples.unique_paths, rows=rows)
    if config.cache == "memmap":
        return ImageCache(samples.unique_paths, memmap_path=out / CACHE_FILE,
                          memory_limit_bytes=0, rows=rows)
    return ImageCache(samples.unique_paths, memmap_path=out / CACHE_FILE,
                      memory_limit_bytes=config.cache_memory_limit_mb * 1024**2, rows=rows)


def _report(recipe: Recipe, config: DatasetConfig, samples: Samples, balanced: _Balanced,
            split: Split, images: _Images) -> dict:
    """dataset.json up to the final counts (the caller adds train_samples, val_samples and
    images_cached, in that order)."""
    result = balanced.result
    return {
        "recordings": [
            {"name": spec.name, "path": str(spec.path), "cameras": spec.cameras,
             "correction": spec.correction, "steering_offset": spec.steering_offset,
             "flip": spec.flip, "weight": spec.weight}
            for spec in recipe.recordings
        ],
        "rows_read": samples.rows_read,
        "side_images_missing": samples.side_images_missing,
        "rows_with_target_speed": samples.rows_with_target_speed,
        "skipped_rows": samples.skipped,
        "skipped_row_details": samples.skipped_details[:100],
        "samples_before_balance": int(result.counts_before.sum()),
        "samples_after_balance": int(result.counts_after.sum()) + balanced.kept_for_speed,
        "speed_samples_kept": balanced.kept_for_speed,
        "speed_labels_raised": balanced.raised,  # labels at the top speed trained with headroom
        "balance": {
            "enabled": config.balance,
            "bin_edges": [round(float(edge), 6) for edge in result.bin_edges],
            "counts_before": result.counts_before.tolist(),
            "counts_after": result.counts_after.tolist(),
            "target_per_bin": result.target,
        },
        "split": {"kind": split.kind, "description": split.description,
                  "val_fraction": config.val_fraction,
                  "block_s": config.block_s if split.kind == "blocks" else None},
        "skipped_images": images.bad,
        "skipped_image_samples": images.dropped_samples,
    }


def _count_reasons(failed: dict[int, ImageDecodeError]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for error in failed.values():
        counts[error.reason] = counts.get(error.reason, 0) + 1
    return counts


def _counts_text(counts: dict[str, int]) -> str:
    return ", ".join(f"{count} {reason}" for reason, count in counts.items())
