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

The package: :mod:`~clonedrive.sim.scenery.themes` (colours and switches per theme),
:mod:`~clonedrive.sim.scenery.site` (what the builders share, derived once from the track),
:mod:`~clonedrive.sim.scenery.road` (road, shadows on it, kerbs, bridge),
:mod:`~clonedrive.sim.scenery.terrain` (ground height, colours, rock, water) and
:mod:`~clonedrive.sim.scenery.props` (trees, boulders, barriers, signs, lamp posts);
:func:`build_scenery` runs them in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from clonedrive.sim.meshes import Mesh
from clonedrive.sim.scenery import props, road, terrain
from clonedrive.sim.scenery.site import Site, Span, find_bridge, interior_side, longest_run
from clonedrive.sim.scenery.themes import THEME_STYLES, TREE_ATLAS_KINDS, ThemeStyle
from clonedrive.world.track import Track

__all__ = ["THEME_STYLES", "TREE_ATLAS_KINDS", "Scenery", "Span", "ThemeStyle", "build_scenery",
           "find_bridge", "interior_side", "longest_run"]


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


def build_scenery(track: Track, *, full: bool = True, style: ThemeStyle | None = None) -> Scenery:
    """Derive the scenery of ``track`` from its geometry and theme.

    ``full=False`` gives the road, kerbs, bridge and a narrow ground strip only (fast to build;
    for tests that only need the road). ``style``: colours and switches other than the theme's
    (driving conditions, :mod:`clonedrive.sim.conditions`).
    """
    site = Site(track, full, style)
    road.build_road(site)
    terrain.build_terrain(site)
    if full:
        terrain.build_water(site)
        props.build_trees(site)
        props.build_boulders(site)
        props.build_barriers(site)
        props.build_signs(site)
        props.build_lamp_posts(site)
    positions = site.terrain[0]
    low = positions[:, :2].min(axis=0)
    high = positions[:, :2].max(axis=0)
    return Scenery(
        theme=site.theme,
        style=site.style,
        meshes=site.meshes,
        bridge=site.bridge,
        water_level_m=site.water_level,
        wall_side=site.wall_side,
        bounds_xy=(float(low[0]), float(low[1]), float(high[0]), float(high[1])),
        counts=site.counts,
    )
