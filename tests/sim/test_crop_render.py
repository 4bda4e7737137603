"""Rendering only the rows a network's crop keeps (``CameraRig(rows=...)``, ``SimConfig``).

The strip is drawn through a lens whose film size and offset select exactly those rows, into a
buffer of that many rows. The software renderer clips triangles at the strip's edges instead of
the frame's, which moves its texture sampling by a texel here and there: the strip's pixels are
close to, not bit-identical with, the full frame's (measured over whole laps of lake and
mountain by ``benchmarks/crop.py``: mean absolute difference 2.2-4.6 grey levels, the largest
single difference 228 where a texel of a kerb stripe flips). These tests check, at the real
160x320 and along part of a lap of each track, that the strip is the same view (aligned to the
row) within that noise, and that everything outside it is the fill value.
"""

from __future__ import annotations

import numpy as np
import pytest

from clonedrive.sim.cameras import FILL_VALUE, CameraRig, check_rows
from clonedrive.sim.scene import Scene
from clonedrive.sim.simulator import SimConfig, Simulator
from clonedrive.world.catalog import load_track

#: The write-up's crop (rows 80-135) and --crop-top 60's.
CROPS = [(80, 135), (60, 135)]
#: Mean absolute difference [grey levels] allowed between the strip and the same rows of the
#: full frame, over the frames of a test (measured: at most 4.6 over a whole lap).
MEAN_DIFFERENCE_BOUND = 8.0
#: Frames compared per track, and the distance between them along the lap [m].
FRAMES, SPACING_M = 24, 9.0


def lap_poses(track, frames=FRAMES, spacing_m=SPACING_M):
    for s in np.arange(frames) * spacing_m:
        x, y, z = track.point(float(s))
        yield float(x), float(y), float(z), float(track.heading_at(s)), float(track.grade(s))


@pytest.mark.parametrize("track_name", ["lake", "mountain"])
def test_the_strip_shows_the_full_frames_rows_and_nothing_else(track_name):
    track = load_track(track_name)
    differences = {rows: {shift: [] for shift in (-1, 0, 1)} for rows in CROPS}
    with Scene(track, renderer="software") as scene, \
            CameraRig(scene, cameras=("center",)) as full, \
            CameraRig(scene, cameras=("center",), rows=CROPS[0]) as strip80, \
            CameraRig(scene, cameras=("center",), rows=CROPS[1]) as strip60:
        for pose in lap_poses(track):
            whole = full.render(*pose)["center"].astype(np.int16)
            for rig, (top, bottom) in ((strip80, CROPS[0]), (strip60, CROPS[1])):
                frame = rig.render(*pose)["center"]
                assert frame.shape == (160, 320, 3) and frame.dtype == np.uint8
                assert (frame[:top] == FILL_VALUE).all() and (frame[bottom:] == FILL_VALUE).all()
                kept = frame[top + 1:bottom - 1].astype(np.int16)
                for shift, found in differences[(top, bottom)].items():
                    rows = whole[top + 1 + shift:bottom - 1 + shift]
                    found.append(float(np.abs(kept - rows).mean()))
    for rows, by_shift in differences.items():
        here = np.mean(by_shift[0])
        assert here < MEAN_DIFFERENCE_BOUND, (rows, here)
        # The same view to the row: the full frame one row up or down differs more.
        assert here < min(np.mean(by_shift[-1]), np.mean(by_shift[1])), (rows, by_shift)


def test_a_strip_of_every_row_is_the_full_frame_to_the_bit():
    track = load_track("lake")
    with Scene(track, scenery=False) as scene, \
            CameraRig(scene, cameras=("center",)) as full, \
            CameraRig(scene, cameras=("center",), rows=(0, 160)) as every_row:
        for pose in lap_poses(track, frames=4):
            assert np.array_equal(full.render(*pose)["center"], every_row.render(*pose)["center"])


def test_rows_are_checked():
    assert check_rows(None, 160) == (0, 160)
    assert check_rows([80, 135], 160) == (80, 135)
    for rows in ((135, 80), (-1, 100), (0, 161), (50, 50)):
        with pytest.raises(ValueError, match="not a strip"):
            check_rows(rows, 160)
    with pytest.raises(ValueError, match="not a strip"):
        SimConfig(render_rows=(0, 200))
    assert SimConfig(render_rows=[80, 135]).render_rows == (80, 135)


def test_a_cropped_simulator_steps_as_a_full_frame_one_does():
    """The crop changes pixels only: the car's path and the lap counting are the state's."""
    from clonedrive.sim.simulator import Controls

    found = []
    for rows in (None, (80, 135)):
        config = SimConfig(cameras=("center",), scenery=False, render_rows=rows)
        with Simulator("lake", config) as sim:
            sim.reset(seed=0, options={"speed_mph": 10.0})
            for _ in range(30):
                obs, _ = sim.step(Controls(steering=0.05, throttle=0.3))
            found.append((obs.x_m, obs.y_m, obs.cte_m, obs.images["center"]))
    assert found[0][:3] == found[1][:3]
    assert (found[1][3][:80] == FILL_VALUE).all()


def test_the_pool_shares_a_scene_only_among_the_same_rows_and_renderer():
    from clonedrive.sim.camera_pool import CameraPool

    track = load_track("lake")
    base = SimConfig(cameras=("center",), scenery=False, renderer="software")
    cropped = SimConfig(cameras=("center",), scenery=False, renderer="software",
                        render_rows=(80, 135))
    assert CameraPool.key(track, base) != CameraPool.key(track, cropped)
    assert CameraPool.key(track, cropped) == CameraPool.key(
        track, SimConfig(cameras=("center",), scenery=False, renderer="software",
                         render_rows=[80, 135]))


def test_a_filmed_simulator_sees_the_strip_and_films_the_whole_frame():
    """``SimConfig(render_rows=..., film=True)``: the observations' frames are the strip an
    unfilmed simulator renders, bit for bit (so a filmed run drives as an unfilmed one), and
    each observation also carries the whole frame a whole-frame simulator renders there."""
    from clonedrive.sim.camera_pool import CameraPool
    from clonedrive.world.vehicle import Controls

    rows = CROPS[1]
    common = {"cameras": ("center",), "scenery": False}
    with CameraPool() as pool:
        sims = [Simulator("lake", SimConfig(**common, render_rows=rows, film=True), pool=pool),
                Simulator("lake", SimConfig(**common, render_rows=rows), pool=pool),
                Simulator("lake", SimConfig(**common))]
        observations = [[sim.reset(seed=0)[0]] for sim in sims]
        for step in range(6):
            for sim, seen in zip(sims, observations, strict=True):
                seen.append(sim.step(Controls(steering=0.3 * (-1) ** step, throttle=0.8))[0])
        for filmed, strip, whole in zip(*observations, strict=True):
            np.testing.assert_array_equal(filmed.images["center"], strip.images["center"])
            assert (filmed.images["center"][:rows[0]] == FILL_VALUE).all()
            np.testing.assert_array_equal(filmed.film_frame, whole.images["center"])
            assert strip.film_frame is None and whole.film_frame is None
        for sim in sims:
            sim.close()
        assert pool.scenes == 0  # the film's rig went back to the pool too
