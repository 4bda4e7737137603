"""A whole recipe: the recordings, the training settings and the driving settings of one
driver, in one TOML file with a name and a version.

Layout (every table but ``[recipe]`` and ``[[recording]]`` is optional)::

    [recipe]
    name = "best"            # what reports call it
    version = 3              # raised whenever a change changes results
    summary = "one line"

    [defaults]               # how each recording becomes samples (data.recipe's keys)
    correction = 0.054

    [[recording]]            # recorded by the expert into DATA/<name>/ (clonedrive demo) ...
    name = "middle"
    track = "lake"
    style = "center"
    laps = 3
    speed_mph = 30
    noise = 0.15
    steering_offset = 0.0    # ... and turned into samples with data.recipe's keys

    [[recording]]
    name = "mine"
    path = "my_laps"         # or an existing folder (relative to this file): nothing to record

    [train]                  # TrainConfig fields (model.train); left out: TrainConfig's
    model = "fast"

    [finetune]               # a second stage from the first one's model (recipes.training)
    epochs = 1
    consistency = 30
                             # or [[finetune]] tables: one more stage each, from the one before

    [drive]                  # DrivingSettings fields, stored in the trained model's file
    mirror_average = true

    [[evaluate]]             # EvalConfig fields per group of runs (clonedrive demo)
    tracks = ["lake"]
    speeds_mph = [15, 30]

    [bench]                  # clonedrive demo also benches the model on these splits
    suite = "v4"             # a built-in suite (bench's default when left out)
    splits = ["dev"]

    [measured]               # figures measured once with this recipe, for comparisons
    date = "2026-12-04"

Unknown keys anywhere are errors naming the key and the file.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from clonedrive.base.config import config_from_dict, parse_toml
from clonedrive.data.recipe import SETTING_KEYS, Recipe, recipe_from_table, reject_unknown
from clonedrive.network.driving_settings import DrivingSettings

#: The recipes that ship with clonedrive (``<name>.toml`` in this package).
BUILT_IN = ("best", "writeup")
#: What ``clonedrive demo`` and ``clonedrive train`` use when given no recipe.
DEFAULT_RECIPE = "best"
#: Recipe files larger than this are refused (they are a few kilobytes).
MAX_RECIPE_BYTES = 1_000_000

_TOP_KEYS = ("recipe", "defaults", "recording", "train", "finetune", "drive", "evaluate",
             "bench", "measured")
_IDENTITY_KEYS = ("name", "version", "summary", "compare_with")


@dataclass(frozen=True)
class RecordSpec:
    """One recording the expert makes for a recipe (data.recorder.RecordConfig's fields)."""

    name: str
    track: str
    style: str
    laps: int
    speed_mph: float
    reverse: bool = False
    noise: float = 0.0
    seconds: float | None = None
    turn_curvature_per_m: float | None = None  #: turns style: record only tighter curves
    #: a condition family (``record --look``, e.g. "udacity") the recording's look is drawn from
    look: str | None = None


_RECORD_KEYS = tuple(item.name for item in dataclasses.fields(RecordSpec))


@dataclass(frozen=True)
class DemoBench:
    """A recipe's ``[bench]``: the splits of a built-in suite ``clonedrive demo`` benches its
    model on, after the evaluation, so its report shows the model where the road is hard."""

    splits: tuple[str, ...]
    suite: str | None = None  #: a built-in suite's name (None: bench's default suite)


@dataclass(frozen=True)
class RecipeFile:
    """A whole recipe as read from its file (see the module doc)."""

    name: str
    version: int
    source: str  #: the file, or "built-in NAME"
    text: str  #: the file's text, copied into run folders
    recordings: tuple[RecordSpec, ...]  #: what the expert records (not the ``path`` ones)
    data_table: dict  #: ``defaults`` and ``recording`` as data.recipe reads them
    base_dir: Path  #: where relative ``path``s are taken from
    train: dict = field(default_factory=dict)  #: TrainConfig fields
    #: TrainConfig fields of each further stage, each from the one before's model
    #: (recipes.training): one per ``[[finetune]]`` table, or the one ``[finetune]`` table
    finetune: tuple[dict, ...] = ()
    driving: DrivingSettings = DrivingSettings()
    evaluation: tuple[dict, ...] = ()  #: EvalConfig fields per group
    bench: DemoBench | None = None  #: the benchmark splits the demo drives the model on
    measured: dict = field(default_factory=dict)
    summary: str = ""
    compare_with: str | None = None  #: a recipe whose ``measured`` figures reports show beside

    def identity(self) -> dict:
        """``{"name", "version"}``: what model files and reports name."""
        return {"name": self.name, "version": self.version}

    def label(self) -> str:
        return f"{self.name} v{self.version}"

    def data_recipe(self, data_dir: str | os.PathLike) -> Recipe:
        """The training data: recorded recordings in ``data_dir/<name>``, the others at their
        ``path``."""
        data_dir = Path(data_dir).absolute()
        entries = []
        for entry in self.data_table["recording"]:
            entry = dict(entry)
            if "path" in entry:
                entry["path"] = str((self.base_dir / entry["path"]).absolute())
            else:
                entry["path"] = str(data_dir / entry["name"])
            entries.append(entry)
        table = {"recording": entries}
        if "defaults" in self.data_table:
            table["defaults"] = self.data_table["defaults"]
        return recipe_from_table(table, source=self.source, base_dir=data_dir)

    def data_recipe_without_data(self) -> Recipe:
        """The training data when no data folder is given: every recording must have a
        ``path``; ``ValueError`` naming the ones the expert records otherwise."""
        if self.recordings:
            names = ", ".join(spec.name for spec in self.recordings)
            raise ValueError(f"recipe {self.label()} records its data ({names}): give --data "
                             "FOLDER holding those recordings by name (clonedrive demo --recipe "
                             f"{self.name} records them into runs/demo/data), or DIRs")
        return self.data_recipe(self.base_dir)

    def folders_recipe(self, dirs, *, correction: float | None = None) -> Recipe:
        """Recording folders ``dirs`` turned into samples as this recipe's [defaults] say
        (``correction``, when given, instead of the recipe's)."""
        defaults = dict(self.data_table.get("defaults", {}))
        if correction is not None:
            defaults["correction"] = correction
        table = {"defaults": defaults,
                 "recording": [{"path": str(Path(folder).absolute())} for folder in dirs]}
        return recipe_from_table(table, source="command line", base_dir=Path.cwd())

    def train_config(self, **overrides):
        """The TrainConfig of this recipe, with ``overrides`` (fields) on top."""
        from clonedrive.model.train_config import TrainConfig

        defaults = self.data_table.get("defaults", {})
        base = {"correction": defaults["correction"]} if "correction" in defaults else {}
        return config_from_dict(TrainConfig, {**base, **self.train, **overrides},
                                source=f"{self.source}: [train]")

    def notes(self) -> dict:
        """What a model trained with this recipe carries in its file."""
        from clonedrive.network.driving_settings import notes_for

        return notes_for(self.driving, self.identity())


def recipe_choices_text() -> str:
    return ", ".join(BUILT_IN)


def load_recipe_file(name_or_path: str | os.PathLike) -> RecipeFile:
    """A built-in recipe by name (:data:`BUILT_IN`) or a recipe file by path. ``ValueError``
    or ``FileNotFoundError`` naming the file and what is wrong."""
    text_name = str(name_or_path)
    if text_name in BUILT_IN:
        text = resources.files(__package__).joinpath(f"{text_name}.toml").read_text("utf-8")
        return parse_recipe_file(text, source=f"built-in {text_name}", base_dir=Path.cwd())
    path = Path(name_or_path)
    if not path.is_file():
        raise FileNotFoundError(f"recipe {text_name!r} not found: not a file, nor one of the "
                                f"built-in recipes ({recipe_choices_text()})")
    _check_size(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    return parse_recipe_file(text, source=str(path), base_dir=path.parent)


def _check_size(path: Path) -> None:
    """``ValueError`` naming ``path`` if it is larger than a recipe file may be."""
    size = path.stat().st_size
    if size > MAX_RECIPE_BYTES:
        raise ValueError(f"{path}: {size} bytes; a recipe file is at most {MAX_RECIPE_BYTES}")


def is_whole_recipe(path: str | os.PathLike) -> bool:
    """True for a built-in recipe name or a TOML file with a ``[recipe]`` table (a data-only
    recipe, data.recipe's format, has none). A file that is not TOML (or nests too deep, ...)
    raises :func:`~clonedrive.base.config.parse_toml`'s ``ValueError`` now, before any work."""
    if str(path) in BUILT_IN:
        return True
    try:
        _check_size(Path(path))  # too large for either kind of recipe: say so, not what it lacks
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):  # refused, with its reason, where it is loaded
        return False
    return "recipe" in parse_toml(text, source=str(path))


def parse_recipe_file(text: str, *, source: str, base_dir: str | os.PathLike) -> RecipeFile:
    """Parse a whole recipe's TOML ``text`` (see the module doc)."""
    data = parse_toml(text, source=source)
    reject_unknown(data, _TOP_KEYS, source, "the top level")
    identity = _table(data, "recipe", source)
    reject_unknown(identity, _IDENTITY_KEYS, source, "[recipe]")
    name, version = identity.get("name"), identity.get("version")
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{source}: [recipe] needs a name (a string)")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(f"{source}: [recipe] needs a version (a whole number >= 1)")
    recordings, data_table = _recordings(data, source)
    recipe = RecipeFile(
        name=name.strip(), version=version, source=source, text=text,
        recordings=recordings, data_table=data_table, base_dir=Path(base_dir).absolute(),
        train=_table(data, "train", source), finetune=_finetune(data, source),
        evaluation=_evaluation(data, source), bench=_bench(data, source),
        driving=DrivingSettings.from_dict(_table(data, "drive", source), f"{source}: [drive]"),
        measured=_table(data, "measured", source), summary=str(identity.get("summary", "")),
        compare_with=identity.get("compare_with"))
    from clonedrive.recipes.training import train_stages

    train_stages(recipe)  # bad training settings fail now, naming the file
    recipe.data_recipe(Path(base_dir) / "data")  # and bad sample settings
    return recipe


def _recordings(data: dict, source: str) -> tuple[tuple[RecordSpec, ...], dict]:
    entries = data.get("recording")
    if not entries or not isinstance(entries, list) \
            or not all(isinstance(entry, dict) for entry in entries):
        raise ValueError(f"{source}: needs [[recording]] tables (at least one)")
    specs, data_entries = [], []
    for number, entry in enumerate(entries, start=1):
        where = f"[[recording]] #{number}"
        reject_unknown(entry, ("path", *_RECORD_KEYS, *SETTING_KEYS), source, where)
        if not isinstance(entry.get("name"), str) or not entry["name"]:
            raise ValueError(f"{source}: {where} needs a name (a string)")
        data_entries.append({key: entry[key] for key in ("name", "path", *SETTING_KEYS)
                             if key in entry})
        if "path" in entry:
            if any(key in entry for key in _RECORD_KEYS if key != "name"):
                raise ValueError(f"{source}: {where} ({entry['name']}) has a path and "
                                 "recording settings; give one or the other")
            continue
        specs.append(_record_spec(entry, source, where))
    table = {"recording": data_entries}
    if "defaults" in data:
        table["defaults"] = _table(data, "defaults", source)
    return tuple(specs), table


def _record_spec(entry: dict, source: str, where: str) -> RecordSpec:
    values = {key: entry[key] for key in _RECORD_KEYS if key in entry}
    missing = [key for key in ("track", "style", "laps", "speed_mph") if key not in values]
    if missing:
        raise ValueError(f"{source}: {where} ({entry['name']}) needs {', '.join(missing)} "
                         "(or a path to an existing recording)")
    for key in ("speed_mph", "noise", "seconds", "turn_curvature_per_m"):
        value = values.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)
                                  or not math.isfinite(value) or value < 0):
            raise ValueError(f"{source}: {where}: {key} = {value!r}; expected a number >= 0")
    laps = values["laps"]
    if isinstance(laps, bool) or not isinstance(laps, int) or not 1 <= laps <= 100:
        raise ValueError(f"{source}: {where}: laps = {laps!r}; expected a whole number 1-100")
    if not isinstance(values.get("reverse", False), bool):
        raise ValueError(f"{source}: {where}: reverse must be true or false")
    from clonedrive.sim.conditions import check_recording_look

    try:
        check_recording_look(values.get("look"))
    except ValueError as error:
        raise ValueError(f"{source}: {where}: {error}") from None
    return RecordSpec(**values)


