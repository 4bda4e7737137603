"""Driving conditions as data: how the world looks, what the camera does, how late the car obeys.

Two levels:

- :class:`Conditions`: one concrete set, for one episode. **Appearance**: the sun's elevation
  and azimuth [deg] (time of day, down to dusk), light intensity, warmth, sky brightness, fog
  density (x the theme's), road brightness, line colour, road wear (patchy asphalt, edge lines
  faded), shadow strength, vegetation density (x the theme's trees). **Sensor**: camera height
  [m] and pitch [deg] offsets from the Udacity mount (drawn per episode: a differently mounted
  camera), JPEG quality (frames go through a JPEG, as the Udacity simulator's telemetry does),
  pixel noise. **Actuation**: latency, in control steps (0-3) between a decision and the car
  applying it. ``None`` or the neutral value leaves the theme's own look.
- :class:`ConditionFamily`: named ranges from which a concrete :class:`Conditions` is drawn per
  episode with a seeded generator. A field is a fixed value, ``[low, high]`` (uniform; integers
  for ``jpeg_quality`` and ``latency_steps``, both ends included) or, for ``line``, a list of
  colour names to choose from. Fog
  has two parts: ``fog`` scales the theme's fog baked into the scenery by distance from the
  road (the far hills fade), ``visibility_m`` adds fog by distance from the camera, drawn over
  each frame (the road ahead fades: see :func:`fog_alpha`). ``held_out``: the family is never
  used for training data (the look lies outside what ``record --randomize`` draws), so a split
  driven under it measures driving in unseen conditions.

:data:`FAMILIES` holds the built-in families; a suite file (``clonedrive bench``) carries its own
copy that a user can edit. Speed caps are the suite's (per split), not a condition's.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass, replace

import numpy as np

#: Edge-line colours a condition may paint (0-255 RGB albedo); None keeps the theme's.
LINE_COLOURS: dict[str, tuple[float, float, float]] = {
    "yellow": (212.0, 177.0, 46.0),
    "white": (226.0, 226.0, 218.0),
    "faded-white": (176.0, 176.0, 168.0),
}
MAX_LATENCY_STEPS = 3

#: Allowed range of each numeric field (inclusive), for validation.
_BOUNDS: dict[str, tuple[float, float]] = {
    "sun_elevation_deg": (3.0, 90.0),
    "sun_azimuth_deg": (-360.0, 720.0),
    "light": (0.2, 2.0),
    "warmth": (-0.5, 0.8),
    "sky": (0.2, 1.5),
    "fog": (0.0, 12.0),
    "visibility_m": (20.0, 2000.0),
    "road_brightness": (0.4, 1.8),
    "road_wear": (0.0, 1.0),
    "shadows": (0.0, 1.5),
    "vegetation": (0.0, 3.0),
    "camera_height_m": (-0.5, 0.5),
    "camera_pitch_deg": (-8.0, 8.0),
    "jpeg_quality": (5, 100),
    "pixel_noise_std": (0.0, 30.0),
    "latency_steps": (0, MAX_LATENCY_STEPS),
}
_INTEGER_FIELDS = ("jpeg_quality", "latency_steps")


@dataclass(frozen=True)
class Conditions:
    """One concrete set of driving conditions (see the module for what each field does)."""

    # appearance
    sun_elevation_deg: float | None = None  #: None: the theme's sun
    sun_azimuth_deg: float | None = None  #: counter-clockwise from east; None: the theme's
    light: float = 1.0  #: sun intensity, x the theme's
    warmth: float = 0.0  #: colour temperature: + = warm (evening), - = cool
    sky: float | None = None  #: sky brightness, x the theme's (None: follows the light)
    fog: float = 1.0  #: fog density, x the theme's (baked: by distance from the road)
    visibility_m: float | None = None  #: fog seen from the camera: 5 % contrast at this [m]
    road_brightness: float = 1.0  #: asphalt albedo, x the theme's
    line: str | None = None  #: edge-line colour, a LINE_COLOURS name (None: the theme's)
    road_wear: float = 0.0  #: 0 = fresh, 1 = patchy asphalt with the lines mostly gone
    shadows: float = 1.0  #: darkness of shadow patches on the road, x the theme's
    vegetation: float = 1.0  #: trees and bushes, x the theme's density
    # sensor
    camera_height_m: float = 0.0  #: camera height offset from the Udacity mount [m]
    camera_pitch_deg: float = 0.0  #: extra downward pitch [deg]
    jpeg_quality: int | None = None  #: frames go through a JPEG of this quality (None: raw)
    pixel_noise_std: float = 0.0  #: Gaussian pixel noise [0-255 units]
    # actuation
    latency_steps: int = 0  #: control steps between a decision and the car applying it

    def __post_init__(self) -> None:
        for name, (low, high) in _BOUNDS.items():
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value) and low <= value <= high):
                raise ValueError(f"conditions: {name} must be a number in [{low:g}, {high:g}], "
                                 f"got {value!r}")
            if name in _INTEGER_FIELDS and int(value) != value:
                raise ValueError(f"conditions: {name} must be a whole number, got {value!r}")
        if self.line is not None and self.line not in LINE_COLOURS:
            raise ValueError(f"conditions: line must be one of {', '.join(LINE_COLOURS)}, got "
                             f"{self.line!r}")

    @property
    def relit(self) -> bool:
        """Whether the sun or sky differ from the theme's."""
        return (self.sun_elevation_deg is not None or self.sun_azimuth_deg is not None
                or self.light != 1.0 or self.warmth != 0.0 or self.sky is not None)

    def appearance(self, theme: str):
        """The scene's :class:`~clonedrive.sim.randomization.Appearance` under these conditions."""
        from clonedrive.sim.randomization import (
            default_appearance,
            lit_appearance,
            theme_sun_deg,
        )

        if self.relit:
            elevation, azimuth = theme_sun_deg(theme)
            look = lit_appearance(
                theme,
                sun_elevation_deg=elevation if self.sun_elevation_deg is None
                else self.sun_elevation_deg,
                sun_azimuth_deg=azimuth if self.sun_azimuth_deg is None else self.sun_azimuth_deg,
                light_intensity=self.light, warmth=self.warmth, sky_scale=self.sky,
                fog_density_scale=self.fog)
        else:
            look = default_appearance(theme)
            lighting = replace(look.lighting,
                               fog_density_per_m=look.lighting.fog_density_per_m * self.fog)
            look = replace(look, lighting=lighting)
        return replace(look, camera_height_offset_m=self.camera_height_m,
                       camera_pitch_offset_deg=self.camera_pitch_deg,
                       pixel_noise_std=self.pixel_noise_std, visibility_m=self.visibility_m,
                       jpeg_quality=None if self.jpeg_quality is None else int(self.jpeg_quality))

    def style(self, theme: str):
        """The scenery's :class:`~clonedrive.sim.scenery.ThemeStyle` under these conditions."""
        from clonedrive.sim.scenery import THEME_STYLES

        base = THEME_STYLES[theme]
        road = tuple(float(min(255.0, c * self.road_brightness)) for c in base.road_rgb)
        line = base.edge_line_rgb if self.line is None else LINE_COLOURS[self.line]
        return replace(base, road_rgb=road, edge_line_rgb=line,
                       tree_keep=float(min(1.0, base.tree_keep * self.vegetation)),
                       shadow_strength=self.shadows)

    def to_dict(self) -> dict:
        """The fields that differ from the neutral conditions (what bench.json records)."""
        neutral = Conditions()
        out = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if value != getattr(neutral, field.name):
                out[field.name] = round(value, 4) if isinstance(value, float) else value
        return out


