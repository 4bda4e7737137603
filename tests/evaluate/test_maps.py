"""Track maps: a run's path drawn over the track's kept map looks as the whole figure does."""

from __future__ import annotations

import numpy as np
from PIL import Image

from clonedrive.evaluate import maps
from clonedrive.evaluate.maps import plot_track_map
from clonedrive.world.catalog import load_track


def weaving_path(track, offset_m: float, until: float = 0.6):
    s = np.linspace(0.0, until * track.length_m, 400)
    cte = offset_m * np.sin(s / 35.0)
    xy = np.array([track.offset_point(v, c)[:2] for v, c in zip(s, cte, strict=True)])
    return xy, np.abs(cte)


def pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def test_a_runs_map_over_the_kept_track_map_matches_the_whole_figure(tmp_path):
    maps._BACKGROUNDS.clear()
    track = load_track("lake")
    first_xy, first_cte = weaving_path(track, 2.0, until=0.9)
    second_xy, second_cte = weaving_path(track, 1.5)  # the same colour scale (0-2 m) as the first
    plot_track_map(track, tmp_path / "first.png", title="first run", driven_xy=first_xy,
                   abs_cte_m=first_cte)
    assert len(maps._BACKGROUNDS) == 1  # the track's map is kept for its next runs
    track = load_track("lake")  # another simulator's copy of the same track: the same map
    kwargs = {"title": "second run", "driven_xy": second_xy, "abs_cte_m": second_cte,
              "off_road_xy": second_xy[[50, 300]]}
    plot_track_map(track, tmp_path / "reused.png", **kwargs)
    plot_track_map(track, tmp_path / "whole.png", reuse=False, **kwargs)
    reused, whole = pixels(tmp_path / "reused.png"), pixels(tmp_path / "whole.png")
    assert reused.shape == whole.shape == (770, 880, 3)
    # The same picture: no trace of the first run's path, title, markers and legend in place
    # (a few anti-aliased edge pixels may round differently).
    assert (np.abs(reused - whole).max(axis=2) > 30).mean() < 1e-3
    assert not np.array_equal(pixels(tmp_path / "first.png"), reused)
    assert len(maps._BACKGROUNDS) == 1


def test_a_path_beyond_the_kept_axes_is_drawn_whole_and_the_cache_is_bounded(tmp_path):
    maps._BACKGROUNDS.clear()
    track = load_track("lake")
    xy, cte = weaving_path(track, 1.0)
    far = np.vstack([xy, xy[-1] + (600.0, 0.0)])  # far outside the track's axes
    far_cte = np.append(cte, 600.0)
    plot_track_map(track, tmp_path / "far.png", driven_xy=far, abs_cte_m=far_cte)
    plot_track_map(track, tmp_path / "far_whole.png", driven_xy=far, abs_cte_m=far_cte,
                   reuse=False)
    assert np.array_equal(pixels(tmp_path / "far.png"), pixels(tmp_path / "far_whole.png"))
    names = ["lake", "mountain", "gen2:easy:2002", "gen2:medium:2001", "gen2:hard:2003"]
    tracks = [load_track(name) for name in names]
    for index, other in enumerate(tracks):
        path_xy, path_cte = weaving_path(other, 1.0, until=0.2)
        plot_track_map(other, tmp_path / f"{index}.png", driven_xy=path_xy, abs_cte_m=path_cte)
    kept = [background.track.name for background in maps._BACKGROUNDS.values()]
    assert kept == names[-maps._BACKGROUND_TRACKS:]  # the newest few, the oldest dropped


def test_the_colour_scale_fits_the_run(tmp_path):
    """A calm run is not drawn in one colour on a scale made for the road's edge: the scale tops
    out at the first round figure above the run's largest |CTE|, and each scale keeps its own
    track map."""
    assert maps.cte_scale_top(np.array([0.05, 0.09])) == 0.25
    assert maps.cte_scale_top(np.array([0.3, np.nan, 1.1])) == 2.0
    assert maps.cte_scale_top(np.array([600.0])) == maps.CTE_SCALE_TOPS_M[-1]
    assert maps.cte_scale_top(None) == maps.CTE_SCALE_TOPS_M[0]
    maps._BACKGROUNDS.clear()
    track = load_track("lake")
    calm_xy, calm_cte = weaving_path(track, 0.2)
    wide_xy, wide_cte = weaving_path(track, 3.0)
    plot_track_map(track, tmp_path / "calm.png", driven_xy=calm_xy, abs_cte_m=calm_cte)
    plot_track_map(track, tmp_path / "wide.png", driven_xy=wide_xy, abs_cte_m=wide_cte)
    assert sorted(key[-1] for key in maps._BACKGROUNDS) == [0.25, 4.0]
    # The calm path spans the colour map: drawn again with |CTE| 0 throughout (one colour, the
    # same scale), most of its pixels change, and into several colours.
    plot_track_map(track, tmp_path / "flat.png", driven_xy=calm_xy,
                   abs_cte_m=np.zeros(len(calm_cte)))
    calm, flat = pixels(tmp_path / "calm.png"), pixels(tmp_path / "flat.png")
    changed = np.abs(calm - flat).max(axis=2) > 60
    assert changed.sum() > 500
    assert len({tuple(colour) for colour in calm[changed] // 48}) >= 4


def test_the_direction_arrows_stay_on_the_road_and_point_along_it():
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.text import Annotation

    for name in ("mountain", "lake"):
        track = load_track(name)
        axes = Figure().add_subplot()
        maps.draw_track(axes, track, elevation=False)
        arrows = [a for a in axes.texts if isinstance(a, Annotation) and a.arrow_patch]
        assert len(arrows) == 11
        for arrow in arrows:
            start, end = np.array(arrow.xyann), np.array(arrow.xy)
            line = start + np.linspace(0.0, 1.0, 20)[:, None] * (end - start)
            where = track.project(line)
            assert np.all(np.abs(where.cte_m) < where.half_width_m), name
            # Along the driving direction: the road's arc length grows from tail to head.
            ahead = (where.s_m[-1] - where.s_m[0]) % track.length_m
            assert 0 < ahead < track.length_m / 2, name
