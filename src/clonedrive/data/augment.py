"""Training-only image augmentation, vectorised over a batch, RGB in and RGB out.

Every function takes a batch of uint8 RGB frames ``(N, H, W, 3)`` and steering labels
``(N,)`` in [-1, 1] (wheel angle / 25 deg, positive = right) and a
``numpy.random.Generator``; nothing touches global random state.

- **flip**: mirror left-right and negate the steering.
- **horizontal shift** (the PilotNet viewpoint shift): the picture moves ``dx`` pixels to
  the right (``dx < 0``: to the left), which is what the camera sees when the car stands
  further left on the road; the label becomes ``steering + dx * steering_per_px`` (steer back
  right). ``steering_per_px`` = 0.004 per pixel by default: a 50 px shift is worth 0.2, the
  side-camera correction for a camera about 0.8 m off centre; edge columns are repeated
  into the gap.
- **vertical shift**: up to a few pixels up or down (the road's pitch changes), label kept.
- **brightness**: all three channels scaled by one factor per image (same hue).
- **shadow**: one side of a random slanted line across the frame is darkened.

The label of a shifted-and-flipped sample is ``-(steering + dx * steering_per_px)``: the
shift is applied in the unflipped frame, then the flip mirrors picture and label together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Steering change per pixel of horizontal shift ([-1, 1] units per pixel).
STEERING_PER_PX = 0.004


@dataclass(frozen=True)
class AugmentConfig:
    """Augmentation strengths (all drawn independently per image)."""

    flip_probability: float = 0.5
    shift_max_px: int = 40  # horizontal shift drawn uniformly in [-max, max] pixels
    steering_per_px: float = STEERING_PER_PX  # label change per pixel of horizontal shift
    vertical_shift_max_px: int = 6  # vertical shift drawn uniformly in [-max, max] pixels
    brightness_min: float = 0.5  # brightness factor drawn uniformly in [min, max]
    brightness_max: float = 1.2
    shadow_probability: float = 0.5
    shadow_darkness_min: float = 0.5  # factor applied inside a shadow, uniform in [min, max]
    shadow_darkness_max: float = 0.8


def flip_horizontal(images: np.ndarray, steering: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mirror every frame left-right and negate every label."""
    return images[:, :, ::-1].copy(), -np.asarray(steering, dtype=np.float32) + 0.0


