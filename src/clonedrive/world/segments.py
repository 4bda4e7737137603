"""Generator v2: closed tracks built from road segments, graded by difficulty.

A track is a sequence of pieces of known curvature, laid end to end like a road engineer's
alignment: **straights**, **arcs** (corners), **hairpins** (about 180 deg), **S-bends** (two
opposite arcs), **chicanes** (left-right-left at a tight radius, back on the same line) and
**switchbacks** (two opposite hairpins joined by a short leg, the way a road climbs a slope).
Every arc is entered and left through a clothoid (curvature ramping linearly over a few metres),
so the curvature is continuous and the tightest radius is the arc's own.

The corners turn through exactly one full turn in total; S-bends, chicanes and switchbacks turn
through none. The loop is closed by lengthening the straights (the least change that brings the
end onto the start, :func:`scipy.optimize.lsq_linear`, every straight at least 8 m). Elevation is
a few harmonics of arc length scaled to the difficulty's steepest grade (a third of it on the
lake theme). A draw that fails :class:`~clonedrive.world.track.Track` validation (the road
overlapping itself) or the difficulty's bounds is redrawn from the same generator, so the
track is a pure function of (difficulty, seed).

Difficulty (:class:`Difficulty`, presets in :data:`DIFFICULTIES`): tightest radius, road width,
steepest grade, curvature density (the share of the length in curves) and which pieces appear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial import cKDTree

from clonedrive.world.track import THEMES, Track, TrackError, TrackSpec

#: This generator's version (the ``version`` of the tracks it makes).
VERSION = 2
#: Piece kinds a difficulty may allow (corners and straights always appear).
FEATURES = ("s_bend", "chicane", "hairpin", "switchback")
#: Spacing of the centreline control points written to the track [m].
POINT_SPACING_M = 1.5
#: Shortest straight the closure may leave [m].
MIN_STRAIGHT_M = 8.0
#: Clothoid length in and out of an arc [m] (shorter on very short arcs).
RAMP_M = 7.0
_STEP_M = 0.25  # integration step of the alignment [m]


@dataclass(frozen=True)
class Difficulty:
    """What makes a generated track hard. Radii and widths in metres; grade as dz/ds."""

    name: str
    min_radius_m: float  #: tightest arc: hairpins and chicanes are drawn from here
    max_radius_m: float  #: widest corner
    width_m: tuple[float, float]  #: road width is drawn uniformly from this range
    max_grade: float  #: steepest grade on the mountain theme (lake: a third of it)
    curve_density: float  #: share of the track's length in curves, 0..1
    features: tuple[str, ...]  #: pieces besides straights and corners, from FEATURES
    length_m: tuple[float, float]  #: the length aimed for is drawn from this range

    def __post_init__(self) -> None:
        if not 6.0 <= self.min_radius_m <= self.max_radius_m <= 500.0:
            raise ValueError(f"difficulty {self.name}: need 6 <= min_radius_m <= max_radius_m "
                             f"<= 500, got {self.min_radius_m}, {self.max_radius_m}")
        low, high = self.width_m
        if not 5.0 <= low <= high <= 12.0:
            raise ValueError(f"difficulty {self.name}: width_m must lie in [5, 12] m, got "
                             f"{self.width_m}")
        if not 0.0 <= self.max_grade <= 0.15:
            raise ValueError(f"difficulty {self.name}: max_grade must be in [0, 0.15], got "
                             f"{self.max_grade}")
        if not 0.1 <= self.curve_density <= 0.9:
            raise ValueError(f"difficulty {self.name}: curve_density must be in [0.1, 0.9], got "
                             f"{self.curve_density}")
        unknown = sorted(set(self.features) - set(FEATURES))
        if unknown:
            raise ValueError(f"difficulty {self.name}: unknown feature(s) {unknown}; use "
                             f"{', '.join(FEATURES)}")
        if not 400.0 <= self.length_m[0] <= self.length_m[1] <= 3000.0:
            raise ValueError(f"difficulty {self.name}: length_m must lie in [400, 3000] m, got "
                             f"{self.length_m}")
        if 2.0 * self.min_radius_m < high + 2.0 and (
                "hairpin" in self.features or "switchback" in self.features):
            raise ValueError(f"difficulty {self.name}: a hairpin of radius {self.min_radius_m} m "
                             f"needs roads narrower than {2 * self.min_radius_m - 2:.0f} m")


#: The three presets. ``hard``: 10 m hairpins and switchbacks on a 6-7 m road with 12 % grades.
DIFFICULTIES: dict[str, Difficulty] = {
    "easy": Difficulty("easy", min_radius_m=30.0, max_radius_m=90.0, width_m=(8.0, 9.0),
                       max_grade=0.04, curve_density=0.35, features=("s_bend",),
                       length_m=(900.0, 1600.0)),
    "medium": Difficulty("medium", min_radius_m=15.0, max_radius_m=60.0, width_m=(7.0, 8.5),
                         max_grade=0.08, curve_density=0.5,
                         features=("s_bend", "chicane", "hairpin"), length_m=(800.0, 1400.0)),
    "hard": Difficulty("hard", min_radius_m=10.0, max_radius_m=40.0, width_m=(6.0, 7.0),
                       max_grade=0.12, curve_density=0.6,
                       features=("s_bend", "chicane", "hairpin", "switchback"),
                       length_m=(800.0, 1400.0)),
}
#: The difficulty of ``gen2:<seed>``.
DEFAULT_DIFFICULTY = "medium"


# ---------------------------------------------------------------------- the alignment
@dataclass(frozen=True)
class _Piece:
    """A stretch of road whose curvature goes linearly from ``k0`` to ``k1`` [1/m]."""

    length_m: float
    k0: float = 0.0
    k1: float = 0.0
    free: bool = False  #: a straight whose length the closure may change
    kind: str = "straight"
    min_m: float = 0.0  #: a free straight is never made shorter than this [m]


def _arc(angle_rad: float, radius_m: float, kind: str) -> list[_Piece]:
    """Clothoid in, constant arc, clothoid out: turns exactly ``angle_rad`` (+ = left)."""
    k = math.copysign(1.0 / radius_m, angle_rad)
    total = abs(angle_rad) * radius_m  # heading change = k * (core + ramp)
    ramp = min(RAMP_M, 0.4 * total)
    return [_Piece(ramp, 0.0, k, kind=kind), _Piece(total - ramp, k, k, kind=kind),
            _Piece(ramp, k, 0.0, kind=kind)]


def _straight(length_m: float, *, free: bool = True, min_m: float = MIN_STRAIGHT_M) -> _Piece:
    return _Piece(max(length_m, min_m), free=free, min_m=min_m)


def _integrate(pieces: list[_Piece]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (n, 2), arc length (n,) and the piece index of each step of the alignment laid
    from the origin heading east (exact headings, midpoint positions every ~0.25 m)."""
    xs, ys, ss, owner = [0.0], [0.0], [0.0], []
    x = y = heading = s = 0.0
    for index, piece in enumerate(pieces):
        n = max(1, int(math.ceil(piece.length_m / _STEP_M)))
        ds = piece.length_m / n
        u = (np.arange(n) + 0.5) * ds  # midpoints of the steps
        h_mid = heading + piece.k0 * u + 0.5 * (piece.k1 - piece.k0) * u * u / max(
            piece.length_m, 1e-12)
        steps_x = np.cos(h_mid) * ds
        steps_y = np.sin(h_mid) * ds
        xs.extend((x + np.cumsum(steps_x)).tolist())
        ys.extend((y + np.cumsum(steps_y)).tolist())
        ss.extend((s + ds * np.arange(1, n + 1)).tolist())
        owner.extend([index] * n)
        x, y = xs[-1], ys[-1]
        heading += piece.length_m * 0.5 * (piece.k0 + piece.k1)
        s += piece.length_m
    return np.column_stack([xs, ys]), np.asarray(ss), np.asarray(owner)


