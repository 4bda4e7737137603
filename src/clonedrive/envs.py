"""Gymnasium environments: ``clonedrive/Lake-v0``, ``clonedrive/Mountain-v0``,
``clonedrive/Generated-v0`` (``track_seed=N``, generator v1) and ``clonedrive/Generated-v1``
(generator v2: ``track_seed=N``, ``difficulty="easy"|"medium"|"hard"``). Registered when this
module is imported (``import clonedrive.envs``, or
``gymnasium.make("clonedrive.envs:clonedrive/Lake-v0")``, which imports it); ``import
clonedrive`` alone registers nothing.

Observation: the center camera image (uint8 RGB 160x320x3) by default, or with
``observation="state"`` a float32 vector (speed mph, steering, CTE m, heading error rad,
curvature 1/m, all tyres on road). Action: ``[steering, throttle]`` in [-1, 1].
Reward: metres of progress along the track this step; -10 and termination when a tyre leaves
the road. Episodes are truncated after ``max_episode_steps`` (default 1500 = 100 s at 15 Hz).

Rendering options: ``renderer`` (``"auto"``, ``"software"`` or ``"egl"``: sim/engine.py) and
``render_rows=(top, bottom)``: only those rows of the image are rendered, the rest are a
constant (what a policy that crops its input needs; not with ``render_mode``, which shows whole
frames). ``sim_config`` replaces all of them.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from clonedrive.sim.engine import DEFAULT_RENDERER
from clonedrive.sim.simulator import Controls, SimConfig, Simulator
from clonedrive.world.catalog import load_track

OFF_ROAD_REWARD = -10.0


class DrivingEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(self, track: str = "lake", *, track_seed: int | None = None,
                 generator: int = 1, difficulty: str = "medium",
                 observation: str = "image", render_mode: str | None = None,
                 sim_config: SimConfig | None = None, renderer: str = DEFAULT_RENDERER,
                 render_rows: tuple[int, int] | None = None):
        if observation not in ("image", "state"):
            raise ValueError(f"observation must be 'image' or 'state', got {observation!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if generator not in (1, 2):
            raise ValueError(f"generator must be 1 or 2, got {generator!r}")
        if render_rows is not None and render_mode is not None:
            raise ValueError("render_rows renders part of each frame; render_mode needs whole "
                             "frames: give one of them")
        name = track
        if track_seed is not None:
            name = f"gen:{track_seed}" if generator == 1 else f"gen2:{difficulty}:{track_seed}"
        self.observation_kind = observation
        self.render_mode = render_mode
        cameras = ("center",) if observation == "image" or render_mode else ()
        config = sim_config or SimConfig(cameras=cameras, renderer=renderer,
                                         render_rows=render_rows)
        self.sim = Simulator(load_track(name), config)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        if observation == "image":
            shape = (config.image_height, config.image_width, 3)
            self.observation_space = spaces.Box(0, 255, shape=shape, dtype=np.uint8)
        else:
            low = np.array([-10.0, -1.0, -100.0, -np.pi, -1.0, 0.0], dtype=np.float32)
            high = np.array([40.0, 1.0, 100.0, np.pi, 1.0, 1.0], dtype=np.float32)
            self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._last = None

    def _observation(self, obs):
        if self.observation_kind == "image":
            return obs.images["center"]
        space = self.observation_space
        return np.clip(obs.state_vector(), space.low, space.high)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        obs, info = self.sim.reset(seed=seed, options=options)
        self._last = obs
        return self._observation(obs), {"s_m": obs.s_m, "cte_m": obs.cte_m}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        before = self._last
        obs, info = self.sim.step(Controls(steering=float(action[0]), throttle=float(action[1])))
        self._last = obs
        length = self.sim.track.length_m
        progress = (obs.s_m - before.s_m + 0.5 * length) % length - 0.5 * length
        terminated = bool(info["events"])
        reward = OFF_ROAD_REWARD if terminated else float(progress)
        return self._observation(obs), reward, terminated, False, {
            "s_m": obs.s_m, "cte_m": obs.cte_m, "laps": obs.laps, "speed_mph": obs.speed_mph,
        }

    def render(self):
        if self.render_mode == "rgb_array" and self._last is not None:
            return self._last.images.get("center")
        return None

    def close(self):
        self.sim.close()


def register_envs() -> None:
    """Register the clonedrive environments with Gymnasium (idempotent)."""
    specs = {
        "clonedrive/Lake-v0": {"track": "lake"},
        "clonedrive/Mountain-v0": {"track": "mountain"},
        "clonedrive/Generated-v0": {"track_seed": 0},
        "clonedrive/Generated-v1": {"track_seed": 0, "generator": 2},
    }
    for env_id, kwargs in specs.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="clonedrive.envs:DrivingEnv", kwargs=kwargs,
                         max_episode_steps=1500)


register_envs()
