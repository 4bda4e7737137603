"""Top-down track maps (matplotlib, Agg): the road, its driving direction (blue arrows, named
in the map's corner), the start line, elevation by colour, and optionally a driven path coloured
by |CTE| with off-road points marked. The |CTE| colour scale fits the run: it tops out at the
first of :data:`CTE_SCALE_TOPS_M` above the run's largest |CTE|, so a path that stayed within
0.3 m of the centre is not drawn in one colour on a scale made for the road's edge.

Evaluation draws one map per run, and most of a map's cost is the track's part (road, axes,
ticks, colour bar), the same for every run on that track. So maps with a driven path reuse it:
the track's figure is drawn once per process (:data:`_BACKGROUNDS`, the last few tracks), its
pixels are kept (one per track and colour scale), and each run restores them and draws only its
own path, markers and title on top (matplotlib's blitting). A path that leaves the track's axes
falls back to a full drawing, so nothing is cut off.
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402

from clonedrive.base.config import atomic_path  # noqa: E402
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
    # Direction arrows every ~1/12 of the lap, and what they are.
    ax.text(0.01, 0.01, "blue arrows: driving direction", transform=ax.transAxes, fontsize=8,
            color="tab:blue", va="bottom", zorder=6)
    size = max(track.length_m / 35, 12.0)
    for s in _arrow_places(track, size):
        (x, y, _), (x1, y1, _) = track.point(s), track.point(s + size)
        ax.annotate("", xy=(x1, y1), xytext=(x, y),
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


def _arrow_places(track: Track, size: float, count: int = 12) -> list[float]:
    """Where the direction arrows start [m along the road]: about every ``1/count`` of the lap
    (not at the start line), each moved to where the road bends least over the arrow's
    ``size`` metres, so an arrow drawn from there to ``size`` metres on stays on the road."""
    spacing = track.length_m / count
    places = []
    for middle in np.linspace(0, track.length_m, count, endpoint=False)[1:]:
        candidates = middle + np.linspace(-spacing / 3, spacing / 3, 9)
        along = candidates[:, None] + np.linspace(0.0, size, 8)[None, :]
        bend = np.abs(track.curvature(along)).max(axis=1)
        places.append(float(candidates[np.argmin(bend)]))
    return places


#: Tops [m] the |CTE| colour scale may have; a run's scale takes the first at or above its
#: largest |CTE| (the last: anything beyond, up to the road's half width and past it).
CTE_SCALE_TOPS_M = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
#: The drawn maps (figure and pixels) kept for their tracks' next runs, newest last.
_BACKGROUNDS: OrderedDict = OrderedDict()
_BACKGROUND_TRACKS = 4
_FIGURE = {"figsize": (8, 7), "dpi": 110}
_MARGINS = {"left": 0.1, "right": 0.88, "bottom": 0.07, "top": 0.95}


def plot_track_map(track: Track, path: str | Path, *, title: str | None = None,
                   driven_xy: np.ndarray | None = None, abs_cte_m: np.ndarray | None = None,
                   off_road_xy: np.ndarray | None = None, reuse: bool = True) -> Path:
    """Write a map PNG of ``track``; with ``driven_xy`` the path is drawn coloured by |CTE|.

    ``reuse``: draw a driven path over the track's kept map (see the module); False draws the
    whole figure (the same picture, at several times the cost)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    title = title or _default_title(track)
    top = cte_scale_top(abs_cte_m)
    if reuse and driven_xy is not None and len(driven_xy) > 1:
        background = _background(track, top)
        if background.contains(driven_xy, off_road_xy):
            background.draw_run(path, title, driven_xy, abs_cte_m, off_road_xy)
            return path
    fig, ax = plt.subplots(**_FIGURE)
    draw_track(ax, track, elevation=driven_xy is None)
    if driven_xy is not None and len(driven_xy) > 1:
        colorbar = fig.colorbar(_path_lines(driven_xy, abs_cte_m, ax, top), ax=ax,
                                fraction=0.04, pad=0.02)
        colorbar.set_label("|cross-track error| [m]")
    _off_road_markers(ax, off_road_xy)
    ax.set_title(title, fontsize=10)
    # Fixed margins rather than tight_layout, which lays the ticks out once more (0.12 s a map).
    fig.subplots_adjust(**_MARGINS)
    with atomic_path(path) as temporary:
        fig.savefig(temporary)
    plt.close(fig)
    return path


def _default_title(track: Track) -> str:
    summary = track.summary()
    return (f"{track.name}: {summary['length_m']:.0f} m, width {summary['width_m']:.1f} m, "
            f"elevation range {summary['elevation_range_m']:.0f} m, "
            f"min radius {summary['min_radius_m']:.0f} m")


