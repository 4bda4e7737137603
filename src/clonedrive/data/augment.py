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
- **looks** (off unless ``looks_probability`` > 0; :func:`restyle`): a colour cast (a gain per
  channel), lower contrast, haze (the frame blended towards a light grey, most at its top,
  the far road, fading downwards), a slight blur, pixel noise and (with ``saturation_min`` < 1)
  colours washed towards grey. Generic camera and weather
  effects drawn in image space, none of them a benchmark's held-out condition family (those
  are rendered in the scene, sim/conditions.py), so that a look the network has not seen is
  less new to it.

The label of a shifted-and-flipped sample is ``-(steering + dx * steering_per_px)``: the
shift is applied in the unflipped frame, then the flip mirrors picture and label together.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

#: Steering change per pixel of horizontal shift ([-1, 1] units per pixel).
STEERING_PER_PX = 0.004
#: Where :func:`restyle`'s haze is whole: this fraction of the frame's height from its top,
#: about where the road meets the sky in the Udacity camera; below it, haze fades downwards.
HAZE_HORIZON = 0.4
#: Rows a :func:`restyle` blur reaches beyond a pixel (its largest kernel is 5 x 5).
BLUR_MARGIN = 2
#: The range of greys (0-255) :func:`restyle`'s haze is drawn from, and how far each channel
#: strays from it (a bluish, reddish or greenish haze).
HAZE_GREYS = (140.0, 235.0)
HAZE_TINT = 12.0
#: The grey :func:`restyle`'s contrast is lowered towards (0-255).
CONTRAST_PIVOT = 128.0
#: The seed of :func:`restyle`'s fixed noise field.
NOISE_FIELD_SEED = 20261207


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
    looks_probability: float = 0.0  # share of frames restyled by :func:`restyle` (0: none)
    tint_max: float = 0.15  # each channel's gain drawn in [1 - max, 1 + max]
    contrast_min: float = 0.6  # contrast factor drawn in [min, 1]
    haze_max: float = 0.85  # haze at the horizon and above drawn in [0, max]
    haze_power_max: float = 4.0  # how fast haze fades downwards: power drawn in [1, max]
    blur_probability: float = 0.3  # of a restyled frame: a 3x3 or 5x5 Gaussian blur
    noise_max: float = 6.0  # of a restyled frame, half the time: pixel noise std in [0, max]
    # Of a restyled frame: colour saturation drawn in [min, 1] (0: grey). 1: off, and nothing is
    # drawn for it, so the other looks are drawn as without it.
    saturation_min: float = 1.0


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
    restyling = config.looks_probability > 0.0
    # Restyling blurs: the rows its kernel reaches beyond the window are computed too.
    computed = _widened(rows, images.shape[1], BLUR_MARGIN) if restyling else rows
    shifted, labels = shift_and_flip(
        images, steering, dx, dy, flip, steering_per_px=config.steering_per_px, mirror=mirror,
        rows=computed,
    )
    shaded = shade(shifted, brightness, shadow, top_x, bottom_x, darkness, right_side,
                   rows=computed)
    if restyling:  # drawn after the rest: the other draws stay as they were without it
        looks = draw_looks(rng, count, config)
        if pairs:
            looks = LookDraws(*(np.concatenate([drawn, drawn]) for drawn in looks))
        restyle(shaded, looks, rng, rows=rows)
        _clear_outside(shaded, rows, computed)
    return shaded, labels


def _widened(rows: tuple[int, int] | None, height: int, margin: int
             ) -> tuple[int, int] | None:
    if rows is None:
        return None
    first, end = _row_window(rows, height)
    return max(0, first - margin), min(height, end + margin)


def _clear_outside(images: np.ndarray, rows: tuple[int, int] | None,
                   computed: tuple[int, int] | None) -> None:
    """Zero the rows computed beyond the window, as a windowed batch leaves them."""
    if rows is None:
        return
    images[:, computed[0]:rows[0]] = 0
    images[:, rows[1]:computed[1]] = 0


class LookDraws(NamedTuple):
    """Per frame, what :func:`restyle` does to it (see :class:`AugmentConfig`)."""

    chosen: np.ndarray  #: (N,) bool: restyled at all
    tint: np.ndarray  #: (N, 3) gain per channel
    contrast: np.ndarray  #: (N,)
    haze: np.ndarray  #: (N,) haze at the top row
    haze_power: np.ndarray  #: (N,)
    haze_colour: np.ndarray  #: (N, 3)
    blur: np.ndarray  #: (N,) kernel size: 0 (none), 3 or 5
    noise: np.ndarray  #: (N,) pixel noise std
    saturation: np.ndarray  #: (N,) colour saturation, 1 = unchanged


