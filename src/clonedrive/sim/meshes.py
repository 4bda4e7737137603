"""Triangle meshes built with NumPy and turned into Panda3D Geoms, with baked light and haze.

The software renderer is fastest without per-vertex lighting and has no fog, so both are baked
into vertex colours::

    lit = albedo x (ambient x (s + (1 - s) x sunlit) + sun x max(0, n . l) x sunlit)
    colour = lit x (1 - f) + fog x f,   f = 1 - exp(-fog_density x haze_m)

``sunlit`` (0-1) is the share of direct sun a vertex gets (shadows), ``haze_m`` how far it is
from the road [m]: the camera is always on the road, so that distance is a lower bound of the
distance to the camera, and distant scenery fades into the fog colour (exponential fog by
distance from the road; the far road itself is left clear). A :class:`BakedGeom` keeps normals,
albedo and these attributes so its colours can be re-baked for a new look (domain randomisation)
without rebuilding the scene.

Shapes are in metres in whatever frame the caller uses; helpers here build boxes, crossed-quad
sprites and generic indexed triangle sets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: One vertex: position (3 x float32), colour (4 x uint8 RGBA), texture coordinate (2 x float32).
VERTEX_DTYPE = np.dtype(
    {"names": ["xyz", "rgba", "uv"], "formats": [("<f4", 3), ("u1", 4), ("<f4", 2)],
     "offsets": [0, 12, 16], "itemsize": 24}
)
_FIELDS = ("xyz", "normal", "uv", "albedo", "sunlit", "haze", "alpha", "triangles")


@dataclass(frozen=True)
class Lighting:
    """Light and fog baked into vertex colours; light colours are multipliers (1 = unchanged)."""

    sun_direction: tuple[float, float, float]  #: unit vector pointing TO the sun (world)
    sun_rgb: tuple[float, float, float]
    ambient_rgb: tuple[float, float, float]
    shadow_ambient: float = 0.85  #: ambient kept in shadow (occlusion of sky light)
    fog_rgb: tuple[float, float, float] = (180.0, 200.0, 220.0)  #: 0-255
    fog_density_per_m: float = 0.0


class Mesh:
    """Accumulates triangles with per-vertex positions, normals, uvs, albedo (0-255 RGB),
    sunlit (0-1), haze distance [m] and alpha (0-255)."""

    def __init__(self) -> None:
        self._parts: list[tuple[np.ndarray, ...]] = []
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def add(
        self,
        positions: np.ndarray,
        normals: np.ndarray,
        uvs: np.ndarray,
        albedo: np.ndarray,
        triangles: np.ndarray,
        *,
        sunlit: np.ndarray | float = 1.0,
        haze_m: np.ndarray | float = 0.0,
        alpha: np.ndarray | float = 255.0,
    ) -> None:
        """Add vertices (n, 3) with triangles (m, 3) indexing them (0-based, local to this call).

        ``albedo`` is (n, 3) or (3,); ``sunlit`` (n,) multiplies the direct sun (shadows);
        ``haze_m`` (n,) is the distance from the road that sets how much fog the vertex gets.
        """
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        count = len(positions)
        if count == 0:
            return

        def per_vertex(value, width=None):
            shape = (count,) if width is None else (count, width)
            return np.broadcast_to(np.asarray(value, dtype=float), shape)

        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3) + self._count
        self._parts.append((
            positions, per_vertex(normals, 3), per_vertex(uvs, 2), per_vertex(albedo, 3),
            per_vertex(sunlit), per_vertex(haze_m), per_vertex(alpha), triangles,
        ))
        self._count += count

    def arrays(self) -> dict[str, np.ndarray]:
        """All parts concatenated: xyz, normal, uv, albedo, sunlit, haze, alpha, triangles."""
        if not self._parts:
            widths = {"xyz": 3, "normal": 3, "uv": 2, "albedo": 3, "triangles": 3}
            return {
                name: np.zeros((0, widths[name]) if name in widths else (0,),
                               dtype=np.int64 if name == "triangles" else float)
                for name in _FIELDS
            }
        return {
            name: np.concatenate([part[i] for part in self._parts])
            for i, name in enumerate(_FIELDS)
        }


def bake_colours(
    normals: np.ndarray,
    albedo: np.ndarray,
    sunlit: np.ndarray,
    haze_m: np.ndarray,
    lighting: Lighting | None,
) -> np.ndarray:
    """Lit and fogged RGB (n, 3) in 0-255; ``lighting=None`` returns the albedo unchanged."""
    if lighting is None:
        return albedo
    sun = np.asarray(lighting.sun_direction, dtype=float)
    sun = sun / np.linalg.norm(sun)
    lambert = np.clip(normals @ sun, 0.0, None) * sunlit
    ambient = np.asarray(lighting.ambient_rgb)[None, :] * (
        lighting.shadow_ambient + (1 - lighting.shadow_ambient) * sunlit[:, None]
    )
    lit = albedo * (ambient + lambert[:, None] * np.asarray(lighting.sun_rgb)[None, :])
    if lighting.fog_density_per_m <= 0:
        return lit
    fog = 1.0 - np.exp(-lighting.fog_density_per_m * np.clip(haze_m, 0.0, None))[:, None]
    return lit * (1.0 - fog) + np.asarray(lighting.fog_rgb)[None, :] * fog


class BakedGeom:
    """A Panda3D ``Geom`` whose vertex colours can be re-baked for new lighting."""

    def __init__(self, mesh: Mesh, lighting: Lighting | None, name: str = "mesh"):
        from panda3d.core import Geom, GeomTriangles, GeomVertexData, GeomVertexFormat

        data = mesh.arrays()
        self._normals = data["normal"]
        self._albedo = data["albedo"]
        self._sunlit = data["sunlit"]
        self._haze = data["haze"]
        self._alpha = data["alpha"]
        count = len(data["xyz"])
        vertex_data = GeomVertexData(name, GeomVertexFormat.get_v3c4t2(), Geom.UH_static)
        vertex_data.unclean_set_num_rows(count)
        view = np.frombuffer(memoryview(vertex_data.modify_array(0)), dtype=VERTEX_DTYPE)
        view["xyz"] = data["xyz"]
        view["uv"] = data["uv"]
        self.vertex_data = vertex_data
        self.bake(lighting)
        triangles = data["triangles"]
        primitive = GeomTriangles(Geom.UH_static)
        index_type = np.uint16 if count < 65535 else np.uint32
        primitive.set_index_type(Geom.NT_uint16 if index_type is np.uint16 else Geom.NT_uint32)
        handle = primitive.modify_vertices()
        handle.unclean_set_num_rows(triangles.size)
        indices = np.frombuffer(memoryview(handle), dtype=index_type)
        indices[:] = triangles.reshape(-1)
        self.geom = Geom(vertex_data)
        self.geom.add_primitive(primitive)
        self.triangle_count = len(triangles)

    def bake(self, lighting: Lighting | None) -> None:
        rgb = bake_colours(self._normals, self._albedo, self._sunlit, self._haze, lighting)
        view = np.frombuffer(memoryview(self.vertex_data.modify_array(0)), dtype=VERTEX_DTYPE)
        view["rgba"][:, :3] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
        view["rgba"][:, 3] = np.clip(np.rint(self._alpha), 0, 255).astype(np.uint8)


# ---------------------------------------------------------------------- shapes
def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """Triangles of a (rows x cols) vertex grid stored row-major; two per cell, CCW seen from
    the side where row index increases 'forward' and column index increases 'right'... i.e.
    with rows along +v and columns along +u the front face is the one whose normal is u x v."""
    r, c = np.mgrid[0 : rows - 1, 0 : cols - 1]
    a = (r * cols + c).ravel()
    b = a + 1
    d = a + cols
    e = d + 1
    return np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)])


def box(
    centre: np.ndarray,
    heading_rad: np.ndarray,
    size: tuple[float, float, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Boxes at ``centre`` (k, 3) (bottom centre), rotated by ``heading_rad`` (k,) about z.

    ``size`` = (length along the heading, width, height) [m]. Returns positions (k*20, 3),
    normals, uvs (u along the length/around, v up) and triangles (k*10, 3): four sides and a
    top, no bottom.
    """
    centre = np.asarray(centre, dtype=float).reshape(-1, 3)
    heading = np.broadcast_to(np.asarray(heading_rad, dtype=float), (len(centre),))
    length, width, height = size
    hl, hw = length / 2, width / 2
    # local faces: (4 corners as (along, across, up)), normal
    faces = [
        ([(-hl, -hw, 0), (hl, -hw, 0), (hl, -hw, height), (-hl, -hw, height)], (0, -1, 0)),
        ([(hl, hw, 0), (-hl, hw, 0), (-hl, hw, height), (hl, hw, height)], (0, 1, 0)),
        ([(hl, -hw, 0), (hl, hw, 0), (hl, hw, height), (hl, -hw, height)], (1, 0, 0)),
        ([(-hl, hw, 0), (-hl, -hw, 0), (-hl, -hw, height), (-hl, hw, height)], (-1, 0, 0)),
        ([(-hl, -hw, height), (hl, -hw, height), (hl, hw, height), (-hl, hw, height)], (0, 0, 1)),
    ]
    corners = np.array([f[0] for f in faces], dtype=float).reshape(-1, 3)  # (20, 3)
    normals = np.repeat(np.array([f[1] for f in faces], dtype=float), 4, axis=0)
    uv_face = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], dtype=float)
    uvs = np.tile(uv_face, (5, 1))
    tri_face = np.array([[0, 1, 2], [0, 2, 3]])
    tris = np.concatenate([tri_face + 4 * i for i in range(5)])
    # local (along, across, up) -> world: along = heading direction, across = its left
    cos, sin = np.cos(heading)[:, None], np.sin(heading)[:, None]

    def rotate(local: np.ndarray) -> np.ndarray:
        x = cos * local[None, :, 0] - sin * local[None, :, 1]
        y = sin * local[None, :, 0] + cos * local[None, :, 1]
        return np.stack([x, y, np.broadcast_to(local[None, :, 2], x.shape)], axis=-1)

    positions = rotate(corners) + centre[:, None, :]
    world_normals = rotate(normals)
    count = len(centre)
    triangles = (tris[None, :, :] + 20 * np.arange(count)[:, None, None]).reshape(-1, 3)
    return (
        positions.reshape(-1, 3),
        world_normals.reshape(-1, 3),
        np.tile(uvs, (count, 1)),
        triangles,
    )


