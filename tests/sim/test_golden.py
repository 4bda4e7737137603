"""Golden image: the lake track rendered at a fixed pose by the real Panda3D software renderer
must look as the checked-in PNG does.

The comparison allows what a renderer on another machine may change (a few pixels a little)
and nothing a change of the scene makes: the tests below show that moving the camera 5 cm
sideways, turning it by a quarter of a degree, painting the edge lines white or making the
asphalt 5 % brighter each fail it (measured: mean difference 4.8, 7.9, 1.5 and 2.6 against
the tolerance's 1.0; 3.1 %, 5.6 %, 1.2 % and 0.02 % of pixels changed against 0.5 %).
If the scene is changed on purpose, look at the new frame and regenerate the PNG with
``python tests/sim/test_golden.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from clonedrive.base.images import read_rgb
from clonedrive.sim.cameras import CameraRig
from clonedrive.sim.conditions import Conditions
from clonedrive.sim.scene import Scene
from clonedrive.world.catalog import load_track

GOLDEN = Path(__file__).resolve().parent / "golden" / "lake_s330_center_160x80.png"
WIDTH, HEIGHT = 160, 80
#: The pose: centred on the lake track at s = 330 m, in a bend with kerbs, trees and hills.
POSE_S_M = 330.0
#: A pixel "changed" when one of its channels differs by more than this [0-255].
CHANGED_LEVEL = 24
#: Tolerance: mean |difference| (largest channel) [0-255] and share of changed pixels.
MAX_MEAN_DIFFERENCE = 1.0
MAX_CHANGED_SHARE = 0.005


def render(scene: Scene, offset_m: float = 0.0, turn_rad: float = 0.0) -> np.ndarray:
    track = scene.track
    x, y, z = track.offset_point(POSE_S_M, offset_m)
    yaw = float(track.heading_at(POSE_S_M)) + turn_rad
    with CameraRig(scene, ("center",), WIDTH, HEIGHT) as rig:
        return rig.render(float(x), float(y), float(z), yaw)["center"]


def difference(image: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(mean |difference| of the largest channel, share of pixels that changed)."""
    assert image.shape == reference.shape, (image.shape, reference.shape)
    per_pixel = np.abs(image.astype(np.int16) - reference.astype(np.int16)).max(axis=-1)
    return float(per_pixel.mean()), float(np.mean(per_pixel > CHANGED_LEVEL))


def looks_the_same(image: np.ndarray, reference: np.ndarray) -> bool:
    mean, changed = difference(image, reference)
    return mean <= MAX_MEAN_DIFFERENCE and changed <= MAX_CHANGED_SHARE


@pytest.fixture(scope="module")
def lake():
    with Scene(load_track("lake")) as scene:
        yield scene


@pytest.fixture(scope="module")
def golden() -> np.ndarray:
    return read_rgb(GOLDEN, shape=(HEIGHT, WIDTH, 3))


def test_the_lake_at_a_fixed_pose_looks_as_the_golden_image(lake, golden, tmp_path):
    image = render(lake)
    mean, changed = difference(image, golden)
    if not looks_the_same(image, golden):
        actual = tmp_path / GOLDEN.name
        write_png(actual, image)
        pytest.fail(f"the frame differs from {GOLDEN.name}: mean {mean:.2f} (max "
                    f"{MAX_MEAN_DIFFERENCE}), {changed:.2%} of pixels changed (max "
                    f"{MAX_CHANGED_SHARE:.1%}); this run's frame: {actual}")


@pytest.mark.parametrize(("offset_m", "turn_rad"), [(0.05, 0.0), (0.0, math.radians(0.25))])
def test_moving_the_camera_fails_the_comparison(lake, golden, offset_m, turn_rad):
    assert not looks_the_same(render(lake, offset_m, turn_rad), golden)


@pytest.mark.parametrize("conditions", [Conditions(line="white"),
                                        Conditions(road_brightness=1.05)],
                         ids=["white edge lines", "asphalt 5% brighter"])
def test_changing_a_colour_fails_the_comparison(golden, conditions):
    with Scene(load_track("lake"), conditions=conditions) as scene:
        assert not looks_the_same(render(scene), golden)


def write_png(path: Path, image_rgb: np.ndarray) -> None:
    import cv2

    ok, data = cv2.imencode(".png", np.ascontiguousarray(image_rgb[..., ::-1]))
    assert ok
    path.write_bytes(data.tobytes())


if __name__ == "__main__":  # regenerate the golden image (look at it first)
    with Scene(load_track("lake")) as scene:
        write_png(GOLDEN, render(scene))
    print(f"wrote {GOLDEN}")
