"""The Panda3D scene of a track: road, scenery, sky, fog and the car, and the engine that draws it.

Each scene owns a :class:`~clonedrive.sim.engine.RenderEngine` (:mod:`clonedrive.sim.engine`):
one Panda3D ``GraphicsEngine`` and its pipe, headless, with the software renderer
(``p3tinydisplay``) or OpenGL through EGL (``renderer``).

:class:`Scene` builds the scene graph of a :class:`~clonedrive.world.track.Track` from
:mod:`clonedrive.sim.scenery` (geometry derived from the track and its theme) and
:mod:`clonedrive.sim.textures` (procedural textures), and owns its engine. Cameras are attached
with :class:`clonedrive.sim.cameras.CameraRig`.

How it stays fast in a software renderer:

- lighting is baked into vertex colours (no per-vertex lighting at draw time);
- static geometry is merged per 96 m cell (one node per cell, one Geom per material), under
  384 m blocks, so view-frustum culling drops what is behind or beyond the far plane; trees
  and small objects are not drawn beyond :data:`LOD_DISTANCE_M`;
- the software renderer has no fog: exponential fog by distance from the road is baked into
  vertex colours with the lighting (the camera is always on the road); the sky is an opaque
  vertex-coloured cylinder at ~0.93 :data:`FAR_M` that also hides the far plane;
- textures are small, nearest-neighbour sampled with mipmaps (the software renderer ignores
  bilinear filtering: the output is identical).

Frames are the same for the same pose in every scene of a track: the opaque geometry is drawn in
scene-graph order (:data:`DRAW_BIN`, unsorted), not in Panda3D's default state-sorted order. That
order follows the addresses of render states in memory, and where two surfaces lie in one plane
(a kerb on the road) it decides which one shows: a second scene of the same track in the same
process drew a few pixels of its first frame differently, and so drove differently.

``benchmarks/render.py`` measures how fast scenes render.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from clonedrive.sim import textures
from clonedrive.sim.conditions import Conditions
from clonedrive.sim.engine import DEFAULT_RENDERER, RenderEngine
from clonedrive.sim.meshes import BakedGeom, Mesh, grid_triangles
from clonedrive.sim.randomization import (
    Appearance,
    RandomizationConfig,
    default_appearance,
    sample_appearance,
)
from clonedrive.sim.reuse import reused, track_key
from clonedrive.sim.scenery import TREE_ATLAS_KINDS, Scenery, build_scenery
from clonedrive.world.catalog import load_track
from clonedrive.world.track import Track

#: Camera clipping planes [m]. Nothing beyond FAR_M is drawn; the sky cylinder is just inside.
NEAR_M = 0.2
FAR_M = 220.0
#: Static geometry cell and block sizes [m] (culling granularity).
CELL_M = 96.0
BLOCK_CELLS = 4
#: Materials drawn only within this distance [m] of the camera (per cell).
LOD_DISTANCE_M = {"tree": 150.0, "barrier": 110.0, "sign": 110.0, "plain": 110.0}
#: The sky cylinder's radius (fraction of FAR_M).
HORIZON_WALL = 0.93

#: How far below the horizon the sky cylinder reaches [deg]: deep valleys in the mountains.
_SKY_DEPRESSION_DEG = {"lake": 4.0, "mountain": 10.0}
#: The cull bin of the scene's opaque geometry: drawn in scene-graph order (see the module),
#: where Panda3D's "opaque" bin draws in state order; it has the opaque bin's place (sort 20).
DRAW_BIN = "clonedrive-opaque"
#: Sort order inside Panda3D's "fixed" bin (drawn after the opaque bin, in this order).
_BIN_WATER = 0
_BIN_SKY = 10
_BIN_HOOD = 50

def _draw_bin() -> str:
    """:data:`DRAW_BIN`, added to Panda3D's bins the first time a scene needs it."""
    from panda3d.core import CullBinManager

    bins = CullBinManager.get_global_ptr()
    if bins.find_bin(DRAW_BIN) < 0:
        bins.add_bin(DRAW_BIN, CullBinManager.BT_unsorted, bins.get_bin_sort(
            bins.find_bin("opaque")))
    return DRAW_BIN


