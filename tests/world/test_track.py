import json
import math

import numpy as np
import pytest

from clonedrive.world import track as track_module
from clonedrive.world.catalog import builtin_track_names, load_track
from clonedrive.world.generate import generate
from clonedrive.world.track import (
    MIN_DRIVABLE_RADIUS_M,
    Track,
    TrackError,
    TrackSpec,
)


def circle_spec(radius_m=50.0, count=16, clockwise=False, **extra):
    angles = np.linspace(0, 2 * math.pi, count, endpoint=False)
    if clockwise:
        angles = -angles
    points = [[radius_m * math.cos(a), radius_m * math.sin(a), 0.0] for a in angles]
    data = {"name": "circle", "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
            "centerline": points}
    data.update(extra)
    return data


def test_builtin_tracks_match_their_descriptions():
    assert builtin_track_names() == ["lake", "mountain"]
    lake = load_track("lake").summary()
    assert 1000 <= lake["length_m"] <= 1500
    assert lake["elevation_range_m"] <= 5.0
    assert lake["min_radius_m"] >= 20.0  # gentle and medium curves only
    mountain = load_track("mountain").summary()
    assert 2000 <= mountain["length_m"] <= 3000
    assert mountain["elevation_range_m"] >= 40.0
    assert mountain["min_radius_m"] <= 15.0  # the hairpin
    assert 0.08 <= mountain["max_grade"] <= 0.12


def test_circle_curvature_length_and_direction():
    track = Track(TrackSpec.from_dict(circle_spec(50.0)))
    assert track.length_m == pytest.approx(2 * math.pi * 50.0, rel=2e-3)
    assert np.allclose(track.curvature(np.linspace(0, 300, 7)), 1 / 50.0, rtol=0.02)
    clockwise = Track(TrackSpec.from_dict(circle_spec(50.0, clockwise=True)))
    assert np.allclose(clockwise.curvature([0.0, 100.0]), -1 / 50.0, rtol=0.02)
    assert track.min_radius_m == pytest.approx(50.0, rel=0.02)


def test_project_recovers_arc_length_and_signed_offset():
    track = load_track("mountain")
    rng = np.random.default_rng(0)
    s = rng.uniform(0, track.length_m, 200)
    offset = rng.uniform(-3.0, 3.0, 200)
    points = track.offset_point(s, offset)
    proj = track.project(points[:, :2])
    along = (proj.s_m - s + track.length_m / 2) % track.length_m - track.length_m / 2
    assert np.abs(along).max() < 0.3
    assert np.allclose(proj.cte_m, offset, atol=0.05)


@pytest.mark.parametrize("name", ["lake", "mountain", "gen2:hard:2002"])
def test_projecting_a_few_points_equals_the_array_path_bit_for_bit(name, monkeypatch):
    # A car's centre and tyres take the plain-Python path every step; a scenery build's
    # thousands of points take NumPy's. Both must give the same floats.
    track = load_track(name)
    rng = np.random.default_rng(1)
    s = rng.uniform(0, track.length_m, 600)
    s[:30] = rng.uniform(-0.3, 0.3, 30) % track.length_m  # either side of the start line
    offset = rng.normal(0.0, 4.0, 600)
    offset[:10] *= 25.0  # far off the road
    points = track.offset_point(s, offset)[:, :2]
    points[::7] = track.xyz[rng.integers(0, len(track.s), len(points[::7])), :2]  # on samples
    monkeypatch.setattr(track_module, "SMALL_PROJECTION", 0)
    whole = track.project(points)
    monkeypatch.setattr(track_module, "SMALL_PROJECTION", 8)
    for start in range(0, len(points), 5):
        few = track.project(points[start : start + 5])
        for field in ("s_m", "cte_m", "half_width_m", "z_m"):
            np.testing.assert_array_equal(getattr(few, field),
                                          getattr(whole, field)[start : start + 5])
    one = track.project(points[3])  # a single (2,) point keeps its scalar shape
    assert one.s_m.shape == () and one.s_m == whole.s_m[3]


def test_right_of_centre_is_positive_cte():
    track = Track(TrackSpec.from_dict(circle_spec(50.0)))  # counter-clockwise
    # Driving counter-clockwise, the outside of the circle is on the right.
    outside = track.project(np.array([[53.0, 0.0]]))
    inside = track.project(np.array([[47.0, 0.0]]))
    assert outside.cte_m[0] == pytest.approx(3.0, abs=0.05)
    assert inside.cte_m[0] == pytest.approx(-3.0, abs=0.05)