def _headings(pieces: list[_Piece]) -> list[float]:
    """Heading [rad] at the start of each piece."""
    out, heading = [], 0.0
    for piece in pieces:
        out.append(heading)
        heading += piece.length_m * 0.5 * (piece.k0 + piece.k1)
    return out


def _close(pieces: list[_Piece]) -> list[_Piece] | None:
    """The pieces with the free straights' lengths changed (least squares, each at least
    MIN_STRAIGHT_M) so that the alignment ends where it starts; None if that is impossible."""
    free = [i for i, p in enumerate(pieces) if p.free]
    headings = _headings(pieces)
    zeroed = [_Piece(0.0) if p.free else p for p in pieces]
    gap = _integrate(zeroed)[0][-1]  # where the end lies with every free straight at 0 m
    directions = np.array([[math.cos(headings[i]), math.sin(headings[i])] for i in free]).T
    wanted = np.array([pieces[i].length_m for i in free])
    weight = 100.0  # closing the loop matters far more than keeping the drawn lengths
    matrix = np.vstack([weight * directions, np.eye(len(free))])
    target = np.concatenate([-weight * gap, wanted])
    lowest = np.array([pieces[i].min_m for i in free])
    result = lsq_linear(matrix, target, bounds=(lowest, np.inf), method="bvls")
    lengths = result.x
    if np.linalg.norm(directions @ lengths + gap) > 0.05:
        return None
    out = list(pieces)
    for i, length in zip(free, lengths, strict=True):
        out[i] = _straight(float(length), min_m=pieces[i].min_m)
    return out