@dataclass
class _Materials:
    states: dict = field(default_factory=dict)
    textures: dict = field(default_factory=dict)


_HOOD_RGB = {"lake": (150.0, 146.0, 126.0), "mountain": (168.0, 170.0, 176.0)}


class Scene:
    """A track's Panda3D scene graph and the engine that renders it.

    Parameters: ``track`` (a Track or a name for :func:`load_track`), ``scenery`` (False: road,
    kerbs and a narrow verge only, quick to build), ``randomization`` (None: the theme's fixed
    look; a :class:`RandomizationConfig`: a look drawn from ``seed``), ``seed`` (also seeds pixel
    noise), ``window`` (use the OpenGL pipe; see :class:`RenderEngine`), ``renderer``
    (``"software"``, ``"egl"`` or ``"auto"``: :mod:`clonedrive.sim.engine`), ``conditions`` (a
    :class:`~clonedrive.sim.conditions.Conditions`: road and line colours, wear, shadows,
    vegetation, sun, fog and the camera's sensor; it replaces ``randomization``).

    Attributes: ``root`` (the scene's top NodePath), ``car`` (the car's node: cameras and the
    hood hang from it), ``appearance``, ``scenery``, ``engine``.
    """

    def __init__(
        self,
        track: Track | str,
        *,
        scenery: bool = True,
        randomization: RandomizationConfig | None = None,
        seed: int = 0,
        window: bool = False,
        conditions: Conditions | None = None,
        renderer: str = DEFAULT_RENDERER,
    ):
        from panda3d.core import NodePath

        self.track = load_track(track) if isinstance(track, str) else track
        self.theme = self.track.theme
        self.randomization = randomization
        self.conditions = conditions
        self.engine = RenderEngine(window=window, renderer=renderer)
        self.closed = False
        self._rigs: list = []
        self._baked: list[BakedGeom] = []
        try:
            self.root = NodePath("scene")
            self.root.set_bin(_draw_bin(), 0)  # geometry in a fixed bin (sky, hood) keeps it
            self.static = self.root.attach_new_node("static")
            self.follow = self.root.attach_new_node("follow-car")  # sky and fog: position only
            self.car = self.root.attach_new_node("car")
            style = conditions.style(self.theme) if conditions is not None else None
            self._scenery_key = ("scenery", track_key(self.track), bool(scenery), style)
            self.scenery: Scenery = reused(
                self._scenery_key, lambda: build_scenery(self.track, full=scenery, style=style))
            self._materials = self._make_materials()
            self._build_static()
            self._build_hood()
            self._atmosphere = None
            self.appearance = default_appearance(self.theme)
            self.randomize(seed)
        except BaseException:
            self.engine.close()
            raise

    # ------------------------------------------------------------------ appearance
    def randomize(self, seed: int) -> Appearance:
        """Draw a new look from ``seed`` (if randomisation is on) and re-seed pixel noise."""
        self.seed = int(seed)
        rng = np.random.default_rng([self.seed, 0x5CE7E])
        if self.conditions is not None:
            appearance = self.conditions.appearance(self.theme)
        elif self.randomization is not None:
            appearance = sample_appearance(self.theme, self.randomization, rng)
        else:
            appearance = default_appearance(self.theme)
        self.noise_rng = np.random.default_rng([self.seed, 0x401CE])
        self.apply_appearance(appearance)
        return appearance

    def apply_appearance(self, appearance: Appearance) -> None:
        """Re-bake lighting and fog into the vertex colours and rebuild the sky."""
        self.appearance = appearance
        for baked in self._baked:
            baked.bake(appearance.lighting)
        self._build_atmosphere(appearance)
        tint = appearance.tint_rgb
        if tint != (1.0, 1.0, 1.0):
            self.root.set_color_scale(tint[0], tint[1], tint[2], 1.0)
        else:
            self.root.clear_color_scale()
        for rig in self._rigs:
            rig.on_appearance_changed()

    @property
    def clear_rgb(self) -> tuple[float, float, float]:
        """Background colour (0-1): the sky's zenith colour (the horizon wall fades into it)."""
        return tuple(c / 255.0 for c in self.appearance.sky_zenith_rgb)

    @property
    def horizon_rgb(self) -> tuple[float, float, float]:
        """Fog colour (0-1)."""
        return tuple(c / 255.0 for c in self.appearance.sky_horizon_rgb)

    # ------------------------------------------------------------------ building
    def _make_materials(self) -> _Materials:
        from panda3d.core import (
            CullBinAttrib,
            CullFaceAttrib,
            RenderState,
            TextureAttrib,
            TransparencyAttrib,
        )

        style = self.scenery.style
        width = float(np.median(self.track.width))
        wear = self.conditions.road_wear if self.conditions else 0.0
        images = reused(("textures", self.theme, style, width, wear),
                        lambda: _texture_images(self.theme, style, width, wear))
        materials = _Materials()
        for name, image in images.items():
            texture = textures.to_panda_texture(image, name, mipmaps=name != "tree")
            materials.textures[name] = texture
            state = RenderState.make(TextureAttrib.make(texture))
            if name == "tree":
                state = state.add_attrib(TransparencyAttrib.make(TransparencyAttrib.M_binary))
                state = state.add_attrib(CullFaceAttrib.make(CullFaceAttrib.M_cull_none))
            if name == "water":
                state = state.add_attrib(CullBinAttrib.make("fixed", _BIN_WATER))
            materials.states[name] = state
        materials.states["plain"] = RenderState.make_empty()
        return materials

    def _build_static(self) -> None:
        """Merge static meshes per cell (one Geom per material) under blocks, for culling.

        Small things (trees, signs, posts, barriers) hang under a ``LODNode`` per cell and are
        not drawn beyond :data:`LOD_DISTANCE_M` (they are a pixel or two there, and in fog).
        """
        from panda3d.core import GeomNode, LODNode, Point3

        always: dict[tuple[int, int], list] = {}
        near_only: dict[tuple[int, int], list] = {}
        triangles = 0
        for material, mesh in self.scenery.meshes.items():
            state = self._materials.states[material]
            cells = reused((self._scenery_key, "cells", material),
                           lambda mesh=mesh: _split_by_cell(mesh, CELL_M))
            for cell, part in cells.items():
                baked = BakedGeom(part, None, name=material)
                self._baked.append(baked)
                triangles += baked.triangle_count
                if material in LOD_DISTANCE_M:
                    near_only.setdefault(cell, []).append((material, baked.geom, state, part))
                else:
                    always.setdefault(cell, []).append((baked.geom, state))
        blocks: dict[tuple[int, int], object] = {}
        for cell in sorted(set(always) | set(near_only)):
            block_key = (cell[0] // BLOCK_CELLS, cell[1] // BLOCK_CELLS)
            if block_key not in blocks:
                blocks[block_key] = self.static.attach_new_node(f"block{block_key}")
            parent = blocks[block_key].attach_new_node(f"cell{cell}")
            if cell in always:
                geom_node = GeomNode("ground")
                for geom, state in always[cell]:
                    geom_node.add_geom(geom, state)
                parent.attach_new_node(geom_node)
            groups: dict[float, list] = {}
            for material, geom, state, part in near_only.get(cell, []):
                groups.setdefault(LOD_DISTANCE_M[material], []).append((geom, state, part))
            for distance, members in groups.items():
                lod = LODNode(f"near-{distance:.0f}m")
                centre = np.concatenate([part.arrays()["xyz"] for _, _, part in members])
                lod.set_center(Point3(*centre.mean(axis=0)))
                lod.add_switch(distance, 0.0)
                geom_node = GeomNode(f"near-{distance:.0f}m")
                for geom, state, _ in members:
                    geom_node.add_geom(geom, state)
                parent.attach_new_node(lod).attach_new_node(geom_node)
        self.cell_count = len(set(always) | set(near_only))
        self.triangle_count = triangles

    def _build_hood(self) -> None:
        """The car's hood, drawn last over everything at the bottom of the frame.

        It is a curtain 1.6 m ahead of the cameras (car frame: x right, y forward, z up, origin
        on the road under the car's centre) whose top edge is shaped so that the centre camera
        sees the Udacity car's hood: top at row ~138 of 160 in the middle, reaching the bottom
        corners ~125 px either side. The side cameras see it shifted, as on the real car.
        """
        from panda3d.core import (
            CullBinAttrib,
            DepthTestAttrib,
            DepthWriteAttrib,
            GeomNode,
            RenderState,
        )

        mesh = Mesh()
        positions, albedo, triangles = _hood_geometry(np.asarray(_HOOD_RGB[self.theme]))
        mesh.add(positions, (0.0, -1.0, 0.0), (0.0, 0.0), albedo, triangles)
        self._hood = BakedGeom(mesh, None, name="hood")
        node = GeomNode("hood")
        state = RenderState.make(
            CullBinAttrib.make("fixed", _BIN_HOOD),
            DepthTestAttrib.make(DepthTestAttrib.M_none),
            DepthWriteAttrib.make(DepthWriteAttrib.M_off),
        )
        node.add_geom(self._hood.geom, state)
        self.hood = self.car.attach_new_node(node)
        self.hood.set_two_sided(True)

    def _build_atmosphere(self, appearance: Appearance) -> None:
        """The sky: an opaque vertical cylinder around the car (the "horizon wall", at
        ``HORIZON_WALL x FAR_M``), horizon-coloured up to 4 deg above the car, graded to the
        zenith colour at 34 deg; above it the background is cleared to the zenith colour. It
        also hides the far plane. Fog is baked into vertex colours (see meshes.py).
        """
        from panda3d.core import CullBinAttrib, GeomNode, RenderState

        if self._atmosphere is not None:
            self._atmosphere.remove_node()
        radius = HORIZON_WALL * FAR_M
        depression = _SKY_DEPRESSION_DEG[self.theme]
        heights = radius * np.tan(np.radians([-depression, 0.0, 4.0, 12.0, 22.0, 34.0]))
        blend = np.array([0.0, 0.0, 0.0, 0.45, 0.8, 1.0])[:, None]
        colours = (np.asarray(appearance.sky_horizon_rgb) * (1 - blend)
                   + np.asarray(appearance.sky_zenith_rgb) * blend)
        # The software rasteriser can leave hairline gaps between huge clipped triangles, so
        # the cylinder is built as separate columns that overlap their neighbours a little.
        segments, overlap = 48, 0.004
        azimuth = np.linspace(0, 2 * math.pi, segments + 1)
        mesh = Mesh()
        for a0, a1 in zip(azimuth[:-1], azimuth[1:], strict=True):
            column = np.array([a0 - overlap, a1 + overlap])
            h, az = np.meshgrid(heights, column, indexing="ij")
            positions = np.stack([radius * np.cos(az), radius * np.sin(az), h], -1)
            # rows go up, columns counter-clockwise: faces point out; flip to face in
            mesh.add(positions.reshape(-1, 3), (0.0, 0.0, 1.0), (0.0, 0.0),
                     np.repeat(colours, 2, axis=0),
                     grid_triangles(len(heights), 2)[:, ::-1])
        node = GeomNode("sky")
        node.add_geom(BakedGeom(mesh, None, name="sky").geom,
                      RenderState.make(CullBinAttrib.make("fixed", _BIN_SKY)))
        self._atmosphere = self.follow.attach_new_node(node)

    # ------------------------------------------------------------------ pose, lifetime
    def set_car_pose(
        self, x_m: float, y_m: float, z_m: float, yaw_rad: float, pitch_rad: float = 0.0,
        roll_rad: float = 0.0,
    ) -> None:
        """Place the car: position of the road surface under its centre [m], yaw [rad, CCW from
        +x], pitch [rad, + = nose up], roll [rad, + = right side down]."""
        self.car.set_pos_hpr(
            x_m, y_m, z_m, math.degrees(yaw_rad) - 90.0, math.degrees(pitch_rad),
            math.degrees(roll_rad),
        )
        self.follow.set_pos(x_m, y_m, z_m)

    def register_rig(self, rig) -> None:
        self._rigs.append(rig)

    def unregister_rig(self, rig) -> None:
        if rig in self._rigs:
            self._rigs.remove(rig)

    def close(self) -> None:
        """Release the engine, buffers and scene graph. Safe to call twice."""
        if self.closed:
            return
        for rig in list(self._rigs):
            rig.close()
        self.engine.close()
        self.root.remove_node()
        self._baked.clear()
        self._materials = _Materials()
        self.closed = True

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def _hood_geometry(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hood curtain vertices (car frame), colours and triangles; see ``Scene._build_hood``."""
    camera = np.array([0.0, 1.0, 1.2])  # the Udacity centre camera, car frame
    pitch = math.radians(9.4)
    tan_v = math.tan(math.radians(30.0))
    tan_h = 2.0 * tan_v  # 320 x 160
    ahead_m = 1.6
    dx = np.linspace(-1.0, 1.0, 17) * 240.0  # pixels from the centre column (320 wide)
    dy = 58.0 + 22.0 * np.clip((np.abs(dx) - 40.0) / 85.0, 0.0, None) ** 1.6  # rows below centre
    right = dx / 160.0 * tan_h
    up = -dy / 80.0 * tan_v
    direction = np.stack(
        [right, math.cos(pitch) + math.sin(pitch) * up, -math.sin(pitch) + math.cos(pitch) * up],
        axis=1,
    )
    edge = camera + direction * (ahead_m / direction[:, 1:2])
    # bands below the edge: light rim, shade, a dark crease, then the bright hood top
    drop = np.array([0.0, 0.1, 0.16, 0.18, 0.2, 0.6])
    shade = np.array([1.08, 1.0, 0.82, 0.42, 1.12, 1.18])
    positions = np.repeat(edge[None], len(drop), axis=0)
    positions[..., 2] -= drop[:, None]
    side = 1.0 - 0.25 * (np.abs(dx) / 240.0) ** 2
    albedo = rgb[None, None, :] * shade[:, None, None] * side[None, :, None]
    triangles = grid_triangles(len(drop), len(dx))
    return positions.reshape(-1, 3), albedo.reshape(-1, 3), triangles


def _texture_images(theme: str, style, road_width_m: float, wear: float
                    ) -> dict[str, np.ndarray]:
    """The texture images of a scene (RGB or RGBA uint8), drawn from the theme's own seed."""
    rng = np.random.default_rng(zlib.crc32(f"textures:{theme}".encode()))
    return {
        "road": textures.asphalt(rng, base_rgb=style.road_rgb, road_width_m=road_width_m,
                                 edge_rgb=style.edge_line_rgb, centre_line=style.centre_line,
                                 tyre_tracks=style.tyre_tracks, wear=wear),
        "ground": textures.ground_detail(rng),
        "rock": textures.rock(rng),
        "water": textures.water(rng),
        "kerb": textures.kerb(),
        "barrier": textures.barrier(),
        "sign": textures.chevron_sign(),
        "tree": textures.tree_atlas(rng, TREE_ATLAS_KINDS),
    }


def _split_by_cell(mesh: Mesh, cell_m: float) -> dict[tuple[int, int], Mesh]:
    """Split a world-space mesh into meshes per square cell (by triangle centroid)."""
    data = mesh.arrays()
    triangles = data["triangles"]
    if len(triangles) == 0:
        return {}
    centroid = data["xyz"][triangles].mean(axis=1)[:, :2]
    keys = np.floor(centroid / cell_m).astype(np.int64)
    order = np.lexsort((keys[:, 1], keys[:, 0]))
    keys, triangles = keys[order], triangles[order]
    change = np.flatnonzero(np.any(np.diff(keys, axis=0) != 0, axis=1)) + 1
    parts = {}
    for start, end in zip(np.r_[0, change], np.r_[change, len(keys)], strict=True):
        tris = triangles[start:end]
        used, local = np.unique(tris, return_inverse=True)
        part = Mesh()
        part.add(data["xyz"][used], data["normal"][used], data["uv"][used],
                 data["albedo"][used], local.reshape(-1, 3), sunlit=data["sunlit"][used],
                 haze_m=data["haze"][used], alpha=data["alpha"][used])
        parts[(int(keys[start, 0]), int(keys[start, 1]))] = part
    return parts
