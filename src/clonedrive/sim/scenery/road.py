"""The road: its strip (level across, dense stations on curves), the shadow patches on it,
kerbs on sharp curves (lake) and the bridge over the lake (parapets, fascia, piers).
"""

from __future__ import annotations

import math

import numpy as np

from clonedrive.sim.meshes import box, grid_triangles, vertex_normals
from clonedrive.sim.scenery.site import (
    KERB_CURVATURE,
    ROAD_STEP_M,
    Site,
    circular_runs,
    dilate,
    right_normal,
)
from clonedrive.sim.textures import ROAD_TEXTURE_REPEAT_M

#: Road mesh stations: spacing from the chord error allowed on curves, within these bounds [m].
ROAD_MESH_STEP_M = (1.5, 5.0)
ROAD_CHORD_ERROR_M = 0.04
#: Road mesh cross-section (fractions of the half width): the road is level across, the edge
#: lines are in the texture and shadows are separate patches, so the edges are enough.
ROAD_ACROSS = np.array([-1.0, 1.0])
KERB_WIDTH_M = 0.6
KERB_HEIGHT_M = 0.05


def road_stations(site: Site) -> np.ndarray:
    """Road mesh stations [m]: dense on curves, sparse on straights (chord error bound)."""
    fine = site.track.s
    radius = 1.0 / np.maximum(np.abs(site.track.curvature_table), 1e-6)
    step = np.clip(np.sqrt(8.0 * radius * ROAD_CHORD_ERROR_M), *ROAD_MESH_STEP_M)
    stations = [0.0]
    while True:
        i = min(int(stations[-1] / site.track.ds_m), len(fine) - 1)
        # the tightest curve within the next few metres sets the step
        window = step[i : i + int(ROAD_MESH_STEP_M[1] / site.track.ds_m) + 1]
        nxt = stations[-1] + float(window.min())
        if nxt > site.length - 0.5 * ROAD_MESH_STEP_M[0]:
            break
        stations.append(nxt)
    return np.asarray(stations)


def build_road(site: Site) -> None:
    """The road strip, then its shadows, kerbs and bridge."""
    track = site.track
    s = np.append(road_stations(site), site.length)  # close the loop; v continues
    centre = track.point(s)
    normal = right_normal(track, s)
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
    site.mesh("road").add(positions, normals, uv, (255.0, 255.0, 255.0), triangles)
    site.counts["road_triangles"] = len(triangles)
    build_road_shadows(site)
    if site.style.kerbs:
        build_kerbs(site)
    if site.bridge is not None:
        build_bridge(site)


def strip(site: Site, s: np.ndarray, offsets: np.ndarray, heights: np.ndarray):
    """Positions (n, k, 3) of a strip at stations ``s`` and lateral ``offsets`` (k,) from the
    road edge on the right (positive) or the left (negative offsets mirrored by caller)."""
    track = site.track
    centre = track.point(s)
    normal = right_normal(track, s)
    xy = centre[:, None, :2] + normal[:, None, :] * offsets[..., None]
    z = centre[:, 2:3] + heights
    return np.concatenate([xy, np.broadcast_to(z, offsets.shape)[..., None]], axis=-1)


def build_road_shadows(site: Site) -> None:
    """Shadow patches on the road: lumpy polygons of shaded asphalt just above the road
    (same texture and mapping, lit by ambient light only), so their edges are crisp."""
    track = site.track
    mesh = site.mesh("road")
    angles = np.linspace(0.0, 2 * math.pi, 14, endpoint=False)
    # angles turn from forward to right (clockwise seen from above): reverse the fan
    fan = np.stack([np.zeros(14, int), 1 + (np.arange(14) + 1) % 14, 1 + np.arange(14)], 1)
    count = 0
    for x, y, radius, darkness in site.shadow_blobs:
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
    site.counts["road_shadows"] = count


def build_kerbs(site: Site) -> None:
    """Red-and-white kerbs on both sides of sharp curves, a few metres either way."""
    sharp = np.abs(site.curvature) > KERB_CURVATURE
    sharp = dilate(sharp, int(round(5.0 / ROAD_STEP_M)))
    if site.bridge is not None:
        sharp &= ~site.bridge.contains(site.stations, site.length)
    runs = circular_runs(sharp)
    mesh = site.mesh("kerb")
    for first, count in runs:
        idx = (first + np.arange(count + 1)) % len(site.stations)
        s = site.stations[idx] + site.length * ((first + np.arange(count + 1)) >= len(
            site.stations))
        half = 0.5 * site.track.width_at(s)
        for side in (-1.0, 1.0):
            offsets = side * (half[:, None] + np.array([0.0, 0.15, KERB_WIDTH_M])[None, :])
            heights = np.array([0.01, KERB_HEIGHT_M, KERB_HEIGHT_M])[None, :]
            positions = strip(site, s, offsets, heights).reshape(-1, 3)
            u = np.array([0.0, 0.25, 1.0])
            uv = np.stack(np.broadcast_arrays(u[None, :], (s / 2.0)[:, None]), -1)
            triangles = grid_triangles(len(s), 3)
            if side < 0:  # columns run leftwards: flip to face up
                triangles = triangles[:, ::-1]
            mesh.add(positions, (0.0, 0.0, 1.0), uv.reshape(-1, 2), (255.0, 255.0, 255.0),
                     triangles, sunlit=site.sunlit(positions[:, :2]))
    site.counts["kerb_runs"] = len(runs)


def build_bridge(site: Site) -> None:
    """The bridge's parapets and deck fascia, and piers down into the water every 18 m."""
    bridge = site.bridge
    s = np.linspace(bridge.start_m, bridge.end_m, max(2, int(bridge.length_m / 3.0)) + 1)
    half = 0.5 * site.track.width_at(s)
    stone = site.mesh("rock")
    parapet_rgb = (150.0, 138.0, 128.0)
    for side in (-1.0, 1.0):
        # parapet: inner face, top, outer face, fascia below the deck
        offsets = side * (half[:, None] + np.array([0.0, 0.0, 0.35, 0.35, 0.35])[None, :])
        heights = np.array([0.0, 0.65, 0.65, 0.65, -1.3])[None, :]
        positions = strip(site, s, offsets, heights)
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
        base = site.track.offset_point(pier_s, side * (0.5 * site.track.width_at(pier_s) - 1))
        base[:, 2] = site.water_level - 3.0
        heading = site.track.heading_at(pier_s)
        height = float(site.track.point(bridge.middle_m)[2] - base[0, 2])
        positions, normals, uv, triangles = box(base, heading, (1.6, 1.6, height))
        stone.add(positions, normals, uv * (1.0, 3.0), parapet_rgb, triangles)
