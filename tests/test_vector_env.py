"""Generated-v1 (generator v2): check_env passes and make_vec's async vector env steps."""

import gymnasium
import numpy as np
from gymnasium.utils.env_checker import check_env

import clonedrive.envs  # noqa: F401  (registers the environments)


def test_generated_v1_passes_check_env_and_uses_generator_v2():
    env = gymnasium.make("clonedrive/Generated-v1", observation="state", difficulty="hard",
                         track_seed=3)
    try:
        check_env(env.unwrapped)
        assert env.unwrapped.sim.track.name == "gen2:hard:3"
    finally:
        env.close()


def test_make_vec_async_runs_four_generated_envs():
    vec = gymnasium.make_vec("clonedrive/Generated-v1", num_envs=4, vectorization_mode="async",
                             observation="state")
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (4, 6)
        for _ in range(3):
            obs, reward, terminated, truncated, _ = vec.step(
                np.tile([0.0, 0.5], (4, 1)).astype(np.float32))
        assert reward.shape == (4,) and not terminated.any()
        assert np.allclose(obs, obs[0])  # same track, same seedless start: same state
    finally:
        vec.close()
