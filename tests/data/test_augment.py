"""Augmentation: flips mirror pixels and negate steering, shifts correct steering the right way."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.augment import (
    STEERING_PER_PX,
    AugmentConfig,
    augment_batch,
    flip_horizontal,
    shade,
    shift_and_flip,
)
from clonedrive.data.batches import read_rgb
from clonedrive.data.driving_log import read_driving_log

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
NONE = AugmentConfig(
    flip_probability=0.0, shift_max_px=0, vertical_shift_max_px=0, brightness_min=1.0,
    brightness_max=1.0, shadow_probability=0.0,
)


def _frames(count: int = 4, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (count, 160, 320, 3), dtype=np.uint8)


def test_flip_mirrors_pixels_and_negates_steering() -> None:
    frames = _frames()
    steering = np.array([0.3, -0.5, 0.0, 1.0], dtype=np.float32)
    flipped, labels = flip_horizontal(frames, steering)
    np.testing.assert_array_equal(flipped[:, :, 0], frames[:, :, -1])
    np.testing.assert_array_equal(flipped[:, 37, 200], frames[:, 37, 119])
    np.testing.assert_array_equal(flipped[..., 0], frames[:, :, ::-1, 0])  # channels untouched
    np.testing.assert_array_equal(labels, -steering)
    same, labels_again = shift_and_flip(frames, steering, [0] * 4, [0] * 4, [True] * 4)
    np.testing.assert_array_equal(same, flipped)
    np.testing.assert_array_equal(labels_again, labels)


def test_shift_moves_pixels_and_corrects_steering() -> None:
    frames = _frames(2)
    steering = np.array([0.1, 0.1], dtype=np.float32)
    out, labels = shift_and_flip(frames, steering, [10, -20], [0, 3], [False, False])
    # Image 0: picture moved 10 px right, the left edge column repeated into the gap.
    np.testing.assert_array_equal(out[0, :, 10:], frames[0, :, :-10])
    np.testing.assert_array_equal(out[0, :, :10], np.repeat(frames[0, :, :1], 10, axis=1))
    # Image 1: 20 px left and 3 px down.
    np.testing.assert_array_equal(out[1, 3:, :-20], frames[1, :-3, 20:])
    np.testing.assert_array_equal(out[1, :3, :-20], np.repeat(frames[1, :1, 20:], 3, axis=0))
    np.testing.assert_allclose(
        labels, [0.1 + 10 * STEERING_PER_PX, 0.1 - 20 * STEERING_PER_PX], rtol=1e-6
    )
    # Shift then flip: the label of the shifted frame, negated.
    _, mirrored = shift_and_flip(frames, steering, [10, -20], [0, 0], [True, True])
    np.testing.assert_allclose(mirrored, -labels)


def test_shift_correction_has_the_sign_of_the_side_cameras() -> None:
    """The left camera (label +correction) sees the road where the center camera's picture,
    shifted to the right, shows it; a right shift must therefore add steering too."""
    log = read_driving_log(FIXTURES / "lake_posix_mixed_columns")
    road = (slice(95, 135), slice(90, 230))  # the road just ahead of the car
    shifts = np.arange(-80, 81, 2)
    count = len(shifts)
    for row in log.rows[::20]:
        center = np.repeat(read_rgb(row.center)[None], count, axis=0)
        shifted, labels = shift_and_flip(
            center, np.zeros(count), shifts, np.zeros(count), np.zeros(count, bool)
        )
        road_views = shifted[(slice(None), *road)].astype(np.int32)
        best = {}
        for camera in ("left", "right"):
            side = read_rgb(row.image(camera))[road].astype(np.int32)
            errors = np.abs(road_views - side[None]).mean(axis=(1, 2, 3))
            best[camera] = int(np.argmin(errors))
        assert shifts[best["left"]] > 15 and shifts[best["right"]] < -15
        assert labels[best["left"]] > 0  # same sign as the left camera's +correction
        assert labels[best["right"]] < 0


def test_shade_brightness_and_shadow_sides() -> None:
    frames = np.full((3, 160, 320, 3), 200, dtype=np.uint8)
    line = np.full(3, 160.0, dtype=np.float32)
    out = shade(frames, brightness=np.array([0.5, 1.0, 1.0]), shadow=np.array([False, True, True]),
                top_x=line, bottom_x=line, darkness=np.array([0.5, 0.5, 0.5]),
                right_side=np.array([False, False, True]))
    assert np.all(out[0] == 100)
    assert np.all(out[1, :, :160] == 100) and np.all(out[1, :, 160:] == 200)
    assert np.all(out[2, :, :160] == 200) and np.all(out[2, :, 160:] == 100)
    bright = shade(frames, np.array([1.2] * 3), np.zeros(3, bool), line, line, np.ones(3),
                   np.zeros(3, bool))
    assert np.all(bright == 240) and bright.dtype == np.uint8


def test_augment_batch_is_seeded_and_leaves_its_input_alone() -> None:
    frames = _frames(8)
    original = frames.copy()
    steering = np.linspace(-0.5, 0.5, 8).astype(np.float32)
    first = augment_batch(frames, steering, np.random.default_rng(3))
    second = augment_batch(frames, steering, np.random.default_rng(3))
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])
    np.testing.assert_array_equal(frames, original)
    assert first[0].dtype == np.uint8 and first[0].shape == frames.shape
    assert first[1].dtype == np.float32 and first[1].shape == (8,)
    # Labels move only by flips and the shift correction.
    config = AugmentConfig()
    bound = config.shift_max_px * config.steering_per_px + 1e-6
    assert np.all(np.minimum(abs(first[1] - steering), abs(first[1] + steering)) <= bound)


def test_mirror_flag_equals_augmenting_a_mirrored_copy() -> None:
    """A recipe's flipped copy is stored unmirrored and mirrored inside the augmentation."""
    frames = _frames(6)
    steering = np.linspace(-0.3, 0.3, 6).astype(np.float32)  # labels of the mirrored pictures
    mirror = np.array([True, False, True, True, False, False])
    premirrored = frames.copy()
    premirrored[mirror] = frames[mirror][:, :, ::-1]
    expected = augment_batch(premirrored, steering, np.random.default_rng(8))
    got = augment_batch(frames, steering, np.random.default_rng(8), mirror=mirror)
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])


