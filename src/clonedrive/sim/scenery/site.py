"""What every part of the scenery shares: the :class:`Site` (the track, the stations along it,
its curvature, the bridge span, water level and wall side, the noise fields and the shadow
patches, all derived once and deterministically from the track) and the helpers on road
geometry (spans, circular runs, the bridge, the loop's interior).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from clonedrive.sim.meshes import Mesh
from clonedrive.sim.scenery.themes import THEME_STYLES, ThemeStyle
from clonedrive.world.track import Track

#: Curves sharper than this [1/m] get kerbs (lake) and chevrons when sharper still.
KERB_CURVATURE = 1.0 / 60.0
CHEVRON_CURVATURE = 1.0 / 40.0
#: A straight is where |curvature| stays below one of these [1/m] (strictest tried first).
STRAIGHT_CURVATURES = (1.0 / 600.0, 1.0 / 250.0)
#: Feature station spacing [m] (kerbs, barriers, signs).
ROAD_STEP_M = 1.5
#: The lake's water lies this far [m] below the bridge deck's lowest point...
WATER_BELOW_BRIDGE_M = 2.2
#: ...and at least this far below the road's lowest point anywhere on the track, so that no
#: stretch of road runs under the water (the lake track's road clears it by 0.52 m).
WATER_BELOW_ROAD_M = 0.5


@dataclass(frozen=True)
class Span:
    """A stretch of road from ``start_m`` to ``end_m`` (arc length; end > start, may pass L)."""

    start_m: float
    end_m: float

    @property
    def length_m(self) -> float:
        return self.end_m - self.start_m

    @property
    def middle_m(self) -> float:
        return 0.5 * (self.start_m + self.end_m)

    def contains(self, s_m: np.ndarray, length_m: float) -> np.ndarray:
        rel = np.mod(np.asarray(s_m) - self.start_m, length_m)
        return rel <= self.length_m


def smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    """0 below ``edge0``, 1 above ``edge1``, a smooth cubic between."""
    t = np.clip((np.asarray(x, dtype=float) - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


class SineField:
    """A smooth random scalar field over the plane: a sum of plane waves, range about [-1, 1]."""

    def __init__(self, rng: np.random.Generator, waves: int, wavelength_m: tuple[float, float]):
        angle = rng.uniform(0, 2 * math.pi, waves)
        wavelength = np.exp(rng.uniform(*np.log(wavelength_m), waves))
        self._k = np.stack([np.cos(angle), np.sin(angle)], 1) * (2 * math.pi / wavelength)[:, None]
        self._phase = rng.uniform(0, 2 * math.pi, waves)
        amplitude = wavelength / wavelength.max()
        self._amplitude = amplitude / np.sqrt(0.5 * np.sum(amplitude**2)) / 2.0

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float)
        return np.sin(xy @ self._k.T + self._phase) @ self._amplitude


def track_rng(track: Track, purpose: str) -> np.random.Generator:
    """A generator seeded from the track and ``purpose``: the same track, the same scenery."""
    key = f"{track.name}:{track.version}:{track.length_m:.3f}:{purpose}".encode()
    return np.random.default_rng(zlib.crc32(key))


def dilate(mask: np.ndarray, samples: int) -> np.ndarray:
    """Circular dilation of a boolean mask by ``samples`` on each side."""
    if samples <= 0 or not mask.any():
        return mask.copy()
    kernel = np.ones(2 * samples + 1)
    padded = np.concatenate([mask[-samples:], mask, mask[:samples]]).astype(float)
    return np.convolve(padded, kernel, mode="valid") > 0


def circular_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Circular runs of True as (first index, length)."""
    n = len(mask)
    if not mask.any():
        return []
    if mask.all():
        return [(0, n)]
    start = int(np.flatnonzero(~mask)[0])
    rolled = np.roll(mask, -start)
    runs, i = [], 0
    while i < n:
        if rolled[i]:
            j = i
            while j < n and rolled[j]:
                j += 1
            runs.append(((i + start) % n, j - i))
            i = j
        else:
            i += 1
    return runs


def longest_run(mask: np.ndarray) -> tuple[int, int]:
    """(start index, length) of the longest circular run of True in ``mask`` ((0, 0) if none)."""
    n = len(mask)
    if mask.all():
        return 0, n
    if not mask.any():
        return 0, 0
    start = int(np.flatnonzero(~mask)[0]) + 1  # begin just after a False: no run wraps
    rolled = np.roll(mask, -start)
    best, best_start, run = 0, 0, 0
    for i, value in enumerate(rolled):
        run = run + 1 if value else 0
        if run > best:
            best, best_start = run, i - run + 1
    return (best_start + start) % n, best


