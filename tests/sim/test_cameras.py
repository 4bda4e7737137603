"""The camera rig: images, where the road is in them, how they move with the car."""

import math

import numpy as np
import pytest

from clonedrive.sim.cameras import UDACITY_RIG, CameraRig
from clonedrive.sim.randomization import RandomizationConfig
from clonedrive.sim.scene import Scene
from clonedrive.world.catalog import load_track

WIDTH, HEIGHT = 160, 80
#: A straight on the lake track, before the bridge: s = 0..25 m.
STRAIGHT_S = 5.0


@pytest.fixture(scope="module")
def lake():
    track = load_track("lake")
    with Scene(track) as scene, CameraRig(scene, width=WIDTH, height=HEIGHT) as rig:
        yield track, rig


def pose(track, s_m=STRAIGHT_S, offset_m=0.0):
    x, y, z = track.offset_point(s_m, offset_m)
    return float(x), float(y), float(z), float(track.heading_at(s_m))


def asphalt_mask(image):
    """Grey, unsaturated pixels of asphalt brightness (not grass, sky, hood or lines)."""
    rgb = image.astype(int)
    spread = rgb.max(axis=-1) - rgb.min(axis=-1)
    level = rgb.mean(axis=-1)
    return (spread < 26) & (level > 60) & (level < 190)


def road_centre_column(image, row):
    columns = np.flatnonzero(asphalt_mask(image)[row])
    assert len(columns) > 10, "no road in that row"
    return columns.mean()


def sky_fraction(image):
    rgb = image.astype(int)
    return float(np.mean((rgb[..., 2] > rgb[..., 0] + 30) & (rgb[..., 2] > 120)))


def test_images_are_uint8_rgb_of_the_requested_size(lake):
    track, rig = lake
    images = rig.render(*pose(track))
    assert set(images) == {"center", "left", "right"}
    for image in images.values():
        assert image.shape == (HEIGHT, WIDTH, 3)
        assert image.dtype == np.uint8
        assert image.flags["C_CONTIGUOUS"]


def test_a_centred_car_sees_asphalt_just_above_the_hood(lake):
    track, rig = lake
    center = rig.render(*pose(track))["center"]
    rows = slice(int(HEIGHT * 0.66), int(HEIGHT * 0.8))
    cols = slice(int(WIDTH * 0.4), int(WIDTH * 0.6))
    patch = center[rows, cols].astype(int)
    assert asphalt_mask(center)[rows, cols].mean() > 0.9
    red, green, blue = patch.reshape(-1, 3).mean(axis=0)
    assert green < red + 12 and green < blue + 20  # not grass
    # the hood covers the bottom rows, in the middle
    hood = center[-3:, int(WIDTH * 0.45):int(WIDTH * 0.55)].astype(int)
    assert np.abs(hood.mean(axis=(0, 1)) - patch.mean(axis=(0, 1))).max() > 8


def test_side_cameras_see_the_road_shifted_the_physical_way(lake):
    track, rig = lake
    images = rig.render(*pose(track))
    row = int(HEIGHT * 0.62)
    left = road_centre_column(images["left"], row)
    center = road_centre_column(images["center"], row)
    right = road_centre_column(images["right"], row)
    # the left camera sits left of the centre line, so the road lies to its right
    assert left > center + 3 > right + 6


def test_image_follows_yaw_offset_height_and_pitch(lake):
    track, rig = lake
    x, y, z, yaw = pose(track)
    base = rig.render(x, y, z, yaw)["center"]
    row = int(HEIGHT * 0.62)
    turned_left = rig.render(x, y, z, yaw + 0.15)["center"]
    assert np.abs(turned_left.astype(int) - base).mean() > 5
    # turning the car left moves the road to the right in the image
    assert road_centre_column(turned_left, row) > road_centre_column(base, row) + 5
    # moving the car right moves the road left
    shifted = rig.render(*pose(track, offset_m=1.5))["center"]
    assert road_centre_column(shifted, row) < road_centre_column(base, row) - 5
    # nose up: more sky; higher camera (climbing): the image changes
    nose_up = rig.render(x, y, z, yaw, pitch_rad=0.08)["center"]
    assert sky_fraction(nose_up) > sky_fraction(base) + 0.05
    higher = rig.render(x, y, z + 1.0, yaw)["center"]
    assert np.abs(higher.astype(int) - base).mean() > 3


def test_roll_right_side_down_tilts_the_horizon(lake):
    track, rig = lake
    x, y, z, yaw = pose(track)
    rolled = rig.render(x, y, z, yaw, roll_rad=math.radians(6))["center"]
    half = WIDTH // 2
    # right side down: the camera looks lower on the right, the horizon rises there
    assert sky_fraction(rolled[:, half:]) < sky_fraction(rolled[:, :half]) - 0.03


def test_same_seed_gives_identical_images_also_with_randomisation():
    track = load_track("lake")
    config = RandomizationConfig()
    frames = []
    for seed in (7, 7, 8):
        with Scene(track, scenery=False, randomization=config, seed=seed) as scene:
            with CameraRig(scene, ("center",), 64, 32) as rig:
                frames.append([rig.render(*pose(track, s))["center"] for s in (5.0, 9.0)])
    for a, b in zip(frames[0], frames[1], strict=True):
        np.testing.assert_array_equal(a, b)
    assert np.abs(frames[0][0].astype(int) - frames[2][0]).mean() > 1
    with Scene(track, scenery=False) as plain, CameraRig(plain, ("center",), 64, 32) as rig:
        default = rig.render(*pose(track))["center"]
    assert np.abs(frames[0][0].astype(int) - default).mean() > 1


def test_randomize_reseeds_the_look_in_place():
    track = load_track("lake")
    with Scene(track, scenery=False, randomization=RandomizationConfig(), seed=1) as scene:
        rig = CameraRig(scene, ("center",), 64, 32)
        first = rig.render(*pose(track))["center"]
        scene.randomize(2)
        other = rig.render(*pose(track))["center"]
        scene.randomize(1)
        again = rig.render(*pose(track))["center"]
    assert np.abs(first.astype(int) - other).mean() > 1
    np.testing.assert_array_equal(first, again)


def test_rig_rejects_unknown_cameras_and_mounts_follow_udacity():
    assert UDACITY_RIG["left"].position_m[0] < 0 < UDACITY_RIG["right"].position_m[0]
    assert UDACITY_RIG["center"].horizontal_fov_deg(320, 160) == pytest.approx(98.2, abs=0.1)
    with Scene("lake", scenery=False) as scene:
        with pytest.raises(ValueError, match="unknown camera"):
            CameraRig(scene, ("roof",))