def test_augment_batch_with_nothing_enabled_is_identity() -> None:
    frames = _frames(3)
    steering = np.array([0.2, -0.1, 0.0], dtype=np.float32)
    images, labels = augment_batch(frames, steering, np.random.default_rng(0), NONE)
    np.testing.assert_array_equal(images, frames)
    np.testing.assert_array_equal(labels, steering)


def test_augment_batch_rejects_non_uint8() -> None:
    with pytest.raises(ValueError, match="uint8 images"):
        augment_batch(np.zeros((1, 160, 320, 3), np.float32), np.zeros(1), np.random.default_rng())


def test_rows_compute_only_the_rows_a_cropping_network_sees_and_the_same_values() -> None:
    frames = _frames(16, seed=5)
    steering = np.linspace(-0.4, 0.4, 16).astype(np.float32)
    mirror = np.arange(16) % 3 == 0
    full, full_labels = augment_batch(frames, steering, np.random.default_rng(2), mirror=mirror)
    part, part_labels = augment_batch(frames, steering, np.random.default_rng(2), mirror=mirror,
                                      rows=(80, 135))
    np.testing.assert_array_equal(part[:, 80:135], full[:, 80:135])
    np.testing.assert_array_equal(part_labels, full_labels)
    assert not part[:, :80].any() and not part[:, 135:].any()
    # Shadows and vertical shifts happened inside the window (the test is not vacuous).
    assert not np.array_equal(part[:, 80:135], frames[:, 80:135])
    with pytest.raises(ValueError, match="rows"):
        augment_batch(frames, steering, np.random.default_rng(2), rows=(100, 200))


def test_a_network_gives_the_same_output_on_row_windowed_batches() -> None:
    """What makes `train` augment only the cropped rows: the network sees identical input."""
    from clonedrive.model.architectures import build_model
    from clonedrive.network.crop import visible_rows

    frames = _frames(8, seed=6)
    steering = np.zeros(8, np.float32)
    for name, crop_top in (("fast", 80), ("seed", 60)):
        model = build_model(name, crop_top_px=crop_top)
        rows = visible_rows(model)
        assert rows == (crop_top, 135)
        full, _ = augment_batch(frames, steering, np.random.default_rng(4))
        part, _ = augment_batch(frames, steering, np.random.default_rng(4), rows=rows)
        np.testing.assert_array_equal(model.predict_on_batch(part.astype(np.float32)),
                                      model.predict_on_batch(full.astype(np.float32)))


LOOKS = AugmentConfig(looks_probability=0.5)


def test_looks_restyle_some_frames_and_leave_the_rest_and_the_labels_as_without() -> None:
    frames = _frames(32, seed=4)
    steering = np.linspace(-0.4, 0.4, 32).astype(np.float32)
    plain, plain_labels = augment_batch(frames, steering, np.random.default_rng(6))
    styled, labels = augment_batch(frames, steering, np.random.default_rng(6), LOOKS)
    np.testing.assert_array_equal(labels, plain_labels)
    changed = np.array([not np.array_equal(a, b) for a, b in zip(plain, styled, strict=True)])
    assert 5 <= changed.sum() <= 27  # about half restyled, the others exactly as without looks
    again, _ = augment_batch(frames, steering, np.random.default_rng(6), LOOKS)
    np.testing.assert_array_equal(again, styled)


