"""A model file carries how it is to be driven; commands use it unless told otherwise."""

from __future__ import annotations

import shutil
import zipfile

import numpy as np
import pytest

from clonedrive.base.udacity_spec import IMAGE_SHAPE
from clonedrive.drivers.policy import load_policy
from clonedrive.network.driving_settings import (
    KERAS_MEMBER,
    MAX_NOTES_BYTES,
    DrivingSettings,
    notes_for,
    read_notes,
    stored_settings,
    with_defaults,
    write_notes,
)

CALM = DrivingSettings(steering_hold=0.02, mirror_average=True)


def _copy(source, tmp_path, name):
    target = tmp_path / name
    shutil.copy(source, target)
    return target


@pytest.mark.parametrize("kind", ["keras", "h5"])
def test_settings_survive_in_the_one_file_and_the_model_still_loads(
        kind, tiny_model_path, tiny_h5_path, tmp_path):
    source = tiny_model_path if kind == "keras" else tiny_h5_path
    path = _copy(source, tmp_path, f"m.{kind}")
    assert stored_settings(path) is None  # a file without notes: drive.py's defaults
    write_notes(path, notes_for(CALM, {"name": "best", "version": 3}))
    (tmp_path / "elsewhere").mkdir()
    copied = _copy(path, tmp_path / "elsewhere", f"copy.{kind}")
    assert stored_settings(copied) == CALM
    assert read_notes(copied)["recipe"] == {"name": "best", "version": 3}
    policy = load_policy(copied)
    assert policy.driving_settings() == CALM
    assert policy.notes["recipe"]["name"] == "best"


def test_notes_are_replaced_not_duplicated(tiny_model_path, tmp_path):
    path = _copy(tiny_model_path, tmp_path, "m.keras")
    write_notes(path, notes_for(CALM))
    write_notes(path, notes_for(DrivingSettings(slow_in_curves=True)))
    with zipfile.ZipFile(path) as archive:
        assert [info.filename for info in archive.infolist()].count(KERAS_MEMBER) == 1
    assert stored_settings(path) == DrivingSettings(slow_in_curves=True)


def test_options_given_override_the_file_one_by_one(tiny_model_path, tmp_path):
    path = _copy(tiny_model_path, tmp_path, "m.keras")
    write_notes(path, notes_for(CALM))
    policy = load_policy(path, mirror_average=False, steering_hold=None)
    assert policy.mirror_average is False
    assert policy.steering_hold == 0.02  # None leaves the file's setting


def test_a_model_without_notes_drives_as_drive_py(tiny_model_path):
    policy = load_policy(tiny_model_path)
    assert policy.driving_settings() == DrivingSettings()
    assert policy.notes == {}
    frame = np.full((1, *IMAGE_SHAPE), 100, dtype=np.uint8)
    assert policy.predict_steering(frame).shape == (1,)


@pytest.mark.parametrize("notes, message", [
    ("not json", "not valid JSON"),
    ('["a list"]', "not a JSON object"),
    ('{"driving": {"steering_hold": -1}}', "steering_hold"),
    ('{"driving": {"warp_speed": true}}', "warp_speed"),
    ("x" * (MAX_NOTES_BYTES + 1), "over"),
])
def test_bad_notes_are_refused_naming_the_file(notes, message, tiny_model_path, tmp_path):
    path = _copy(tiny_model_path, tmp_path, "bad.keras")
    with zipfile.ZipFile(path, "a") as archive:
        archive.writestr(KERAS_MEMBER, notes)
    with pytest.raises(ValueError, match=message) as caught:
        load_policy(path)
    assert "bad.keras" in str(caught.value)


@pytest.mark.parametrize("values", [{"steering_hold": 1.5}, {"mirror_average": "yes"},
                                    {"steering_filter_s": float("nan")}, {"speed_scale": 0},
                                    {"speed_scale": 2.0}, {"speed_scale": True},
                                    {"speed_scale": float("inf")}, {"full_speed_at": 0.8},
                                    {"full_speed_at": 1.01}, {"full_speed_at": "0.9"},
                                    {"steering_scale_from_mph": 3.0},
                                    {"steering_scale_from_mph": -24.0},
                                    {"steering_scale_from_mph": float("nan")},
                                    {"caution": -1.0, "mirror_average": True},
                                    {"caution": 1e3, "mirror_average": True},
                                    {"caution_from": 0.5}, {"caution_from": float("inf")}])
def test_bad_settings_are_refused(values):
    with pytest.raises(ValueError):
        DrivingSettings(**values)


def test_describe_names_what_is_on():
    assert "mirror averaging" in CALM.describe() and "hold 0.02" in CALM.describe()
    assert "drive.py" in DrivingSettings().describe()
    assert "learned speed x1.05" in DrivingSettings(speed_scale=1.05).describe()
    assert "full speed from 0.92 of the set speed" in \
        DrivingSettings(full_speed_at=0.92).describe()
    assert "steering times 24 mph / speed above 24 mph" in \
        DrivingSettings(steering_scale_from_mph=24).describe()
    assert "mirror image disagree by more than 0.012 (caution 40)" in \
        DrivingSettings(mirror_average=True, caution=40, caution_from=0.012).describe()


def test_a_file_made_before_speed_scale_drives_at_the_learned_speed(tiny_model_path, tmp_path):
    path = _copy(tiny_model_path, tmp_path, "old.keras")
    with zipfile.ZipFile(path, "a") as archive:  # notes as files carried them before
        archive.writestr(KERAS_MEMBER, '{"driving": {"steering_hold": 0.01, '
                                       '"mirror_average": true}}')
    assert load_policy(path).speed_scale == 1.0
    assert load_policy(path, speed_scale=1.1).speed_scale == 1.1
    assert load_policy(path).steering_scale_from_mph == 0.0  # nor scales its steering


def test_a_recorded_run_without_a_later_setting_reads_as_its_default():
    recorded = {"mirror_average": True, "steering_hold": 0.02}  # before speed_scale existed
    filled = with_defaults(recorded)
    assert filled["speed_scale"] == 1.0 and filled["steering_hold"] == 0.02
    assert DrivingSettings(**filled) == DrivingSettings(mirror_average=True, steering_hold=0.02)
    assert with_defaults({"speed_scale": 1.05})["speed_scale"] == 1.05
    assert with_defaults(recorded)["full_speed_at"] == 1.0  # before full_speed_at existed
    assert with_defaults(recorded)["steering_scale_from_mph"] == 0.0
    assert with_defaults(recorded)["caution"] == 0.0  # before caution existed


def test_copy_notes_gives_a_file_anothers_settings(tiny_model_path, tmp_path):
    from clonedrive.network.driving_settings import copy_notes

    source = _copy(tiny_model_path, tmp_path, "source.keras")
    write_notes(source, notes_for(CALM, {"name": "best", "version": 1}))
    target = _copy(tiny_model_path, tmp_path, "target.keras")
    copy_notes(source, target)
    assert read_notes(target) == read_notes(source)
    plain = _copy(tiny_model_path, tmp_path, "plain.keras")
    copy_notes(plain, target)  # a source without notes leaves the target's
    assert stored_settings(target) == CALM
    other = tmp_path / "weights.bin"
    other.write_bytes(b"x")
    copy_notes(source, other)  # a kind of file that holds none: untouched
    assert other.read_bytes() == b"x"
