"""Track names: the one place that turns ``lake``, ``gen2:hard:17`` or a file path into a Track.

Generated names (see :mod:`clonedrive.world.generate` for what each generator makes):

- ``gen:<seed>``: generator v1, the name published with v1's figures (it keeps meaning v1);
- ``gen1:<seed>``: generator v1, by its versioned name;
- ``gen2:<seed>``: generator v2 at medium difficulty, the same as ``gen2:medium:<seed>``;
- ``gen2:<difficulty>:<seed>``: generator v2 at ``easy``, ``medium`` or ``hard``.

It sits above :mod:`clonedrive.world.track` and :mod:`clonedrive.world.generate`, so neither of
those imports the other. Generated tracks are kept (a few dozen) once made: a suite names the
same track from many places, and a hard v2 track takes a few tenths of a second to draw.
"""

from __future__ import annotations

import difflib
import functools
from importlib import resources
from pathlib import Path

import numpy as np

from clonedrive.world.generate import V1_VERSION, generate
from clonedrive.world.names import GENERATED_NAMES
from clonedrive.world.segments import DEFAULT_DIFFICULTY, DIFFICULTIES
from clonedrive.world.segments import VERSION as V2_VERSION
from clonedrive.world.track import Track, TrackError


def builtin_track_names() -> list[str]:
    folder = resources.files("clonedrive.world") / "tracks"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def is_generated_name(name: str) -> bool:
    return name.split(":", 1)[0] in ("gen", "gen1", "gen2") and ":" in name


def parse_generated_name(name: str) -> tuple[int, str | None, int]:
    """``(version, difficulty or None, seed)`` of a generated track's name."""
    prefix, _, rest = name.partition(":")
    parts = rest.split(":")
    difficulty = None
    if prefix == "gen2" and len(parts) == 2:
        difficulty, parts = parts[0], parts[1:]
        if difficulty not in DIFFICULTIES:
            raise TrackError(f"{name!r}: unknown difficulty {difficulty!r}; use "
                             f"{', '.join(DIFFICULTIES)}")
    try:
        if len(parts) != 1:
            raise ValueError(name)
        seed = int(parts[0])
    except ValueError:
        raise TrackError(f"{name!r}: generated tracks are named {GENERATED_NAMES} "
                         "(integer seed)") from None
    if seed < 0 or seed > 2**31:
        raise TrackError(f"{name!r}: the seed must be in [0, 2^31]")
    if prefix == "gen2":
        return V2_VERSION, difficulty or DEFAULT_DIFFICULTY, seed
    return V1_VERSION, None, seed


def _shared(track: Track) -> Track:
    """``track`` with its arrays made read-only: the one copy a process hands out to every
    caller, which a write would change for all of them."""
    for value in vars(track).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return track


@functools.lru_cache(maxsize=48)
def _generated(name: str) -> Track:
    version, difficulty, seed = parse_generated_name(name)
    if version == V1_VERSION:
        track = generate(seed, version=V1_VERSION, name=name)
    else:
        track = generate(seed, version=version, difficulty=difficulty, name=name)
    return _shared(track)


@functools.lru_cache(maxsize=16)
def _builtin(name: str) -> Track:
    folder = resources.files("clonedrive.world") / "tracks"
    with resources.as_file(folder / f"{name}.json") as path:
        return _shared(Track.from_file(path))


def load_track(name_or_path: str | Path) -> Track:
    """A track by built-in name (``lake``), generated name (``gen2:hard:17``) or JSON path.

    Built-in and generated tracks are made once per process and then handed out again (a
    built-in track's file takes ~13 ms to read and check; an evaluation asked for its track 24
    times); like every Track, they are only read. A path is read each time (the file may have
    changed)."""
    name = str(name_or_path)
    if is_generated_name(name):
        return _generated(name)
    if name in builtin_track_names():
        return _builtin(name)
    path = Path(name)
    if path.suffix == ".json" or path.exists():
        return Track.from_file(path)
    close = difflib.get_close_matches(name, builtin_track_names(), n=1, cutoff=0.6)
    guess = f"did you mean {close[0]!r}? " if close else ""
    raise TrackError(
        f"unknown track {name!r}: {guess}use one of {', '.join(builtin_track_names())}, "
        f"{GENERATED_NAMES}, or a path to a track .json file"
    )