CONDITION_FIELDS = tuple(field.name for field in dataclasses.fields(Conditions))


@dataclass(frozen=True)
class ConditionFamily:
    """Named ranges of conditions; :meth:`sample` draws one episode's :class:`Conditions`."""

    name: str
    #: field name -> fixed value, (low, high) or, for ``line``, a tuple of colour names
    ranges: tuple[tuple[str, object], ...] = ()
    held_out: bool = False  #: never used for training data
    description: str = ""

    def __post_init__(self) -> None:
        for field, value in self.ranges:
            if field not in CONDITION_FIELDS:
                raise ValueError(f"condition family {self.name!r}: unknown field {field!r}; "
                                 f"use {', '.join(CONDITION_FIELDS)}")
            if isinstance(value, tuple) and field != "line":
                if len(value) != 2 or not all(isinstance(v, int | float) for v in value) \
                        or value[0] > value[1]:
                    raise ValueError(f"condition family {self.name!r}: {field} must be a value "
                                     f"or [low, high] with low <= high, got {list(value)}")
                for end in value:  # both ends must be valid conditions
                    Conditions(**{field: end})
            elif isinstance(value, tuple):
                if not value:
                    raise ValueError(f"condition family {self.name!r}: line must be a colour or "
                                     "a non-empty list of colours")
                for colour in value:
                    Conditions(line=colour)
            else:
                Conditions(**{field: value})

    @classmethod
    def from_dict(cls, name: str, data: dict, *, source: str = "conditions") -> ConditionFamily:
        """From a suite file's table: field values plus ``held_out`` and ``description``."""
        if not isinstance(data, dict):
            raise ValueError(f"{source}: conditions.{name} must be a table of fields")
        data = dict(data)
        held_out = data.pop("held_out", False)
        description = data.pop("description", "")
        if not isinstance(held_out, bool):
            raise ValueError(f"{source}: conditions.{name}.held_out must be true or false")
        if not isinstance(description, str):
            raise ValueError(f"{source}: conditions.{name}.description must be a string")
        ranges = []
        for field, value in data.items():
            if isinstance(value, list):
                value = tuple(value)
            ranges.append((field, value))
        try:
            return cls(name=name, ranges=tuple(ranges), held_out=held_out,
                       description=str(description))
        except (ValueError, TypeError) as error:
            raise ValueError(f"{source}: {error}") from None

    def to_dict(self) -> dict:
        out: dict = {"held_out": self.held_out}
        if self.description:
            out["description"] = self.description
        for field, value in self.ranges:
            out[field] = list(value) if isinstance(value, tuple) else value
        return out

    def sample(self, seed: int) -> Conditions:
        """One episode's conditions: the same (family, seed) gives the same conditions."""
        rng = np.random.default_rng([int(seed), zlib.crc32(self.name.encode())])
        values = {}
        for field, value in self.ranges:
            if isinstance(value, tuple) and field == "line":
                values[field] = str(value[int(rng.integers(len(value)))])
            elif isinstance(value, tuple) and field in _INTEGER_FIELDS:
                values[field] = int(rng.integers(int(value[0]), int(value[1]) + 1))
            elif isinstance(value, tuple):
                values[field] = float(rng.uniform(value[0], value[1]))
            else:
                values[field] = value
        return Conditions(**values)


