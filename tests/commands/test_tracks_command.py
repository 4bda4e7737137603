"""``clonedrive tracks`` through the CLI: the figures, the maps and camera strips it writes,
and one clear line for what it cannot do."""

from __future__ import annotations

import json

import pytest

from clonedrive.base.images import read_rgb
from clonedrive.cli import main
from clonedrive.commands.tracks import TracksConfig
from clonedrive.world.catalog import builtin_track_names, load_track


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(arg) for arg in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_lists_every_built_in_track_with_its_figures(capsys, tmp_path):
    code, out, err = run(capsys, "tracks", "--no-images", "--json", "--out", tmp_path / "x")
    assert code == 0, err
    rows = json.loads(out)
    assert [row["name"] for row in rows] == list(builtin_track_names())
    for row in rows:
        assert row == load_track(row["name"]).summary()
        assert row["length_m"] > 500 and row["min_radius_m"] > 5
    assert not (tmp_path / "x").exists()  # --no-images writes nothing


def test_a_generated_track_gets_a_map_and_a_table_row(capsys, tmp_path):
    code, out, err = run(capsys, "tracks", "--track", "gen:3", "--out", tmp_path, "--no-strip")
    assert code == 0, err
    header, row = out.splitlines()[:2]
    assert header.split()[:3] == ["track", "length", "m"]
    summary = load_track("gen:3").summary()
    assert row.split()[0] == "gen:3" and float(row.split()[1]) == round(summary["length_m"])
    maps = list(tmp_path.iterdir())
    assert [path.name for path in maps] == ["gen_3_map.png"]
    assert f"wrote {maps[0]}" in out
    image = read_rgb(maps[0])
    assert image.shape[0] > 200 and image.std() > 10


def test_the_camera_strip_shows_three_cameras_at_each_place(capsys, tmp_path):
    code, out, err = run(capsys, "tracks", "--track", "lake", "--out", tmp_path, "--json")
    assert code == 0, err
    (row,) = json.loads(out)
    strip = read_rgb(row["cameras_png"])
    height, width = strip.shape[:2]
    assert width >= 3 * 320 and height >= 160  # left, center, right side by side, a row a place
    assert read_rgb(row["map_png"]).std() > 10


def test_bad_input_is_one_clear_line(capsys, tmp_path):
    code, _, err = run(capsys, "tracks", "--track", "nowhere", "--no-images")
    assert code == 2 and err.startswith("clonedrive tracks: ") and "nowhere" in err
    assert len(err.strip().splitlines()) == 1
    a_file = tmp_path / "maps.png"
    a_file.write_text("not a folder")
    code, _, err = run(capsys, "tracks", "--track", "gen:3", "--out", a_file)
    assert code == 2 and "not a folder" in err and str(a_file) in err
    assert a_file.read_text() == "not a folder"


def test_the_options_default_to_the_config():
    from clonedrive.cli import build_parser

    args = build_parser().parse_args(["tracks"])
    defaults = TracksConfig()
    assert (args.out, args.images, args.strip) == (defaults.out, defaults.images, defaults.strip)
    with pytest.raises(ValueError, match="not one string"):
        TracksConfig(tracks="lake")
    with pytest.raises(ValueError, match="not a track name"):
        TracksConfig(tracks=("lake", " "))
