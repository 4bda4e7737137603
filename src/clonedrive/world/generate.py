"""Procedural closed tracks from a seed: the unseen tracks for generalisation tests.

``generate(seed)`` draws length, curviness, elevation and theme from ``seed`` and returns a valid
:class:`~clonedrive.world.track.Track`, identical for the same seed. A shape that fails validation
(too tight, overlapping) is redrawn from the same generator, so the result is still a pure function
of the seed. ``gen:<seed>`` names these tracks wherever a track name is accepted.
"""

from __future__ import annotations

import math

import numpy as np

from clonedrive.world.track import THEMES, Track, TrackError, TrackSpec

#: Bump when the generator's output changes, so earlier published numbers stay comparable.
GENERATOR_VERSION = 1
#: Generated tracks are drivable by a learner: no curve tighter than this [m].
MIN_GENERATED_RADIUS_M = 15.0


def _draw_spec(rng: np.random.Generator, seed: int) -> TrackSpec:
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
        name=f"gen:{seed}",
        version=GENERATOR_VERSION,
        theme=theme,
        width_m=round(width_m, 2),
        closed=True,
        centerline=centerline,
    )


def generate(seed: int, *, max_attempts: int = 50) -> Track:
    """A valid closed track drawn from ``seed`` (same seed, same track)."""
    if seed < 0:
        raise TrackError(f"generated track seed must be >= 0, got {seed}")
    rng = np.random.default_rng([GENERATOR_VERSION, seed])
    last_error = None
    for _ in range(max_attempts):
        spec = _draw_spec(rng, seed)
        try:
            track = Track(spec)
        except TrackError as error:
            last_error = error
            continue
        if track.min_radius_m >= MIN_GENERATED_RADIUS_M:
            return track
        last_error = f"tightest curve {track.min_radius_m:.1f} m < {MIN_GENERATED_RADIUS_M} m"
    raise TrackError(f"gen:{seed}: no valid track in {max_attempts} draws ({last_error})")