def _family(name: str, description: str, held_out: bool = False, **ranges) -> ConditionFamily:
    return ConditionFamily(name=name, description=description, held_out=held_out,
                           ranges=tuple(ranges.items()))


#: The built-in families. The held-out ones lie outside ``record --randomize``'s ranges
#: (sun 18-75 deg, fog x0.4-2.5, the theme's yellow lines, raw frames or JPEG 75).
FAMILIES: dict[str, ConditionFamily] = {family.name: family for family in (
    _family("clear", "the theme's own look: what the training data is recorded in"),
    _family("dusk", "sun 4-9 deg above the horizon, warm, dim",
            held_out=True, sun_elevation_deg=(4.0, 9.0), sun_azimuth_deg=(0.0, 360.0),
            light=(0.45, 0.6), warmth=(0.25, 0.4), sky=(0.45, 0.6), fog=(1.0, 2.0),
            shadows=0.5),
    _family("fog", "thick fog: 60-120 m visibility", held_out=True, visibility_m=(60.0, 120.0),
            fog=(3.0, 5.0), light=(0.8, 0.95), shadows=0.3),
    _family("worn-road", "white, worn edge lines on patchy asphalt of another shade",
            held_out=True, line=("white", "faded-white"), road_wear=(0.4, 0.7),
            road_brightness=(0.75, 1.3)),
    _family("overgrown", "two to three times the trees, darker shadows", held_out=True,
            vegetation=(2.0, 3.0), shadows=(1.1, 1.3)),
    _family("sensor", "camera 15 cm higher or lower, pitched +-2.5 deg, JPEG quality 25-50, "
            "pixel noise", held_out=True, camera_height_m=(-0.15, 0.15),
            camera_pitch_deg=(-2.5, 2.5), jpeg_quality=(25, 50), pixel_noise_std=(3.0, 8.0)),
    _family("latency", "the car applies each decision 1-3 control steps late",
            held_out=True, latency_steps=(1, 3)),
    # Suite v3's harder tier: a held-out look and a late car together.
    _family("dusk-late", "dusk, and each decision applied 1-3 control steps late",
            held_out=True, sun_elevation_deg=(4.0, 9.0), sun_azimuth_deg=(0.0, 360.0),
            light=(0.45, 0.6), warmth=(0.25, 0.4), sky=(0.45, 0.6), fog=(1.0, 2.0),
            shadows=0.5, latency_steps=(1, 3)),
    _family("fog-late", "thick fog, and each decision applied 1-3 control steps late",
            held_out=True, visibility_m=(60.0, 120.0), fog=(3.0, 5.0), light=(0.8, 0.95),
            shadows=0.3, latency_steps=(1, 3)),
    _family("sensor-late", "the sensor family's camera, and each decision applied 1-3 "
            "control steps late", held_out=True, camera_height_m=(-0.15, 0.15),
            camera_pitch_deg=(-2.5, 2.5), jpeg_quality=(25, 50), pixel_noise_std=(3.0, 8.0),
            latency_steps=(1, 3)),
    # Training data that looks more like the Udacity simulator's frames (issue 15; compared
    # against the real slices in ../shared/fixtures by `clonedrive crosscheck`): its roads
    # are darker or lighter grey with yellow, white or worn lines, its light brighter or
    # duller, its shadows softer or harder, its frames JPEG 60-90.
    _family("udacity", "towards the Udacity simulator's look: road shade, line colour and "
            "wear, light, warmth, shadows, vegetation, JPEG", road_brightness=(0.75, 1.25),
            line=("yellow", "white", "faded-white"), road_wear=(0.0, 0.6),
            sun_elevation_deg=(25.0, 75.0), sun_azimuth_deg=(0.0, 360.0), light=(0.8, 1.25),
            warmth=(-0.1, 0.2), shadows=(0.5, 1.4), vegetation=(0.6, 1.6),
            jpeg_quality=(60, 90), pixel_noise_std=(0.0, 3.0)),
)}
#: The families a recording may be made in (``record --look NAME``): those not held out.
TRAINING_LOOKS = tuple(name for name, family in FAMILIES.items() if not family.held_out)
#: The look of domain randomisation (sim/randomization.py): light, fog, tint, camera height and
#: noise drawn afresh from each recording's seed, within ranges no held-out family enters.
RANDOMIZED_LOOK = "randomized"
#: Every look training data may be recorded in: one way to choose it, ``look = NAME``.
RECORDING_LOOKS = (*TRAINING_LOOKS, RANDOMIZED_LOOK)


