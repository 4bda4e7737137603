"""Scenery derived from a track's geometry and theme: pure NumPy/SciPy, no rendering imports.

Track files hold only the centreline; everything around the road is derived here,
deterministically (the same track always gets the same scenery):

- **road** strip following the centreline, width and elevation (level across), u across the
  road (edge lines are in the texture), v along it;
- **kerbs** (lake theme) on both sides wherever |curvature| > 1/60 m^-1, a few metres either way;
- **bridge** (lake theme) over water on the middle of the longest straight (>= 60 m), with
  parapet walls, deck fascia and piers; the terrain under it drops into a lake basin;
- **terrain**: one height field for the whole map, triangulated (Delaunay) from rings of points
  along both road edges plus a coarse grid further out, so that no two parts of the track can
  put ground over each other's road. Height = road height of the nearest road point + a
  theme profile of the distance from the road edge + smooth noise:
  lake: a sandy verge, then rolling grassy hills; dirt run-off on the outside of sharp curves;
  mountain: a gravel shoulder, then a rock wall rising on the inside of the loop and a drop
  falling away on the outside, with mountains beyond;
- **objects**: trees (crossed-quad sprites), boulders, concrete barriers on the drop side of
  mountain curves, chevron signs on the outside of sharp curves, lamp posts (mountain);
- **shadows**: soft dark patches (the mountain theme has many) baked into the ``sunlit`` vertex
  attribute of the road and the ground near it.

The result is a :class:`Scenery`: one :class:`~clonedrive.sim.meshes.Mesh` per material in
world coordinates (metres, x east, y north, z up) plus the derived features (bridge span, water
level) that previews and tests use.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from clonedrive.sim.meshes import Mesh, box, crossed_quads, grid_triangles, vertex_normals
from clonedrive.sim.textures import ROAD_TEXTURE_REPEAT_M
from clonedrive.world.track import Track

#: Curves sharper than this [1/m] get kerbs (lake) and chevrons when sharper still.
KERB_CURVATURE = 1.0 / 60.0
CHEVRON_CURVATURE = 1.0 / 40.0
#: Mountain barriers line the drop side wherever the road bends more than this [1/m].
BARRIER_CURVATURE = 1.0 / 120.0
#: A straight is where |curvature| stays below one of these [1/m] (strictest tried first).
STRAIGHT_CURVATURES = (1.0 / 600.0, 1.0 / 250.0)
#: Feature station spacing [m] (kerbs, barriers, signs).
ROAD_STEP_M = 1.5
#: Road mesh stations: spacing from the chord error allowed on curves, within these bounds [m].
ROAD_MESH_STEP_M = (1.5, 5.0)
ROAD_CHORD_ERROR_M = 0.04
#: Road mesh cross-section (fractions of the half width): the road is level across, the edge
#: lines are in the texture and shadows are separate patches, so the edges are enough.
ROAD_ACROSS = np.array([-1.0, 1.0])
KERB_WIDTH_M = 0.6
KERB_HEIGHT_M = 0.05
#: Terrain below the road level at the road edge [m] (the road sits on a slight bank).
VERGE_DROP_M = 0.1
#: How far scenery extends from the road [m]; the camera far plane is about this.
SCENERY_RADIUS_M = 240.0
#: Terrain rings: distance beyond the road edge [m] and spacing along the road [m].
RING_OFFSETS_M = (-0.6, 0.7, 2.5, 5.0, 9.0, 15.0, 24.0, 36.0, 52.0, 72.0)
RING_SPACING_M = (4.0, 3.0, 3.0, 4.0, 5.0, 7.0, 10.0, 14.0, 18.0, 22.0)
GRID_SPACING_M = 20.0
#: Triangles steeper than this [deg] use the rock material.
ROCK_SLOPE_DEG = 38.0


@dataclass(frozen=True)
class ThemeStyle:
    """Colours (0-255 RGB albedo) and switches of a scenery theme."""

    road_rgb: tuple[float, float, float]
    edge_line_rgb: tuple[float, float, float]
    centre_line: bool
    tyre_tracks: float
    kerbs: bool
    bridge: bool
    barriers: bool
    lamp_posts: bool
    verge_rgb: tuple[float, float, float]
    grass_rgb: tuple[float, float, float]
    grass_alt_rgb: tuple[float, float, float]
    dirt_rgb: tuple[float, float, float]
    rock_rgb: tuple[float, float, float]
    tree_kinds: tuple[str, ...]
    tree_weights: tuple[float, ...]
    tree_keep: float  #: fraction of candidate tree sites kept
    shadow_spacing_m: float  #: mean road length between shadow patches
    shadow_strength: float = 1.0  #: darkness of the shadow patches, x the theme's (0 = none)


THEME_STYLES = {
    "lake": ThemeStyle(
        road_rgb=(128.0, 128.0, 117.0),
        edge_line_rgb=(210.0, 178.0, 52.0),
        centre_line=False,
        tyre_tracks=0.0,
        kerbs=True,
        bridge=True,
        barriers=False,
        lamp_posts=False,
        verge_rgb=(222.0, 206.0, 160.0),
        grass_rgb=(196.0, 170.0, 98.0),
        grass_alt_rgb=(118.0, 134.0, 62.0),
        dirt_rgb=(214.0, 192.0, 140.0),
        rock_rgb=(118.0, 132.0, 118.0),
        tree_kinds=("pine", "broadleaf", "bush"),
        tree_weights=(0.6, 0.15, 0.25),
        tree_keep=0.35,
        shadow_spacing_m=60.0,
    ),
    "mountain": ThemeStyle(
        road_rgb=(88.0, 88.0, 94.0),
        edge_line_rgb=(214.0, 176.0, 40.0),
        centre_line=False,
        tyre_tracks=1.0,
        kerbs=False,
        bridge=False,
        barriers=True,
        lamp_posts=True,
        verge_rgb=(128.0, 118.0, 96.0),
        grass_rgb=(132.0, 104.0, 58.0),
        grass_alt_rgb=(96.0, 90.0, 60.0),
        dirt_rgb=(150.0, 128.0, 84.0),
        rock_rgb=(82.0, 82.0, 86.0),
        tree_kinds=("autumn", "pine", "broadleaf"),
        tree_weights=(0.5, 0.3, 0.2),
        tree_keep=0.3,
        shadow_spacing_m=14.0,
    ),
}

#: Sprite kinds in the tree texture atlas, in atlas order.
TREE_ATLAS_KINDS = ("pine", "broadleaf", "autumn", "bush")
_TREE_HEIGHT_M = {"pine": (8.0, 14.0), "broadleaf": (6.0, 10.0), "autumn": (6.0, 10.0),
                  "bush": (1.0, 1.8)}
_TREE_ASPECT = {"pine": 0.5, "broadleaf": 0.6, "autumn": 0.6, "bush": 1.8}


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


@dataclass
class Scenery:
    """Everything around the road, as world-space meshes per material plus derived features."""

    theme: str
    style: ThemeStyle
    meshes: dict[str, Mesh]
    bridge: Span | None = None
    water_level_m: float | None = None
    wall_side: int = -1  #: mountain: +1 = walls on the right of the driving direction
    #: terrain extent: min x, min y, max x, max y [m]
    bounds_xy: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    counts: dict[str, int] = field(default_factory=dict)


# ---------------------------------------------------------------------- helpers
def smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
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


def _track_rng(track: Track, purpose: str) -> np.random.Generator:
    key = f"{track.name}:{track.version}:{track.length_m:.3f}:{purpose}".encode()
    return np.random.default_rng(zlib.crc32(key))


def _dilate(mask: np.ndarray, samples: int) -> np.ndarray:
    """Circular dilation of a boolean mask by ``samples`` on each side."""
    if samples <= 0 or not mask.any():
        return mask.copy()
    kernel = np.ones(2 * samples + 1)
    padded = np.concatenate([mask[-samples:], mask, mask[:samples]]).astype(float)
    return np.convolve(padded, kernel, mode="valid") > 0


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


# ---------------------------------------------------------------------- the builder
class _Builder:
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
        self.water_level = None
        if self.bridge is not None:
            on_bridge = self.bridge.contains(track.s, self.length)
            self.water_level = float(track.xyz[on_bridge, 2].min()) - 2.2
        self.wall_side = interior_side(track)
        noise_rng = _track_rng(track, "terrain")
        self.hills = SineField(noise_rng, 14, (60.0, 420.0))
        self.rough = SineField(noise_rng, 10, (12.0, 60.0))
        self.cliff = SineField(noise_rng, 8, (30.0, 160.0))
        self.patches = SineField(noise_rng, 10, (15.0, 90.0))
        self.shadow_blobs = self._shadow_blobs()

    def road_stations(self) -> np.ndarray:
        """Road mesh stations [m]: dense on curves, sparse on straights (chord error bound)."""
        fine = self.track.s
        radius = 1.0 / np.maximum(np.abs(self.track.curvature_table), 1e-6)
        step = np.clip(np.sqrt(8.0 * radius * ROAD_CHORD_ERROR_M), *ROAD_MESH_STEP_M)
        stations = [0.0]
        while True:
            i = min(int(stations[-1] / self.track.ds_m), len(fine) - 1)
            # the tightest curve within the next few metres sets the step
            window = step[i : i + int(ROAD_MESH_STEP_M[1] / self.track.ds_m) + 1]
            nxt = stations[-1] + float(window.min())
            if nxt > self.length - 0.5 * ROAD_MESH_STEP_M[0]:
                break
            stations.append(nxt)
        return np.asarray(stations)

    def mesh(self, material: str) -> Mesh:
        return self.meshes.setdefault(material, Mesh())

    # ------------------------------------------------------------ shadows
    def _shadow_blobs(self) -> np.ndarray:
        """(k, 4) rows of (x, y, radius, darkness) for soft shadow patches on and by the road."""
        rng = _track_rng(self.track, "shadows")
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

    # ------------------------------------------------------------ terrain height
    def height(self, s: np.ndarray, cte: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Terrain height [m] at points given their nearest road point (s, cte) and position."""
        track = self.track
        base = track.point(s)[..., 2]
        beyond = np.abs(cte) - 0.5 * track.width_at(s)  # distance past the road edge
        verge = -VERGE_DROP_M - 0.25 * smoothstep(0.0, 1.5, beyond) * (
            1 - smoothstep(2.0, 4.5, beyond)
        )
        if self.theme == "lake":
            hills = 5.0 + 9.0 * self.hills(xy) + 1.2 * self.rough(xy)
            rise = smoothstep(4.0, 40.0, beyond)
            h = base + verge + rise * hills
            if self.water_level is not None:
                # keep the ground by the road above the water; elsewhere hollows become lakes
                dry = self.water_level + 0.6 - base
                h = np.where(beyond < 25.0, np.maximum(h, base + np.maximum(verge, dry)), h)
                h = self._lake_basin(s, cte, xy, h)
            return h
        # mountain: walls on the interior side, a drop on the other
        wall = np.sign(cte) == self.wall_side
        cliff_m = 15.0 + 8.0 * self.cliff(xy)
        wall_h = (
            cliff_m * smoothstep(2.5, 2.5 + 0.55 * cliff_m, beyond)
            + 0.35 * np.clip(beyond - 14.0, 0.0, None)
            + 2.0 * self.rough(xy) * smoothstep(2.5, 8.0, beyond)
        )
        drop_m = 16.0 + 8.0 * self.cliff(xy + 500.0)
        drop_h = (
            -drop_m * smoothstep(3.0, 3.0 + 1.3 * drop_m, beyond)
            + 0.45 * np.clip(beyond - 45.0, 0.0, None)
            + 6.0 * self.hills(xy) * smoothstep(20.0, 90.0, beyond)
            + 1.5 * self.rough(xy) * smoothstep(3.0, 10.0, beyond)
        )
        h = base + verge + np.where(wall, wall_h, drop_h)
        return np.minimum(h, base + 75.0)

    def _lake_basin(self, s: np.ndarray, cte: np.ndarray, xy: np.ndarray, h: np.ndarray):
        """Lower the ground into a lake around the bridge (the deck spans it)."""
        bridge = self.bridge
        centre = self.track.point(bridge.middle_m)[:2]
        heading = float(self.track.heading_at(bridge.middle_m))
        along_dir = np.array([math.cos(heading), math.sin(heading)])
        delta = xy - centre
        along = np.abs(delta @ along_dir)
        across = np.abs(delta @ np.array([-along_dir[1], along_dir[0]]))
        half = 0.5 * bridge.length_m
        weight = (1.0 - smoothstep(half - 16.0, half - 1.0, along)) * (
            1.0 - smoothstep(60.0, 110.0, across + 0.15 * self.hills(xy) * 40.0)
        )
        return h * (1 - weight) + (self.water_level - 3.0) * weight

    # ------------------------------------------------------------ road, kerbs, bridge
    def build_road(self) -> None:
        track = self.track
        s = np.append(self.road_stations(), self.length)  # close the loop; v continues
        centre = track.point(s)
        normal = _right_normal(track, s)
        half = 0.5 * track.width_at(s)
        across = ROAD_ACROSS[None, :] * half[:, None]  # (n, k)
        xy = centre[:, None, :2] + normal[:, None, :] * across[..., None]
        z = np.repeat(centre[:, 2:3], len(ROAD_ACROSS), axis=1)
        positions = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
        u = (ROAD_ACROSS + 1.0) / 2.0
        v = s / ROAD_TEXTURE_REPEAT_M
        uv = np.stack(np.broadcast_arrays(u[None, :], v[:, None]), -1).reshape(-1, 2)
        heading = track.heading_at(s)
        tangent = np.column_stack([np.cos(heading), np.sin(heading)])
        normals = np.column_stack([-track.grade(s)[:, None] * tangent, np.ones((len(s), 1))])
        normals = np.repeat(normals / np.linalg.norm(normals, axis=1, keepdims=True), len(u), 0)
        triangles = grid_triangles(len(s), len(u))
        # grid rows run forward and columns run right: counter-clockwise seen from above
        self.mesh("road").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles)
        self.counts["road_triangles"] = len(triangles)
        self.build_road_shadows()
        if self.style.kerbs:
            self.build_kerbs()
        if self.bridge is not None:
            self.build_bridge()

    def _strip(self, s: np.ndarray, offsets: np.ndarray, heights: np.ndarray):
        """Positions (n, k, 3) of a strip at stations ``s`` and lateral ``offsets`` (k,) from the
        road edge on the right (positive) or the left (negative offsets mirrored by caller)."""
        track = self.track
        centre = track.point(s)
        normal = _right_normal(track, s)
        xy = centre[:, None, :2] + normal[:, None, :] * offsets[..., None]
        z = centre[:, 2:3] + heights
        return np.concatenate([xy, np.broadcast_to(z, offsets.shape)[..., None]], axis=-1)

    def build_road_shadows(self) -> None:
        """Shadow patches on the road: lumpy polygons of shaded asphalt just above the road
        (same texture and mapping, lit by ambient light only), so their edges are crisp."""
        track = self.track
        mesh = self.mesh("road")
        angles = np.linspace(0.0, 2 * math.pi, 14, endpoint=False)
        # angles turn from forward to right (clockwise seen from above): reverse the fan
        fan = np.stack([np.zeros(14, int), 1 + (np.arange(14) + 1) % 14, 1 + np.arange(14)], 1)
        count = 0
        for x, y, radius, darkness in self.shadow_blobs:
            proj = track.project(np.array([[x, y]]))
            s0, l0, half = float(proj.s_m[0]), float(proj.cte_m[0]), float(proj.half_width_m[0])
            if abs(l0) > half + 0.5 * radius:
                continue
            r = radius * (1.0 + 0.25 * np.sin(3 * angles + x) + 0.15 * np.sin(5 * angles + y))
            s = np.concatenate([[s0], s0 + r * np.cos(angles)])
            lateral = np.clip(np.concatenate([[l0], l0 + r * np.sin(angles)]),
                              -half + 0.02, half - 0.02)
            positions = track.offset_point(s, lateral)
            positions[:, 2] = track.point(s)[:, 2] + 0.012
            width = 2.0 * half
            uv = np.column_stack([(lateral + half) / width, s / ROAD_TEXTURE_REPEAT_M])
            sunlit = np.full(len(s), 1.0 - darkness)
            mesh.add(positions, (0.0, 0.0, 1.0), uv, (255.0, 255.0, 255.0), fan, sunlit=sunlit)
            count += 1
        self.counts["road_shadows"] = count

    def build_kerbs(self) -> None:
        sharp = np.abs(self.curvature) > KERB_CURVATURE
        sharp = _dilate(sharp, int(round(5.0 / ROAD_STEP_M)))
        if self.bridge is not None:
            sharp &= ~self.bridge.contains(self.stations, self.length)
        runs = _runs(sharp)
        mesh = self.mesh("kerb")
        for first, count in runs:
            idx = (first + np.arange(count + 1)) % len(self.stations)
            s = self.stations[idx] + self.length * ((first + np.arange(count + 1)) >= len(
                self.stations))
            half = 0.5 * self.track.width_at(s)
            for side in (-1.0, 1.0):
                offsets = side * (half[:, None] + np.array([0.0, 0.15, KERB_WIDTH_M])[None, :])
                heights = np.array([0.01, KERB_HEIGHT_M, KERB_HEIGHT_M])[None, :]
                positions = self._strip(s, offsets, heights).reshape(-1, 3)
                u = np.array([0.0, 0.25, 1.0])
                uv = np.stack(np.broadcast_arrays(u[None, :], (s / 2.0)[:, None]), -1)
                triangles = grid_triangles(len(s), 3)
                if side < 0:  # columns run leftwards: flip to face up
                    triangles = triangles[:, ::-1]
                mesh.add(positions, (0.0, 0.0, 1.0), uv.reshape(-1, 2), (255.0, 255.0, 255.0),
                         triangles, sunlit=self.sunlit(positions[:, :2]))
        self.counts["kerb_runs"] = len(runs)

    def build_bridge(self) -> None:
        bridge = self.bridge
        s = np.linspace(bridge.start_m, bridge.end_m, max(2, int(bridge.length_m / 3.0)) + 1)
        half = 0.5 * self.track.width_at(s)
        stone = self.mesh("rock")
        parapet_rgb = (150.0, 138.0, 128.0)
        for side in (-1.0, 1.0):
            # parapet: inner face, top, outer face, fascia below the deck
            offsets = side * (half[:, None] + np.array([0.0, 0.0, 0.35, 0.35, 0.35])[None, :])
            heights = np.array([0.0, 0.65, 0.65, 0.65, -1.3])[None, :]
            positions = self._strip(s, offsets, heights)
            rows, cols = positions.shape[:2]
            uv = np.stack(
                np.broadcast_arrays(np.array([0.0, 0.25, 0.3, 0.55, 0.9])[None, :],
                                    (s / 3.0)[:, None]), -1)
            triangles = grid_triangles(rows, cols)
            if side < 0:  # mirrored: flip so faces point out
                triangles = triangles[:, ::-1]
            flat = positions.reshape(-1, 3)
            normals = vertex_normals(flat, triangles)
            stone.add(flat, normals, uv.reshape(-1, 2), parapet_rgb, triangles)
        # piers down into the water every 18 m
        pier_s = np.arange(bridge.start_m + 9.0, bridge.end_m - 4.0, 18.0)
        for side in (-1.0, 1.0):
            base = self.track.offset_point(pier_s, side * (0.5 * self.track.width_at(pier_s) - 1))
            base[:, 2] = self.water_level - 3.0
            heading = self.track.heading_at(pier_s)
            height = float(self.track.point(bridge.middle_m)[2] - base[0, 2])
            positions, normals, uv, triangles = box(base, heading, (1.6, 1.6, height))
            stone.add(positions, normals, uv * (1.0, 3.0), parapet_rgb, triangles)

    # ------------------------------------------------------------ terrain
    def terrain_points(self) -> np.ndarray:
        track = self.track
        points = []
        for offset, spacing in zip(RING_OFFSETS_M, RING_SPACING_M, strict=True):
            if not self.full and offset > 15.0:
                break
            count = max(8, int(round(self.length / spacing)))
            s = (np.arange(count) + (0.5 if offset in (2.5, 9.0, 24.0) else 0.0)) * (
                self.length / count)
            half = 0.5 * track.width_at(s)
            for side in (-1.0, 1.0):
                xy = track.offset_point(s, side * (half + offset))[:, :2]
                proj = track.project(xy)
                along = np.abs(proj.s_m - s)
                along = np.minimum(along, self.length - along)
                own = along < max(3.0, 0.8 * abs(offset) + 2.0)
                points.append(xy[own])
        ring = np.concatenate(points)
        if not self.full:
            return ring
        low = ring.min(axis=0) - SCENERY_RADIUS_M
        high = ring.max(axis=0) + SCENERY_RADIUS_M
        gx = np.arange(low[0], high[0], GRID_SPACING_M)
        gy = np.arange(low[1], high[1], GRID_SPACING_M)
        grid = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
        rng = _track_rng(track, "grid")
        grid += rng.uniform(-0.3, 0.3, grid.shape) * GRID_SPACING_M
        distance, _ = cKDTree(track.xyz[:, :2]).query(grid)
        half_max = 0.5 * float(track.width.max())
        keep = (distance > half_max + RING_OFFSETS_M[-1] + 8.0) & (
            distance < SCENERY_RADIUS_M + 20.0
        )
        return np.concatenate([ring, grid[keep]])

    def build_terrain(self) -> None:
        track = self.track
        xy = self.terrain_points()
        proj = track.project(xy)
        z = self.height(proj.s_m, proj.cte_m, xy)
        triangles = Delaunay(xy).simplices
        # drop triangles wholly under a road, and long thin hull triangles
        centroid = xy[triangles].mean(axis=1)
        cproj = track.project(centroid)
        under = np.abs(cproj.cte_m) < cproj.half_width_m - 0.8
        edge = np.max(
            np.linalg.norm(xy[triangles] - xy[np.roll(triangles, 1, axis=1)], axis=2), axis=1
        )
        triangles = triangles[~under & (edge < 4.5 * GRID_SPACING_M)]
        positions = np.column_stack([xy, z])
        # counter-clockwise seen from above
        a, b, c = (positions[triangles[:, i]] for i in range(3))
        up = np.cross(b - a, c - a)[:, 2]
        triangles = np.where((up < 0)[:, None], triangles[:, ::-1], triangles)
        normals = vertex_normals(positions, triangles)
        beyond = np.abs(proj.cte_m) - proj.half_width_m
        albedo = self.ground_colours(positions, proj.s_m, proj.cte_m, beyond, normals)
        sunlit = self.sunlit(xy)
        face_normal = np.cross(b - a, c - a)
        face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-12)
        steep = np.degrees(np.arccos(np.abs(face_normal[:, 2]))) > ROCK_SLOPE_DEG
        steep = np.where((up < 0), steep, steep)  # orientation does not change steepness
        ground_uv = xy / 6.0
        rock_uv = np.column_stack([(xy[:, 0] + xy[:, 1]) / 9.0, z / 7.0])
        rock_albedo = np.asarray(self.style.rock_rgb) * (
            1.0 + 0.12 * self.patches(xy)
        )[:, None]
        for material, tris, uv, colours in (
            ("ground", triangles[~steep], ground_uv, albedo),
            ("rock", triangles[steep], rock_uv, rock_albedo),
        ):
            if len(tris) == 0:
                continue
            used, local = np.unique(tris, return_inverse=True)
            self.mesh(material).add(
                positions[used], normals[used], uv[used], colours[used],
                local.reshape(-1, 3), sunlit=sunlit[used], haze_m=np.clip(beyond[used], 0, None)
            )
        self.counts["terrain_triangles"] = len(triangles)
        self.terrain = (positions, triangles, normals, proj, beyond)

    def ground_colours(self, positions, s, cte, beyond, normals) -> np.ndarray:
        style = self.style
        xy = positions[:, :2]
        mix = smoothstep(-0.4, 0.6, self.patches(xy))[:, None]
        grass = (1 - mix) * np.asarray(style.grass_rgb) + mix * np.asarray(style.grass_alt_rgb)
        grass *= (1.0 + 0.08 * self.rough(xy * 3.0))[:, None]
        verge_width = 1.4 if self.theme == "lake" else 2.6
        verge = 1.0 - smoothstep(verge_width - 0.4, verge_width + 0.6, beyond)
        # dirt run-off on the outside of sharp curves (lake) / gravel by the walls (mountain)
        curvature = self.track.curvature(s)
        outside = np.sign(cte) == -np.sign(curvature)
        runoff = (np.abs(curvature) > KERB_CURVATURE * 1.2) & outside
        runoff_w = np.where(runoff, 1.0 - smoothstep(5.0, 9.0, beyond), 0.0)
        colour = grass * (1 - verge)[:, None] + np.asarray(style.verge_rgb) * verge[:, None]
        colour = colour * (1 - runoff_w)[:, None] + np.asarray(style.dirt_rgb) * runoff_w[:, None]
        if self.water_level is not None:
            shore = 1.0 - smoothstep(0.3, 1.6, positions[:, 2] - self.water_level)
            colour = colour * (1 - shore)[:, None] + np.array([200.0, 186.0, 140.0]) * shore[
                :, None]
        return colour

    # ------------------------------------------------------------ water
    def build_water(self) -> None:
        """Water squares (16 m) wherever the ground dips below the water level, and around."""
        if self.water_level is None:
            return
        positions, triangles, _, _, _ = self.terrain
        size = 16.0
        # every triangle's lowest corner marks the squares its bounding box touches
        corners = positions[triangles]
        low_z = corners[:, :, 2].min(axis=1)
        wet = low_z < self.water_level + 0.05
        squares = set()
        for tri in corners[wet]:
            lo = np.floor(tri[:, :2].min(axis=0) / size).astype(int)
            hi = np.floor(tri[:, :2].max(axis=0) / size).astype(int)
            for ix in range(lo[0], hi[0] + 1):
                for iy in range(lo[1], hi[1] + 1):
                    squares.add((ix, iy))
        if not squares:
            return
        keys = np.array(sorted(squares), dtype=float)
        corner = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], dtype=float)
        xy = ((keys[:, None, :] + corner[None]) * size).reshape(-1, 2)
        flat = np.column_stack([xy, np.full(len(xy), self.water_level)])
        quad = np.array([[0, 1, 2], [0, 2, 3]])
        tris = (quad[None] + 4 * np.arange(len(keys))[:, None, None]).reshape(-1, 3)
        proj = self.track.project(xy)
        haze = np.clip(np.abs(proj.cte_m) - proj.half_width_m, 0.0, None)
        self.mesh("water").add(flat, (0.0, 0.0, 1.0), xy / 9.0, (255.0, 255.0, 255.0), tris,
                               haze_m=haze)
        self.counts["water_squares"] = len(keys)

    # ------------------------------------------------------------ objects
    def ground_height(self, xy: np.ndarray) -> np.ndarray:
        proj = self.track.project(xy)
        return self.height(proj.s_m, proj.cte_m, xy)

    def build_trees(self) -> None:
        style = self.style
        rng = _track_rng(self.track, "trees")
        positions, triangles, normals, proj, beyond = self.terrain
        spacing = 8.0
        low = positions[:, :2].min(axis=0)
        high = positions[:, :2].max(axis=0)
        gx = np.arange(low[0], high[0], spacing)
        gy = np.arange(low[1], high[1], spacing)
        sites = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
        sites = sites + rng.uniform(-0.45, 0.45, sites.shape) * spacing
        site_proj = self.track.project(sites)
        edge = np.abs(site_proj.cte_m) - site_proj.half_width_m
        keep = (edge > 5.0) & (edge < 130.0) & (rng.random(len(sites)) < style.tree_keep)
        # thin out far away (they are small there) and keep clumps: a patch field
        keep &= self.patches(sites * 1.7) > -0.3
        sites, edge = sites[keep], edge[keep]
        z = self.height(site_proj.s_m[keep], site_proj.cte_m[keep], sites)
        # not in water, not on cliffs (steepness from the terrain normal at the nearest vertex)
        _, nearest = cKDTree(positions[:, :2]).query(sites)
        flat_enough = normals[nearest, 2] > math.cos(math.radians(ROCK_SLOPE_DEG))
        dry = np.ones(len(sites), bool)
        if self.water_level is not None:
            dry = z > self.water_level + 0.4
        ok = flat_enough & dry
        sites, z, edge = sites[ok], z[ok], edge[ok]
        weights = np.asarray(style.tree_weights) / np.sum(style.tree_weights)
        kind_index = rng.choice(len(style.tree_kinds), size=len(sites), p=weights)
        kinds = np.array(style.tree_kinds)[kind_index]
        # bushes only near the road
        kinds = np.where((kinds == "bush") & (edge > 40.0), style.tree_kinds[0], kinds)
        heights = np.array([rng.uniform(*_TREE_HEIGHT_M[k]) for k in kinds])
        widths = heights * np.array([_TREE_ASPECT[k] for k in kinds]) * rng.uniform(
            0.85, 1.15, len(kinds))
        atlas_index = np.array([TREE_ATLAS_KINDS.index(k) for k in kinds])
        cell = 1.0 / len(TREE_ATLAS_KINDS)
        uv_rect = np.column_stack([
            atlas_index * cell + 0.01, np.full(len(kinds), 0.0),
            (atlas_index + 1) * cell - 0.01, np.full(len(kinds), 1.0),
        ])
        base = np.column_stack([sites, z - 0.3])
        angle = rng.uniform(0, math.pi, len(sites))
        positions_t, normals_t, uv, tris = crossed_quads(base, heights, widths, angle, uv_rect)
        tint = rng.uniform(0.8, 1.1, len(sites))
        albedo = np.repeat(np.outer(tint, (255.0, 255.0, 255.0)), 8, axis=0)
        self.mesh("tree").add(positions_t, normals_t, uv, albedo, tris,
                              haze_m=np.repeat(edge, 8))
        self.counts["trees"] = len(sites)
        # shadows of the trees right by the road fall on it: darker verge under them
        self.tree_sites = np.column_stack([sites, heights])

    def build_boulders(self) -> None:
        rng = _track_rng(self.track, "boulders")
        count = int(self.length / (90.0 if self.theme == "lake" else 60.0))
        s = rng.uniform(0, self.length, count)
        side = rng.choice([-1.0, 1.0], count)
        offset = side * (0.5 * self.track.width_at(s) + rng.uniform(4.0, 20.0, count))
        xy = self.track.offset_point(s, offset)[:, :2]
        if self.bridge is not None:
            keep = ~self.bridge.contains(s, self.length)
            xy, s = xy[keep], s[keep]
        z = self.ground_height(xy)
        if self.water_level is not None:
            keep = z > self.water_level + 0.3
            xy, z = xy[keep], z[keep]
        sizes = rng.uniform(1.2, 4.0, len(xy))
        proj = self.track.project(xy)
        distances = np.clip(np.abs(proj.cte_m) - proj.half_width_m, 0.0, None)
        mesh = self.mesh("rock")
        unit, unit_tris = _rock_shape()
        for (x, y), h, size, haze in zip(xy, z, sizes, distances, strict=True):
            scale = size * rng.uniform(0.7, 1.3, 3) * (1.0, 1.0, 0.6)
            positions = unit * scale + (x, y, h - 0.2 * size)
            normals = vertex_normals(positions, unit_tris)
            uv = np.column_stack([(positions[:, 0] + positions[:, 1]) / 4.0,
                                  positions[:, 2] / 4.0])
            mesh.add(positions, normals, uv, np.asarray(self.style.rock_rgb) * 0.9, unit_tris,
                     haze_m=haze)
        self.counts["boulders"] = len(xy)

    def build_barriers(self) -> None:
        if not self.style.barriers:
            return
        drop_side = -self.wall_side
        bends = _dilate(np.abs(self.curvature) > BARRIER_CURVATURE, int(round(12 / ROAD_STEP_M)))
        spacing = 1.8
        s = np.arange(0.0, self.length, spacing)
        on = bends[np.minimum((s / (self.length / len(self.stations))).astype(int),
                              len(self.stations) - 1)]
        s = s[on]
        half = 0.5 * self.track.width_at(s)
        base = self.track.offset_point(s, drop_side * (half + 0.9))
        heading = self.track.heading_at(s)
        positions, normals, uv, triangles = box(base, heading, (1.3, 0.45, 0.75))
        self.mesh("barrier").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles,
                                 sunlit=np.repeat(self.sunlit(base[:, :2]), 20))
        self.counts["barriers"] = len(s)

    def build_signs(self) -> None:
        sharp = np.abs(self.curvature) > CHEVRON_CURVATURE
        if self.bridge is not None:
            sharp &= ~self.bridge.contains(self.stations, self.length)
        stride = max(1, int(round(14.0 / ROAD_STEP_M)))
        idx = np.flatnonzero(sharp)
        idx = idx[(idx % stride) == 0]
        if len(idx) == 0:
            return
        s = self.stations[idx]
        turn = np.sign(self.curvature[idx])  # + = left turn: sign on the right side
        half = 0.5 * self.track.width_at(s)
        base = self.track.offset_point(s, turn * (half + 2.2))
        heading = self.track.heading_at(s)
        post_pos, post_n, post_uv, post_tris = box(base, heading, (0.08, 0.08, 1.2))
        self.mesh("plain").add(post_pos, post_n, post_uv, (90.0, 90.0, 90.0), post_tris)
        board_base = base + np.array([0.0, 0.0, 1.2])
        # the board faces oncoming traffic: its normal points back along -tangent
        positions, normals, uv, triangles = box(board_base, heading + math.pi / 2,
                                                (0.9, 0.05, 0.9))
        # the arrow points the way the road turns: mirror u for left turns
        flip = np.repeat(turn > 0, 20)
        uv = np.where(flip[:, None], np.column_stack([1 - uv[:, 0], uv[:, 1]]), uv)
        self.mesh("sign").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles)
        self.counts["signs"] = len(s)

    def build_lamp_posts(self) -> None:
        if not self.style.lamp_posts:
            return
        s = np.arange(10.0, self.length, 45.0)
        half = 0.5 * self.track.width_at(s)
        side = float(self.wall_side)
        base = self.track.offset_point(s, side * (half + 1.6))
        heading = self.track.heading_at(s)
        mesh = self.mesh("plain")
        grey = (120.0, 122.0, 128.0)
        positions, normals, uv, triangles = box(base, heading, (0.14, 0.14, 6.5))
        mesh.add(positions, normals, uv, grey, triangles)
        normal = _right_normal(self.track, s)
        arm_base = base.copy()
        arm_base[:, :2] -= side * normal * 0.9
        arm_base[:, 2] += 6.3
        positions, normals, uv, triangles = box(arm_base, heading + math.pi / 2, (1.9, 0.1, 0.1))
        mesh.add(positions, normals, uv, grey, triangles)
        lamp = arm_base.copy()
        lamp[:, :2] -= side * normal * 0.9
        lamp[:, 2] -= 0.15
        positions, normals, uv, triangles = box(lamp, heading, (0.5, 0.25, 0.15))
        mesh.add(positions, normals, uv, (235.0, 235.0, 225.0), triangles)
        self.counts["lamp_posts"] = len(s)

    def build(self) -> Scenery:
        self.build_road()
        self.build_terrain()
        if self.full:
            self.build_water()
            self.build_trees()
            self.build_boulders()
            self.build_barriers()
            self.build_signs()
            self.build_lamp_posts()
        positions = self.terrain[0]
        low = positions[:, :2].min(axis=0)
        high = positions[:, :2].max(axis=0)
        return Scenery(
            theme=self.theme,
            style=self.style,
            meshes=self.meshes,
            bridge=self.bridge,
            water_level_m=self.water_level,
            wall_side=self.wall_side,
            bounds_xy=(float(low[0]), float(low[1]), float(high[0]), float(high[1])),
            counts=self.counts,
        )


