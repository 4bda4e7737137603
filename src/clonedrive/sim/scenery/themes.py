"""Scenery themes: the colours and switches of each look (``lake``, ``mountain``), and the tree
sprites' kinds, heights and shapes. Data only; driving conditions derive variants of a theme
(:meth:`clonedrive.sim.conditions.Conditions.style`).
"""

from __future__ import annotations

from dataclasses import dataclass


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
#: Tree heights [m] (uniform between) and width / height of each sprite kind.
TREE_HEIGHT_M = {"pine": (8.0, 14.0), "broadleaf": (6.0, 10.0), "autumn": (6.0, 10.0),
                 "bush": (1.0, 1.8)}
TREE_ASPECT = {"pine": 0.5, "broadleaf": 0.6, "autumn": 0.6, "bush": 1.8}
