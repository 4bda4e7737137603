"""``clonedrive tracks``: list tracks with their figures and draw a map (and camera strip) each."""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass

from clonedrive.world.names import TRACK_NAMES_HELP

HELP = "list tracks (length, width, elevation, tightest curve) and draw their maps"
DESCRIPTION = (
    "List the built-in tracks (or those named with --track: a JSON file or gen:<seed>) with "
    "length, width, elevation range, minimum radius and maximum grade, and write for each a "
    "top-down map PNG (road, direction, start line, elevation by colour) and a strip of "
    "center/left/right camera frames at a few places along the track."
)
#: Example command lines, shown at the end of ``clonedrive tracks --help``.
EXAMPLES = (
    "clonedrive tracks                     # every track, maps and camera strips in runs/tracks/",
    "clonedrive tracks --track gen2:hard:7 --json",
)


@dataclass(frozen=True)
class TracksConfig:
    """What ``clonedrive tracks`` describes and draws."""

    tracks: tuple[str, ...] = ()  #: names, gen:<seed> or .json paths; () = the built-in tracks
    out: str = "runs/tracks"  #: folder for the map and camera-strip PNGs
    images: bool = True  #: draw a map per track (False: figures only)
    strip: bool = True  #: also render a strip of camera frames per track

    def __post_init__(self) -> None:
        if isinstance(self.tracks, str):
            raise ValueError("tracks must be a sequence of track names, not one string")
        for name in self.tracks:
            if not isinstance(name, str) or not name.strip():
                raise ValueError(f"tracks: {name!r} is not a track name")
        if not str(self.out).strip():
            raise ValueError("out must name a folder")


def add_arguments(parser) -> None:
    defaults = TracksConfig()
    parser.add_argument("--track", action="append", default=None, metavar="NAME",
                        help=f"{TRACK_NAMES_HELP} (repeatable); "
                             "default: all built-in tracks")
    parser.add_argument("--out", default=defaults.out, help="folder for the map and strip PNGs")
    parser.add_argument("--no-images", dest="images", action="store_false",
                        default=defaults.images,
                        help="only print the figures: no map or camera strip")
    parser.add_argument("--no-strip", dest="strip", action="store_false", default=defaults.strip,
                        help="draw the maps but skip rendering camera strips")
    parser.add_argument("--json", action="store_true", help="print the figures as a JSON list")


def run(args) -> int:
    from clonedrive.world.track import TrackError

    try:
        config = TracksConfig(tracks=tuple(args.track or ()), out=args.out, images=args.images,
                              strip=args.strip)
        rows = describe_tracks(config)
    except (TrackError, ValueError) as error:
        print(f"clonedrive tracks: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    header = f"{'track':<12}{'length m':>10}{'width m':>9}{'elev. range m':>15}" \
             f"{'min radius m':>14}{'max grade %':>13}"
    print(header)
    for row in rows:
        print(f"{row['name']:<12}{row['length_m']:>10.0f}{row['width_m']:>9.1f}"
              f"{row['elevation_range_m']:>15.1f}{row['min_radius_m']:>14.1f}"
              f"{100 * row['max_grade']:>13.1f}")
    for row in rows:
        for key in ("map_png", "cameras_png"):
            if key in row:
                print(f"wrote {row[key]}")
    return 0


def describe_tracks(config: TracksConfig) -> list[dict]:
    """Each track's figures (:meth:`Track.summary`), with the paths of the map and camera strip
    written for it (``map_png``, ``cameras_png``). ``TrackError`` for a track that cannot be
    loaded, ``ValueError`` when ``config.out`` is a file, ``OSError`` when it is read-only
    (checked before any work)."""
    from pathlib import Path

    from clonedrive.base.paths import inside, prepare_output_folder, safe_stem
    from clonedrive.world.catalog import builtin_track_names, load_track

    names = config.tracks or builtin_track_names()
    out = Path(config.out)
    if config.images:
        prepare_output_folder(out)  # ValueError for a file, OSError for a read-only folder
    rows = []
    stems: set[str] = set()
    for name in names:
        track = load_track(name)
        row = track.summary()
        if config.images:
            from clonedrive.evaluate.maps import plot_track_map

            # The name comes from the track file: one safe component, distinct per track.
            stem = _unused(safe_stem(track.name, fallback="track"), stems)
            row["map_png"] = str(plot_track_map(track, inside(out, f"{stem}_map.png")))
            if config.strip:
                strip = _write_strip(track, inside(out, f"{stem}_cameras.png"))
                if strip is not None:
                    row["cameras_png"] = str(strip)
        rows.append(row)
    return rows


def _unused(stem: str, used: set[str]) -> str:
    """``stem``, or ``stem-2``, ``stem-3``... if an earlier track took it; added to ``used``."""
    candidate, number = stem, 1
    while candidate in used:
        number += 1
        candidate = f"{stem}-{number}"
    used.add(candidate)
    return candidate


def _write_strip(track, path):
    try:
        from clonedrive.sim.preview import write_track_strip
    except ModuleNotFoundError as error:
        if error.name != "clonedrive.sim.preview":
            raise
        return None
    return write_track_strip(track, path)
