"""The ground: one height field for the whole map (a theme profile of the distance from the
road edge plus smooth noise, a lake basin under the bridge), triangulated from rings along the
road and a coarse grid beyond, coloured (verge, grass, dirt run-off, shore), steep parts as
rock; and the water.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from clonedrive.sim.meshes import vertex_normals
from clonedrive.sim.scenery.site import KERB_CURVATURE, Site, smoothstep, track_rng

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


def height(site: Site, s: np.ndarray, cte: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Terrain height [m] at points given their nearest road point (s, cte) and position."""
    track = site.track
    base = track.point(s)[..., 2]
    beyond = np.abs(cte) - 0.5 * track.width_at(s)  # distance past the road edge
    verge = -VERGE_DROP_M - 0.25 * smoothstep(0.0, 1.5, beyond) * (
        1 - smoothstep(2.0, 4.5, beyond)
    )
    if site.theme == "lake":
        hills = 5.0 + 9.0 * site.hills(xy) + 1.2 * site.rough(xy)
        rise = smoothstep(4.0, 40.0, beyond)
        h = base + verge + rise * hills
        if site.water_level is not None:
            # keep the ground by the road above the water; elsewhere hollows become lakes
            dry = site.water_level + 0.6 - base
            h = np.where(beyond < 25.0, np.maximum(h, base + np.maximum(verge, dry)), h)
            h = _lake_basin(site, s, cte, xy, h)
        return h
    # mountain: walls on the interior side, a drop on the other
    wall = np.sign(cte) == site.wall_side
    cliff_m = 15.0 + 8.0 * site.cliff(xy)
    wall_h = (
        cliff_m * smoothstep(2.5, 2.5 + 0.55 * cliff_m, beyond)
        + 0.35 * np.clip(beyond - 14.0, 0.0, None)
        + 2.0 * site.rough(xy) * smoothstep(2.5, 8.0, beyond)
    )
    drop_m = 16.0 + 8.0 * site.cliff(xy + 500.0)
    drop_h = (
        -drop_m * smoothstep(3.0, 3.0 + 1.3 * drop_m, beyond)
        + 0.45 * np.clip(beyond - 45.0, 0.0, None)
        + 6.0 * site.hills(xy) * smoothstep(20.0, 90.0, beyond)
        + 1.5 * site.rough(xy) * smoothstep(3.0, 10.0, beyond)
    )
    h = base + verge + np.where(wall, wall_h, drop_h)
    return np.minimum(h, base + 75.0)


def _lake_basin(site: Site, s: np.ndarray, cte: np.ndarray, xy: np.ndarray, h: np.ndarray):
    """Lower the ground into a lake around the bridge (the deck spans it)."""
    bridge = site.bridge
    centre = site.track.point(bridge.middle_m)[:2]
    heading = float(site.track.heading_at(bridge.middle_m))
    along_dir = np.array([math.cos(heading), math.sin(heading)])
    delta = xy - centre
    along = np.abs(delta @ along_dir)
    across = np.abs(delta @ np.array([-along_dir[1], along_dir[0]]))
    half = 0.5 * bridge.length_m
    weight = (1.0 - smoothstep(half - 16.0, half - 1.0, along)) * (
        1.0 - smoothstep(60.0, 110.0, across + 0.15 * site.hills(xy) * 40.0)
    )
    return h * (1 - weight) + (site.water_level - 3.0) * weight


def terrain_points(site: Site) -> np.ndarray:
    """Terrain vertices (n, 2): rings along both road edges, then a coarse grid out to the
    scenery radius (rings only when not ``full``)."""
    track = site.track
    points = []
    for offset, spacing in zip(RING_OFFSETS_M, RING_SPACING_M, strict=True):
        if not site.full and offset > 15.0:
            break
        count = max(8, int(round(site.length / spacing)))
        s = (np.arange(count) + (0.5 if offset in (2.5, 9.0, 24.0) else 0.0)) * (
            site.length / count)
        half = 0.5 * track.width_at(s)
        for side in (-1.0, 1.0):
            xy = track.offset_point(s, side * (half + offset))[:, :2]
            proj = track.project(xy)
            along = np.abs(proj.s_m - s)
            along = np.minimum(along, site.length - along)
            own = along < max(3.0, 0.8 * abs(offset) + 2.0)
            points.append(xy[own])
    ring = np.concatenate(points)
    if not site.full:
        return ring
    low = ring.min(axis=0) - SCENERY_RADIUS_M
    high = ring.max(axis=0) + SCENERY_RADIUS_M
    gx = np.arange(low[0], high[0], GRID_SPACING_M)
    gy = np.arange(low[1], high[1], GRID_SPACING_M)
    grid = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
    rng = track_rng(track, "grid")
    grid += rng.uniform(-0.3, 0.3, grid.shape) * GRID_SPACING_M
    distance, _ = cKDTree(track.xyz[:, :2]).query(grid)
    half_max = 0.5 * float(track.width.max())
    keep = (distance > half_max + RING_OFFSETS_M[-1] + 8.0) & (
        distance < SCENERY_RADIUS_M + 20.0
    )
    return np.concatenate([ring, grid[keep]])