# ---------------------------------------------------------------------- drawing a layout
def _corner_angles(rng: np.random.Generator, hairpins: int) -> list[tuple[float, str]]:
    """Signed corner angles [rad] that add up to one full left turn: ``hairpins`` of about
    180 deg, the rest ordinary corners, sometimes one counter-turn."""
    top = 195.0 if hairpins < 2 else 182.0
    corners = [(math.radians(rng.uniform(165.0, top)), "hairpin") for _ in range(hairpins)]
    # Two hairpins nearly close the loop alone; a counter-turn then leaves room for two more
    # corners, so that the straights point in enough directions to close the loop.
    if hairpins >= 2 or rng.random() < 0.5:
        corners.append((-math.radians(rng.uniform(40.0, 80.0)), "corner"))
    remaining = 2.0 * math.pi - sum(a for a, _ in corners)
    count = max(3, int(math.ceil(remaining / math.radians(rng.uniform(60.0, 110.0)))))
    weights = rng.uniform(0.6, 1.4, count)
    corners += [(remaining * w / weights.sum(), "corner") for w in weights]
    return corners


def _feature(kind: str, rng: np.random.Generator, d: Difficulty) -> list[_Piece]:
    """A piece that turns through nothing in total (it may shift the road sideways)."""
    side = 1.0 if rng.random() < 0.5 else -1.0
    tight = lambda: float(rng.uniform(d.min_radius_m, 1.4 * d.min_radius_m))  # noqa: E731
    if kind == "s_bend":
        angle = math.radians(rng.uniform(35.0, 80.0))
        low = max(d.min_radius_m, 1.5 * d.min_radius_m)
        radius = float(rng.uniform(low, max(low, d.max_radius_m)))
        return (_arc(side * angle, radius, "s_bend")
                + [_straight(rng.uniform(0.0, 15.0), min_m=0.0)]
                + _arc(-side * angle, radius, "s_bend"))
    if kind == "chicane":
        angle = math.radians(rng.uniform(25.0, 45.0))
        radius = tight()
        return (_arc(side * angle, radius, "chicane") + _arc(-2 * side * angle, radius, "chicane")
                + _arc(side * angle, radius, "chicane"))
    if kind == "switchback":
        side = -1.0  # the loop turns left: a switchback that first turns right bulges outward
        radius = tight()
        leg = float(rng.uniform(30.0, 70.0))
        return (_arc(side * math.pi, radius, "switchback") + [_straight(leg, min_m=25.0)]
                + _arc(-side * math.pi, radius, "switchback"))
    raise ValueError(kind)