def check_recording_look(look: str | None) -> None:
    """ValueError unless ``look`` is None (the theme's own) or one of :data:`RECORDING_LOOKS`."""
    if look is not None and look not in RECORDING_LOOKS:
        raise ValueError(f"look {look!r} is not one of {', '.join(RECORDING_LOOKS)} (the looks "
                         "training data may be recorded in; the others are held out)")


def fog_alpha(height: int, *, vertical_fov_deg: float, pitch_down_deg: float,
              camera_height_m: float, visibility_m: float, far_m: float = 250.0) -> np.ndarray:
    """Per image row (top first), how much of the fog colour covers it: ``1 - exp(-3 d / V)``
    with ``d`` the distance at which that row's ray meets a level road (rows at or above the
    horizon: ``far_m``), ``V`` the visibility."""
    rows = (np.arange(height) + 0.5) / height  # 0 = top
    tan_half = math.tan(math.radians(vertical_fov_deg) / 2.0)
    below_axis = np.arctan((2.0 * rows - 1.0) * tan_half)  # + = below the optical axis
    down = below_axis + math.radians(pitch_down_deg)
    with np.errstate(divide="ignore"):
        distance = np.where(down > 1e-3, camera_height_m / np.tan(np.maximum(down, 1e-3)), far_m)
    distance = np.minimum(distance, far_m)
    return 1.0 - np.exp(-3.0 * distance / visibility_m)


def jpeg_round_trip(image_rgb: np.ndarray, quality: int) -> np.ndarray:
    """``image_rgb`` (uint8 RGB) as it comes back from a JPEG of ``quality``."""
    import cv2

    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError(f"could not encode a JPEG of quality {quality}")
    from clonedrive.base.images import decode_rgb

    return decode_rgb(data, name=f"a JPEG of quality {quality}")