def _right_normal(track: Track, s_m: np.ndarray) -> np.ndarray:
    """Unit vectors (n, 2) pointing to the right of the driving direction at ``s_m``."""
    heading = track.heading_at(s_m)
    return np.column_stack([np.sin(heading), -np.cos(heading)])


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
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


def _rock_shape() -> tuple[np.ndarray, np.ndarray]:
    """A unit boulder: an octahedron with its upper faces split (12 faces), bottom open."""
    top = np.array([[0.0, 0.0, 1.0]])
    ring_up = np.array([[math.cos(a) * 0.7, math.sin(a) * 0.7, 0.55]
                        for a in np.linspace(0, 2 * math.pi, 6, endpoint=False) + 0.3])
    ring_low = np.array([[math.cos(a), math.sin(a), 0.0]
                         for a in np.linspace(0, 2 * math.pi, 6, endpoint=False)])
    positions = np.concatenate([top, ring_up, ring_low])
    triangles = []
    for i in range(6):
        j = (i + 1) % 6
        triangles.append([0, 1 + i, 1 + j])
        triangles.append([1 + i, 7 + i, 7 + j])
        triangles.append([1 + i, 7 + j, 1 + j])
    return positions, np.array(triangles)


def build_scenery(track: Track, *, full: bool = True, style: ThemeStyle | None = None) -> Scenery:
    """Derive the scenery of ``track`` from its geometry and theme.

    ``full=False`` gives the road, kerbs, bridge and a narrow ground strip only (fast to build;
    for tests that only need the road). ``style``: colours and switches other than the theme's
    (driving conditions, :mod:`clonedrive.sim.conditions`).
    """
    return _Builder(track, full, style).build()
