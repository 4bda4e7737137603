import gymnasium as gym
import numpy as np
import pytest

import clonedrive.envs  # noqa: F401  (registers the environments)


@pytest.mark.parametrize("env_id", ["clonedrive/Lake-v0", "clonedrive/Mountain-v0"])
def test_state_env_passes_check_env_and_is_deterministic(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, observation="state")
    check_env(env.unwrapped, skip_render_check=True)
    rollouts = []
    for _ in range(2):
        obs, _ = env.reset(seed=3)
        trace = [obs]
        for _ in range(40):
            obs, reward, terminated, truncated, info = env.step(np.array([0.05, 0.8]))
            trace.append(obs)
        rollouts.append(np.array(trace))
    env.close()
    assert np.array_equal(rollouts[0], rollouts[1])
    assert rollouts[0][-1][0] > 5.0  # the car got going (speed in mph)


def test_generated_env_takes_a_track_seed_and_rewards_progress():
    env = gym.make("clonedrive/Generated-v0", track_seed=5, observation="state")
    assert env.unwrapped.sim.track.name == "gen:5"
    env.reset(seed=0)
    total = 0.0
    for _ in range(30):
        _, reward, terminated, _, _ = env.step(np.array([0.0, 1.0]))
        total += reward
    env.close()
    assert total > 5.0


def test_image_env_renders_only_the_rows_asked_for():
    env = gym.make("clonedrive/Lake-v0", renderer="software", render_rows=(80, 135))
    obs, _ = env.reset(seed=0)
    obs, *_ = env.step(np.array([0.0, 0.5]))
    env.close()
    assert obs.shape == (160, 320, 3)
    assert not obs[:80].any() and not obs[135:].any() and obs[80:135].any()
    with pytest.raises(ValueError, match="render_rows"):
        gym.make("clonedrive/Lake-v0", render_rows=(80, 135), render_mode="rgb_array")