def _evaluation(data: dict, source: str) -> tuple[dict, ...]:
    from clonedrive.evaluate.config import EvalConfig

    groups = data.get("evaluate", [])
    if not isinstance(groups, list) or not all(isinstance(group, dict) for group in groups):
        raise ValueError(f"{source}: 'evaluate' must be [[evaluate]] tables")
    checked = []
    for number, group in enumerate(groups, start=1):
        values = {key: tuple(value) if isinstance(value, list) else value
                  for key, value in group.items()}
        for key in ("speeds_mph", "unseen_speed_mph"):  # 30 and 30.0 alike, as the CLI's
            if key in values:
                values[key] = _floats(values[key])
        config_from_dict(EvalConfig, values, source=f"{source}: [[evaluate]] #{number}")
        checked.append(values)
    return tuple(checked)


def _bench(data: dict, source: str) -> DemoBench | None:
    """The ``[bench]`` table (None when the recipe has none); whether its suite has those
    splits is checked where the demo plans its stages (the suite is a layer above)."""
    if "bench" not in data:
        return None
    table = _table(data, "bench", source)
    reject_unknown(table, ("suite", "splits"), source, "[bench]")
    suite, splits = table.get("suite"), table.get("splits")
    if suite is not None and (not isinstance(suite, str) or not suite):
        raise ValueError(f"{source}: [bench] suite = {suite!r}; expected a suite's name")
    if not isinstance(splits, list) or not splits \
            or not all(isinstance(split, str) and split for split in splits):
        raise ValueError(f"{source}: [bench] splits = {splits!r}; expected a list of split "
                         "names")
    return DemoBench(splits=tuple(splits), suite=suite)


def _floats(value):
    if isinstance(value, tuple):
        return tuple(_floats(item) for item in value)
    if isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def _finetune(data: dict, source: str) -> tuple[dict, ...]:
    """The fine-tune stages: one ``[finetune]`` table, or ``[[finetune]]`` tables in order."""
    value = data.get("finetune", {})
    if isinstance(value, list) and value and all(isinstance(stage, dict) for stage in value):
        return tuple(dict(stage) for stage in value)
    if not isinstance(value, dict):
        raise ValueError(f"{source}: [finetune] must be a table, or [[finetune]] tables")
    return (dict(value),) if value else ()


def _table(data: dict, key: str, source: str) -> dict:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ValueError(f"{source}: [{key}] must be a table")
    return dict(value)
