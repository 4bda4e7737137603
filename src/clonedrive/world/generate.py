"""Procedural closed tracks from a seed: the unseen tracks for generalisation tests.

Two generators, both pure functions of their inputs (a shape that fails validation is redrawn
from the same random generator):

- **v1** (this module, frozen): a circle perturbed by a few harmonics, no curve under 15 m.
  Named ``gen1:<seed>``, and also plain ``gen:<seed>``: that name was published with v1
  figures (the demo's unseen tracks, evaluate ``--unseen``), so it keeps meaning v1.
- **v2** (:mod:`clonedrive.world.segments`): tracks built from straights, arcs, hairpins,
  S-bends, chicanes and switchbacks at a difficulty. Named ``gen2:<seed>`` (medium) or
  ``gen2:<easy|medium|hard>:<seed>``.

:func:`generate` makes either; :data:`GENERATOR_VERSION` is the newest.
"""

from __future__ import annotations

import math

import numpy as np

from clonedrive.world import segments
from clonedrive.world.track import THEMES, Track, TrackError, TrackSpec

#: The newest generator. A generator's output never changes: a new one gets the next version,
#: and the old stays reachable by its versioned name, so earlier numbers stay comparable.
GENERATOR_VERSION = segments.VERSION
#: Version 1's number: part of its random seed and of its tracks' ``version``.
V1_VERSION = 1
#: Generated tracks are drivable by a learner: no curve tighter than this [m].
MIN_GENERATED_RADIUS_M = 15.0


def _draw_spec(rng: np.random.Generator, seed: int, name: str) -> TrackSpec:
    length_m = rng.uniform(700.0, 1600.0)
    curviness = rng.uniform(0.12, 0.32)
    theme = THEMES[int(rng.integers(len(THEMES)))]
    hilly = theme == "mountain"
    width_m = float(rng.uniform(7.0, 9.0) if not hilly else rng.uniform(6.5, 8.0))
    # Radius as a function of polar angle: a circle perturbed by a few low harmonics.
    count = 48
    theta = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    radius = np.ones(count)
    for k in range(2, 6):
        amplitude = curviness * rng.uniform(0.2, 1.0) / k**0.5
        radius += amplitude * np.cos(k * theta + rng.uniform(0, 2 * math.pi))
    radius = np.clip(radius, 0.35, None)
    x, y = radius * np.cos(theta), radius * np.sin(theta)
    perimeter = np.linalg.norm(np.diff(np.column_stack([x, y]), axis=0, append=[[x[0], y[0]]]),
                               axis=1).sum()
    scale = length_m / perimeter
    x, y = x * scale, y * scale
    # Elevation: two harmonics along the loop, scaled to a maximum grade.
    max_grade = rng.uniform(0.06, 0.10) if hilly else rng.uniform(0.0, 0.015)
    z = np.zeros(count)
    for k in (1, 2, 3):
        z += rng.uniform(0.3, 1.0) * np.sin(k * theta + rng.uniform(0, 2 * math.pi)) / k
    grade = np.abs(np.diff(np.append(z, z[0]))) / (length_m / count)
    if grade.max() > 0:
        z *= max_grade / grade.max()
    if rng.random() < 0.5:  # half the tracks run clockwise
        x, y, z = x[::-1], y[::-1], z[::-1]
    centerline = tuple((float(a), float(b), float(c)) for a, b, c in zip(x, y, z, strict=True))
    return TrackSpec(
        name=name,
        version=V1_VERSION,
        theme=theme,
        width_m=round(width_m, 2),
        closed=True,
        centerline=centerline,
    )


def generate(seed: int, *, version: int = GENERATOR_VERSION,
             difficulty: str = segments.DEFAULT_DIFFICULTY, name: str | None = None) -> Track:
    """A valid closed track drawn from ``seed`` by generator ``version`` (1 or 2; ``difficulty``
    applies to 2). Same arguments, same track."""
    if version == V1_VERSION:
        return generate_v1(seed, name=name)
    if version == segments.VERSION:
        return segments.generate_v2(seed, difficulty, name=name)
    raise TrackError(f"unknown track generator version {version}: use 1 or {GENERATOR_VERSION}")


def generate_v1(seed: int, *, name: str | None = None, max_attempts: int = 50) -> Track:
    """Version 1: a valid closed track drawn from ``seed`` (same seed, same track)."""
    if seed < 0:
        raise TrackError(f"generated track seed must be >= 0, got {seed}")
    name = name or f"gen:{seed}"
    rng = np.random.default_rng([V1_VERSION, seed])
    last_error = None
    for _ in range(max_attempts):
        spec = _draw_spec(rng, seed, name)
        try:
            track = Track(spec)
        except TrackError as error:
            last_error = error
            continue
        if track.min_radius_m >= MIN_GENERATED_RADIUS_M:
            return track
        last_error = f"tightest curve {track.min_radius_m:.1f} m < {MIN_GENERATED_RADIUS_M} m"
    raise TrackError(f"{name}: no valid track in {max_attempts} draws ({last_error})")
