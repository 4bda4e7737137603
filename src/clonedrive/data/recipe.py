"""Dataset recipes: which recordings to train on, and how each is turned into samples.

A recipe is a TOML file listing recordings and, per recording, what the write-up did by hand::

    # paths are relative to this file's folder (or to ``root`` if given)
    root = "recordings"

    [defaults]                 # optional; applies to every [[recording]] below
    cameras = "all"            # "center", or "all" = center + left/right with correction
    correction = 0.2           # added to the left camera's label, subtracted from the right's
    flip = true                # also add a mirrored copy of every sample, steering negated
    steering_offset = 0.0      # added to every label of the recording
    weight = 1.0               # loss weight of the recording's samples

    [[recording]]
    path = "middle"            # a folder holding driving_log.csv and IMG/ (required)
    name = "middle"            # optional; defaults to the folder name

    [[recording]]
    path = "left"
    cameras = "center"
    steering_offset = 0.25     # the car drove along the left edge: steer back right

Steering is in [-1, 1] (wheel angle / 25 deg, positive = right). A sample's label is
``steering + steering_offset + camera_correction`` (``+correction`` for the left camera,
``-correction`` for the right, 0 for the center), clipped to [-1, 1], then negated for a
flipped copy. Unknown keys anywhere are errors naming the key and the file.

:func:`expand` reads every recording (through :mod:`clonedrive.data.driving_log`, the only
CSV reader) and returns flat per-sample arrays (:class:`~clonedrive.data.samples.Samples`).
A sample's speed label is the expert's target speed where the recording has one
(``target_speed.csv``, see :mod:`clonedrive.data.speed_labels`), else the row's recorded
speed.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.base.config import parse_toml
from clonedrive.base.udacity_spec import CONTROL_HZ, STEERING_CORRECTION
from clonedrive.data.driving_log import CAMERAS, image_time, read_driving_log
from clonedrive.data.samples import Samples
from clonedrive.data.speed_labels import label_or_recorded

CAMERA_MODES = ("center", "all")
DEFAULT_CORRECTION = STEERING_CORRECTION
#: Side-camera steering corrections a recording may use [steering units].
CORRECTION_RANGE = (0.0, 1.0)
#: Sampling period assumed for a row whose image name carries no timestamp (15 Hz), seconds.
FALLBACK_ROW_PERIOD_S = 1.0 / CONTROL_HZ

_TOP_KEYS = ("root", "defaults", "recording")
#: The keys of [defaults] and of each [[recording]] that say how a recording becomes samples.
SETTING_KEYS = ("cameras", "correction", "steering_offset", "flip", "weight")
_SETTING_KEYS = SETTING_KEYS
_RECORDING_KEYS = ("path", "name", *_SETTING_KEYS)
_CAMERA_CODES = {camera: index for index, camera in enumerate(CAMERAS)}


@dataclass(frozen=True)
class RecordingSpec:
    """How one recording becomes samples."""

    path: Path  # folder holding driving_log.csv and IMG/ (absolute)
    name: str  # unique within a recipe
    cameras: str = "all"  # "center" or "all"
    correction: float = DEFAULT_CORRECTION  # side-camera steering correction, [-1, 1] units
    steering_offset: float = 0.0  # added to every label, [-1, 1] units
    flip: bool = True  # add a mirrored copy of every sample with negated steering
    weight: float = 1.0  # loss weight of every sample of this recording


@dataclass(frozen=True)
class Recipe:
    """An ordered list of recordings; ``source`` says where it came from (file or origin)."""

    recordings: tuple[RecordingSpec, ...]
    source: str = "<recipe>"


# --- loading --------------------------------------------------------------------------------


def load_recipe(path: str | os.PathLike) -> Recipe:
    """Read a recipe TOML file. Relative recording paths are taken from the file's folder
    (or from its ``root``, itself relative to the file's folder)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"recipe file {path} does not exist") from None
    return parse_recipe(text, source=str(path), base_dir=path.parent)


def parse_recipe(
    text: str, *, source: str = "<recipe>", base_dir: str | os.PathLike = "."
) -> Recipe:
    """Parse recipe TOML ``text``; errors name ``source`` and the offending key."""
    data = parse_toml(text, source=source)
    return recipe_from_table(data, source=source, base_dir=base_dir)


def recipe_from_table(
    data: Mapping, *, source: str = "<recipe>", base_dir: str | os.PathLike = "."
) -> Recipe:
    """A Recipe from a parsed recipe table (``root``, ``defaults``, ``recording``); errors name
    ``source`` and the offending key."""
    reject_unknown(data, _TOP_KEYS, source, "top level")

    base = Path(base_dir)
    root = data.get("root", ".")
    if not isinstance(root, str):
        raise ValueError(f"{source}: 'root' must be a string (a folder path)")
    base = (base / root).absolute()

    defaults_table = data.get("defaults", {})
    if not isinstance(defaults_table, dict):
        raise ValueError(f"{source}: [defaults] must be a table")
    reject_unknown(defaults_table, _SETTING_KEYS, source, "[defaults]")
    defaults = _settings(defaults_table, source, "[defaults]", {})

    entries = data.get("recording")
    if not entries:
        raise ValueError(f"{source}: no [[recording]] entries; a recipe needs at least one")
    if not isinstance(entries, list) or not all(isinstance(entry, dict) for entry in entries):
        raise ValueError(f"{source}: 'recording' must be an array of tables ([[recording]])")

    recordings = []
    for number, entry in enumerate(entries, start=1):
        where = f"[[recording]] #{number}"
        reject_unknown(entry, _RECORDING_KEYS, source, where)
        if "path" not in entry:
            raise ValueError(f"{source}: {where} has no 'path' (the recording's folder)")
        if not isinstance(entry["path"], str) or not entry["path"]:
            raise ValueError(f"{source}: {where}: 'path' must be a non-empty string")
        folder = (base / entry["path"]).absolute()
        name = entry.get("name", folder.name)
        if not isinstance(name, str) or not name:
            raise ValueError(f"{source}: {where}: 'name' must be a non-empty string")
        settings = _settings(entry, source, where, defaults)
        recordings.append(RecordingSpec(path=folder, name=name, **settings))
    return _checked(Recipe(tuple(recordings), source=source))


def default_recipe_for(
    dirs: Sequence[str | os.PathLike],
    *,
    correction: float = DEFAULT_CORRECTION,
    cameras: str = "all",
    flip: bool = True,
) -> Recipe:
    """The recipe ``clonedrive train DIR [DIR ...]`` uses: every folder with all three
    cameras (side cameras corrected by ``correction``), flipped copies, no offset, weight 1."""
    if not dirs:
        raise ValueError("no recording folders given")
    settings = _settings(
        {"cameras": cameras, "correction": correction, "flip": flip}, "command line", "options", {}
    )
    recordings = []
    for folder in dirs:
        folder = Path(folder).absolute()
        recordings.append(RecordingSpec(path=folder, name=folder.name, **settings))
    return _checked(Recipe(tuple(recordings), source="command line"))


def recipe_to_toml(recipe: Recipe) -> str:
    """TOML text that :func:`parse_recipe` reads back as ``recipe`` (absolute paths)."""
    lines = [f"# recipe from {_toml_string(str(recipe.source))}", ""]
    for spec in recipe.recordings:
        lines += [
            "[[recording]]",
            f"path = {_toml_string(str(spec.path))}",
            f"name = {_toml_string(spec.name)}",
            f"cameras = {_toml_string(spec.cameras)}",
            f"correction = {spec.correction!r}",
            f"steering_offset = {spec.steering_offset!r}",
            f"flip = {'true' if spec.flip else 'false'}",
            f"weight = {spec.weight!r}",
            "",
        ]
    return "\n".join(lines)


def reject_unknown(table: Mapping, known: Sequence[str], source: str, where: str) -> None:
    """``ValueError`` naming ``source``, ``where`` and the first key of ``table`` not in
    ``known``."""
    for key in table:
        if key not in known:
            raise ValueError(
                f"{source}: unknown key {key!r} in {where}; expected one of: {', '.join(known)}"
            )


def _settings(table: Mapping, source: str, where: str, defaults: Mapping) -> dict:
    """The RecordingSpec settings in ``table`` (falling back to ``defaults``), validated."""
    values = {
        field.name: field.default
        for field in dataclasses.fields(RecordingSpec)
        if field.name in _SETTING_KEYS
    }
    values.update(defaults)
    values.update({key: table[key] for key in _SETTING_KEYS if key in table})

    if values["cameras"] not in CAMERA_MODES:
        raise ValueError(
            f"{source}: {where}: cameras = {values['cameras']!r}; expected one of: "
            f"{', '.join(repr(mode) for mode in CAMERA_MODES)}"
        )
    for key, low, high in (
        ("correction", *CORRECTION_RANGE),
        ("steering_offset", -1.0, 1.0),
        ("weight", 0.0, math.inf),
    ):
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{source}: {where}: {key} = {value!r}; expected a number")
        if not (low <= value <= high) or not math.isfinite(value):
            raise ValueError(
                f"{source}: {where}: {key} = {value!r}; expected a finite number in "
                f"[{low:g}, {high:g}]"
            )
        values[key] = float(value)
    if not isinstance(values["flip"], bool):
        raise ValueError(f"{source}: {where}: flip = {values['flip']!r}; expected true or false")
    return values


def _checked(recipe: Recipe) -> Recipe:
    names = [spec.name for spec in recipe.recordings]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(
            f"{recipe.source}: recording name(s) {', '.join(duplicates)} used twice; give each "
            "[[recording]] a distinct 'name'"
        )
    return recipe


def _toml_string(text: str) -> str:
    """A TOML basic string holding ``text`` exactly: backslash, quote and every control
    character (a newline in a folder name, say) escaped."""
    out = []
    for char in text:
        if char in ('"', "\\"):
            out.append("\\" + char)
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


# --- expansion into samples -----------------------------------------------------------------


def expand(recipe: Recipe, *, verify_images: str = "exists") -> Samples:
    """Read every recording of ``recipe`` and list its samples.

    Per CSV row: the center camera, plus left and right with ``cameras = "all"`` (those
    whose image exists: a center-only data set gives center samples, counted in
    ``Samples.side_images_missing``); each of those again mirrored when ``flip``. Rows the
    log reader skips (missing center image, bad numbers, ...) are counted in
    ``Samples.skipped`` by reason; a recording folder without a ``driving_log.csv`` raises
    ``FileNotFoundError`` naming it.
    """
    unique_paths: list[Path] = []
    path_index: dict[Path, int] = {}
    columns: dict[str, list] = {
        key: [] for key in ("image", "camera", "steering", "flip", "recording", "row", "time",
                            "speed", "recorded_speed")
    }
    weights: list[np.ndarray] = []
    skipped: dict[str, int] = {}
    skipped_details: list[str] = []
    rows_read = 0
    side_images_missing = 0
    rows_with_target_speed = 0

    for recording_number, spec in enumerate(recipe.recordings):
        log = read_driving_log(spec.path, verify_images=verify_images)
        for item in log.skipped:
            skipped[item.reason] = skipped.get(item.reason, 0) + 1
            skipped_details.append(f"{spec.name}: {item.detail}")
        rows_read += len(log.rows)
        side_images_missing += log.side_images_missing
        rows_with_target_speed += sum(row.target_speed_mph is not None for row in log.rows)
        if not log.rows:
            continue
        times = _row_times_s(log.rows)
        cameras = CAMERAS if spec.cameras == "all" else ("center",)
        corrections = {"center": 0.0, "left": spec.correction, "right": -spec.correction}
        count_before = len(columns["steering"])
        for row, time_s in zip(log.rows, times, strict=True):
            for camera in cameras:
                if camera not in row.cameras:  # its image is missing: the row has the others
                    continue
                image_path = row.image(camera)
                index = path_index.get(image_path)
                if index is None:
                    index = path_index[image_path] = len(unique_paths)
                    unique_paths.append(image_path)
                label = float(np.clip(row.steering + spec.steering_offset + corrections[camera],
                                      -1.0, 1.0))
                speed_label = label_or_recorded(row.target_speed_mph, row.speed_mph)
                for flipped in (False, True) if spec.flip else (False,):
                    columns["image"].append(index)
                    columns["camera"].append(_CAMERA_CODES[camera])
                    columns["steering"].append(-label + 0.0 if flipped else label)
                    columns["flip"].append(flipped)
                    columns["recording"].append(recording_number)
                    columns["row"].append(row.row)
                    columns["time"].append(time_s)
                    columns["speed"].append(speed_label)
                    columns["recorded_speed"].append(row.speed_mph)
        added = len(columns["steering"]) - count_before
        weights.append(np.full(added, spec.weight, dtype=np.float32))

    return Samples(
        unique_paths=unique_paths,
        image_index=np.asarray(columns["image"], dtype=np.int64),
        camera=np.asarray(columns["camera"], dtype=np.int8),
        steering=np.asarray(columns["steering"], dtype=np.float32),
        flip=np.asarray(columns["flip"], dtype=bool),
        recording=np.asarray(columns["recording"], dtype=np.int32),
        row=np.asarray(columns["row"], dtype=np.int64),
        time_s=np.asarray(columns["time"], dtype=np.float64),
        weight=np.concatenate(weights) if weights else np.zeros(0, dtype=np.float32),
        target_speed_mph=np.asarray(columns["speed"], dtype=np.float32),
        recorded_speed_mph=np.asarray(columns["recorded_speed"], dtype=np.float32),
        recording_names=tuple(spec.name for spec in recipe.recordings),
        skipped=skipped,
        skipped_details=skipped_details,
        rows_read=rows_read,
        side_images_missing=side_images_missing,
        rows_with_target_speed=rows_with_target_speed,
    )


def _row_times_s(rows) -> np.ndarray:
    """Seconds since the first row, from the center image names' timestamps; if any name
    carries none, row order at :data:`FALLBACK_ROW_PERIOD_S` per row instead."""
    moments = [image_time(row.center) for row in rows]
    if any(moment is None for moment in moments):
        return np.arange(len(rows), dtype=np.float64) * FALLBACK_ROW_PERIOD_S
    origin = moments[0]
    return np.array([(moment - origin).total_seconds() for moment in moments], dtype=np.float64)
