"""A strip of camera frames at telling places along a track, to look at the scene.

:func:`write_track_strip` renders the left, center and right cameras with the car on the
centreline at a few places chosen from the geometry: a straight, the sharpest curve (on the
mountain the hairpin), the bridge (lake theme), a crest. One labelled row per place.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from clonedrive.base.config import write_bytes_atomic
from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_WIDTH
from clonedrive.sim.scenery import find_bridge, longest_run
from clonedrive.world.catalog import load_track
from clonedrive.world.track import Track

#: The car stands this far [m] before a curve's apex or a crest, so the feature is in view.
_LEAD_M = 14.0
_LABEL_W = 120
_CAMERA_ORDER = ("left", "center", "right")
#: Height of the header row that names the cameras [px].
_TITLE_H = 24


def strip_places(track: Track) -> list[tuple[str, float]]:
    """(label, s_m) of the places a strip shows, chosen from the track's geometry."""
    places: list[tuple[str, float]] = []
    curvature = np.abs(track.curvature_table)
    start, count = longest_run(curvature < 1.0 / 250.0)
    if count:
        places.append((f"straight s={track.s[start] + 5:.0f}", track.s[start] + 5.0))
    apex = int(np.argmax(curvature))
    kind = "hairpin" if curvature[apex] > 1.0 / 20.0 else "sharpest curve"
    radius = 1.0 / max(curvature[apex], 1e-9)
    places.append((f"{kind} R={radius:.0f}m", track.s[apex] - _LEAD_M))
    if track.theme == "lake":
        bridge = find_bridge(track)
        if bridge is not None:
            places.append((f"bridge s={bridge.start_m:.0f}", bridge.start_m - 12.0))
    crest = _crest(track)
    if crest is not None:
        places.append((f"crest z={track.point(crest)[2]:.0f}m", crest - 2 * _LEAD_M))
    # drop places that nearly coincide with an earlier one
    kept: list[tuple[str, float]] = []
    for label, s in places:
        s = float(track.wrap(s))
        near = [abs(s - other) for _, other in kept]
        if all(min(d, track.length_m - d) > 25.0 for d in near):
            kept.append((label, s))
    return kept


def _crest(track: Track) -> float | None:
    """Arc length of the sharpest convex top among the higher half of the track, if any."""
    z = track.xyz[:, 2]
    if z.max() - z.min() < 1.0:
        return None
    window = max(1, int(round(20.0 / track.ds_m)))
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    padded = np.concatenate([z[-window:], z, z[:window]])
    smooth = np.convolve(padded, kernel, mode="valid")
    bend = np.gradient(np.gradient(smooth, track.ds_m), track.ds_m)
    high = smooth >= np.percentile(smooth, 50)
    score = np.where(high, -bend, -np.inf)
    best = int(np.argmax(score))
    return float(track.s[best]) if score[best] > 0 else None


def _label(text: str, height: int) -> np.ndarray:
    import cv2

    panel = np.full((height, _LABEL_W, 3), 32, dtype=np.uint8)
    words = text.split(" ")
    for line, word in enumerate(words):
        cv2.putText(panel, word, (6, 22 + 18 * line), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (235, 235, 235), 1, cv2.LINE_AA)
    return panel


def _camera_titles(width: int, height: int) -> np.ndarray:
    """The strip's header row: each column's camera, above its frames."""
    import cv2

    header = np.full((_TITLE_H, _LABEL_W + len(_CAMERA_ORDER) * (width + 2), 3), 32,
                     dtype=np.uint8)
    for index, name in enumerate(_CAMERA_ORDER):
        left = _LABEL_W + index * (width + 2) + 2
        cv2.putText(header, f"{name} camera", (left + 6, _TITLE_H - 8),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    return header


def write_track_strip(
    track: Track | str,
    path_png: str | os.PathLike,
    places: Sequence[tuple[str, float]] | None = None,
    *,
    width: int = IMAGE_WIDTH,
    height: int = IMAGE_HEIGHT,
) -> Path:
    """Render left/center/right frames at ``places`` ((label, s_m); default
    :func:`strip_places`) with the car on the centreline, and write one PNG: a header naming
    each column's camera, then a labelled row per place (written atomically). Returns the
    PNG's path."""
    import cv2

    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene

    track = load_track(track) if isinstance(track, str) else track
    places = list(places) if places is not None else strip_places(track)
    if not places:
        raise ValueError(f"{track.name}: no places to show")
    rows = []
    with Scene(track) as scene, CameraRig(scene, _CAMERA_ORDER, width, height) as rig:
        for label, s in places:
            x, y, z = (float(v) for v in track.point(s))
            images = rig.render(x, y, z, float(track.heading_at(s)))
            frames = [images[name] for name in _CAMERA_ORDER]
            gap = np.full((height, 2, 3), 255, dtype=np.uint8)
            row = [_label(f"{track.name} {label}", height)]
            for frame in frames:
                row += [gap, frame]
            rows.append(np.hstack(row))
            rows.append(np.full((2, rows[-1].shape[1], 3), 255, dtype=np.uint8))
    picture = np.vstack([_camera_titles(width, height), *rows[:-1]])
    path = Path(path_png)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, encoded = cv2.imencode(".png", cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError(f"could not encode {path}")
    return write_bytes_atomic(path, encoded.tobytes())
