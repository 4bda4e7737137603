"""Benchmark suites: named, versioned splits of episodes, read from a TOML file.

A suite file (``bench/suites/v2.toml`` is the built-in ``v2``; copy it to make your own) holds
an ``id``, the laps per episode, ``[[split]]`` tables and ``[conditions.NAME]`` families (see
:mod:`clonedrive.sim.conditions`). A split drives every combination of its ``tracks``,
``speeds_mph`` and ``conditions`` once; episode ``i`` of a split draws its conditions from its
family with the seed ``seed + i``. So a suite is a fixed list of episodes: the same every time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from clonedrive.base.config import parse_toml
from clonedrive.sim.conditions import ConditionFamily, Conditions
from clonedrive.world.catalog import load_track
from clonedrive.world.track import TrackError

SUITE_KEYS = ("id", "description", "laps", "split", "conditions")
SPLIT_KEYS = ("name", "description", "tracks", "speeds_mph", "conditions", "seed")
#: Built-in suites no longer shipped, and why: their figures cannot be reproduced.
RETIRED_SUITES = {
    "v1": "retired: 6 of its generated lake tracks had stretches of road under the lake's "
          "water; suite v2 drives the same episodes in the fixed scenery",
}
#: Most episodes one suite may hold (a typo like 1e6 tracks must not run for a year).
MAX_EPISODES = 2000


class SuiteError(ValueError):
    """A suite file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode of a suite: what to drive, where, how fast and under which conditions."""

    split: str
    index: int  #: position in its split
    track: str
    speed_mph: float
    family: str  #: the condition family's name
    seed: int  #: conditions seed (split seed + index)
    conditions: Conditions
    laps: int

    @property
    def key(self) -> str:
        """A name unique within a suite."""
        return f"{self.split}/{self.index:03d}"

    @property
    def reference_key(self) -> tuple[str, float]:
        """The expert reference this episode is compared with: same track and speed cap."""
        return (self.track, self.speed_mph)


@dataclass(frozen=True)
class Split:
    name: str
    description: str
    tracks: tuple[str, ...]
    speeds_mph: tuple[float, ...]
    conditions: tuple[str, ...]
    seed: int


@dataclass(frozen=True)
class Suite:
    id: str
    description: str
    laps: int
    splits: tuple[Split, ...]
    families: dict
    source: str

    def episodes(self, splits: tuple[str, ...] | None = None) -> list[EpisodeSpec]:
        """Every episode, split by split in file order (only ``splits`` if given)."""
        out = []
        for split in self.splits:
            if splits and split.name not in splits:
                continue
            index = 0
            for track in split.tracks:
                for speed in split.speeds_mph:
                    for family_name in split.conditions:
                        seed = split.seed + index
                        family = self.families[family_name]
                        out.append(EpisodeSpec(split=split.name, index=index, track=track,
                                               speed_mph=speed, family=family_name, seed=seed,
                                               conditions=family.sample(seed), laps=self.laps))
                        index += 1
        return out

    def split_names(self) -> list[str]:
        return [split.name for split in self.splits]

    def to_dict(self) -> dict:
        return {
            "id": self.id, "description": self.description, "laps": self.laps,
            "source": self.source,
            "splits": [{"name": s.name, "description": s.description, "tracks": list(s.tracks),
                        "speeds_mph": list(s.speeds_mph), "conditions": list(s.conditions),
                        "seed": s.seed} for s in self.splits],
            "conditions": {name: family.to_dict() for name, family in self.families.items()},
        }


def builtin_suite_names() -> list[str]:
    folder = resources.files("clonedrive.bench") / "suites"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_suite(name_or_path: str | Path, *, check_tracks: bool = True) -> Suite:
    """A suite by built-in name (``v2``) or TOML file path; every field is checked, and with
    ``check_tracks`` every track name is loaded once."""
    name = str(name_or_path)
    if name in RETIRED_SUITES and not Path(name).is_file():
        raise SuiteError(f"suite {name}: {RETIRED_SUITES[name]}")
    if name in builtin_suite_names():
        folder = resources.files("clonedrive.bench") / "suites"
        text = (folder / f"{name}.toml").read_text(encoding="utf-8")
        source = f"suite {name}"
    else:
        path = Path(name)
        if not path.is_file():
            raise SuiteError(f"{name}: no such suite (built in: "
                             f"{', '.join(builtin_suite_names())}; or a .toml file)")
        if path.stat().st_size > 1_000_000:
            raise SuiteError(f"{path}: a suite file is at most 1 MB")
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            raise SuiteError(f"{path}: not a UTF-8 text file") from None
        source = str(path)
    try:
        data = parse_toml(text, source=source)
    except ValueError as error:
        raise SuiteError(str(error)) from None
    suite = _parse(data, source)
    if check_tracks:
        for track in sorted({t for split in suite.splits for t in split.tracks}):
            try:
                load_track(track)
            except TrackError as error:
                raise SuiteError(f"{source}: {error}") from None
    return suite


def _parse(data: dict, source: str) -> Suite:
    unknown = sorted(set(data) - set(SUITE_KEYS))
    if unknown:
        raise SuiteError(f"{source}: unknown key(s) {', '.join(unknown)}; allowed: "
                         f"{', '.join(SUITE_KEYS)}")
    suite_id = data.get("id")
    if not isinstance(suite_id, str) or not suite_id.strip():
        raise SuiteError(f"{source}: id must be a non-empty string (it names the figures)")
    laps = data.get("laps", 1)
    if isinstance(laps, bool) or not isinstance(laps, int) or not 1 <= laps <= 20:
        raise SuiteError(f"{source}: laps must be a whole number in [1, 20], got {laps!r}")
    families_data = data.get("conditions", {})
    if not isinstance(families_data, dict):
        raise SuiteError(f"{source}: conditions must be tables [conditions.NAME]")
    families = {}
    for name, table in families_data.items():
        try:
            families[name] = ConditionFamily.from_dict(name, table, source=source)
        except ValueError as error:
            raise SuiteError(str(error)) from None
    splits_data = data.get("split")
    if not isinstance(splits_data, list) or not splits_data:
        raise SuiteError(f"{source}: give at least one [[split]]")
    splits, episodes = [], 0
    for number, table in enumerate(splits_data, start=1):
        split = _parse_split(table, f"{source}: split {number}", families)
        if split.name in {s.name for s in splits}:
            raise SuiteError(f"{source}: split name {split.name!r} is used twice")
        splits.append(split)
        episodes += len(split.tracks) * len(split.speeds_mph) * len(split.conditions)
    if episodes > MAX_EPISODES:
        raise SuiteError(f"{source}: {episodes} episodes; a suite holds at most {MAX_EPISODES}")
    return Suite(id=suite_id, description=_description(data, source), laps=laps,
                 splits=tuple(splits), families=families, source=source)


def _description(table: dict, where: str) -> str:
    """The table's ``description``: text, or none."""
    text = table.get("description", "")
    if not isinstance(text, str):
        raise SuiteError(f"{where}: description must be a string, got {type(text).__name__}")
    return text


