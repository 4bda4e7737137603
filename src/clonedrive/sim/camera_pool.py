"""One scene and camera rig lent to every simulator of a group that would build the same one.

A lock-step group drives several cars on one track (``evaluate``'s set speeds, a benchmark
split's runs), and each :class:`~clonedrive.sim.simulator.Simulator` used to build its own
:class:`~clonedrive.sim.scene.Scene`: its own engine, textures and baked vertex colours. The
software renderer then walks eight copies of the same scene: on the development machine it drew
20-25 % fewer frames per CPU second than one scene rendered at the same eight places along the
track (lake, center camera, 8 cars 130 m apart: 488-665 against 635-794 frames/s;
``benchmarks/evaluate.py`` reports ``shared_scene_speedup``).

A :class:`CameraPool` lends one scene and rig to every simulator that asks for the same look:
the same track geometry and theme, scenery switch, conditions, cameras, image size, renderer and
rendered rows, and no
per-episode randomisation. A car's frame is then still a function of its pose alone
(:meth:`CameraRig.render` places the car, renders and reads back in one call; frames are the
same for the same pose in every scene of a track, see :mod:`clonedrive.sim.scene`), so sharing
changes no pixel. Scenes with pixel noise are never shared (their noise stream is seeded per
simulator) and neither are randomised looks (drawn per seed).

The pool is for one thread: a shared rig must not render for two cars at once (the episode
runner renders on its calling thread only). The pool closes a scene when the last simulator
gives it back, and :meth:`CameraPool.close` closes whatever is left.
"""

from __future__ import annotations

from collections.abc import Hashable

from clonedrive.sim.cameras import CameraRig
from clonedrive.sim.reuse import track_key
from clonedrive.world.track import Track


class CameraPool:
    """Lends camera rigs (and their scenes) to simulators; shares them where the look is one.

    ``open(track, config, seed)`` returns a rig to render with; ``give_back(rig)`` when done.
    ``shared`` counts the rigs handed out that were already lent to another simulator.
    """

    def __init__(self) -> None:
        self._lent: dict[Hashable, list] = {}  # key -> [rig, users]
        self._private: list[CameraRig] = []
        self.shared = 0
        self.closed = False

    @staticmethod
    def key(track: Track, config) -> Hashable | None:
        """What makes two simulators' scenes the same, or None if a scene is never shared
        (a randomised look, drawn from each simulator's seed)."""
        if config.randomize:
            return None
        return (track_key(track), bool(config.scenery), config.conditions,
                tuple(config.cameras), int(config.image_width), int(config.image_height),
                config.renderer, config.render_rows)

    def open(self, track: Track, config, seed: int) -> CameraRig:
        """A rig for a simulator of ``track`` with ``config`` (a SimConfig) and ``seed``."""
        if self.closed:
            raise RuntimeError("the camera pool is closed")
        key = self.key(track, config)
        if key is not None and key in self._lent:
            entry = self._lent[key]
            entry[1] += 1
            self.shared += 1
            return entry[0]
        rig = build_rig(track, config, seed)
        if key is not None and rig.scene.appearance.pixel_noise_std <= 0:
            self._lent[key] = [rig, 1]
        else:  # pixel noise drawn from this simulator's seed: its own scene
            self._private.append(rig)
        return rig

    def give_back(self, rig: CameraRig) -> None:
        """The simulator is done with ``rig``; its scene closes when no one else uses it."""
        if rig in self._private:
            self._private.remove(rig)
            close_rig(rig)
            return
        for key, entry in list(self._lent.items()):
            if entry[0] is rig:
                entry[1] -= 1
                if entry[1] <= 0:
                    del self._lent[key]
                    close_rig(rig)
                return

    @property
    def scenes(self) -> int:
        """Scenes open now."""
        return len(self._lent) + len(self._private)

    def close(self) -> None:
        """Close every scene still open. Safe to call twice."""
        for rig, _ in self._lent.values():
            close_rig(rig)
        for rig in self._private:
            close_rig(rig)
        self._lent.clear()
        self._private.clear()
        self.closed = True

    def __enter__(self) -> CameraPool:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def build_rig(track: Track, config, seed: int) -> CameraRig:
    """A simulator's own rig: a new scene of ``track`` as ``config`` asks, and its rig."""
    from clonedrive.sim.scene import RandomizationConfig, Scene

    randomization = RandomizationConfig() if config.randomize else None
    scene = Scene(track, scenery=config.scenery, randomization=randomization, seed=seed,
                  conditions=config.conditions, renderer=config.renderer)
    try:
        return CameraRig(scene, cameras=config.cameras, width=config.image_width,
                         height=config.image_height, rows=config.render_rows)
    except BaseException:
        scene.close()
        raise


def close_rig(rig: CameraRig) -> None:
    """Close a rig made by :func:`build_rig` and its scene."""
    scene = rig.scene
    rig.close()
    scene.close()