def shift_and_flip(
    images: np.ndarray,
    steering: np.ndarray,
    dx_px: np.ndarray,
    dy_px: np.ndarray,
    flip: np.ndarray,
    *,
    steering_per_px: float = STEERING_PER_PX,
    mirror: np.ndarray | None = None,
    rows: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Shift frame ``i`` by ``dx_px[i]`` pixels right and ``dy_px[i]`` pixels down (edge
    pixels repeated into the gap), then mirror it if ``flip[i]``; labels follow (module doc).

    ``mirror[i]`` means frame ``i`` is stored unmirrored but its label already belongs to
    the mirrored picture (a recipe's flipped copy): it is mirrored first, label untouched.
    Every output pixel is read once from ``images``; returns new arrays. With ``rows`` =
    ``(first, end)`` only those output rows are computed (the rows a network that crops the
    rest sees), exactly as without it; the others are 0.
    """
    count, height, width = images.shape[:3]
    dx = np.asarray(dx_px, dtype=np.int64).reshape(count)
    dy = np.asarray(dy_px, dtype=np.int64).reshape(count)
    flip = np.asarray(flip, dtype=bool).reshape(count)
    columns = np.arange(width)[None, :]
    columns = np.where(flip[:, None], width - 1 - columns, columns)  # read mirrored
    columns = np.clip(columns - dx[:, None], 0, width - 1)  # (N, W)
    if mirror is not None:
        mirror = np.asarray(mirror, dtype=bool).reshape(count)
        columns = np.where(mirror[:, None], width - 1 - columns, columns)
    first, end = _row_window(rows, height)
    sources = np.clip(np.arange(first, end)[None, :] - dy[:, None], 0, height - 1)  # (N, rows)
    out = np.empty_like(images) if (first, end) == (0, height) else np.zeros_like(images)
    for index in range(count):  # per image: two cheap takes beat one (N, H, W) gather
        out[index, first:end] = images[index].take(sources[index], axis=0).take(
            columns[index], axis=1)
    labels = np.asarray(steering, dtype=np.float32) + dx.astype(np.float32) * steering_per_px
    labels = np.where(flip, -labels, labels) + 0.0
    return out, labels.astype(np.float32)


def shade(
    images: np.ndarray,
    brightness: np.ndarray,
    shadow: np.ndarray,
    top_x: np.ndarray,
    bottom_x: np.ndarray,
    darkness: np.ndarray,
    right_side: np.ndarray,
    rows: tuple[int, int] | None = None,
) -> np.ndarray:
    """Scale frame ``i`` by ``brightness[i]``; if ``shadow[i]``, also by ``darkness[i]`` on
    one side of the line from (``top_x[i]``, top row) to (``bottom_x[i]``, bottom row): the
    left side, or the right side if ``right_side[i]``. Returns a new uint8 array.

    A pixel value ``v`` becomes ``min(255, round(v * factor))``, through a 256-entry lookup
    table per image (OpenCV ``LUT``), which is several times faster than float arithmetic.
    With ``rows`` = ``(first, end)`` only those rows are computed (the others are 0).
    """
    import cv2  # here, not at import: training settings read STEERING_PER_PX at start-up

    count, height, width = images.shape[:3]
    first, end = _row_window(rows, height)
    out = np.empty_like(images) if (first, end) == (0, height) else np.zeros_like(images)
    for index in range(count):
        cv2.LUT(images[index, first:end], _scale_table(brightness[index]),
                dst=out[index, first:end])
    shadowed = np.flatnonzero(np.asarray(shadow, dtype=bool))
    if shadowed.size == 0:
        return out
    fraction = np.linspace(0.0, 1.0, height, dtype=np.float32)[None, first:end]
    top_x = np.asarray(top_x, dtype=np.float32)[shadowed]
    bottom_x = np.asarray(bottom_x, dtype=np.float32)[shadowed]
    boundary = top_x[:, None] + (bottom_x - top_x)[:, None] * fraction  # (k, H)
    inside = np.arange(width, dtype=np.float32)[None, None, :] < boundary[:, :, None]
    inside ^= np.asarray(right_side, dtype=bool)[shadowed][:, None, None]
    for number, index in enumerate(shadowed):  # OpenCV's masked copy beats copyto(where=)
        dark = cv2.LUT(images[index, first:end],
                       _scale_table(brightness[index] * darkness[index]))
        cv2.copyTo(dark, inside[number].view(np.uint8), out[index, first:end])
    return out


def _row_window(rows: tuple[int, int] | None, height: int) -> tuple[int, int]:
    if rows is None:
        return 0, height
    first, end = int(rows[0]), int(rows[1])
    if not 0 <= first < end <= height:
        raise ValueError(f"rows {rows} outside the frame's {height} rows")
    return first, end


def _scale_table(factor: float) -> np.ndarray:
    levels = np.arange(256, dtype=np.float32) * np.float32(factor)
    return np.clip(np.rint(levels), 0, 255).astype(np.uint8)


def augment_batch(
    images: np.ndarray,
    steering: np.ndarray,
    rng: np.random.Generator,
    config: AugmentConfig | None = None,
    *,
    mirror: np.ndarray | None = None,
    rows: tuple[int, int] | None = None,
    pairs: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Randomly shift, flip, brighten/darken and shadow a batch of uint8 RGB frames.

    Returns new ``(images uint8 (N, H, W, 3), steering float32 (N,))``; the inputs are not
    modified. All random numbers come from ``rng``, drawn in a fixed order. ``mirror``: see
    :func:`shift_and_flip` (frames to mirror first, their labels already negated).
    ``rows``: compute only these output rows, the same as without it (others 0): a network
    that crops the frame never sees the rest, and it is most of the work.
    ``pairs``: the batch is N frames followed by N partners (their next frames, for
    ``train --consistency``); frame ``i`` and frame ``N + i`` get the same shift, flip, light and
    shadow, so the pair differs only as the two pictures do.
    """
    config = config or AugmentConfig()
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"expected uint8 images (N, H, W, 3), got {images.dtype} {images.shape}")
    total, _, width = images.shape[:3]
    if pairs and total % 2:
        raise ValueError(f"pairs: expected an even number of frames, got {total}")
    count = total // 2 if pairs else total
    flip = rng.random(count) < config.flip_probability
    dx = rng.integers(-config.shift_max_px, config.shift_max_px + 1, size=count)
    dy = rng.integers(-config.vertical_shift_max_px, config.vertical_shift_max_px + 1, size=count)
    brightness = rng.uniform(config.brightness_min, config.brightness_max, size=count)
    shadow = rng.random(count) < config.shadow_probability
    top_x = rng.uniform(0.0, width, size=count).astype(np.float32)
    bottom_x = rng.uniform(0.0, width, size=count).astype(np.float32)
    darkness = rng.uniform(config.shadow_darkness_min, config.shadow_darkness_max, size=count)
    right_side = rng.random(count) < 0.5
    if pairs:
        flip, dx, dy, brightness, shadow, top_x, bottom_x, darkness, right_side = (
            np.concatenate([drawn, drawn]) for drawn in (
                flip, dx, dy, brightness, shadow, top_x, bottom_x, darkness, right_side))
    shifted, labels = shift_and_flip(
        images, steering, dx, dy, flip, steering_per_px=config.steering_per_px, mirror=mirror,
        rows=rows,
    )
    return shade(shifted, brightness, shadow, top_x, bottom_x, darkness, right_side,
                 rows=rows), labels
