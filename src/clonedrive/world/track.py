"""Track geometry: a closed road along a periodic smoothing spline, with width and elevation.

Pure NumPy/SciPy: no rendering imports. Units are metres and radians; x east, y north, z up.
The driving direction is increasing arc length ``s``. Cross-track error (CTE) is positive to the
right of the centreline in the driving direction.

A track is loaded from a JSON file (format in DESIGN.md) into a :class:`TrackSpec`, validated, and
turned into a :class:`Track` that answers geometric queries, vectorised over points.

Every input is bounded before anything is allocated in proportion to it: the file's size
(:data:`MAX_TRACK_FILE_BYTES`), the number of control points (:data:`MAX_CONTROL_POINTS`), their
coordinates (:data:`MAX_COORDINATE_M`) and the track's length (:data:`MAX_TRACK_LENGTH_M`); a
track outside them is refused with a message naming the limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import splev, splprep
from scipy.spatial import cKDTree

from clonedrive.base.config import JsonFileError, read_json
from clonedrive.base.udacity_spec import MAX_WHEEL_ANGLE_DEG

#: Wheelbase [m] and maximum wheel angle [deg] that every track must be drivable with.
DRIVABLE_WHEELBASE_M = 2.7
DRIVABLE_MAX_WHEEL_ANGLE_DEG = MAX_WHEEL_ANGLE_DEG
#: Smallest radius [m] a car with that wheelbase and wheel angle can follow at 10 mph
#: (low-speed kinematic limit L / tan(delta_max)).
MIN_DRIVABLE_RADIUS_M = DRIVABLE_WHEELBASE_M / math.tan(math.radians(DRIVABLE_MAX_WHEEL_ANGLE_DEG))

TRACK_KEYS = ("name", "version", "theme", "width_m", "closed", "centerline")
THEMES = ("lake", "mountain")
_SAMPLE_STEP_M = 0.5

#: Largest track file read [bytes]; the mountain track's 382 points take 15 KB.
MAX_TRACK_FILE_BYTES = 2 << 20
#: Most centreline control points a track may have.
MAX_CONTROL_POINTS = 10_000
#: Largest |x|, |y| or |z| of a control point [m]: the world is 20 km across.
MAX_COORDINATE_M = 10_000.0
#: Longest track [m] (the lake is 1.2 km, the mountain 2.6 km): bounds every table along it.
MAX_TRACK_LENGTH_M = 20_000.0
#: Track.project takes its plain-Python path up to this many points (NumPy's beyond).
SMALL_PROJECTION = 8
#: Longest track name [characters].
MAX_TRACK_NAME_CHARS = 200
#: The newest track version this code knows (tracks count versions from 1, bumped with their
#: geometry: the built-in files and the generator); a file with a newer one is refused.
NEWEST_TRACK_VERSION = 2


class TrackError(ValueError):
    """A track file or specification that cannot be used; the message says where."""


@dataclass(frozen=True)
class TrackSpec:
    """What a track file holds. ``centerline`` rows are (x, y, z) or (x, y, z, width) [m]."""

    name: str
    version: int
    theme: str
    width_m: float
    closed: bool
    centerline: tuple[tuple[float, ...], ...]

    @classmethod
    def from_dict(cls, data: object, *, source: str = "track") -> TrackSpec:
        if not isinstance(data, dict):
            raise TrackError(f"{source}: expected a JSON object with keys {', '.join(TRACK_KEYS)}")
        unknown = sorted(set(data) - set(TRACK_KEYS))
        if unknown:
            raise TrackError(
                f"{source}: unknown key(s) {', '.join(map(repr, unknown))}; "
                f"allowed: {', '.join(TRACK_KEYS)}"
            )
        missing = [key for key in ("name", "centerline") if key not in data]
        if missing:
            raise TrackError(f"{source}: missing key(s) {', '.join(missing)}")
        name = data["name"]
        if not isinstance(name, str) or not 0 < len(name) <= MAX_TRACK_NAME_CHARS:
            raise TrackError(f"{source}: name must be a text of 1 to {MAX_TRACK_NAME_CHARS} "
                             f"characters, got {_short(name)}")
        version = data.get("version", 1)
        if not _is_integer(version) or version < 1:
            raise TrackError(f"{source}: version must be a whole number >= 1, got "
                             f"{_short(version)}")
        if version > NEWEST_TRACK_VERSION:
            raise TrackError(
                f"{source}: track version {version} is newer than this clonedrive knows "
                f"(1 to {NEWEST_TRACK_VERSION}); was it written by a newer clonedrive?")
        theme = data.get("theme", "lake")
        if theme not in THEMES:
            raise TrackError(f"{source}: theme {theme!r} is not one of {', '.join(THEMES)}")
        width = data.get("width_m", 8.0)
        if not _is_number(width) or not 3.0 <= width <= 30.0:
            raise TrackError(f"{source}: width_m must be a number in [3, 30] m, got {width!r}")
        if data.get("closed", True) is not True:
            raise TrackError(f"{source}: only closed tracks are supported (closed: true)")
        points = data["centerline"]
        if not isinstance(points, list):
            raise TrackError(f"{source}: centerline must be a list of [x, y, z] points")
        if len(points) > MAX_CONTROL_POINTS:
            raise TrackError(f"{source}: centerline has {len(points)} points; at most "
                             f"{MAX_CONTROL_POINTS} are allowed")
        rows = []
        for index, point in enumerate(points):
            ok = isinstance(point, list) and len(point) in (3, 4)
            ok = ok and all(_is_number(v) and math.isfinite(v) for v in point)
            if not ok:
                raise TrackError(
                    f"{source}: centerline point {index} is {point!r}; expected [x, y, z] or "
                    "[x, y, z, width_m] with finite numbers"
                )
            rows.append(tuple(float(v) for v in point))
        if len({len(row) for row in rows}) > 1:
            raise TrackError(f"{source}: centerline points mix 3 and 4 values; use one form")
        return cls(
            name=name,
            version=int(version),
            theme=theme,
            width_m=float(width),
            closed=True,
            centerline=tuple(rows),
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "version": self.version,
            "theme": self.theme,
            "width_m": self.width_m,
            "closed": self.closed,
            "centerline": [[round(v, 3) for v in row] for row in self.centerline],
        }


@dataclass(frozen=True)
class Projection:
    """Where points lie relative to the track (arrays, one entry per point)."""

    s_m: np.ndarray  #: arc length of the nearest centreline point [m], in [0, length)
    cte_m: np.ndarray  #: signed lateral distance, + = right of centre [m]
    half_width_m: np.ndarray  #: half the road width there [m]
    z_m: np.ndarray  #: road surface height there [m]


class Track:
    """A validated closed track sampled every 0.5 m along its spline centreline."""

    def __init__(self, spec: TrackSpec, *, source: str | None = None):
        self.spec = spec
        self.name = spec.name
        self.version = spec.version
        self.theme = spec.theme
        where = source or spec.name
        if len(spec.centerline) > MAX_CONTROL_POINTS:
            raise TrackError(f"{where}: centerline has {len(spec.centerline)} points; at most "
                             f"{MAX_CONTROL_POINTS} are allowed")
        control = np.asarray(spec.centerline, dtype=float)
        if len(control) < 8:
            raise TrackError(
                f"{where}: centerline has {len(control)} points; at least 8 are needed"
            )
        _check_extent(control, where)
        if np.allclose(control[0, :2], control[-1, :2]):
            control = control[:-1]  # closing point repeated: the spline is periodic anyway
        widths = control[:, 3] if control.shape[1] == 4 else np.full(len(control), spec.width_m)
        bad_width = np.flatnonzero((widths < 3.0) | (widths > 30.0))
        if bad_width.size:
            raise TrackError(
                f"{where}: centerline point {bad_width[0]} has width {widths[bad_width[0]]:.2f} m; "
                "widths must be in [3, 30] m"
            )
        steps = np.linalg.norm(np.diff(np.vstack([control, control[:1]])[:, :2], axis=0), axis=1)
        duplicate = np.flatnonzero(steps < 1e-6)
        if duplicate.size:
            raise TrackError(f"{where}: centerline points {duplicate[0]} and the next coincide")
        self._build(control[:, :3], widths, where)
        self._validate(where)

    # ------------------------------------------------------------------ construction
    def _build(self, control: np.ndarray, widths: np.ndarray, where: str) -> None:
        closed = np.vstack([control, control[:1]])
        closed_w = np.append(widths, widths[0])
        tck, _ = splprep(
            [closed[:, 0], closed[:, 1], closed[:, 2], closed_w], s=0.0, per=1, k=3, quiet=2
        )
        # Arc length by dense sampling of the spline parameter.
        u_fine = np.linspace(0.0, 1.0, max(4000, 40 * len(control)), endpoint=False)
        fine = np.array(splev(u_fine, tck)).T
        seg = np.linalg.norm(np.diff(np.vstack([fine, fine[:1]])[:, :2], axis=0), axis=1)
        s_fine = np.concatenate([[0.0], np.cumsum(seg)])
        self.length_m = float(s_fine[-1])
        if self.length_m > MAX_TRACK_LENGTH_M:  # the spline swings wider than its points
            raise TrackError(f"{where}: the centreline is {self.length_m / 1000:.1f} "
                             f"km long; at most {MAX_TRACK_LENGTH_M / 1000:g} km are allowed")
        count = int(round(self.length_m / _SAMPLE_STEP_M))
        self.ds_m = self.length_m / count
        self.s = np.arange(count) * self.ds_m
        u = np.interp(self.s, s_fine, np.append(u_fine, 1.0))
        x, y, z, w = splev(u, tck)
        dx, dy, dz, _ = splev(u, tck, der=1)
        ddx, ddy, _, _ = splev(u, tck, der=2)
        speed_xy = np.hypot(dx, dy)
        self.xyz = np.column_stack([x, y, z])
        self.width = np.asarray(w)
        self.tangent = np.column_stack([dx, dy]) / speed_xy[:, None]
        self.heading = np.arctan2(self.tangent[:, 1], self.tangent[:, 0])
        self.right_normal = np.column_stack([self.tangent[:, 1], -self.tangent[:, 0]])
        #: signed curvature [1/m], + = turning left
        self.curvature_table = (dx * ddy - dy * ddx) / speed_xy**3
        #: grade dz/ds along the driving direction
        self.grade_table = np.asarray(dz) / speed_xy
        self._tree = cKDTree(self.xyz[:, :2])
        # Python rows of the tables, for projecting a few points at a time (_project_few).
        self._xy_rows = self.xyz[:, :2].tolist()
        self._xyz_rows = self.xyz.tolist()
        self._normal_rows = self.right_normal.tolist()
        self._width_rows = self.width.tolist()
        self._s_rows = self.s.tolist()

    def _validate(self, where: str) -> None:
        radius = 1.0 / np.maximum(np.abs(self.curvature_table), 1e-9)
        tight = np.flatnonzero(radius < MIN_DRIVABLE_RADIUS_M)
        if tight.size:
            i = tight[np.argmin(radius[tight])]
            raise TrackError(
                f"{where}: curve of radius {radius[i]:.1f} m at s={self.s[i]:.0f} m "
                f"(x={self.xyz[i, 0]:.1f}, y={self.xyz[i, 1]:.1f}) is undrivable at 10 mph with a "
                f"{DRIVABLE_MAX_WHEEL_ANGLE_DEG:.0f} deg wheel angle (minimum "
                f"{MIN_DRIVABLE_RADIUS_M:.1f} m)"
            )
        inner = np.flatnonzero(radius < 0.5 * self.width + 1.0)
        if inner.size:
            i = inner[0]
            raise TrackError(
                f"{where}: curve of radius {radius[i]:.1f} m at s={self.s[i]:.0f} m is tighter "
                "than "
                f"half the road width ({0.5 * self.width[i]:.1f} m): the road folds over itself"
            )
        # The road overlaps itself where two parts far apart along s come closer than their
        # half-widths plus a 1 m verge. A bend of radius R keeps chord >= 2*ds/pi for arcs up to
        # a half circle, so pairs closer along s than pi/2 * gap are neighbours, not overlaps.
        gap = float(self.width.max()) + 1.0
        pairs = self._tree.query_pairs(r=gap, output_type="ndarray")
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            along = np.abs(self.s[i] - self.s[j])
            along = np.minimum(along, self.length_m - along)
            dist = np.linalg.norm(self.xyz[i, :2] - self.xyz[j, :2], axis=1)
            limit = 0.5 * (self.width[i] + self.width[j]) + 1.0
            bad = (dist < limit) & (along > 0.5 * math.pi * gap * 1.2)
            if bad.any():
                k = np.flatnonzero(bad)[0]
                a, b = sorted((self.s[i[k]], self.s[j[k]]))
                raise TrackError(
                    f"{where}: the road intersects or overlaps itself between s={a:.0f} m and "
                    f"s={b:.0f} m (near x={self.xyz[i[k], 0]:.1f}, y={self.xyz[i[k], 1]:.1f})"
                )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_file(cls, path: str | Path) -> Track:
        """Read and validate a track file; any problem is one :class:`TrackError` line."""
        path = Path(path)
        try:
            data = read_json(path, max_bytes=MAX_TRACK_FILE_BYTES, what="track file")
        except FileNotFoundError:
            raise TrackError(f"{path}: no such track file") from None
        except JsonFileError as error:
            raise TrackError(str(error)) from None
        except OSError as error:  # permissions, a name too long, an I/O error
            raise TrackError(f"{path}: cannot read the track file ({error.strerror})") from None
        return cls(TrackSpec.from_dict(data, source=str(path)), source=str(path))

    # ------------------------------------------------------------------ arc-length queries
    def wrap(self, s_m: np.ndarray | float) -> np.ndarray:
        return np.mod(s_m, self.length_m)

    def _interp(self, table: np.ndarray, s_m: np.ndarray | float) -> np.ndarray:
        s = self.wrap(np.asarray(s_m, dtype=float))
        f = s / self.ds_m
        i0 = np.floor(f).astype(int) % len(self.s)
        i1 = (i0 + 1) % len(self.s)
        t = f - np.floor(f)
        if table.ndim == 2:
            t = t[..., None]
        return table[i0] * (1.0 - t) + table[i1] * t

    def point(self, s_m: np.ndarray | float) -> np.ndarray:
        """Centreline point(s) (x, y, z) [m] at arc length ``s_m``."""
        return self._interp(self.xyz, s_m)

    def heading_at(self, s_m: np.ndarray | float) -> np.ndarray:
        """Direction of travel [rad, from +x, counter-clockwise] at ``s_m``."""
        t = self._interp(self.tangent, s_m)
        return np.arctan2(t[..., 1], t[..., 0])

    def curvature(self, s_m: np.ndarray | float) -> np.ndarray:
        """Signed curvature [1/m] at ``s_m``; + = the road turns left."""
        return self._interp(self.curvature_table, s_m)

    def grade(self, s_m: np.ndarray | float) -> np.ndarray:
        """Slope dz/ds along the driving direction at ``s_m`` (0.1 = 10 % uphill)."""
        return self._interp(self.grade_table, s_m)

    def width_at(self, s_m: np.ndarray | float) -> np.ndarray:
        """Road width [m] at ``s_m``."""
        return self._interp(self.width, s_m)

    def offset_point(self, s_m: np.ndarray | float, offset_m: np.ndarray | float) -> np.ndarray:
        """Point(s) (x, y, z) at arc length ``s_m`` and lateral offset ``offset_m`` (+ = right)."""
        p = self.point(s_m)
        n = self._interp(self.right_normal, s_m)
        out = np.array(p, dtype=float, copy=True)
        out[..., :2] += n * np.asarray(offset_m, dtype=float)[..., None]
        return out

    # ------------------------------------------------------------------ point queries
    def project(self, points_xy: np.ndarray) -> Projection:
        """Project world points (..., 2) onto the centreline (nearest sample, refined on the
        two segments beside it)."""
        pts = np.asarray(points_xy, dtype=float)
        shape = pts.shape[:-1]
        flat = pts.reshape(-1, 2)
        _, nearest = self._tree.query(flat)
        if len(flat) <= SMALL_PROJECTION:
            return self._project_few(flat, nearest, shape)
        n = len(self.s)
        best_s = np.empty(len(flat))
        best_d2 = np.full(len(flat), np.inf)
        for i0 in (nearest - 1, nearest):  # the two segments around the nearest sample
            i0 = i0 % n
            i1 = (i0 + 1) % n
            a = self.xyz[i0, :2]
            ab = self.xyz[i1, :2] - a
            t = np.clip(np.einsum("ij,ij->i", flat - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
            foot = a + ab * t[:, None]
            d2 = np.einsum("ij,ij->i", flat - foot, flat - foot)
            better = d2 < best_d2
            best_d2 = np.where(better, d2, best_d2)
            best_s = np.where(better, self.s[i0] + t * self.ds_m, best_s)
        best_s = self.wrap(best_s)
        centre = self.point(best_s)
        normal = self._interp(self.right_normal, best_s)
        cte = np.einsum("ij,ij->i", flat - centre[:, :2], normal)
        return Projection(
            s_m=best_s.reshape(shape),
            cte_m=cte.reshape(shape),
            half_width_m=(0.5 * self.width_at(best_s)).reshape(shape),
            z_m=centre[:, 2].reshape(shape),
        )

    def _project_few(self, flat: np.ndarray, nearest: np.ndarray, shape: tuple) -> Projection:
        """:meth:`project` for a few points (a car's centre and tyres, every step), in plain
        Python floats: the same operations in the same order, so bit-identical results (tested),
        without NumPy's per-call cost on arrays of five."""
        n = len(self.s)
        ds = self.ds_m
        length = self.length_m
        xy = self._xy_rows
        s_rows = self._s_rows
        out_s, out_cte, out_half, out_z = [], [], [], []
        for (px, py), near in zip(flat.tolist(), nearest.tolist(), strict=True):
            best_s, best_d2 = 0.0, math.inf
            for i0 in ((near - 1) % n, near % n):  # the two segments around the nearest sample
                ax, ay = xy[i0]
                bx, by = xy[(i0 + 1) % n]
                abx, aby = bx - ax, by - ay
                t = min(max(((px - ax) * abx + (py - ay) * aby) / (abx * abx + aby * aby), 0.0),
                        1.0)
                fx, fy = ax + abx * t, ay + aby * t
                d2 = (px - fx) * (px - fx) + (py - fy) * (py - fy)
                if d2 < best_d2:
                    best_d2, best_s = d2, s_rows[i0] + t * ds
            best_s = best_s % length
            f = (best_s % length) / ds  # as _interp: it wraps again
            j0 = math.floor(f)
            t = f - j0
            j0 %= n
            j1 = (j0 + 1) % n
            cx, cy, cz = (a * (1.0 - t) + b * t for a, b in zip(self._xyz_rows[j0],
                                                                self._xyz_rows[j1], strict=True))
            nx, ny = (a * (1.0 - t) + b * t for a, b in zip(self._normal_rows[j0],
                                                            self._normal_rows[j1], strict=True))
            out_s.append(best_s)
            out_cte.append((px - cx) * nx + (py - cy) * ny)
            out_half.append(0.5 * (self._width_rows[j0] * (1.0 - t) + self._width_rows[j1] * t))
            out_z.append(cz)
        return Projection(s_m=np.array(out_s).reshape(shape),
                          cte_m=np.array(out_cte).reshape(shape),
                          half_width_m=np.array(out_half).reshape(shape),
                          z_m=np.array(out_z).reshape(shape))

    def on_road(self, points_xy: np.ndarray) -> np.ndarray:
        """True where a point (e.g. a tyre contact point) lies on the drivable road surface."""
        proj = self.project(points_xy)
        return np.abs(proj.cte_m) <= proj.half_width_m

    def surface(self, points_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Road surface height [m] and unit normal (x, y, z) at world points (..., 2).

        The road has no banking: the surface is level across the road and follows the
        centreline's grade along it; off the road the ground continues at the same height.
        """
        proj = self.project(points_xy)
        grade = self.grade(proj.s_m)
        tangent = self._interp(self.tangent, proj.s_m)
        normal = np.concatenate([-grade[..., None] * tangent, np.ones_like(grade)[..., None]], -1)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        return proj.z_m, normal

    def heading_error(self, s_m: np.ndarray | float, yaw_rad: np.ndarray | float) -> np.ndarray:
        """Car yaw minus road heading at ``s_m``, wrapped to [-pi, pi) [rad]."""
        return wrap_angle(np.asarray(yaw_rad) - self.heading_at(s_m))

    def start_pose(self, *, reverse: bool = False) -> tuple[float, float, float, float]:
        """(x, y, z, yaw) at s = 0, heading along the driving direction (or against it)."""
        x, y, z = self.xyz[0]
        yaw = float(self.heading[0]) + (math.pi if reverse else 0.0)
        return float(x), float(y), float(z), float(wrap_angle(yaw))

    def geometry_key(self) -> str:
        """A digest of the centreline, widths and normals: the same for tracks that drive alike
        whatever their name, different for an edited track file (keys caches of what a track
        gives: expert references, maps)."""
        import hashlib

        digest = hashlib.blake2b(digest_size=16)
        for array in (self.xyz, self.width, self.right_normal):
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
        return digest.hexdigest()

    # ------------------------------------------------------------------ summary figures
    @property
    def min_radius_m(self) -> float:
        return float(1.0 / np.abs(self.curvature_table).max())

    @property
    def elevation_range_m(self) -> float:
        return float(self.xyz[:, 2].max() - self.xyz[:, 2].min())

    @property
    def max_grade(self) -> float:
        return float(np.abs(self.grade_table).max())

    def summary(self) -> dict:
        """The figures ``clonedrive tracks --json`` reports."""
        return {
            "name": self.name,
            "version": self.version,
            "theme": self.theme,
            "length_m": round(self.length_m, 1),
            "width_m": round(float(self.width.mean()), 2),
            "elevation_range_m": round(self.elevation_range_m, 1),
            "min_radius_m": round(self.min_radius_m, 1),
            "max_grade": round(self.max_grade, 4),
        }


def _check_extent(control: np.ndarray, where: str) -> None:
    """Refuse control points beyond :data:`MAX_COORDINATE_M` or a control polygon longer than
    :data:`MAX_TRACK_LENGTH_M`, before any table along the track is allocated."""
    far = np.abs(control[:, :3]).max(axis=1)
    beyond = np.flatnonzero(far > MAX_COORDINATE_M)
    if beyond.size:
        i = beyond[0]
        raise TrackError(
            f"{where}: centerline point {i} is {far[i]:.4g} m from the origin in x, y or z; "
            f"coordinates are limited to +-{MAX_COORDINATE_M:g} m")
    closed = np.vstack([control[:, :2], control[:1, :2]])
    polygon_m = float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())
    if polygon_m > MAX_TRACK_LENGTH_M:
        raise TrackError(
            f"{where}: the centerline points span {polygon_m / 1000:.1f} km of road; at most "
            f"{MAX_TRACK_LENGTH_M / 1000:g} km are allowed")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_integer(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def wrap_angle(angle_rad: np.ndarray | float) -> np.ndarray:
    """Wrap angle(s) to [-pi, pi)."""
    return np.mod(np.asarray(angle_rad) + math.pi, 2.0 * math.pi) - math.pi
