"""Top-down track maps (matplotlib, Agg): the road, its direction, the start line, elevation by
colour, and optionally a driven path coloured by |CTE| with off-road points marked."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402

from clonedrive.config import atomic_path  # noqa: E402
from clonedrive.world.track import Track  # noqa: E402


def _road_outline(track: Track) -> tuple[np.ndarray, np.ndarray]:
    half = 0.5 * track.width[:, None]
    left = track.xyz[:, :2] - track.right_normal * half
    right = track.xyz[:, :2] + track.right_normal * half
    return np.vstack([left, left[:1]]), np.vstack([right, right[:1]])


def draw_track(ax, track: Track, *, elevation: bool = True) -> None:
    """Road surface, edges, centreline coloured by elevation, direction arrows and start line."""
    left, right = _road_outline(track)
    polygon = np.vstack([left, right[::-1]])
    # A collection, not ax.fill: fill's patch updates the data limits vertex by vertex in Python
    # (0.14 s for lake's 4,000 vertices); the edge lines below set the same limits.
    ax.add_collection(PolyCollection([polygon], facecolors="0.85", edgecolors="none", zorder=1),
                      autolim=False)
    ax.plot(left[:, 0], left[:, 1], color="0.35", lw=0.8, zorder=2)
    ax.plot(right[:, 0], right[:, 1], color="0.35", lw=0.8, zorder=2)
    if elevation:
        points = np.vstack([track.xyz[:, :2], track.xyz[:1, :2]])
        segments = np.stack([points[:-1], points[1:]], axis=1)
        lines = LineCollection(segments, cmap="terrain", linewidths=2.5, zorder=3)
        lines.set_array(track.xyz[:, 2])
        ax.add_collection(lines)
        colorbar = ax.figure.colorbar(lines, ax=ax, fraction=0.04, pad=0.02)
        colorbar.set_label("elevation [m]")
    # Direction arrows every ~1/12 of the lap.
    for s in np.linspace(0, track.length_m, 12, endpoint=False)[1:]:
        x, y, _ = track.point(s)
        heading = float(track.heading_at(s))
        size = max(track.length_m / 35, 12.0)
        ax.annotate("", xy=(x + size * np.cos(heading), y + size * np.sin(heading)), xytext=(x, y),
                    arrowprops={"arrowstyle": "-|>", "color": "tab:blue", "lw": 1.5}, zorder=4)
    # Start line across the road.
    x0, y0, _ = track.point(0.0)
    n = track.right_normal[0] * 0.7 * track.width[0]
    ax.plot([x0 - n[0], x0 + n[0]], [y0 - n[1], y0 + n[1]], color="k", lw=3, zorder=5)
    ax.annotate("start", (x0, y0), xytext=(8, 8), textcoords="offset points", fontsize=9,
                zorder=6)
    ax.set_aspect("equal")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")


def plot_track_map(track: Track, path: str | Path, *, title: str | None = None,
                   driven_xy: np.ndarray | None = None, abs_cte_m: np.ndarray | None = None,
                   off_road_xy: np.ndarray | None = None) -> Path:
    """Write a map PNG of ``track``; with ``driven_xy`` the path is drawn coloured by |CTE|."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    draw_track(ax, track, elevation=driven_xy is None)
    if driven_xy is not None and len(driven_xy) > 1:
        segments = np.stack([driven_xy[:-1], driven_xy[1:]], axis=1)
        colour = abs_cte_m[:-1] if abs_cte_m is not None else np.zeros(len(segments))
        lines = LineCollection(segments, cmap="plasma", linewidths=1.8, zorder=7)
        lines.set_array(colour)
        lines.set_clim(0.0, max(0.5 * float(track.width.max()), 1e-3))
        ax.add_collection(lines)
        colorbar = fig.colorbar(lines, ax=ax, fraction=0.04, pad=0.02)
        colorbar.set_label("|cross-track error| [m]")
    if off_road_xy is not None and len(off_road_xy):
        ax.scatter(off_road_xy[:, 0], off_road_xy[:, 1], marker="x", s=80, color="red", lw=2.5,
                   zorder=8, label="off road")
        ax.legend(loc="upper right")
    summary = track.summary()
    ax.set_title(title or (
        f"{track.name}: {summary['length_m']:.0f} m, width {summary['width_m']:.1f} m, "
        f"elevation range {summary['elevation_range_m']:.0f} m, "
        f"min radius {summary['min_radius_m']:.0f} m"), fontsize=10)
    # Fixed margins rather than tight_layout, which lays the ticks out once more (0.12 s a map).
    fig.subplots_adjust(left=0.1, right=0.88, bottom=0.07, top=0.95)
    with atomic_path(path) as temporary:
        fig.savefig(temporary)
    plt.close(fig)
    return path
