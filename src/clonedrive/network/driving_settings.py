"""How a model wants to be driven, stored inside its own file.

A trained model knows what stands between it and the wheel: the hand-made curve rule, a
low-pass, the hold, mirror averaging (:class:`DrivingSettings`); whether it has a speed head and
what it crops are in the network itself. ``clonedrive train`` writes the settings of its recipe
into the model file, so copying the one file keeps them:

- ``.keras`` (a zip archive): a member ``clonedrive.json`` beside Keras's own, which Keras
  ignores when it loads the model;
- ``.h5``: an attribute ``clonedrive`` on the file's root group, which Keras ignores too;
- ``.onnx`` (``clonedrive export``): a ``clonedrive`` entry of the model's metadata.

Both hold ``{"driving": {...}, "recipe": {"name": ..., "version": ...}}``. A file without them (a
student's model, an old clonedrive model) drives with :class:`DrivingSettings`' defaults, which
are Udacity's ``drive.py``: none of these, steering passed straight to the wheel.
:func:`clonedrive.drivers.policy.load_policy` reads them; options a command is given override
them one by one.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path

#: The zip member of a ``.keras`` file holding the notes.
KERAS_MEMBER = "clonedrive.json"
#: The root attribute of an ``.h5`` file holding the notes.
H5_ATTRIBUTE = "clonedrive"
#: Notes larger than this are refused (they are a few hundred bytes).
MAX_NOTES_BYTES = 65_536


def full_speed_text(full_speed_at: float) -> str:
    """How eval.json and :meth:`DrivingSettings.describe` name the ``full_speed_at`` setting."""
    return f"full speed from {full_speed_at:g} of the set speed"


@dataclass(frozen=True)
class DrivingSettings:
    """What stands between the network's prediction and the controls (defaults: drive.py)."""

    #: the hand-made curve rule: the target speed falls as the predicted steering grows
    slow_in_curves: bool = False
    steering_filter_s: float = 0.0  #: low-pass time constant on the predicted steering [s]
    steering_hold: float = 0.0  #: hold the wheel through steering jitter smaller than this
    mirror_average: bool = False  #: average each frame's prediction with its mirror image's
    #: a speed head's target speed times this, still capped by the set speed (1: as learned)
    speed_scale: float = 1.0
    #: a speed head's target at or above this fraction of the set speed drives at the set
    #: speed; targets from :data:`STRETCH_FROM` of it up are stretched to match (1: as learned)
    full_speed_at: float = 1.0
    #: above this speed [mph] the wheel gets (this / speed) of the predicted steering, so a
    #: prediction turns the car no faster than it would at this speed (0: off, as drive.py)
    steering_scale_from_mph: float = 0.0
    #: slow where the network is unsure of its steering: the target speed is divided by
    #: ``1 + caution * max(0, disagreement - caution_from)``, the disagreement being half the
    #: gap between a frame's steering prediction and its mirror image's (steering units);
    #: without ``mirror_average`` there is nothing to compare and it does nothing (0: off)
    caution: float = 0.0
    #: the disagreement [steering units] below which ``caution`` does not slow: what a
    #: network's two views differ by where it knows the road (a lopsided scene's bias)
    caution_from: float = 0.0

    def __post_init__(self) -> None:
        for name in ("slow_in_curves", "mirror_average"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        check_steering_filter_s(self.steering_filter_s)
        check_steering_hold(self.steering_hold)
        check_speed_scale(self.speed_scale)
        check_full_speed_at(self.full_speed_at)
        check_steering_scale_from(self.steering_scale_from_mph)
        check_caution(self.caution)
        check_caution_from(self.caution_from)

    def options(self) -> dict:
        """These settings as NetworkPolicy's keyword arguments."""
        return dataclasses.asdict(self)

    def describe(self) -> str:
        """One line for people: what is on."""
        parts = []
        if self.mirror_average:
            parts.append("mirror averaging")
        if self.steering_scale_from_mph:
            limit = self.steering_scale_from_mph
            parts.append(f"steering times {limit:g} mph / speed above {limit:g} mph")
        if self.steering_hold:
            parts.append(f"steering hold {self.steering_hold:g}")
        if self.steering_filter_s:
            parts.append(f"steering low-pass {self.steering_filter_s:g} s")
        if self.slow_in_curves:
            parts.append("slower in curves (the hand-made rule)")
        if self.speed_scale != 1.0:
            parts.append(f"learned speed x{self.speed_scale:g}")
        if self.full_speed_at != 1.0:
            parts.append(full_speed_text(self.full_speed_at))
        if self.caution:
            parts.append(caution_text(self.caution, self.caution_from))
        return ", ".join(parts) or "steering straight to the wheel (as drive.py)"

    @classmethod
    def from_dict(cls, values: dict, source: str) -> DrivingSettings:
        """Settings from a table; unknown keys and bad values are errors naming ``source``."""
        from clonedrive.base.config import config_from_dict

        return config_from_dict(cls, values, source=source)


def with_defaults(options: dict) -> dict:
    """A run's recorded driving settings (:meth:`DrivingSettings.options` names) with every
    setting added since the run was made filled in as its default: what that run drove with."""
    return {**DrivingSettings().options(), **options}


#: The range of ``speed_scale``: a calibration of a speed head's target, not a new speed.
SPEED_SCALE_RANGE = (0.5, 1.5)


def _finite_number(value: object, inside, message: str) -> float:
    """``value`` as a float; ``ValueError(f"{message}, got {value!r}")`` unless it is a finite
    number (not a bool) for which ``inside(value)`` holds."""
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not math.isfinite(value) or not inside(value):
        raise ValueError(f"{message}, got {value!r}")
    return float(value)


def check_steering_filter_s(value: object) -> float:
    """``value`` as ``steering_filter_s``; ``ValueError`` unless a number >= 0 [s]."""
    return _finite_number(value, lambda number: number >= 0,
                          "steering_filter_s (the steering low-pass's time constant) must be a "
                          "number >= 0 s")


def check_steering_hold(value: object) -> float:
    """``value`` as ``steering_hold``; ``ValueError`` unless a number in [0, 1)."""
    return _finite_number(value, lambda number: 0 <= number < 1,
                          "steering_hold must be a number in [0, 1) (steering units)")


def check_speed_scale(value: object) -> float:
    """``value`` as a speed scale; ``ValueError`` unless a number in :data:`SPEED_SCALE_RANGE`."""
    low, high = SPEED_SCALE_RANGE
    return _finite_number(value, lambda number: low <= number <= high,
                          f"speed_scale must be a number in [{low:g}, {high:g}]")


#: Where :attr:`DrivingSettings.full_speed_at`'s stretch starts, as a fraction of the set speed:
#: a speed head's lower targets (its braking for a tight bend) are driven as learned.
STRETCH_FROM = 0.8


def check_full_speed_at(value: object) -> float:
    """``value`` as ``full_speed_at``; ``ValueError`` unless a number in
    (:data:`STRETCH_FROM`, 1]."""
    return _finite_number(value, lambda number: STRETCH_FROM < number <= 1.0,
                          f"full_speed_at must be a number above {STRETCH_FROM:g} and at most 1")


#: The largest ``caution``: at it a disagreement of 0.01 (a quarter of a degree of wheel)
#: already halves the target speed.
MAX_CAUTION = 100.0


def check_caution(value: object) -> float:
    """``value`` as ``caution``; ``ValueError`` unless a number in [0, :data:`MAX_CAUTION`]."""
    return _finite_number(value, lambda number: 0 <= number <= MAX_CAUTION,
                          f"caution must be a number in [0, {MAX_CAUTION:g}]")


#: The largest ``caution_from`` [steering units]: a disagreement of 0.1 is 2.5 deg of wheel.
MAX_CAUTION_FROM = 0.1


def check_caution_from(value: object) -> float:
    """``value`` as ``caution_from``; ``ValueError`` unless a number in
    [0, :data:`MAX_CAUTION_FROM`]."""
    return _finite_number(value, lambda number: 0 <= number <= MAX_CAUTION_FROM,
                          f"caution_from must be a number in [0, {MAX_CAUTION_FROM:g}] "
                          "(steering units)")


def check_caution_needs_mirror(caution: float, mirror_average: bool) -> None:
    """``ValueError`` if ``caution`` is asked for without ``mirror_average``, which it reads
    (a model file's own caution is left to do nothing when mirror averaging is turned off)."""
    if caution and not mirror_average:
        raise ValueError("caution needs mirror averaging: the disagreement it slows for is "
                         "between a frame's prediction and its mirror image's")


def caution_text(caution: float, caution_from: float) -> str:
    """How eval.json and :meth:`DrivingSettings.describe` name the ``caution`` setting."""
    return (f"slower where a frame and its mirror image disagree by more than "
            f"{caution_from:g} (caution {caution:g})")


def read_notes(path: str | os.PathLike) -> dict:
    """The clonedrive notes stored in the model file at ``path`` (``{}`` if it has none, or is
    neither a ``.keras`` nor an ``.h5`` file). ``ValueError`` naming the file if they are
    unreadable."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".keras":
        text = _keras_notes(path)
    elif suffix in (".h5", ".hdf5"):
        text = _h5_notes(path)
    elif suffix == ".onnx":
        text = _onnx_notes(path)
    else:
        return {}
    if text is None:
        return {}
    try:
        notes = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: its clonedrive notes are not valid JSON ({error})") from None
    if not isinstance(notes, dict):
        raise ValueError(f"{path}: its clonedrive notes are not a JSON object")
    return notes


def stored_settings(path: str | os.PathLike) -> DrivingSettings | None:
    """The driving settings stored in the model file at ``path``, or None if it has none."""
    return settings_in(read_notes(path), path)


def settings_in(notes: dict, path: str | os.PathLike) -> DrivingSettings | None:
    """The driving settings in a model file's ``notes`` (None if they hold none); errors name
    the file at ``path``."""
    driving = notes.get("driving")
    if driving is None:
        return None
    if not isinstance(driving, dict):
        raise ValueError(f"{path}: its driving settings are not a table")
    return DrivingSettings.from_dict(driving, f"{path}: driving settings")


def copy_notes(source: str | os.PathLike, target: str | os.PathLike) -> None:
    """Give the model file ``target`` the notes of ``source`` (an ensemble its first member's,
    an ONNX export its Keras model's); nothing when ``source`` has none or ``target`` is a
    kind of file that holds none."""
    notes = read_notes(source)
    if notes and Path(target).suffix.lower() in (".keras", ".h5", ".hdf5", ".onnx"):
        write_notes(target, notes)


def notes_for(settings: DrivingSettings, recipe: dict | None = None) -> dict:
    """The notes a model file carries: its driving settings and the recipe that made it."""
    notes: dict = {"driving": settings.options()}
    if recipe:
        notes["recipe"] = dict(recipe)
    return notes


def write_notes(path: str | os.PathLike, notes: dict) -> None:
    """Store ``notes`` in the model file at ``path`` (``.keras`` or ``.h5``), replacing any
    there. The ``.keras`` archive is rewritten beside itself and renamed into place."""
    path = Path(path)
    text = json.dumps(notes, sort_keys=True)
    suffix = path.suffix.lower()
    if suffix == ".keras":
        _write_keras_notes(path, text)
    elif suffix in (".h5", ".hdf5"):
        import h5py

        with h5py.File(path, "a") as file:
            file.attrs[H5_ATTRIBUTE] = text
    elif suffix == ".onnx":
        import onnx

        model = onnx.load(str(path))
        kept = [entry for entry in model.metadata_props if entry.key != H5_ATTRIBUTE]
        del model.metadata_props[:]
        model.metadata_props.extend(kept)
        entry = model.metadata_props.add()
        entry.key, entry.value = H5_ATTRIBUTE, text
        onnx.save(model, str(path))
    else:
        raise ValueError(f"{path}: driving settings are stored in .keras, .h5 or .onnx files "
                         "only")


def _keras_notes(path: Path) -> str | None:
    try:
        with zipfile.ZipFile(path) as archive:
            try:
                info = archive.getinfo(KERAS_MEMBER)
            except KeyError:
                return None
            if info.file_size > MAX_NOTES_BYTES:
                raise ValueError(f"{path}: its {KERAS_MEMBER} is {info.file_size} bytes, over "
                                 f"the {MAX_NOTES_BYTES} allowed")
            return archive.read(info).decode("utf-8", errors="replace")
    except zipfile.BadZipFile:
        return None  # not a zip: the model loader says what is wrong with it


def _h5_notes(path: Path) -> str | None:
    import h5py

    try:
        with h5py.File(path, "r") as file:
            value = file.attrs.get(H5_ATTRIBUTE)
    except OSError:
        return None  # not HDF5: the model loader says what is wrong with it
    if value is None:
        return None
    text = value.decode("utf-8", errors="replace") if isinstance(value, bytes) else str(value)
    if len(text) > MAX_NOTES_BYTES:
        raise ValueError(f"{path}: its clonedrive notes are over {MAX_NOTES_BYTES} bytes")
    return text


def _onnx_notes(path: Path) -> str | None:
    try:
        import onnx
    except ImportError:  # the onnx extra is not installed: nothing can run the file anyway
        return None
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception:  # noqa: BLE001 - not ONNX: the model loader says what is wrong with it
        return None
    for entry in model.metadata_props:
        if entry.key == H5_ATTRIBUTE:
            if len(entry.value) > MAX_NOTES_BYTES:
                raise ValueError(f"{path}: its clonedrive notes are over {MAX_NOTES_BYTES} "
                                 "bytes")
            return entry.value
    return None


def _write_keras_notes(path: Path, text: str) -> None:
    temporary = path.with_name(f".{path.name}.notes.tmp")
    try:
        with zipfile.ZipFile(path) as source, zipfile.ZipFile(temporary, "w") as target:
            for info in source.infolist():
                if info.filename != KERAS_MEMBER:
                    with source.open(info) as member, target.open(info, "w") as copy:
                        shutil.copyfileobj(member, copy)
            target.writestr(KERAS_MEMBER, text)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


#: The range of a non-zero ``steering_scale_from_mph`` [mph]: below it the scale would cut the
#: steering a car needs at walking pace.
STEERING_SCALE_FROM_RANGE_MPH = (5.0, 100.0)


def check_steering_scale_from(value: object) -> float:
    """``value`` as ``steering_scale_from_mph``; ``ValueError`` unless 0 (off) or a number in
    :data:`STEERING_SCALE_FROM_RANGE_MPH`."""
    low, high = STEERING_SCALE_FROM_RANGE_MPH
    return _finite_number(value, lambda number: number == 0 or low <= number <= high,
                          f"steering_scale_from_mph must be 0 (off) or a number in "
                          f"[{low:g}, {high:g}] mph")
