"""Track names: the one place that turns ``lake``, ``gen:17`` or a file path into a Track.

It sits above :mod:`clonedrive.world.track` and :mod:`clonedrive.world.generate`, so neither of
those imports the other.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from clonedrive.world.generate import generate
from clonedrive.world.track import Track, TrackError


def builtin_track_names() -> list[str]:
    folder = resources.files("clonedrive.world") / "tracks"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def load_track(name_or_path: str | Path) -> Track:
    """A track by built-in name (``lake``), generated name (``gen:17``) or JSON file path."""
    name = str(name_or_path)
    if name.startswith("gen:"):
        try:
            seed = int(name[4:])
        except ValueError:
            raise TrackError(f"{name!r}: generated tracks are named gen:<integer seed>") from None
        return generate(seed)
    if name in builtin_track_names():
        folder = resources.files("clonedrive.world") / "tracks"
        with resources.as_file(folder / f"{name}.json") as path:
            return Track.from_file(path)
    path = Path(name)
    if path.suffix == ".json" or path.exists():
        return Track.from_file(path)
    raise TrackError(
        f"unknown track {name!r}: use one of {', '.join(builtin_track_names())}, gen:<seed>, "
        "or a path to a track .json file"
    )