def build_terrain(site: Site) -> None:
    """The ground and rock meshes from one Delaunay triangulation of :func:`terrain_points`."""
    track = site.track
    xy = terrain_points(site)
    proj = track.project(xy)
    z = height(site, proj.s_m, proj.cte_m, xy)
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
    albedo = ground_colours(site, positions, proj.s_m, proj.cte_m, beyond, normals)
    sunlit = site.sunlit(xy)
    face_normal = np.cross(b - a, c - a)
    face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-12)
    steep = np.degrees(np.arccos(np.abs(face_normal[:, 2]))) > ROCK_SLOPE_DEG
    steep = np.where((up < 0), steep, steep)  # orientation does not change steepness
    ground_uv = xy / 6.0
    rock_uv = np.column_stack([(xy[:, 0] + xy[:, 1]) / 9.0, z / 7.0])
    rock_albedo = np.asarray(site.style.rock_rgb) * (
        1.0 + 0.12 * site.patches(xy)
    )[:, None]
    for material, tris, uv, colours in (
        ("ground", triangles[~steep], ground_uv, albedo),
        ("rock", triangles[steep], rock_uv, rock_albedo),
    ):
        if len(tris) == 0:
            continue
        used, local = np.unique(tris, return_inverse=True)
        site.mesh(material).add(
            positions[used], normals[used], uv[used], colours[used],
            local.reshape(-1, 3), sunlit=sunlit[used], haze_m=np.clip(beyond[used], 0, None)
        )
    site.counts["terrain_triangles"] = len(triangles)
    site.terrain = (positions, triangles, normals, proj, beyond)


def ground_colours(site: Site, positions, s, cte, beyond, normals) -> np.ndarray:
    """Ground albedo (n, 3): grass patches, the verge, dirt run-off, the lake shore."""
    style = site.style
    xy = positions[:, :2]
    mix = smoothstep(-0.4, 0.6, site.patches(xy))[:, None]
    grass = (1 - mix) * np.asarray(style.grass_rgb) + mix * np.asarray(style.grass_alt_rgb)
    grass *= (1.0 + 0.08 * site.rough(xy * 3.0))[:, None]
    verge_width = 1.4 if site.theme == "lake" else 2.6
    verge = 1.0 - smoothstep(verge_width - 0.4, verge_width + 0.6, beyond)
    # dirt run-off on the outside of sharp curves (lake) / gravel by the walls (mountain)
    curvature = site.track.curvature(s)
    outside = np.sign(cte) == -np.sign(curvature)
    runoff = (np.abs(curvature) > KERB_CURVATURE * 1.2) & outside
    runoff_w = np.where(runoff, 1.0 - smoothstep(5.0, 9.0, beyond), 0.0)
    colour = grass * (1 - verge)[:, None] + np.asarray(style.verge_rgb) * verge[:, None]
    colour = colour * (1 - runoff_w)[:, None] + np.asarray(style.dirt_rgb) * runoff_w[:, None]
    if site.water_level is not None:
        shore = 1.0 - smoothstep(0.3, 1.6, positions[:, 2] - site.water_level)
        colour = colour * (1 - shore)[:, None] + np.array([200.0, 186.0, 140.0]) * shore[
            :, None]
    return colour


def build_water(site: Site) -> None:
    """Water squares (16 m) wherever the ground dips below the water level, and around."""
    if site.water_level is None:
        return
    positions, triangles, _, _, _ = site.terrain
    size = 16.0
    # every triangle's lowest corner marks the squares its bounding box touches
    corners = positions[triangles]
    low_z = corners[:, :, 2].min(axis=1)
    wet = low_z < site.water_level + 0.05
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
    flat = np.column_stack([xy, np.full(len(xy), site.water_level)])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    tris = (quad[None] + 4 * np.arange(len(keys))[:, None, None]).reshape(-1, 3)
    proj = site.track.project(xy)
    haze = np.clip(np.abs(proj.cte_m) - proj.half_width_m, 0.0, None)
    site.mesh("water").add(flat, (0.0, 0.0, 1.0), xy / 9.0, (255.0, 255.0, 255.0), tris,
                           haze_m=haze)
    site.counts["water_squares"] = len(keys)


def ground_height(site: Site, xy: np.ndarray) -> np.ndarray:
    """Terrain height [m] at world points (n, 2)."""
    proj = site.track.project(xy)
    return height(site, proj.s_m, proj.cte_m, xy)
