"""The Udacity camera rig: centre, left and right cameras on the car, rendered to NumPy arrays.

Mounts follow the Udacity simulator's training car (UDACITY.md), in Unity axes relative to the
car's origin on the road under its centre: x right, y up, z forward [m]; pitched down 9.4 deg;
60 deg vertical field of view; 320x160 pixels. Resolution and mounts are configurable.

``rows=(top, bottom)`` renders only those rows of each frame (what a network that crops its
input looks at): a buffer of ``bottom - top`` rows and a lens whose film size and offset select
exactly that strip of the full camera's view. Frames keep their full size; the rows not rendered
hold :data:`FILL_VALUE`. The software renderer samples textures a little differently when the
viewport changes, so the strip is close to, not bit-identical with, the same rows of a full
frame (``benchmarks/crop.py`` measures the difference and what it does to a model's driving).

``CameraRig.render(pose)`` places the car, renders every camera in ONE
``GraphicsEngine.render_frame()`` call and returns ``{camera: uint8 RGB (H, W, 3)}``. Each
camera has its own offscreen buffer: one wide buffer cut into three display regions measured
the same within noise (lake 2.8 vs 2.5, mountain 3.4 vs 3.5 ms per step), and separate buffers
serve any subset of cameras directly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from clonedrive.base.udacity_spec import IMAGE_HEIGHT, IMAGE_WIDTH
from clonedrive.sim.conditions import fog_alpha, jpeg_round_trip
from clonedrive.sim.engine import texture_rgb
from clonedrive.sim.scene import FAR_M, NEAR_M, Scene


@dataclass(frozen=True)
class CameraMount:
    """Where a camera sits on the car (Unity axes: x right, y up, z forward) [m] and its optics."""

    position_m: tuple[float, float, float]
    pitch_down_deg: float = 9.4
    vertical_fov_deg: float = 60.0

    def horizontal_fov_deg(self, width: int, height: int) -> float:
        half = math.radians(self.vertical_fov_deg) / 2
        return math.degrees(2 * math.atan(math.tan(half) * width / height))


#: The Udacity training car's cameras.
UDACITY_RIG: Mapping[str, CameraMount] = {
    "center": CameraMount((0.0, 1.2, 1.0)),
    "left": CameraMount((-0.806, 1.2, 0.984)),
    "right": CameraMount((0.825, 1.2, 0.999)),
}

#: The value of every channel of the rows a cropped rig does not render.
FILL_VALUE = 0

#: Noise images kept per camera for pixel noise (one is picked at random each frame).
_NOISE_BANK = 6


class CameraRig:
    """Cameras attached to a :class:`Scene`'s car, each with its own offscreen buffer."""

    def __init__(
        self,
        scene: Scene,
        cameras: Sequence[str] = ("center", "left", "right"),
        width: int = IMAGE_WIDTH,
        height: int = IMAGE_HEIGHT,
        *,
        mounts: Mapping[str, CameraMount] = UDACITY_RIG,
        rows: tuple[int, int] | None = None,
    ):
        from panda3d.core import Camera

        if scene.closed:
            raise RuntimeError("the scene is closed")
        unknown = [name for name in cameras if name not in mounts]
        if unknown:
            raise ValueError(
                f"unknown camera(s) {', '.join(unknown)}; the rig has {', '.join(mounts)}"
            )
        if len(set(cameras)) != len(cameras):
            raise ValueError(f"cameras listed twice: {list(cameras)}")
        if not (8 <= width <= 4096 and 8 <= height <= 4096):
            raise ValueError(f"image size {width}x{height} is out of range (8..4096)")
        self.scene = scene
        self.cameras = tuple(cameras)
        self.width, self.height = int(width), int(height)
        self.mounts = {name: mounts[name] for name in self.cameras}
        #: The rows [top, bottom) rendered; (0, height) for full frames.
        self.rows = check_rows(rows, self.height)
        self._buffers = {}
        self._textures = {}
        self._nodes = {}
        for name in self.cameras:
            mount = self.mounts[name]
            top, bottom = self.rows
            buffer, texture = scene.engine.make_buffer(f"camera-{name}", self.width,
                                                       bottom - top)
            lens = strip_lens(mount, self.width, self.height, self.rows)
            node = scene.car.attach_new_node(Camera(f"camera-{name}", lens))
            node.node().set_scene(scene.root)
            region = buffer.make_display_region()
            region.set_camera(node)
            self._buffers[name] = buffer
            self._textures[name] = texture
            self._nodes[name] = node
        self.closed = False
        scene.register_rig(self)
        self.on_appearance_changed()

    def on_appearance_changed(self) -> None:
        """Apply the scene's current look: background colour, camera height, noise bank."""
        appearance = self.scene.appearance
        red, green, blue = self.scene.clear_rgb
        for name in self.cameras:
            self._buffers[name].set_clear_color((red, green, blue, 1.0))
            x, up, forward = self.mounts[name].position_m
            node = self._nodes[name]
            node.set_pos(x, forward, up + appearance.camera_height_offset_m)
            pitch = self.mounts[name].pitch_down_deg + appearance.camera_pitch_offset_deg
            node.set_hpr(0.0, -pitch, 0.0)
        self._fog = {}
        if appearance.visibility_m is not None:
            fog_rgb = np.asarray(appearance.sky_horizon_rgb, dtype=np.float32)
            for name in self.cameras:
                mount = self.mounts[name]
                alpha = fog_alpha(self.height, vertical_fov_deg=mount.vertical_fov_deg,
                                  pitch_down_deg=mount.pitch_down_deg
                                  + appearance.camera_pitch_offset_deg,
                                  camera_height_m=mount.position_m[1]
                                  + appearance.camera_height_offset_m,
                                  visibility_m=appearance.visibility_m)
                alpha = alpha.astype(np.float32)[:, None, None]
                self._fog[name] = (1.0 - alpha, alpha * fog_rgb)
        self._noise = None
        if appearance.pixel_noise_std > 0:
            rng = np.random.default_rng([self.scene.seed, 0xB0B])
            shape = (_NOISE_BANK, self.height, self.width, 3)
            noise = rng.normal(0.0, appearance.pixel_noise_std, shape)
            self._noise = np.clip(np.rint(noise), -127, 127).astype(np.int16)

    def render(
        self,
        x_m: float,
        y_m: float,
        z_m: float,
        yaw_rad: float,
        pitch_rad: float = 0.0,
        roll_rad: float = 0.0,
    ) -> dict[str, np.ndarray]:
        """Images from every camera with the car at this pose.

        ``(x_m, y_m, z_m)``: the road surface under the car's centre (world, z up) [m];
        ``yaw_rad``: heading, counter-clockwise from +x (east); ``pitch_rad``: + = nose up;
        ``roll_rad``: + = right side down. Returns ``{camera: uint8 RGB (H, W, 3)}``,
        C-contiguous, top row first.
        """
        if self.closed:
            raise RuntimeError("the camera rig is closed")
        self.scene.set_car_pose(x_m, y_m, z_m, yaw_rad, pitch_rad, roll_rad)
        self.scene.engine.render_frame()
        images = {name: texture_rgb(self._textures[name]) for name in self.cameras}
        top, bottom = self.rows
        for name, (keep, fog) in self._fog.items():
            images[name] = np.rint(images[name] * keep[top:bottom] + fog[top:bottom]
                                   ).astype(np.uint8)
        if self._noise is not None:
            picks = self.scene.noise_rng.integers(0, _NOISE_BANK, len(self.cameras))
            for name, pick in zip(self.cameras, picks, strict=True):
                noisy = images[name].astype(np.int16) + self._noise[pick, top:bottom]
                images[name] = np.clip(noisy, 0, 255).astype(np.uint8)
        if (top, bottom) != (0, self.height):
            images = {name: self._full_frame(image) for name, image in images.items()}
        quality = self.scene.appearance.jpeg_quality
        if quality is not None:
            images = {name: jpeg_round_trip(image, quality) for name, image in images.items()}
        return images

    def _full_frame(self, strip: np.ndarray) -> np.ndarray:
        """A full-size frame holding ``strip`` in the rendered rows, :data:`FILL_VALUE`
        elsewhere."""
        frame = np.zeros((self.height, self.width, 3), dtype=np.uint8)  # calloc: cheapest
        if FILL_VALUE:
            frame.fill(FILL_VALUE)
        frame[self.rows[0]:self.rows[1]] = strip
        return frame

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for name in self.cameras:
            self.scene.engine.remove(self._buffers[name])
            self._nodes[name].remove_node()
        self.scene.unregister_rig(self)

    def __enter__(self) -> CameraRig:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def check_rows(rows: tuple[int, int] | None, height: int) -> tuple[int, int]:
    """``rows`` as ``(top, bottom)`` ints after checking ``0 <= top < bottom <= height``;
    None: every row."""
    if rows is None:
        return 0, int(height)
    top, bottom = (int(value) for value in rows)
    if not 0 <= top < bottom <= height:
        raise ValueError(f"rows {tuple(rows)} are not a strip of a {height}-row frame "
                         f"(expected 0 <= top < bottom <= {height})")
    return top, bottom


def strip_lens(mount: CameraMount, width: int, height: int, rows: tuple[int, int]):
    """A Panda3D lens for rows [top, bottom) of ``mount``'s ``width`` x ``height`` view.

    The full view's focal length and film width are kept; the film is cut to the strip's
    height and shifted (film offset, film units up from the centre) to the strip's middle, so
    each rendered row shows what that row of the full frame shows.
    """
    from panda3d.core import PerspectiveLens

    full = PerspectiveLens()
    full.set_fov(mount.horizontal_fov_deg(width, height), mount.vertical_fov_deg)
    film = full.get_film_size()
    top, bottom = rows
    lens = PerspectiveLens()
    lens.set_film_size(film.x, film.y * (bottom - top) / height)
    lens.set_focal_length(full.get_focal_length())
    lens.set_film_offset(0.0, film.y * (0.5 - (top + bottom) / (2.0 * height)))
    lens.set_near_far(NEAR_M, FAR_M)
    return lens