def cte_scale_top(abs_cte_m: np.ndarray | None) -> float:
    """The top [m] of a run's |CTE| colour scale (see :data:`CTE_SCALE_TOPS_M`)."""
    finite = np.asarray(abs_cte_m, dtype=float) if abs_cte_m is not None else np.zeros(0)
    finite = finite[np.isfinite(finite)]
    largest = float(finite.max()) if finite.size else 0.0
    return next((top for top in CTE_SCALE_TOPS_M if largest <= top), CTE_SCALE_TOPS_M[-1])


def _path_lines(driven_xy: np.ndarray, abs_cte_m: np.ndarray | None, ax, top: float):
    """The driven path as a line collection coloured by |CTE| (0 to ``top``)."""
    segments = np.stack([driven_xy[:-1], driven_xy[1:]], axis=1)
    colour = abs_cte_m[:-1] if abs_cte_m is not None else np.zeros(len(segments))
    lines = LineCollection(segments, cmap="plasma", linewidths=1.8, zorder=7)
    lines.set_array(colour)
    lines.set_clim(0.0, top)
    ax.add_collection(lines)
    return lines


def _off_road_markers(ax, off_road_xy: np.ndarray | None) -> list:
    """Red crosses at the off-road points, with their legend (the artists made)."""
    if off_road_xy is None or not len(off_road_xy):
        return []
    points = ax.scatter(off_road_xy[:, 0], off_road_xy[:, 1], marker="x", s=80, color="red",
                        lw=2.5, zorder=8, label="off road")
    return [points, ax.legend(loc="upper right")]


class _Background:
    """A track's map drawn once with an empty title and no path, its |CTE| colour bar topping
    out at ``top``: its figure and pixels."""

    def __init__(self, track: Track, top: float) -> None:
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize

        self.fig, self.ax = plt.subplots(**_FIGURE)
        draw_track(self.ax, track, elevation=False)
        scale = ScalarMappable(Normalize(0.0, top), cmap="plasma")
        colorbar = self.fig.colorbar(scale, ax=self.ax, fraction=0.04, pad=0.02)
        colorbar.set_label("|cross-track error| [m]")
        self.title = self.ax.set_title(" ", fontsize=10)
        self.fig.subplots_adjust(**_MARGINS)
        self.track, self.top = track, top
        canvas = self.fig.canvas
        canvas.draw()
        self.ax.set_autoscale_on(False)  # a run's path must not move the kept axes
        self.xlim, self.ylim = self.ax.get_xlim(), self.ax.get_ylim()
        self.pixels = canvas.copy_from_bbox(self.fig.bbox)

    def contains(self, *points: np.ndarray | None) -> bool:
        """Whether every given point lies inside this map's axes (nothing would be cut off)."""
        for xy in points:
            if xy is None or not len(xy):
                continue
            if not (self.xlim[0] <= xy[:, 0].min() and xy[:, 0].max() <= self.xlim[1]
                    and self.ylim[0] <= xy[:, 1].min() and xy[:, 1].max() <= self.ylim[1]):
                return False
        return True

    def draw_run(self, path: Path, title: str, driven_xy: np.ndarray,
                 abs_cte_m: np.ndarray | None, off_road_xy: np.ndarray | None) -> None:
        """Restore the track's pixels, draw one run's path, markers and title, write the PNG."""
        from PIL import Image

        canvas, ax = self.fig.canvas, self.ax
        canvas.restore_region(self.pixels)
        artists = [_path_lines(driven_xy, abs_cte_m, ax, self.top),
                   *_off_road_markers(ax, off_road_xy)]
        self.title.set_text(title)
        try:
            for artist in [*artists, self.title]:
                self.fig.draw_artist(artist)
            rgba = np.asarray(canvas.buffer_rgba())
            with atomic_path(path) as temporary:
                # zlib level 1: faster than the default level, for slightly larger files.
                Image.fromarray(rgba).save(temporary, format="PNG", compress_level=1,
                                           dpi=(self.fig.dpi, self.fig.dpi))
        finally:
            self.title.set_text(" ")
            for artist in artists:
                artist.remove()


def _background(track: Track, top: float) -> _Background:
    """The kept map of ``track`` with its colour scale topping at ``top`` (drawn now if it is
    not among the last few kept).

    Kept by the track's content (name, centreline, widths), not by the object: each simulator
    loads its own copy of a track."""
    key = (*_track_key(track), top)
    background = _BACKGROUNDS.get(key)
    if background is None:
        background = _BACKGROUNDS[key] = _Background(track, top)
    _BACKGROUNDS.move_to_end(key)
    while len(_BACKGROUNDS) > _BACKGROUND_TRACKS:
        _, old = _BACKGROUNDS.popitem(last=False)
        plt.close(old.fig)
    return background


def _track_key(track: Track) -> tuple:
    return track.name, track.geometry_key()