def _draw_layout(rng: np.random.Generator, d: Difficulty) -> list[_Piece]:
    """Corners adding up to one turn, free straights between them, features on the straights;
    the straights' drawn lengths give the difficulty's curvature density."""
    hairpins = 0
    if "hairpin" in d.features:
        with_switchbacks = "switchback" in d.features
        hairpins = int(rng.integers(0, 2)) if with_switchbacks else int(rng.random() < 0.6)
    corners = _corner_angles(rng, hairpins)
    order = rng.permutation(len(corners))
    corners = [corners[i] for i in order]
    features = [f for f in d.features if f != "hairpin"]
    body: list[list[_Piece]] = []
    for angle, kind in corners:
        if kind == "hairpin":
            radius = float(rng.uniform(d.min_radius_m, 1.3 * d.min_radius_m))
        else:
            # wide corners for long turns, tight ones for short turns
            low = max(d.min_radius_m, 1.2 * d.min_radius_m)
            radius = float(rng.uniform(low, d.max_radius_m))
        body.append(_arc(angle, radius, kind))
    def curved(parts: list[list[_Piece]]) -> float:
        return sum(p.length_m for part in parts for p in part if p.k0 or p.k1)

    # Add features until the length (curves at the difficulty's density) reaches the aim.
    aim_m = float(rng.uniform(*d.length_m))
    extras: list[list[_Piece]] = []
    if "switchback" in features and hairpins == 0:  # a hard track always has a 180 deg turn
        extras.append(_feature("switchback", rng, d))
    while features and (curved(body) + curved(extras)) / d.curve_density < aim_m:
        extras.append(_feature(str(rng.choice(features)), rng, d))
    curved_m = curved(body) + curved(extras)
    straight_total = max(curved_m * (1.0 - d.curve_density) / d.curve_density,
                         aim_m - curved_m if not features else 0.0)
    shares = rng.dirichlet(np.full(len(body) + len(extras) + 1, 2.0)) * straight_total
    # which gap after a corner each feature goes into: spread over the gaps, in random order
    slots = rng.permutation(np.arange(len(extras)) % len(body))
    pieces: list[_Piece] = []
    share = iter(shares)
    for index, corner in enumerate(body):
        pieces.append(_straight(next(share) + MIN_STRAIGHT_M))
        for extra_index in np.flatnonzero(slots == index):
            pieces += extras[extra_index]
            pieces.append(_straight(next(share) + MIN_STRAIGHT_M))
        pieces += corner
    pieces.append(_straight(next(share) + MIN_STRAIGHT_M))
    return pieces


def _elevation(rng: np.random.Generator, s: np.ndarray, length_m: float,
               max_grade: float) -> np.ndarray:
    """Heights [m] along the loop: three harmonics scaled so the steepest grade is max_grade."""
    phase = 2.0 * math.pi * s / length_m
    z = np.zeros_like(s)
    for k in (1, 2, 3):
        z += rng.uniform(0.3, 1.0) * np.sin(k * phase + rng.uniform(0, 2 * math.pi)) / k
    grade = np.abs(np.gradient(z, s))
    if max_grade <= 0 or grade.max() <= 0:
        return np.zeros_like(s)
    return z * max_grade / grade.max()