def find_bridge(track: Track) -> Span | None:
    """The bridge span (lake theme): the middle of the longest straight, if >= 60 m long.

    The strictest straightness that still gives a 60 m run wins (the lake's bridge straight
    starts at s = 11 m and is 142 m long at 1/600 m^-1).
    """
    for limit in STRAIGHT_CURVATURES:  # the straightest long run first
        start, count = longest_run(np.abs(track.curvature_table) < limit)
        run_m = count * track.ds_m
        if run_m >= 60.0:
            break
    else:
        return None
    bridge_m = min(run_m - 30.0, 110.0)
    middle = track.s[start] + 0.5 * run_m
    return Span(middle - 0.5 * bridge_m, middle + 0.5 * bridge_m)


def interior_side(track: Track) -> int:
    """+1 if the loop's interior is on the right of the driving direction, else -1."""
    turning = float(np.sum(track.curvature_table) * track.ds_m)
    return -1 if turning > 0 else 1


def water_level(track: Track, bridge: Span | None) -> float | None:
    """Height [m] of the lake's water under ``bridge`` (None without a bridge): below the deck,
    and below every part of the road, which would otherwise run through a flooded trench."""
    if bridge is None:
        return None
    on_bridge = bridge.contains(track.s, track.length_m)
    under_deck = float(track.xyz[on_bridge, 2].min()) - WATER_BELOW_BRIDGE_M
    return min(under_deck, float(track.xyz[:, 2].min()) - WATER_BELOW_ROAD_M)


def right_normal(track: Track, s_m: np.ndarray) -> np.ndarray:
    """Unit vectors (n, 2) pointing to the right of the driving direction at ``s_m``."""
    heading = track.heading_at(s_m)
    return np.column_stack([np.sin(heading), -np.cos(heading)])


class Site:
    """The track and what the builders derive from it once; collects the meshes and counts."""

    def __init__(self, track: Track, full: bool, style: ThemeStyle | None = None):
        self.track = track
        self.full = full
        self.theme = track.theme
        self.style = style or THEME_STYLES[track.theme]
        self.meshes: dict[str, Mesh] = {}
        self.counts: dict[str, int] = {}
        self.length = track.length_m
        count = max(8, int(round(self.length / ROAD_STEP_M)))
        self.stations = np.arange(count) * (self.length / count)
        self.curvature = track.curvature(self.stations)
        self.bridge = find_bridge(track) if self.style.bridge else None
        self.water_level = water_level(track, self.bridge)
        self.wall_side = interior_side(track)
        noise_rng = track_rng(track, "terrain")
        self.hills = SineField(noise_rng, 14, (60.0, 420.0))
        self.rough = SineField(noise_rng, 10, (12.0, 60.0))
        self.cliff = SineField(noise_rng, 8, (30.0, 160.0))
        self.patches = SineField(noise_rng, 10, (15.0, 90.0))
        self.shadow_blobs = self._shadow_blobs()
        #: (positions, triangles, normals, projection, beyond) once the terrain is built
        self.terrain: tuple | None = None

    def mesh(self, material: str) -> Mesh:
        """The mesh of ``material``, created empty on first use."""
        return self.meshes.setdefault(material, Mesh())

    def _shadow_blobs(self) -> np.ndarray:
        """(k, 4) rows of (x, y, radius, darkness) for soft shadow patches on and by the road."""
        rng = track_rng(self.track, "shadows")
        count = int(self.length / self.style.shadow_spacing_m)
        if count == 0:
            return np.zeros((0, 4))
        s = rng.uniform(0, self.length, count)
        half = 0.5 * self.track.width_at(s)
        offset = rng.uniform(-1.3, 1.3, count) * half
        xy = self.track.offset_point(s, offset)[:, :2]
        radius = rng.uniform(1.8, 5.5, count)
        darkness = np.minimum(rng.uniform(0.6, 0.95, count) * self.style.shadow_strength, 0.98)
        if self.bridge is not None:
            keep = ~self.bridge.contains(s, self.length)
            xy, radius, darkness = xy[keep], radius[keep], darkness[keep]
        return np.column_stack([xy, radius, darkness])

    def sunlit(self, xy: np.ndarray) -> np.ndarray:
        """Direct-sun factor in [0, 1] at world points (n, 2) from the shadow patches."""
        lit = np.ones(len(xy))
        if len(self.shadow_blobs) == 0 or len(xy) == 0:
            return lit
        tree = cKDTree(xy)
        for x, y, radius, darkness in self.shadow_blobs:
            near = tree.query_ball_point((x, y), radius * 1.3)
            if not near:
                continue
            near = np.asarray(near)
            # a lumpy blob: the radius varies with direction
            delta = xy[near] - (x, y)
            angle = np.arctan2(delta[:, 1], delta[:, 0])
            r = radius * (1.0 + 0.25 * np.sin(3 * angle + x) + 0.15 * np.sin(5 * angle + y))
            dist = np.hypot(delta[:, 0], delta[:, 1]) / r
            lit[near] *= 1.0 - darkness * (1.0 - smoothstep(0.75, 1.05, dist))
        return lit
