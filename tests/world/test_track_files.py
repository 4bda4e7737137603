"""Track files at and beyond their bounds: each problem is one TrackError line naming the limit."""

import json
import math

import pytest

from clonedrive.world.catalog import load_track
from clonedrive.world.generate import generate
from clonedrive.world.track import (
    MAX_CONTROL_POINTS,
    MAX_COORDINATE_M,
    MAX_TRACK_FILE_BYTES,
    MAX_TRACK_LENGTH_M,
    NEWEST_TRACK_VERSION,
    Track,
    TrackError,
    TrackSpec,
)


def circle(radius_m: float, count: int = 40, **extra) -> dict:
    angles = [2 * math.pi * i / count for i in range(count)]
    points = [[radius_m * math.cos(a), radius_m * math.sin(a), 0.0] for a in angles]
    return {"name": "circle", "version": 1, "theme": "lake", "width_m": 8.0, "closed": True,
            "centerline": points, **extra}


def write(tmp_path, data, name="t.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return path


def one_line_error(path) -> str:
    with pytest.raises(TrackError) as caught:
        Track.from_file(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    return message


def test_a_huge_circle_is_refused_before_allocation(tmp_path):
    # A 2 KB file describing a 63,000 km road (it once made the process allocate 24 GB).
    message = one_line_error(write(tmp_path, circle(1e7)))
    assert f"+-{MAX_COORDINATE_M:g} m" in message


def test_length_coordinates_and_point_count_each_name_their_limit(tmp_path):
    # Inside the coordinate range, but far longer than allowed: a zig-zag of 9 km strides.
    zigzag = circle(100.0)
    zigzag["centerline"] = [[9000.0 * (i % 2) - 4500.0, i * 10.0, 0.0] for i in range(40)]
    assert f"at most {MAX_TRACK_LENGTH_M / 1000:g} km" in one_line_error(write(tmp_path, zigzag))
    many = circle(3000.0, count=MAX_CONTROL_POINTS + 1)
    assert f"at most {MAX_CONTROL_POINTS} are allowed" in one_line_error(write(tmp_path, many))


def test_a_track_at_the_bounds_loads(tmp_path):
    radius = 0.99 * MAX_TRACK_LENGTH_M / (2 * math.pi)
    track = Track.from_file(write(tmp_path, circle(radius, count=2000)))
    assert MAX_TRACK_LENGTH_M * 0.98 < track.length_m <= MAX_TRACK_LENGTH_M


def test_file_size_is_capped_before_reading(tmp_path):
    path = tmp_path / "big.json"
    with open(path, "wb") as handle:
        handle.truncate(MAX_TRACK_FILE_BYTES + 1)  # sparse: nothing is written or read
    assert "2 MiB" in one_line_error(path)


@pytest.mark.parametrize("content, expected", [
    (json.dumps(circle(100.0)).encode("utf-16"), "UTF-16"),
    (json.dumps(circle(100.0)).encode("utf-16-le"), "UTF-16"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF\x00", "binary"),
    (b"{\"name\": \"caf\xe9\"}", "not UTF-8"),
    (b"[" * 100_000 + b"]" * 100_000, "levels deep"),
    (b"[" * 40 + b"]" * 40, "nested at most"),
    (b'{"name": "x", "width_m": ' + b"9" * 5000 + b"}", "5000 characters"),
    (b'{"name": "x", "width_m": NaN}', "NaN is not a JSON number"),
    (b"{ not json", "not valid JSON"),
])
def test_hostile_json_gets_one_clear_line(tmp_path, content, expected):
    path = tmp_path / "hostile.json"
    path.write_bytes(content)
    assert expected in one_line_error(path)


def test_a_folder_given_as_the_track(tmp_path):
    folder = tmp_path / "tracks.json"
    folder.mkdir()
    assert "is a folder" in one_line_error(folder)
    with pytest.raises(TrackError, match="is a folder"):
        load_track(str(folder))


@pytest.mark.parametrize("version, expected", [
    (99, f"newer than this clonedrive knows \\(1 to {NEWEST_TRACK_VERSION}\\)"),
    (0, "whole number >= 1"), (1.5, "whole number >= 1"), ("1", "whole number >= 1"),
    (True, "whole number >= 1"),
])
def test_versions_outside_those_known_are_refused(tmp_path, version, expected):
    with pytest.raises(TrackError, match=expected):
        Track.from_file(write(tmp_path, circle(100.0, version=version)))


def test_known_tracks_use_known_versions():
    for track in (load_track("lake"), load_track("mountain"), generate(3)):
        assert 1 <= track.version <= NEWEST_TRACK_VERSION


@pytest.mark.parametrize("name", [["a"], "", "x" * 201, 7])
def test_names_must_be_short_text(tmp_path, name):
    with pytest.raises(TrackError, match="name must be a text"):
        Track.from_file(write(tmp_path, circle(100.0, name=name)))


def test_booleans_are_not_coordinates():
    data = circle(100.0)
    data["centerline"][3] = [True, 1.0, 0.0]
    with pytest.raises(TrackError, match="centerline point 3"):
        TrackSpec.from_dict(data)


def test_built_in_and_generated_tracks_are_made_once_and_read_only(tmp_path):
    lake = load_track("lake")
    assert load_track("lake") is lake  # the file is read once per process
    assert load_track("gen2:hard:5") is load_track("gen2:hard:5")
    for track in (lake, load_track("gen2:hard:5")):
        with pytest.raises(ValueError, match="read-only"):
            track.xyz[0, 0] = 1.0  # a write would change every caller's track
    # A track file is read again each time: it may have changed in between.
    path = tmp_path / "copy.json"
    path.write_text(json.dumps(lake.spec.to_dict()))
    first = load_track(str(path))
    assert load_track(str(path)) is not first
    first.xyz[0, 0] += 1.0  # and it is the caller's own
