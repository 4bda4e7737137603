"""Viewpoint synthesis: a recorded Udacity frame as seen from a camera moved sideways and turned.

The world is split at the horizon. Below it everything is taken to be flat road at the camera's
height under the camera (a plane-induced homography); above it everything is infinitely far (a
pure rotation, so a sideways move changes nothing). Each pixel of the new view is traced back
into a recorded camera: the centre camera first, then the side cameras (where the log has them)
for what the centre camera never saw, then the centre image's nearest edge pixel. The car's
hood, below :attr:`Rig.hood_row`, moves with the car and is copied unchanged.

Frames (Udacity axes for a camera): x right, y down, z forward; the new camera sits
``offset_m`` to the right of the recorded centre camera and is turned ``yaw_rad`` to the right.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_WIDTH

#: Rows below the horizon left out of the road region (too far away to compare pixel by pixel).
ROAD_MARGIN_ROWS = 8
#: Side-camera offsets tried when calibrating [m]: a coarse grid, then a fine one around its best.
COARSE_OFFSETS_M = tuple(round(0.4 + 0.05 * step, 2) for step in range(15))
FINE_STEP_M = 0.01
#: The horizon is searched this many rows either side of the rig's, a row at a time.
HORIZON_SEARCH_ROWS = 3
#: Frames of a log the calibration looks at (evenly spaced).
CALIBRATION_FRAMES = 8
#: Gaussian smoothing [px, odd] of both images before a view is compared: the road's markings
#: and edges count, not its asphalt grain, which no geometry predicts (1 = none).
COMPARE_SMOOTHING_PX = 3


@dataclass(frozen=True)
class Rig:
    """The Udacity camera rig as a pinhole model (defaults: UDACITY.md and fits on real logs)."""

    focal_px: float = 140.0  #: focal length [px] (60 deg vertical field of view: 138.6)
    horizon_row: float = 59.5  #: image row of the horizon (the camera looks down about 8 deg)
    camera_height_m: float = 1.2
    left_x_m: float = -0.76  #: lateral position of the left camera [m], right = +
    right_x_m: float = 0.76
    hood_row: int = 136  #: rows from here down show the car's own hood
    width: int = IMAGE_WIDTH
    height: int = IMAGE_HEIGHT

    def __post_init__(self) -> None:
        if self.focal_px <= 0 or self.camera_height_m <= 0:
            raise ValueError("the focal length and the camera height must be positive")
        if not 0 < self.horizon_row < self.hood_row <= self.height:
            raise ValueError(f"need 0 < horizon_row ({self.horizon_row}) < hood_row "
                             f"({self.hood_row}) <= image height ({self.height})")

    @property
    def pitch_rad(self) -> float:
        """How far the camera looks down, from the horizon's row."""
        return math.atan2((self.height - 1) / 2 - self.horizon_row, self.focal_px)

    def source_x(self, camera: str) -> float:
        return {"center": 0.0, "left": self.left_x_m, "right": self.right_x_m}[camera]