def _draw_spec(rng: np.random.Generator, d: Difficulty, name: str) -> TrackSpec | None:
    theme = THEMES[int(rng.integers(len(THEMES)))]
    width_m = round(float(rng.uniform(*d.width_m)), 2)
    pieces = _close(_draw_layout(rng, d))
    if pieces is None:
        return None
    points, s, _ = _integrate(pieces)
    length = float(s[-1])
    if not 500.0 <= length <= 3200.0:
        return None
    # Spread the closure's last centimetres along the loop, then drop the repeated start.
    points = points - np.outer(s / length, points[-1] - points[0])
    count = int(round(length / POINT_SPACING_M))
    at = np.arange(count) * (length / count)
    xy = np.column_stack([np.interp(at, s, points[:, 0]), np.interp(at, s, points[:, 1])])
    if _overlaps(xy, length / count, width_m):
        return None
    grade = d.max_grade if theme == "mountain" else d.max_grade / 3.0
    z = _elevation(rng, at, length, grade)
    # start in the middle of the longest straight: the start line is never in a bend
    starts = np.cumsum([0.0] + [p.length_m for p in pieces])
    longest = int(np.argmax([p.length_m if not (p.k0 or p.k1) else -1.0 for p in pieces]))
    start = int(round((starts[longest] + 0.5 * pieces[longest].length_m) / (length / count)))
    xy, z = np.roll(xy, -start, axis=0), np.roll(z, -start)
    xy -= xy[0]
    if rng.random() < 0.5:  # half the tracks turn right (run the loop mirrored)
        xy[:, 1] = -xy[:, 1]
    centerline = tuple((float(a), float(b), float(c)) for (a, b), c in zip(xy, z, strict=True))
    return TrackSpec(name=name, version=VERSION, theme=theme, width_m=width_m, closed=True,
                     centerline=centerline)


def _overlaps(xy: np.ndarray, step_m: float, width_m: float) -> bool:
    """A cheap early form of Track's overlap check on the control points: parts of the loop
    far apart along it that come closer than a road width plus a 1 m verge."""
    gap = width_m + 1.0
    pairs = cKDTree(xy).query_pairs(r=gap, output_type="ndarray")
    if not len(pairs):
        return False
    along = np.abs(pairs[:, 0] - pairs[:, 1]) * step_m
    along = np.minimum(along, len(xy) * step_m - along)
    return bool((along > 0.5 * math.pi * gap * 1.2).any())


def generate_v2(seed: int, difficulty: str | Difficulty = DEFAULT_DIFFICULTY, *,
                name: str | None = None, max_attempts: int = 200) -> Track:
    """A valid closed track from ``seed`` at ``difficulty`` (same inputs, same track)."""
    d = DIFFICULTIES[difficulty] if isinstance(difficulty, str) else difficulty
    if isinstance(difficulty, str) and difficulty not in DIFFICULTIES:
        raise TrackError(f"unknown difficulty {difficulty!r}: use {', '.join(DIFFICULTIES)}")
    if seed < 0:
        raise TrackError(f"generated track seed must be >= 0, got {seed}")
    name = name or f"gen2:{d.name}:{seed}"
    # the difficulty's name is part of the seed: easy:5 and hard:5 are unrelated tracks
    rng = np.random.default_rng([VERSION, seed, *d.name.encode()])
    last_error: object = "no closed layout"
    for _ in range(max_attempts):
        spec = _draw_spec(rng, d, name)
        if spec is None:
            continue
        try:
            track = Track(spec)
        except TrackError as error:
            last_error = error
            continue
        if track.min_radius_m < 0.9 * d.min_radius_m:
            last_error = f"tightest curve {track.min_radius_m:.1f} m"
            continue
        return track
    raise TrackError(f"{name}: no valid track in {max_attempts} draws ({last_error})")


def curved_fraction(track: Track, radius_m: float = 100.0) -> float:
    """Share of the track's length where the road bends tighter than ``radius_m``."""
    return float(np.mean(np.abs(track.curvature_table) > 1.0 / radius_m))
