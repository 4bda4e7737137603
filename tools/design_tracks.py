"""Regenerate the built-in track files (src/clonedrive/world/tracks/*.json).

Each track is drawn as a turtle path of straights and arcs; two straights' lengths are solved so
the path closes. Elevation is a function of arc length. Run: python tools/design_tracks.py
Change a track's "version" whenever its geometry changes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "src" / "clonedrive" / "world" / "tracks"


def turtle(segments: list[tuple], step_m: float = 2.0) -> np.ndarray:
    """Points (x, y) along ('S', length) and ('A', radius, angle_deg: + left) segments."""
    x = y = heading = 0.0
    points = [(x, y)]
    for seg in segments:
        if seg[0] == "S":
            n = max(1, int(round(seg[1] / step_m)))
            for _ in range(n):
                x += math.cos(heading) * seg[1] / n
                y += math.sin(heading) * seg[1] / n
                points.append((x, y))
        else:
            radius, angle = seg[1], math.radians(seg[2])
            n = max(2, int(round(abs(angle) * radius / step_m)))
            for _ in range(n):
                heading += angle / n
                chord = 2 * radius * math.sin(abs(angle / n) / 2)
                x += math.cos(heading - angle / n / 2) * chord
                y += math.sin(heading - angle / n / 2) * chord
                points.append((x, y))
    return np.array(points)


def close_by_straights(segments: list[tuple], i: int, j: int) -> list[tuple]:
    """Adjust the lengths of straights i and j so the turtle path ends where it starts."""
    def end(segs):
        return turtle(segs)[-1]

    base = end(segments)
    unit = []
    for k in (i, j):
        segs = list(segments)
        segs[k] = ("S", segs[k][1] + 1.0)
        unit.append(end(segs) - base)
    delta = np.linalg.solve(np.column_stack(unit), -base)
    out = list(segments)
    out[i] = ("S", segments[i][1] + delta[0])
    out[j] = ("S", segments[j][1] + delta[1])
    return out


def close_best(segments: list[tuple]) -> list[tuple]:
    """Close the path by the pair of straights that needs the smallest change (all >= 20 m)."""
    straights = [k for k, seg in enumerate(segments) if seg[0] == "S"]
    best = None
    for a in straights:
        for b in straights:
            if b <= a:
                continue
            try:
                out = close_by_straights(segments, a, b)
            except np.linalg.LinAlgError:
                continue
            if min(out[a][1], out[b][1]) < 20:
                continue
            cost = abs(out[a][1] - segments[a][1]) + abs(out[b][1] - segments[b][1])
            if best is None or cost < best[0]:
                best = (cost, out, a, b)
    assert best is not None, "no pair of straights closes the path"
    print(f"closed by straights {best[2]} and {best[3]} (change {best[0]:.0f} m)")
    return best[1]


def resample(points: np.ndarray, spacing_m: float) -> np.ndarray:
    pts = points[:-1]  # last point repeats the first
    d = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(d)])
    length = s[-1]
    n = int(length // spacing_m)
    t = np.linspace(0, length, n, endpoint=False)
    closed = np.vstack([pts, pts[:1]])
    xy = np.column_stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])])
    return xy, t, length


def write(name: str, theme: str, width: float, xy: np.ndarray, z: np.ndarray, version: int):
    data = {
        "name": name,
        "version": version,
        "theme": theme,
        "width_m": width,
        "closed": True,
        "centerline": [[round(float(a), 2), round(float(b), 2), round(float(c), 2)]
                       for (a, b), c in zip(xy, z, strict=True)],
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{name}.json").write_text(json.dumps(data) + "\n")


def lake() -> None:
    # Counter-clockwise loop: a long straight bridge over the lake, then gentle and medium curves.
    segments = [
        ("S", 160),          # 0: start straight, then the bridge
        ("A", 70, 75),
        ("S", 60),
        ("A", 45, 50),
        ("A", 90, -30),      # gentle S-bend
        ("S", 70),           # 4: solved
        ("A", 38, 95),       # medium, kerbed
        ("S", 50),
        ("A", 60, 40),
        ("A", 55, -35),
        ("S", 80),           # 9: solved
        ("A", 40, 90),
        ("A", 120, 20),
        ("S", 30),
        ("A", 50, 55),
    ]
    assert abs(sum(s[2] for s in segments if s[0] == "A") - 360) < 1e-6
    segments = close_best(segments)
    xy, s, length = resample(turtle(segments), 8.0)
    z = 0.8 * np.sin(2 * np.pi * s / length) + 0.6 * np.sin(6 * np.pi * s / length + 1.0)
    write("lake", "lake", 8.0, xy - xy.mean(axis=0), z + 1.5, version=1)


def mountain() -> None:
    # Hills, sharp turns and a 12 m hairpin; runs counter-clockwise overall.
    segments = [
        ("S", 260),          # start straight, heading east
        ("A", 30, 60),
        ("S", 100),
        ("A", 22, -60),      # sharp right
        ("S", 180),
        ("A", 40, 90),
        ("S", 140),
        ("A", 25, 70),
        ("S", 100),
        ("A", 12, -180),     # the hairpin
        ("S", 120),
        ("A", 25, 180),      # switchback
        ("S", 180),
        ("A", 30, 70),
        ("S", 200),
        ("A", 20, 60),       # sharp left
        ("S", 140),
        ("A", 35, -40),
        ("S", 180),
        ("A", 28, 110),
    ]
    assert abs(sum(s[2] for s in segments if s[0] == "A") - 360) < 1e-6
    segments = close_best(segments)
    xy, s, length = resample(turtle(segments), 6.0)
    u = 2 * np.pi * s / length
    z = 30 * np.sin(u) + 3 * np.sin(3 * u + 0.8) + 1.0 * np.sin(9 * u + 2.0)
    # Scale so the steepest grade is 10 %; the short harmonic makes blind crests.
    grade = np.abs(np.gradient(z, s))
    z *= 0.10 / grade.max()
    write("mountain", "mountain", 7.0, xy - xy.mean(axis=0), z - z.min(), version=1)


if __name__ == "__main__":
    lake()
    mountain()