def source_coordinates(rig: Rig, offset_m: float, yaw_rad: float,
                       source_x_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel of the new view, the (column, row) it comes from in the recorded camera
    at ``source_x_m``; NaN where that camera looks away from it."""
    cx, cy = (rig.width - 1) / 2, (rig.height - 1) / 2
    cols, rows = np.meshgrid(np.arange(rig.width, dtype=np.float64),
                             np.arange(rig.height, dtype=np.float64))
    x_cam, y_cam = (cols - cx) / rig.focal_px, (rows - cy) / rig.focal_px
    cos_p, sin_p = math.cos(rig.pitch_rad), math.sin(rig.pitch_rad)
    # The new camera's rays in a level frame, then turned into the recorded camera's heading.
    y_level = y_cam * cos_p + sin_p
    z_level = -y_cam * sin_p + cos_p
    cos_y, sin_y = math.cos(yaw_rad), math.sin(yaw_rad)
    x_src = x_cam * cos_y + z_level * sin_y
    z_src = -x_cam * sin_y + z_level * cos_y
    # Below the horizon the ray meets the road at depth h / y: seen from the recorded camera,
    # its direction gains the sideways move scaled by y / h (0 at the horizon: continuous).
    below = y_level > 0
    x_src = x_src + np.where(below, (offset_m - source_x_m) * y_level / rig.camera_height_m, 0.0)
    # Back into the recorded (pitched) camera and onto its image.
    y_out = y_level * cos_p - z_src * sin_p
    z_out = y_level * sin_p + z_src * cos_p
    ahead = z_out > 1e-6
    safe = np.where(ahead, z_out, 1.0)
    map_x = np.where(ahead, cx + rig.focal_px * x_src / safe, np.nan)
    map_y = np.where(ahead, cy + rig.focal_px * y_out / safe, np.nan)
    return map_x.astype(np.float32), map_y.astype(np.float32)


def inside(rig: Rig, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """Where the coordinates fall on the recorded image (NaN: outside)."""
    with np.errstate(invalid="ignore"):
        return ((map_x >= 0) & (map_x <= rig.width - 1)
                & (map_y >= 0) & (map_y <= rig.height - 1))


def _remap(image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, replicate: bool):
    import cv2

    border = cv2.BORDER_REPLICATE if replicate else cv2.BORDER_CONSTANT
    return cv2.remap(image, np.nan_to_num(map_x, nan=-1.0), np.nan_to_num(map_y, nan=-1.0),
                     cv2.INTER_LINEAR, borderMode=border)


def synthesise(images: Mapping[str, np.ndarray], rig: Rig, offset_m: float,
               yaw_rad: float) -> np.ndarray:
    """The view from ``offset_m`` right of the recorded centre camera, turned ``yaw_rad`` right.

    ``images`` maps camera names (``center``, and ``left``/``right`` where the log has them) to
    RGB (or BGR: channels are not touched) images of the rig's size.
    """
    if offset_m == 0.0 and yaw_rad == 0.0:
        return np.array(images["center"], copy=True)
    map_x, map_y = source_coordinates(rig, offset_m, yaw_rad)
    out = _remap(images["center"], map_x, map_y, replicate=True)
    missing = ~inside(rig, map_x, map_y)
    sides = sorted((camera for camera in ("left", "right") if camera in images),
                   key=lambda camera: abs(offset_m - rig.source_x(camera)))
    for camera in sides:
        if not missing[:rig.hood_row].any():
            break
        side_x, side_y = source_coordinates(rig, offset_m, yaw_rad, rig.source_x(camera))
        usable = missing & inside(rig, side_x, side_y)
        usable[rig.hood_row:] = False
        if usable.any():
            out[usable] = _remap(images[camera], side_x, side_y, replicate=False)[usable]
            missing &= ~usable
    out[rig.hood_row:] = images["center"][rig.hood_row:]
    return out


def road_mask(rig: Rig, offset_m: float, yaw_rad: float = 0.0) -> np.ndarray:
    """The road region of a synthesised view that the centre image covers: below the horizon
    (by :data:`ROAD_MARGIN_ROWS`), above the hood."""
    map_x, map_y = source_coordinates(rig, offset_m, yaw_rad)
    mask = inside(rig, map_x, map_y)
    mask[:int(math.ceil(rig.horizon_row)) + ROAD_MARGIN_ROWS] = False
    mask[rig.hood_row:] = False
    return mask


def view_error(synthesised: np.ndarray, real: np.ndarray, mask: np.ndarray,
               smoothing_px: int = COMPARE_SMOOTHING_PX) -> float:
    """Mean absolute difference (0-255, all channels) over ``mask``, both images smoothed by a
    ``smoothing_px`` Gaussian first."""
    if smoothing_px > 1:
        import cv2

        kernel = (smoothing_px, smoothing_px)
        synthesised = cv2.GaussianBlur(synthesised, kernel, 0)
        real = cv2.GaussianBlur(real, kernel, 0)
    difference = np.abs(synthesised.astype(np.int16) - real.astype(np.int16))
    return float(difference[mask].mean())


def side_view_errors(rig: Rig, frames: list[Mapping[str, np.ndarray]], camera: str,
                     source_x_m: float | None = None,
                     smoothing_px: int = COMPARE_SMOOTHING_PX) -> tuple[float, float]:
    """(synthesised, unshifted): the mean error against the real ``camera`` images of the view
    synthesised from the centre image alone at that camera's position, and of the centre image
    itself, over the road region."""
    where = rig.source_x(camera) if source_x_m is None else source_x_m
    mask = road_mask(rig, where)
    synthesised = [view_error(synthesise({"center": frame["center"]}, rig, where, 0.0),
                              frame[camera], mask, smoothing_px) for frame in frames]
    unshifted = [view_error(frame["center"], frame[camera], mask, smoothing_px)
                 for frame in frames]
    return float(np.mean(synthesised)), float(np.mean(unshifted))


def fit_side_offsets(rig: Rig, frames: list[Mapping[str, np.ndarray]]) -> Rig:
    """``rig`` with the side-camera offsets that best map the centre images onto the side ones
    (a coarse grid, then a fine one around its best)."""
    fitted = {}
    for camera, sign in (("left", -1.0), ("right", 1.0)):
        def error(distance: float, camera: str = camera, sign: float = sign) -> float:
            return side_view_errors(rig, frames, camera, sign * distance)[0]

        best = min(COARSE_OFFSETS_M, key=error)
        fine = [best + FINE_STEP_M * step for step in range(-4, 5)]
        fitted[camera] = sign * round(min(fine, key=error), 3)
    return replace(rig, left_x_m=fitted["left"], right_x_m=fitted["right"])


def fit_horizon(rig: Rig, frames: list[Mapping[str, np.ndarray]]) -> Rig:
    """``rig`` with the horizon row, within :data:`HORIZON_SEARCH_ROWS` of its own, that best
    maps the centre images onto both side ones at the rig's side offsets."""
    def error(row: float) -> float:
        candidate = replace(rig, horizon_row=row)
        return sum(side_view_errors(candidate, frames, camera)[0] for camera in ("left", "right"))

    rows = [rig.horizon_row + step for step in range(-HORIZON_SEARCH_ROWS,
                                                      HORIZON_SEARCH_ROWS + 1)]
    return replace(rig, horizon_row=min(rows, key=error))


def calibrate(rig: Rig, frames: list[Mapping[str, np.ndarray]]) -> Rig:
    """``rig`` fitted to three-camera frames: the side offsets, then the horizon at those
    offsets, then the side offsets again at that horizon."""
    return fit_side_offsets(fit_horizon(fit_side_offsets(rig, frames), frames), frames)