def test_on_road_uses_half_width():
    track = load_track("lake")
    s = np.full(4, 200.0)
    points = track.offset_point(s, np.array([0.0, 3.9, -3.9, 4.2]))
    assert track.on_road(points[:, :2]).tolist() == [True, True, True, False]


def test_surface_height_and_normal_follow_grade():
    track = load_track("mountain")
    s = float(np.argmax(np.abs(track.grade_table)) * track.ds_m)
    z, normal = track.surface(track.offset_point(s, 2.0)[None, :2])
    assert z[0] == pytest.approx(track.point(s)[2], abs=0.05)
    grade = track.grade(s)
    tilt = math.degrees(math.acos(normal[0, 2]))
    assert tilt == pytest.approx(math.degrees(math.atan(abs(grade))), abs=0.3)


def test_start_pose_heads_along_the_road():
    track = load_track("lake")
    x, y, z, yaw = track.start_pose()
    ahead = track.point(5.0)
    assert math.atan2(ahead[1] - y, ahead[0] - x) == pytest.approx(yaw, abs=0.02)
    _, _, _, back = track.start_pose(reverse=True)
    assert abs(abs(back - yaw) - math.pi) < 1e-6


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"centerline": [[0, 0, 0]] * 5}, "at least 8"),
        ({"colour": "red"}, "unknown key(s) 'colour'"),
        ({"theme": "moon"}, "theme 'moon'"),
        ({"width_m": -1}, "width_m"),
        ({"centerline": [[0, 0, 0], [1, "a", 0]] + [[i, i, 0] for i in range(8)]},
         "centerline point 1"),
    ],
)
def test_invalid_specs_say_what_is_wrong(change, message):
    data = circle_spec()
    data.update(change)
    with pytest.raises(TrackError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Track(TrackSpec.from_dict(data, source="bad.json"))


def test_too_tight_curve_is_rejected_with_where():
    with pytest.raises(TrackError) as error:
        Track(TrackSpec.from_dict(circle_spec(radius_m=5.0)))
    assert "undrivable" in str(error.value)
    assert "s=" in str(error.value)
    assert MIN_DRIVABLE_RADIUS_M == pytest.approx(2.7 / math.tan(math.radians(25)))


def test_self_intersection_is_rejected_with_where():
    t = np.linspace(0, 2 * math.pi, 40, endpoint=False)
    figure_eight = [[200 * math.sin(a), 100 * math.sin(2 * a), 0.0] for a in t]
    data = circle_spec()
    data["centerline"] = figure_eight
    with pytest.raises(TrackError, match=r"intersects or overlaps itself between s=\d+"):
        Track(TrackSpec.from_dict(data))


def test_file_errors_name_the_file(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text("{ not json")
    with pytest.raises(TrackError, match="broken.json: not valid JSON"):
        Track.from_file(path)
    path.write_text(json.dumps(circle_spec(extra_key=1)))
    with pytest.raises(TrackError, match="broken.json: unknown key"):
        load_track(str(path))
    with pytest.raises(TrackError, match="unknown track 'nowhere'"):
        load_track("nowhere")


def test_spec_round_trips_through_json(tmp_path):
    track = load_track("lake")
    path = tmp_path / "copy.json"
    path.write_text(json.dumps(track.spec.to_dict()))
    copy = load_track(str(path))
    assert copy.length_m == pytest.approx(track.length_m, rel=1e-4)


def test_generated_tracks_are_valid_and_reproducible():
    a, b = generate(17, version=1), load_track("gen:17")
    assert np.array_equal(a.xyz, b.xyz)
    assert a.name == "gen:17"
    assert not np.array_equal(generate(18, version=1).xyz[:10], a.xyz[:10])
    themes = set()
    for seed in range(20):
        track = generate(seed, version=1)
        assert 650 <= track.length_m <= 1900
        assert track.min_radius_m >= 15.0
        themes.add(track.theme)
    assert themes == {"lake", "mountain"}
    with pytest.raises(TrackError, match="integer seed"):
        load_track("gen:x")
