"""How the scene looks: light, sky, fog, tint, camera height jitter and pixel noise.

:func:`default_appearance` gives each theme's fixed look. With a :class:`RandomizationConfig`
(domain randomisation, for robustness of a learned driver), :func:`sample_appearance` draws a
look from the config's ranges with a seeded ``np.random.Generator``: time of day (sun elevation,
azimuth and colour), light intensity, fog density, a colour tint, the camera height and the
standard deviation of pixel noise. Same generator state -> same appearance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clonedrive.sim.meshes import Lighting


@dataclass(frozen=True)
class RandomizationConfig:
    """Ranges (low, high) that domain randomisation draws from uniformly."""

    sun_elevation_deg: tuple[float, float] = (18.0, 75.0)
    sun_azimuth_deg: tuple[float, float] = (0.0, 360.0)
    light_intensity: tuple[float, float] = (0.75, 1.2)
    #: colour temperature shift: - = cool/blue, + = warm/evening
    warmth: tuple[float, float] = (-0.12, 0.25)
    fog_density_scale: tuple[float, float] = (0.4, 2.5)
    #: per-channel multiplicative tint: 1 +- this
    tint: float = 0.08
    #: camera height offset [m]: +- this
    camera_height_m: float = 0.06
    #: pixel noise standard deviation [0-255 units]
    pixel_noise_std: tuple[float, float] = (0.0, 5.0)

    def __post_init__(self) -> None:
        for name in ("sun_elevation_deg", "sun_azimuth_deg", "light_intensity", "warmth",
                     "fog_density_scale", "pixel_noise_std"):
            low, high = getattr(self, name)
            if not low <= high:
                raise ValueError(f"RandomizationConfig.{name}: low {low} > high {high}")
        if not (5.0 <= self.sun_elevation_deg[0] and self.sun_elevation_deg[1] <= 90.0):
            raise ValueError("RandomizationConfig.sun_elevation_deg must lie in [5, 90] deg")
        if self.fog_density_scale[0] < 0 or self.pixel_noise_std[0] < 0:
            raise ValueError("RandomizationConfig: fog density and noise must be >= 0")


@dataclass(frozen=True)
class Appearance:
    """One concrete look of a scene."""

    lighting: Lighting  #: sun, ambient light and fog (fog colour = the horizon colour)
    sky_zenith_rgb: tuple[float, float, float]  #: 0-255
    sky_horizon_rgb: tuple[float, float, float]  #: 0-255
    tint_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    camera_height_offset_m: float = 0.0
    pixel_noise_std: float = 0.0
    camera_pitch_offset_deg: float = 0.0  #: + = the cameras look further down
    jpeg_quality: int | None = None  #: frames go through a JPEG of this quality (None: raw)
    #: fog by distance from the camera, in image space [m]: contrast falls to 5 % at this
    #: distance along a level road (None: only the baked fog by distance from the road)
    visibility_m: float | None = None


_THEME_LOOK = {
    # sun (elevation, azimuth) deg, sun rgb, ambient rgb, zenith, horizon, fog density
    "lake": ((48.0, 210.0), (0.78, 0.74, 0.64), (0.50, 0.54, 0.60), (62.0, 104.0, 178.0),
             (170.0, 196.0, 222.0), 0.0030),
    "mountain": ((40.0, 150.0), (0.70, 0.68, 0.62), (0.46, 0.48, 0.56), (52.0, 92.0, 170.0),
                 (150.0, 170.0, 200.0), 0.0040),
}


def _sun_vector(elevation_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    """Unit vector toward the sun; azimuth counter-clockwise from east (x) [deg]."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


def default_appearance(theme: str) -> Appearance:
    """The fixed look of a theme (no randomisation)."""
    (elevation, azimuth), sun, ambient, zenith, horizon, fog = _THEME_LOOK[theme]
    return Appearance(
        lighting=Lighting(_sun_vector(elevation, azimuth), sun, ambient, fog_rgb=horizon,
                          fog_density_per_m=fog),
        sky_zenith_rgb=zenith,
        sky_horizon_rgb=horizon,
    )


def sample_appearance(
    theme: str, config: RandomizationConfig, rng: np.random.Generator
) -> Appearance:
    """A randomised look around the theme's default, drawn from ``config`` with ``rng``."""

    def draw(bounds: tuple[float, float]) -> float:
        return float(rng.uniform(*bounds))

    elevation = draw(config.sun_elevation_deg)
    azimuth = draw(config.sun_azimuth_deg)
    intensity = draw(config.light_intensity)
    warmth = draw(config.warmth)
    tint = 1.0 + rng.uniform(-config.tint, config.tint, 3)
    fog_scale = draw(config.fog_density_scale)
    camera_height = float(rng.uniform(-config.camera_height_m, config.camera_height_m))
    noise = draw(config.pixel_noise_std)
    return lit_appearance(theme, sun_elevation_deg=elevation, sun_azimuth_deg=azimuth,
                          light_intensity=intensity, warmth=warmth,
                          tint_rgb=tuple(float(v) for v in tint), fog_density_scale=fog_scale,
                          camera_height_offset_m=camera_height, pixel_noise_std=noise)


def lit_appearance(
    theme: str,
    *,
    sun_elevation_deg: float,
    sun_azimuth_deg: float,
    light_intensity: float = 1.0,
    warmth: float = 0.0,
    tint_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0),
    fog_density_scale: float = 1.0,
    sky_scale: float | None = None,
    camera_height_offset_m: float = 0.0,
    pixel_noise_std: float = 0.0,
) -> Appearance:
    """The theme's look under a given sun: a low sun is warmer and weaker; ``warmth`` moves
    red up and blue down; ``sky_scale`` (default from the light) darkens or brightens the sky.
    :func:`sample_appearance` draws these; :mod:`clonedrive.sim.conditions` sets them."""
    base = default_appearance(theme)
    elevation, intensity = sun_elevation_deg, light_intensity
    low_sun = 1.0 - min(1.0, (elevation - 5.0) / 40.0)
    warm = warmth + 0.2 * low_sun
    colour = np.array([1.0 + 0.5 * warm, 1.0 + 0.1 * warm, 1.0 - 0.6 * warm])
    sun = np.asarray(base.lighting.sun_rgb) * intensity * colour * (1.0 - 0.25 * low_sun)
    ambient = np.asarray(base.lighting.ambient_rgb) * (0.85 + 0.15 * intensity) * (
        1.0 + 0.3 * (colour - 1.0))
    if sky_scale is None:
        sky_scale = 0.85 + 0.15 * intensity
    zenith = np.clip(np.asarray(base.sky_zenith_rgb) * sky_scale * (1 + 0.2 * (colour - 1)), 0,
                     255)
    horizon = np.clip(np.asarray(base.sky_horizon_rgb) * sky_scale * (1 + 0.4 * (colour - 1)),
                      0, 255)
    horizon = tuple(float(v) for v in horizon)
    fog = base.lighting.fog_density_per_m * fog_density_scale
    return Appearance(
        lighting=Lighting(_sun_vector(elevation, sun_azimuth_deg), tuple(sun), tuple(ambient),
                          fog_rgb=horizon, fog_density_per_m=fog),
        sky_zenith_rgb=tuple(float(v) for v in zenith),
        sky_horizon_rgb=horizon,
        tint_rgb=tuple(float(v) for v in tint_rgb),
        camera_height_offset_m=float(camera_height_offset_m),
        pixel_noise_std=float(pixel_noise_std),
    )


def theme_sun_deg(theme: str) -> tuple[float, float]:
    """The theme's own sun (elevation, azimuth) [deg]."""
    return _THEME_LOOK[theme][0]
