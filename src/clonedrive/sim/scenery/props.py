"""Objects by the road: trees (crossed-quad sprites), boulders, concrete barriers on the drop
side of mountain bends, chevron signs on the outside of sharp curves, lamp posts (mountain).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from clonedrive.sim.meshes import box, crossed_quads, vertex_normals
from clonedrive.sim.scenery.site import (
    CHEVRON_CURVATURE,
    ROAD_STEP_M,
    Site,
    dilate,
    right_normal,
    track_rng,
)
from clonedrive.sim.scenery.terrain import ROCK_SLOPE_DEG, ground_height, height
from clonedrive.sim.scenery.themes import TREE_ASPECT, TREE_ATLAS_KINDS, TREE_HEIGHT_M

#: Mountain barriers line the drop side wherever the road bends more than this [1/m].
BARRIER_CURVATURE = 1.0 / 120.0


def build_trees(site: Site) -> None:
    """Tree sprites on a jittered 8 m grid, in clumps, not on cliffs or in water."""
    style = site.style
    rng = track_rng(site.track, "trees")
    positions, triangles, normals, proj, beyond = site.terrain
    spacing = 8.0
    low = positions[:, :2].min(axis=0)
    high = positions[:, :2].max(axis=0)
    gx = np.arange(low[0], high[0], spacing)
    gy = np.arange(low[1], high[1], spacing)
    spots = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
    spots = spots + rng.uniform(-0.45, 0.45, spots.shape) * spacing
    spot_proj = site.track.project(spots)
    edge = np.abs(spot_proj.cte_m) - spot_proj.half_width_m
    keep = (edge > 5.0) & (edge < 130.0) & (rng.random(len(spots)) < style.tree_keep)
    # thin out far away (they are small there) and keep clumps: a patch field
    keep &= site.patches(spots * 1.7) > -0.3
    spots, edge = spots[keep], edge[keep]
    z = height(site, spot_proj.s_m[keep], spot_proj.cte_m[keep], spots)
    # not in water, not on cliffs (steepness from the terrain normal at the nearest vertex)
    _, nearest = cKDTree(positions[:, :2]).query(spots)
    flat_enough = normals[nearest, 2] > math.cos(math.radians(ROCK_SLOPE_DEG))
    dry = np.ones(len(spots), bool)
    if site.water_level is not None:
        dry = z > site.water_level + 0.4
    ok = flat_enough & dry
    spots, z, edge = spots[ok], z[ok], edge[ok]
    weights = np.asarray(style.tree_weights) / np.sum(style.tree_weights)
    kind_index = rng.choice(len(style.tree_kinds), size=len(spots), p=weights)
    kinds = np.array(style.tree_kinds)[kind_index]
    # bushes only near the road
    kinds = np.where((kinds == "bush") & (edge > 40.0), style.tree_kinds[0], kinds)
    heights = np.array([rng.uniform(*TREE_HEIGHT_M[k]) for k in kinds])
    widths = heights * np.array([TREE_ASPECT[k] for k in kinds]) * rng.uniform(
        0.85, 1.15, len(kinds))
    atlas_index = np.array([TREE_ATLAS_KINDS.index(k) for k in kinds])
    cell = 1.0 / len(TREE_ATLAS_KINDS)
    uv_rect = np.column_stack([
        atlas_index * cell + 0.01, np.full(len(kinds), 0.0),
        (atlas_index + 1) * cell - 0.01, np.full(len(kinds), 1.0),
    ])
    base = np.column_stack([spots, z - 0.3])
    angle = rng.uniform(0, math.pi, len(spots))
    positions_t, normals_t, uv, tris = crossed_quads(base, heights, widths, angle, uv_rect)
    tint = rng.uniform(0.8, 1.1, len(spots))
    albedo = np.repeat(np.outer(tint, (255.0, 255.0, 255.0)), 8, axis=0)
    site.mesh("tree").add(positions_t, normals_t, uv, albedo, tris,
                          haze_m=np.repeat(edge, 8))
    site.counts["trees"] = len(spots)


def build_boulders(site: Site) -> None:
    """Boulders 4-20 m off the road edge, off the bridge and out of the water."""
    rng = track_rng(site.track, "boulders")
    count = int(site.length / (90.0 if site.theme == "lake" else 60.0))
    s = rng.uniform(0, site.length, count)
    side = rng.choice([-1.0, 1.0], count)
    offset = side * (0.5 * site.track.width_at(s) + rng.uniform(4.0, 20.0, count))
    xy = site.track.offset_point(s, offset)[:, :2]
    if site.bridge is not None:
        keep = ~site.bridge.contains(s, site.length)
        xy, s = xy[keep], s[keep]
    z = ground_height(site, xy)
    if site.water_level is not None:
        keep = z > site.water_level + 0.3
        xy, z = xy[keep], z[keep]
    sizes = rng.uniform(1.2, 4.0, len(xy))
    proj = site.track.project(xy)
    distances = np.clip(np.abs(proj.cte_m) - proj.half_width_m, 0.0, None)
    mesh = site.mesh("rock")
    unit, unit_tris = rock_shape()
    for (x, y), h, size, haze in zip(xy, z, sizes, distances, strict=True):
        scale = size * rng.uniform(0.7, 1.3, 3) * (1.0, 1.0, 0.6)
        positions = unit * scale + (x, y, h - 0.2 * size)
        normals = vertex_normals(positions, unit_tris)
        uv = np.column_stack([(positions[:, 0] + positions[:, 1]) / 4.0,
                              positions[:, 2] / 4.0])
        mesh.add(positions, normals, uv, np.asarray(site.style.rock_rgb) * 0.9, unit_tris,
                 haze_m=haze)
    site.counts["boulders"] = len(xy)


def build_barriers(site: Site) -> None:
    """Concrete barriers on the drop side of mountain bends."""
    if not site.style.barriers:
        return
    drop_side = -site.wall_side
    bends = dilate(np.abs(site.curvature) > BARRIER_CURVATURE, int(round(12 / ROAD_STEP_M)))
    spacing = 1.8
    s = np.arange(0.0, site.length, spacing)
    on = bends[np.minimum((s / (site.length / len(site.stations))).astype(int),
                          len(site.stations) - 1)]
    s = s[on]
    half = 0.5 * site.track.width_at(s)
    base = site.track.offset_point(s, drop_side * (half + 0.9))
    heading = site.track.heading_at(s)
    positions, normals, uv, triangles = box(base, heading, (1.3, 0.45, 0.75))
    site.mesh("barrier").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles,
                             sunlit=np.repeat(site.sunlit(base[:, :2]), 20))
    site.counts["barriers"] = len(s)


def build_signs(site: Site) -> None:
    """Chevron signs on the outside of sharp curves, pointing the way the road turns."""
    sharp = np.abs(site.curvature) > CHEVRON_CURVATURE
    if site.bridge is not None:
        sharp &= ~site.bridge.contains(site.stations, site.length)
    stride = max(1, int(round(14.0 / ROAD_STEP_M)))
    idx = np.flatnonzero(sharp)
    idx = idx[(idx % stride) == 0]
    if len(idx) == 0:
        return
    s = site.stations[idx]
    turn = np.sign(site.curvature[idx])  # + = left turn: sign on the right side
    half = 0.5 * site.track.width_at(s)
    base = site.track.offset_point(s, turn * (half + 2.2))
    heading = site.track.heading_at(s)
    post_pos, post_n, post_uv, post_tris = box(base, heading, (0.08, 0.08, 1.2))
    site.mesh("plain").add(post_pos, post_n, post_uv, (90.0, 90.0, 90.0), post_tris)
    board_base = base + np.array([0.0, 0.0, 1.2])
    # the board faces oncoming traffic: its normal points back along -tangent
    positions, normals, uv, triangles = box(board_base, heading + math.pi / 2,
                                            (0.9, 0.05, 0.9))
    # the arrow points the way the road turns: mirror u for left turns
    flip = np.repeat(turn > 0, 20)
    uv = np.where(flip[:, None], np.column_stack([1 - uv[:, 0], uv[:, 1]]), uv)
    site.mesh("sign").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles)
    site.counts["signs"] = len(s)


def build_lamp_posts(site: Site) -> None:
    """Lamp posts every 45 m on the wall side (mountain)."""
    if not site.style.lamp_posts:
        return
    s = np.arange(10.0, site.length, 45.0)
    half = 0.5 * site.track.width_at(s)
    side = float(site.wall_side)
    base = site.track.offset_point(s, side * (half + 1.6))
    heading = site.track.heading_at(s)
    mesh = site.mesh("plain")
    grey = (120.0, 122.0, 128.0)
    positions, normals, uv, triangles = box(base, heading, (0.14, 0.14, 6.5))
    mesh.add(positions, normals, uv, grey, triangles)
    normal = right_normal(site.track, s)
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
    site.counts["lamp_posts"] = len(s)


def rock_shape() -> tuple[np.ndarray, np.ndarray]:
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