def test_looks_in_a_row_window_are_the_whole_frame_s_rows() -> None:
    frames = _frames(12, seed=9)
    steering = np.zeros(12, np.float32)
    config = AugmentConfig(looks_probability=1.0, blur_probability=1.0)
    full, _ = augment_batch(frames, steering, np.random.default_rng(1), config)
    part, _ = augment_batch(frames, steering, np.random.default_rng(1), config, rows=(60, 135))
    np.testing.assert_array_equal(part[:, 60:135], full[:, 60:135])
    assert not part[:, :60].any() and not part[:, 135:].any()


def test_haze_covers_the_far_road_and_fades_to_nothing_at_the_bottom() -> None:
    black = np.zeros((4, 160, 320, 3), np.uint8)
    config = AugmentConfig(
        looks_probability=1.0, tint_max=0.0, contrast_min=1.0, haze_max=0.9, blur_probability=0.0,
        noise_max=0.0, flip_probability=0.0, shift_max_px=0, vertical_shift_max_px=0,
        brightness_min=1.0, brightness_max=1.0, shadow_probability=0.0)
    hazy, _ = augment_batch(black, np.zeros(4, np.float32), np.random.default_rng(3), config)
    rows = hazy.mean(axis=(2, 3))  # (frame, row)
    assert np.all(rows[:, 159] == 0)  # the bottom row: no haze
    assert np.all(rows[:, 30] >= rows[:, 100]) and np.all(rows[:, 100] >= rows[:, 150])
    assert rows[:, 30].max() > 60  # some frame is hazed towards a light grey at the top


def test_looks_give_a_consistency_pair_the_same_look() -> None:
    frames = _frames(4, seed=2)
    pairs = np.concatenate([frames, frames])  # each frame beside an identical partner
    config = AugmentConfig(looks_probability=1.0, noise_max=0.0)
    out, _ = augment_batch(pairs, np.zeros(8, np.float32), np.random.default_rng(5), config,
                           pairs=True)
    np.testing.assert_array_equal(out[:4], out[4:])
    assert not np.array_equal(out[:4], frames)


def test_looks_without_washed_colours_draw_as_before_they_existed() -> None:
    """saturation_min = 1 draws nothing for it, so recipes without it (best v8) train on the
    very batches they did before the setting existed (this digest was taken then)."""
    import hashlib

    frames = _frames(16, seed=11)
    out, labels = augment_batch(frames, np.linspace(-0.3, 0.3, 16).astype(np.float32),
                                np.random.default_rng(12), LOOKS, rows=(52, 142))
    digest = hashlib.sha256(out.tobytes() + labels.tobytes()).hexdigest()[:16]
    assert digest == "d3224f2df3fd038b"


def test_desaturate_moves_each_pixel_towards_its_own_grey() -> None:
    from clonedrive.data.augment import LUMA_WEIGHTS, _desaturate

    pixels = _frames(1, seed=8)[0].astype(np.float32)
    luma = pixels @ LUMA_WEIGHTS
    grey = pixels.copy()
    _desaturate(grey, 0.0)
    np.testing.assert_allclose(grey, np.repeat(luma[..., None], 3, axis=2), atol=1e-3)
    half = pixels.copy()
    _desaturate(half, 0.5)
    np.testing.assert_allclose(half, (pixels + grey) / 2, atol=1e-3)


def test_washed_colours_only_ever_shrink_a_restyled_frame_s_colour_spread() -> None:
    frames = _frames(16, seed=8)
    config = AugmentConfig(looks_probability=1.0, saturation_min=0.0, tint_max=0.0,
                           contrast_min=1.0, haze_max=0.0, blur_probability=0.0, noise_max=0.0,
                           flip_probability=0.0, shift_max_px=0, vertical_shift_max_px=0,
                           brightness_min=1.0, brightness_max=1.0, shadow_probability=0.0)
    washed, _ = augment_batch(frames, np.zeros(16, np.float32), np.random.default_rng(2), config)

    def spread(images):
        return images.astype(int).max(axis=3) - images.astype(int).min(axis=3)

    assert np.all(spread(washed) <= spread(frames) + 1)  # + rounding
    shrunk = spread(washed).mean(axis=(1, 2)) / spread(frames).mean(axis=(1, 2))
    assert shrunk.min() < 0.3 and shrunk.max() > 0.7  # saturations drawn across [0, 1]