def crossed_quads(
    base: np.ndarray,
    height_m: np.ndarray,
    width_m: np.ndarray,
    angle_rad: np.ndarray,
    uv_rect: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sprites as two vertical quads crossed at right angles (a cheap tree).

    Draw them without back-face culling. ``base`` (k, 3) bottom centre; ``uv_rect`` (k, 4) =
    (u0, v0, u1, v1) of the sprite in its atlas. Returns positions (k*8, 3), normals (pointing
    up: foliage is lit like the ground), uvs and triangles (k*4, 3).
    """
    base = np.asarray(base, dtype=float).reshape(-1, 3)
    count = len(base)
    height = np.broadcast_to(np.asarray(height_m, dtype=float), (count,))[:, None]
    half = np.broadcast_to(np.asarray(width_m, dtype=float), (count,))[:, None] / 2
    zeros = np.zeros_like(half)
    positions, uvs = [], []
    face_uv = np.stack(
        [uv_rect[:, [0, 1]], uv_rect[:, [2, 1]], uv_rect[:, [2, 3]], uv_rect[:, [0, 3]]], 1
    )
    for quad in range(2):
        angle = np.asarray(angle_rad, dtype=float)[:, None] + quad * np.pi / 2
        step = np.concatenate([np.cos(angle) * half, np.sin(angle) * half, zeros], axis=1)
        up = np.concatenate([zeros, zeros, height], axis=1)
        positions.append(np.stack([base - step, base + step, base + step + up, base - step + up],
                                  axis=1))
        uvs.append(face_uv)
    positions = np.stack(positions, axis=1).reshape(-1, 3)
    uvs = np.stack(uvs, axis=1).reshape(-1, 2)
    normals = np.tile(np.array([0.0, 0.0, 1.0]), (len(positions), 1))
    per_sprite = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    triangles = (per_sprite[None] + 8 * np.arange(count)[:, None, None]).reshape(-1, 3)
    return positions, normals, uvs, triangles


def vertex_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (n, 3) of a triangle mesh (z-up fallback where degenerate)."""
    a, b, c = (positions[triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)
    normals = np.zeros_like(positions)
    for i in range(3):
        np.add.at(normals, triangles[:, i], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    fallback = np.array([0.0, 0.0, 1.0])
    return np.where(length > 1e-12, normals / np.maximum(length, 1e-12), fallback)