#: Each channel's share of a pixel's grey (ITU-R BT.601 luma), for :func:`_desaturate`.
LUMA_WEIGHTS = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def _desaturate(pixels: np.ndarray, saturation: float) -> None:
    """Move float RGB ``pixels`` (rows, columns, 3) in place towards their grey: ``grey +
    saturation * (pixel - grey)``."""
    grey = pixels @ LUMA_WEIGHTS
    pixels *= saturation
    pixels += ((1.0 - saturation) * grey)[..., None]


def draw_looks(rng: np.random.Generator, count: int, config: AugmentConfig) -> LookDraws:
    """Draw :func:`restyle`'s settings for ``count`` frames, in a fixed order."""
    chosen = rng.random(count) < config.looks_probability
    tint = rng.uniform(1.0 - config.tint_max, 1.0 + config.tint_max, size=(count, 3))
    contrast = rng.uniform(config.contrast_min, 1.0, size=count)
    haze = rng.uniform(0.0, config.haze_max, size=count)
    haze_power = rng.uniform(1.0, config.haze_power_max, size=count)
    grey = rng.uniform(*HAZE_GREYS, size=(count, 1))
    haze_colour = grey + rng.uniform(-HAZE_TINT, HAZE_TINT, size=(count, 3))
    blur = np.where(rng.random(count) < config.blur_probability,
                    rng.choice([3, 2 * BLUR_MARGIN + 1], size=count), 0)
    noise = np.where(rng.random(count) < 0.5, rng.uniform(0.0, config.noise_max, size=count), 0.0)
    saturation = (rng.uniform(config.saturation_min, 1.0, size=count)
                  if config.saturation_min < 1.0 else np.ones(count))
    return LookDraws(chosen, tint.astype(np.float32), contrast.astype(np.float32),
                     haze.astype(np.float32), haze_power.astype(np.float32),
                     haze_colour.astype(np.float32), blur, noise.astype(np.float32),
                     saturation.astype(np.float32))


def restyle(images: np.ndarray, looks: LookDraws, rng: np.random.Generator,
            rows: tuple[int, int] | None = None) -> None:
    """Restyle the chosen frames of ``images`` in place (module doc): blur, then the colours
    towards grey (``looks.saturation``), then the cast and
    the contrast (about mid-grey), then haze towards its colour, whole above the horizon
    (:data:`HAZE_HORIZON`) and falling as ``(1 - depth) ** power`` to none at the bottom row,
    then noise (read from a fixed field at offsets drawn from ``rng``). Every step depends only
    on the pixel's place in the whole frame, so ``rows`` computes those rows exactly as
    without it."""
    import cv2

    height, width = images.shape[1:3]
    first, end = _row_window(rows, height)
    horizon = HAZE_HORIZON * height
    depth = np.clip((np.arange(first, end, dtype=np.float32) - horizon) / (height - horizon),
                    0.0, 1.0)
    field = _noise_field(height, width)
    offsets = rng.integers(0, [height, width], size=(len(images), 2))
    for index in np.flatnonzero(looks.chosen):
        # Cast, contrast and haze are one affine map per row and channel: gain, then offset.
        alpha = looks.haze[index] * (1.0 - depth) ** looks.haze_power[index]  # (rows,)
        keep = (1.0 - alpha)[:, None]
        gain = keep * (looks.tint[index] * looks.contrast[index])  # (rows, 3)
        offset = keep * ((1.0 - looks.contrast[index]) * CONTRAST_PIVOT) + alpha[:, None] * (
            looks.haze_colour[index])
        pixels = _blurred(images[index], int(looks.blur[index]), first, end)
        if looks.saturation[index] < 1.0:
            _desaturate(pixels, float(looks.saturation[index]))
        pixels *= gain[:, None, :]
        pixels += offset[:, None, :]
        if looks.noise[index] > 0.0:
            down, across = offsets[index]
            pixels += looks.noise[index] * field[down + first:down + end, across:across + width]
        np.maximum(pixels, 0.0, out=pixels)
        images[index, first:end] = cv2.convertScaleAbs(pixels)  # rounded, saturated at 255


def _blurred(frame: np.ndarray, size: int, first: int, end: int) -> np.ndarray:
    """Rows ``[first, end)`` of ``frame`` as float32, Gaussian-blurred with a ``size`` kernel
    (0: not), as blurring the whole frame would make them: the rows the kernel reaches
    beyond the window are blurred with it, and a border is reflected only where the frame
    itself ends."""
    import cv2

    if not size:
        return frame[first:end].astype(np.float32)
    margin = size // 2
    top, bottom = max(0, first - margin), min(frame.shape[0], end + margin)
    blurred = cv2.GaussianBlur(frame[top:bottom], (size, size), 0)
    return blurred[first - top:end - top].astype(np.float32)


@functools.cache
def _noise_field(height: int, width: int) -> np.ndarray:
    """A fixed field of unit Gaussian noise, twice a frame each way: a frame's noise is a
    window of it at a drawn offset, which costs no generation per frame."""
    field = np.random.default_rng(NOISE_FIELD_SEED).standard_normal((2 * height, 2 * width, 3))
    return field.astype(np.float32)
