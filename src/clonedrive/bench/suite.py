"""Benchmark suites: named, versioned splits of episodes, read from a TOML file.

A suite file (``bench/suites/v4.toml`` is the built-in ``v4``; copy it to make your own) holds
an ``id``, the laps per episode, ``[[split]]`` tables and ``[conditions.NAME]`` families (see
:mod:`clonedrive.sim.conditions`). A split drives every combination of its ``tracks``,
``speeds_mph``, ``directions`` (``forward``, ``reverse``; default forward only), ``starts``
(where on the lap the car starts, as a fraction of the track from its start line; default 0)
and ``conditions`` once, in that nesting; episode ``i`` of a split draws its conditions from
its family with the seed ``seed + i``. So a suite is a fixed list of episodes: the same every
time. A lap is a whole track's length from wherever the car starts.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from clonedrive.base.config import parse_toml
from clonedrive.sim.conditions import ConditionFamily, Conditions
from clonedrive.world.catalog import load_track
from clonedrive.world.track import TrackError

SUITE_KEYS = ("id", "description", "laps", "split", "conditions")
SPLIT_KEYS = ("name", "description", "tracks", "speeds_mph", "directions", "starts",
              "conditions", "seed")
DIRECTIONS = ("forward", "reverse")
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
    reverse: bool = False  #: driven against the track's direction
    start_fraction: float = 0.0  #: where the car starts: this fraction of the track along

    @property
    def key(self) -> str:
        """A name unique within a suite."""
        return f"{self.split}/{self.index:03d}"

    @property
    def reference_key(self) -> str:
        """The expert reference this episode is compared with: same track, speed cap,
        direction and start."""
        return reference_name(self.track, self.speed_mph, self.reverse, self.start_fraction)

    def reset_options(self, track_length_m: float) -> dict:
        """The simulator's reset options that place the car for this episode."""
        return {"reverse": self.reverse, "s_m": self.start_fraction * track_length_m}


def reference_name(track: str, speed_mph: float, reverse: bool = False,
                   start_fraction: float = 0.0) -> str:
    """An expert reference's name in bench.json: ``track@speed`` (v2's names), with
    ``/reverse`` and ``/start=F`` where they are not the defaults."""
    name = f"{track}@{float(speed_mph):g}"
    if reverse:
        name += "/reverse"
    if start_fraction:
        name += f"/start={float(start_fraction):g}"
    return name


@dataclass(frozen=True)
class Split:
    name: str
    description: str
    tracks: tuple[str, ...]
    speeds_mph: tuple[float, ...]
    conditions: tuple[str, ...]
    seed: int
    directions: tuple[str, ...] = ("forward",)
    starts: tuple[float, ...] = (0.0,)

    @property
    def size(self) -> int:
        """How many episodes the split holds."""
        return (len(self.tracks) * len(self.speeds_mph) * len(self.directions)
                * len(self.starts) * len(self.conditions))


@dataclass(frozen=True)
class Suite:
    id: str
    description: str
    laps: int
    splits: tuple[Split, ...]
    families: dict
    source: str

    def episodes(self, splits: tuple[str, ...] | None = None) -> list[EpisodeSpec]:
        """Every episode, split by split in file order (only ``splits`` if given).
        ``SuiteError`` naming any of ``splits`` the suite does not have."""
        unknown = [name for name in splits or () if name not in self.split_names()]
        if unknown:
            raise SuiteError(f"suite {self.id}: no split named {', '.join(unknown)}; it has "
                             f"{', '.join(self.split_names())}")
        out = []
        for split in self.splits:
            if splits and split.name not in splits:
                continue
            combinations = itertools.product(split.tracks, split.speeds_mph, split.directions,
                                             split.starts, split.conditions)
            for index, (track, speed, direction, start, family_name) in enumerate(combinations):
                seed = split.seed + index
                out.append(EpisodeSpec(
                    split=split.name, index=index, track=track, speed_mph=speed,
                    family=family_name, seed=seed,
                    conditions=self.families[family_name].sample(seed), laps=self.laps,
                    reverse=direction == "reverse", start_fraction=start))
        return out

    def split_names(self) -> list[str]:
        return [split.name for split in self.splits]

    def to_dict(self) -> dict:
        return {
            "id": self.id, "description": self.description, "laps": self.laps,
            "source": self.source,
            "splits": [{"name": s.name, "description": s.description, "tracks": list(s.tracks),
                        "speeds_mph": list(s.speeds_mph), "directions": list(s.directions),
                        "starts": list(s.starts), "conditions": list(s.conditions),
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
        episodes += split.size
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
                 seed=seed, directions=_directions(table, where), starts=_starts(table, where))


def _directions(table: dict, where: str) -> tuple[str, ...]:
    directions = table.get("directions", ["forward"])
    if not isinstance(directions, list) or not directions or any(
            d not in DIRECTIONS for d in directions) or len(set(directions)) < len(directions):
        raise SuiteError(f"{where}: directions must be a list of distinct values from "
                         f"{', '.join(DIRECTIONS)}, got {directions!r}")
    return tuple(directions)


def _starts(table: dict, where: str) -> tuple[float, ...]:
    starts = table.get("starts", [0.0])
    if not isinstance(starts, list) or not starts or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v < 1
            for v in starts) or len(set(starts)) < len(starts):
        raise SuiteError(f"{where}: starts must be a list of distinct fractions of the lap in "
                         f"[0, 1), got {starts!r}")
    return tuple(float(v) for v in starts)
