"""A camera pool shares one scene among simulators that look alike, and changes no pixel."""

import numpy as np
import pytest

from clonedrive.sim.camera_pool import CameraPool
from clonedrive.sim.conditions import Conditions
from clonedrive.sim.simulator import Controls, SimConfig, Simulator

SMALL = SimConfig(cameras=("center",), image_width=96, image_height=48)
#: Two cars driven differently, so that they are at different places when they render.
CONTROLS = (Controls(steering=0.05, throttle=0.6), Controls(steering=-0.08, throttle=0.3))


def drive(sims, steps=12):
    """Reset each simulator at its own start, step them in turn; every frame, in order."""
    frames = []
    for k, sim in enumerate(sims):
        obs, _ = sim.reset(seed=k, options={"s_m": 40.0 * k, "speed_mph": 10.0})
        frames.append(obs.images["center"])
    for _ in range(steps):
        for sim, controls in zip(sims, CONTROLS, strict=True):
            frames.append(sim.step(controls)[0].images["center"])
    return frames


def own_and_pooled(config):
    own = [Simulator("lake", config) for _ in CONTROLS]
    try:
        expected = drive(own)
    finally:
        for sim in own:
            sim.close()
    with CameraPool() as pool:
        pooled = [Simulator("lake", config, pool=pool) for _ in CONTROLS]
        try:
            got = drive(pooled)
            scenes, shared = pool.scenes, pool.shared
        finally:
            for sim in pooled:
                sim.close()
        assert pool.scenes == 0  # the last simulator's close closed the scene
    return expected, got, scenes, shared


def test_pooled_simulators_share_one_scene_and_see_the_same_frames():
    expected, got, scenes, shared = own_and_pooled(SMALL)
    assert (scenes, shared) == (1, 1)
    assert len(got) == len(expected) == 2 + 2 * 12
    for mine, theirs in zip(got, expected, strict=True):
        np.testing.assert_array_equal(mine, theirs)
    # The two cars are at different places: sharing did not hand one car the other's frame.
    assert not np.array_equal(got[-1], got[-2])


def test_a_scene_with_pixel_noise_is_not_shared():
    noisy = SimConfig(cameras=("center",), image_width=96, image_height=48,
                      conditions=Conditions(pixel_noise_std=6.0))
    expected, got, scenes, shared = own_and_pooled(noisy)
    assert (scenes, shared) == (2, 0)
    for mine, theirs in zip(got, expected, strict=True):
        np.testing.assert_array_equal(mine, theirs)


def test_randomised_looks_and_other_sizes_get_their_own_scene():
    with CameraPool() as pool:
        sims = [Simulator("lake", SimConfig(cameras=("center",), image_width=96,
                                            image_height=48, randomize=True), pool=pool),
                Simulator("lake", SimConfig(cameras=("center",), image_width=96,
                                            image_height=48, randomize=True), pool=pool),
                Simulator("lake", SimConfig(cameras=("center",), image_width=64,
                                            image_height=32), pool=pool),
                Simulator("lake", SMALL, pool=pool)]
        for sim in sims:
            sim.reset(seed=3)
        assert (pool.scenes, pool.shared) == (4, 0)
        sims[0].close()
        assert pool.scenes == 3
        sims[3].step(Controls(throttle=0.5))  # the others still render
    assert pool.scenes == 0 and pool.closed
    with pytest.raises(RuntimeError, match="closed"):
        Simulator("lake", SMALL, pool=pool).reset()