def _parse_split(table: object, where: str, families: dict) -> Split:
    if not isinstance(table, dict):
        raise SuiteError(f"{where}: expected a table")
    unknown = sorted(set(table) - set(SPLIT_KEYS))
    if unknown:
        raise SuiteError(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: "
                         f"{', '.join(SPLIT_KEYS)}")
    name = table.get("name")
    if not isinstance(name, str) or not name.strip():
        raise SuiteError(f"{where}: name must be a non-empty string")
    where = f"{where} ({name})"
    tracks = table.get("tracks")
    if not isinstance(tracks, list) or not tracks or not all(
            isinstance(t, str) and t for t in tracks):
        raise SuiteError(f"{where}: tracks must be a non-empty list of track names")
    speeds = table.get("speeds_mph")
    if not isinstance(speeds, list) or not speeds or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            and 0 < v <= 30 for v in speeds):
        raise SuiteError(f"{where}: speeds_mph must be a non-empty list of speeds in (0, 30]")
    conditions = table.get("conditions", ["clear"])
    if not isinstance(conditions, list) or not conditions:
        raise SuiteError(f"{where}: conditions must be a non-empty list of family names")
    for family in conditions:
        if not isinstance(family, str):
            raise SuiteError(f"{where}: conditions must be a list of family names, got "
                             f"{family!r}")
        if family not in families:
            raise SuiteError(f"{where}: conditions {family!r} is not defined; the suite "
                             f"defines {', '.join(families) or 'none'} ([conditions.NAME])")
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**31:
        raise SuiteError(f"{where}: seed must be a whole number >= 0")
    return Split(name=name, description=_description(table, where), tracks=tuple(tracks),
                 speeds_mph=tuple(float(v) for v in speeds), conditions=tuple(conditions),
                 seed=seed)
