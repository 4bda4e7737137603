"""The expert's reference run: what the networks' lap times and smoothness are measured against.

DESIGN.md's **lap-time ratio** is a clean lap's time over the expert's clean lap time on the same
track, start and speed cap; the **smoothness ratios** divide a run's steering rate, steering
jerk and lateral figures by the expert's on the same track and cap. :func:`expert_reference`
drives the expert (no steering noise, cameras off: physics only, fast) from the evaluation's
start through the episode runner, under the same rules as the evaluated car, and returns its
run summary (``lap_time_s``: the first clean lap's time, from a standing start, as for the
network). Results are cached within a process per (track geometry, speed, laps, cap): a track
file edited between two evaluations gets a fresh reference, a renamed copy reuses it.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from clonedrive.world.track import Track

#: Expert references kept per process (the oldest dropped first).
CACHED_REFERENCES = 256
_CACHE: OrderedDict = OrderedDict()
_CACHE_LOCK = threading.Lock()


def expert_reference(track: str | Track, speed_mph: float, *, laps: int = 1,
                     max_seconds: float | None = None) -> dict:
    """The expert's run summary on ``track`` (a name or path, or the loaded :class:`Track`) at
    up to ``speed_mph`` (see the module doc)."""
    from clonedrive.world.catalog import load_track

    loaded = load_track(track) if isinstance(track, str) else track
    name = track if isinstance(track, str) else track.name
    key = (loaded.geometry_key(), float(speed_mph), int(laps), max_seconds)
    with _CACHE_LOCK:
        if key not in _CACHE:
            _CACHE[key] = _drive_expert(loaded, name, float(speed_mph), int(laps),
                                        max_seconds)
            while len(_CACHE) > CACHED_REFERENCES:
                _CACHE.popitem(last=False)
        _CACHE.move_to_end(key)
        return dict(_CACHE[key])


def _drive_expert(track, name: str, speed_mph: float, laps: int, max_seconds: float | None
                  ) -> dict:
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.episode.drivers import ExpertDriver
    from clonedrive.episode.rules import EpisodeRules
    from clonedrive.episode.runner import Episode, PerCar, Runner
    from clonedrive.sim.simulator import SimConfig, Simulator

    with Simulator(track, SimConfig(cameras=())) as sim:
        episode = Episode(sim, EpisodeRules(laps=laps, set_speed_mph=speed_mph,
                                            max_seconds=max_seconds), track=name)
        expert = ExpertPolicy(sim.track, ExpertConfig(speed_mph=speed_mph))
        Runner([episode], PerCar([ExpertDriver(expert)])).run()
        return episode.trace.summary()


def against_expert(run: dict, *, max_seconds: float | None = None,
                   track: Track | None = None) -> dict:
    """For one run's summary (eval.json entry): ``expert`` (the expert's lap time and
    smoothness figures on the same track, cap and laps), ``lap_time_ratio`` (None unless both
    drove a clean first lap) and the ``<figure>_ratio`` of every smoothness figure. ``track``:
    the run's track as it drove it (else loaded from the run's track name)."""
    from clonedrive.episode.smoothness import FIGURES, smoothness_ratios

    expert = expert_reference(run["track"] if track is None else track, run["speed_mph"],
                              laps=run["laps_target"], max_seconds=max_seconds)
    mine, theirs = run.get("lap_time_s"), expert.get("lap_time_s")
    return {
        "expert": {key: expert.get(key) for key in ("lap_time_s", "smoothness", *FIGURES,
                                                    "mean_speed_mph", "interventions")},
        "lap_time_ratio": round(mine / theirs, 4) if mine and theirs else None,
        **smoothness_ratios(run, expert),
    }
