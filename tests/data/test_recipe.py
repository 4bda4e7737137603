"""Dataset recipes: TOML parsing and its errors, the default and write-up recipes, expansion."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from clonedrive.data.driving_log import CAMERAS, read_driving_log
from clonedrive.data.recipe import (
    Recipe,
    RecordingSpec,
    default_recipe_for,
    expand,
    load_recipe,
    parse_recipe,
    recipe_to_toml,
)

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "udacity"
LAKE = FIXTURES / "lake_posix_mixed_columns"
MOUNTAIN = FIXTURES / "mountain_windows_paths"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "recipe.toml"
    path.write_text(text, encoding="utf-8")
    return path


# --- parsing -------------------------------------------------------------------------------


def test_recipe_defaults_overrides_and_relative_paths(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        """
root = "recordings"
[defaults]
cameras = "center"
correction = 0.15
flip = false

[[recording]]
path = "middle"

[[recording]]
path = "edge"
name = "left edge"
cameras = "all"
steering_offset = 0.25
weight = 2
""",
    )
    recipe = load_recipe(path)
    assert recipe.source == str(path)
    middle, edge = recipe.recordings
    assert middle == RecordingSpec(
        path=(tmp_path / "recordings" / "middle").absolute(), name="middle", cameras="center",
        correction=0.15, steering_offset=0.0, flip=False, weight=1.0,
    )
    assert edge.name == "left edge" and edge.cameras == "all" and edge.correction == 0.15
    assert edge.steering_offset == 0.25 and edge.weight == 2.0 and edge.flip is False


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('colour = "red"\n[[recording]]\npath = "a"\n', r"unknown key 'colour' in top level"),
        ('[defaults]\nflips = true\n[[recording]]\npath = "a"\n',
         r"unknown key 'flips' in \[defaults\]"),
        ('[[recording]]\npath = "a"\ncamera = "all"\n',
         r"unknown key 'camera' in \[\[recording\]\] #1"),
        ('[[recording]]\nname = "a"\n', r"#1 has no 'path'"),
        ('[[recording]]\npath = "a"\ncameras = "left"\n', r"cameras = 'left'; expected one of"),
        ('[[recording]]\npath = "a"\ncorrection = "big"\n', r"correction = 'big'; expected a"),
        ('[[recording]]\npath = "a"\nsteering_offset = 1.5\n', r"steering_offset = 1.5"),
        ('[[recording]]\npath = "a"\nflip = 1\n', r"flip = 1; expected true or false"),
        ('[[recording]]\npath = "a"\n[[recording]]\npath = "b/a"\n', r"name\(s\) a used twice"),
        ("root = 3\n", r"'root' must be a string"),
        ("", r"no \[\[recording\]\] entries"),
        ("[[recording]\n", r"not valid TOML"),
    ],
)
def test_recipe_errors_name_the_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match=message) as error:
        load_recipe(path)
    assert str(path) in str(error.value)


def test_missing_recipe_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="recipe file .*nope.toml does not exist"):
        load_recipe(tmp_path / "nope.toml")


def test_default_recipe_for_folders() -> None:
    recipe = default_recipe_for([LAKE, str(MOUNTAIN)])
    assert [spec.name for spec in recipe.recordings] == [LAKE.name, MOUNTAIN.name]
    for spec in recipe.recordings:
        assert (spec.cameras, spec.correction, spec.flip) == ("all", 0.2, True)
        assert (spec.steering_offset, spec.weight) == (0.0, 1.0)
    assert default_recipe_for([LAKE], correction=0.1).recordings[0].correction == 0.1
    with pytest.raises(ValueError, match="no recording folders"):
        default_recipe_for([])


def test_recipe_to_toml_round_trips(tmp_path: Path) -> None:
    recipe = Recipe(
        (
            RecordingSpec(path=tmp_path / 'we"ird\\name', name="x", cameras="center",
                          correction=0.1, steering_offset=-0.25, flip=False, weight=0.5),
            RecordingSpec(path=tmp_path / "y", name="y"),
        )
    )
    assert parse_recipe(recipe_to_toml(recipe)).recordings == recipe.recordings


def test_names_with_newlines_and_control_characters_round_trip(tmp_path: Path) -> None:
    """A folder named with a newline (or a tab, or DEL) is written escaped, in the values and in
    the header comment, so ``train --resume`` and ``dagger`` read the recipe back."""
    odd = tmp_path / "line\nbreak\tand\x7fdel"
    recipe = Recipe((RecordingSpec(path=odd, name="a\nname"),), source=str(odd / "r.toml"))
    text = recipe_to_toml(recipe)
    assert "\n[[recording]]" in text and "line\nbreak" not in text
    assert parse_recipe(text).recordings == recipe.recordings


def test_expand_all_cameras_with_flips_labels_every_sample() -> None:
    samples = expand(default_recipe_for([LAKE]))
    rows = read_driving_log(LAKE).rows
    assert len(samples) == len(rows) * 3 * 2 and samples.rows_read == len(rows)
    assert len(samples.unique_paths) == len(rows) * 3  # a flipped copy shares its image
    assert samples.skipped == {}
    by_row = {row.row: row for row in rows}
    corrections = {"center": 0.0, "left": 0.2, "right": -0.2}
    for index in range(len(samples)):
        row = by_row[int(samples.row[index])]
        camera = CAMERAS[samples.camera[index]]
        assert samples.image_path(index) == row.image(camera)
        expected = np.clip(row.steering + corrections[camera], -1, 1)
        if samples.flip[index]:
            expected = -expected
        assert samples.steering[index] == pytest.approx(expected, abs=1e-6)
    assert samples.recording_names == (LAKE.name,)
    # Time comes from the image names: 0 at the first row, in recording order.
    assert samples.time_s[0] == 0.0 and np.all(np.diff(samples.time_s) >= 0)
    assert samples.time_s.max() > 1.0


def test_expand_center_offset_no_flip_and_weight(tmp_path: Path) -> None:
    recipe = parse_recipe(
        f'[[recording]]\npath = "{MOUNTAIN.as_posix()}"\ncameras = "center"\nflip = false\n'
        "steering_offset = -0.25\nweight = 3\n"
    )
    samples = expand(recipe)
    rows = read_driving_log(MOUNTAIN).rows
    assert len(samples) == len(rows)
    expected = np.clip([row.steering - 0.25 for row in rows], -1, 1)
    np.testing.assert_allclose(samples.steering, expected, atol=1e-6)
    assert not samples.flip.any() and np.all(samples.weight == 3.0)
    assert (samples.steering == -1.0).any()  # full left lock minus 0.25 is clipped to -1


def test_expand_counts_skipped_rows(tmp_path: Path) -> None:
    copy = tmp_path / "lake"
    shutil.copytree(LAKE, copy)
    rows = read_driving_log(copy).rows
    rows[3].center.unlink()
    rows[5].left.unlink()  # a missing side image turns that camera off for the row
    samples = expand(default_recipe_for([copy]))
    assert samples.skipped == {"image_missing": 1}
    assert samples.side_images_missing == 1
    assert len(samples) == (len(rows) - 2) * 6 + 4
    assert "lake:" in samples.skipped_details[0]


def test_expand_missing_recording_folder_names_it(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        expand(default_recipe_for([tmp_path / "nowhere"]))


def test_subset_compact_and_drop_images() -> None:
    samples = expand(default_recipe_for([LAKE]))
    part = samples.subset(np.arange(0, 12)).compact()  # rows 1 and 2: 6 images, 12 samples
    assert len(part) == 12 and len(part.unique_paths) == 6
    assert [part.image_path(i) for i in range(12)] == [samples.image_path(i) for i in range(12)]
    kept, dropped = part.drop_images([0])
    assert dropped == 2 and len(kept) == 10
    assert part.image_path(0) not in {kept.image_path(i) for i in range(len(kept))}
