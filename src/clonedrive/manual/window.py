"""The ``clonedrive sim`` window: a Panda3D shell around a manual ``DrivingSession``.

The window forwards Panda3D's key, pointer and gamepad input to the session, steps it at the
control rate (15 Hz of simulated time, paced to the wall clock), and draws what the session
exposes: the track menu with a map of the chosen track, or the center camera's image (the very
image a recording stores, scaled up) under a HUD with speed, steering (and a steering bar), CTE,
who drives, the recording state and row counts.

Renderers: an OpenGL window (``pandagl``) where a display exists, else, on request, the software
renderer's window (``p3tinydisplay``, for displays without OpenGL), or, with no display at all,
an offscreen software buffer: the shell then runs a scripted drive (a track, keys held, optional
recording, ``steps`` control steps) and can save a screenshot -- the way the shell itself is
tested headless. The simulator's cameras always render with the software renderer, so images
recorded here look exactly like those of ``clonedrive record``.

No ``ShowBase``: the window belongs to a :class:`~clonedrive.sim.scene.RenderEngine` that is
opened and closed with the window, and input is read from the window's own input device.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.config import atomic_path
from clonedrive.manual.human_input import GAMEPAD_AXES
from clonedrive.manual.session import MENU, DrivingSession

#: Window size [px] (fixed): the camera view (2:1, like the 320x160 images) above a HUD panel.
WINDOW_SIZE = (960, 640)
#: The view's texture: a power of two in both directions, as the software renderer requires.
_VIEW_TEXTURE = (512, 256)
_FONT_PX = 19.0
_SMALL_FONT_PX = 14.0
_WHITE = (0.95, 0.95, 0.95, 1.0)
_GREY = (0.65, 0.67, 0.7, 1.0)
_RED = (1.0, 0.25, 0.2, 1.0)
_CYAN = (0.35, 0.85, 1.0, 1.0)
_YELLOW = (1.0, 0.85, 0.35, 1.0)
_PANEL_RGB = (0.08, 0.09, 0.11)
#: Mouse buttons are not driving keys.
_IGNORED_BUTTONS = frozenset({"mouse1", "mouse2", "mouse3", "wheel_up", "wheel_down"})


def display_available() -> bool:
    """Whether a window can be opened: on Linux and other X11 systems, a ``DISPLAY`` (or
    ``WAYLAND_DISPLAY``) is needed; Windows and macOS always have a display."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


@dataclass
class WindowSummary:
    """What a run of the window did."""

    renderer: str  #: e.g. "OpenGL: llvmpipe (LLVM 15.0.6, 256 bits)"
    onscreen: bool
    steps: int  #: control steps driven
    rows_recorded: int  #: rows of the latest recording
    folder_rows: int  #: rows in the output folder's log (when something was recorded)
    out_dir: str
    screenshot: str | None
    track: str


class DrivingWindow:
    """A window (or an offscreen buffer) showing a :class:`DrivingSession`.

    ``onscreen``: open a window (needs a display) or render offscreen with the software
    renderer. ``software``: use the software renderer for the window too (no OpenGL).
    """

    def __init__(self, session: DrivingSession, *, onscreen: bool = True,
                 software: bool = False, title: str = "clonedrive sim") -> None:
        from clonedrive.sim.engine import RenderEngine

        self.session = session
        self.onscreen = onscreen
        self.width, self.height = WINDOW_SIZE
        if onscreen:
            options = {"load-display": "p3tinydisplay"} if software else None
            self.engine = RenderEngine(window=True, options=options)
        else:
            self.engine = RenderEngine()
        try:
            self._open_output(title)
            self._build_overlay()
        except BaseException:
            self.engine.close()
            raise
        self._gamepads = _GamepadReader() if onscreen else None
        self._map_track: str | None = None
        self.closed = False

    # ------------------------------------------------------------------ construction
    def _open_output(self, title: str) -> None:
        from panda3d.core import (
            FrameBufferProperties,
            GraphicsPipe,
            WindowProperties,
        )

        self._texture = None
        if not self.onscreen:
            self.output, self._texture = self.engine.make_buffer(
                "clonedrive-sim", self.width, self.height)
            return
        props = FrameBufferProperties()
        props.set_rgb_color(True)
        props.set_color_bits(24)
        props.set_depth_bits(24)
        window_props = WindowProperties.size(self.width, self.height)
        window_props.set_title(title)
        window_props.set_fixed_size(True)
        engine = self.engine.engine
        output = engine.make_output(self.engine.pipe, "clonedrive-sim", 0, props, window_props,
                                    GraphicsPipe.BF_require_window)
        if output is None:
            raise RuntimeError("Panda3D could not open a window on this display")
        engine.open_windows()
        if not output.is_valid():
            engine.remove_window(output)
            raise RuntimeError("Panda3D could not open a window on this display")
        self.output = output

    def _build_overlay(self) -> None:
        """A 2D scene in pixels: x right from the left edge, z up from the top edge (so
        z = -y_px)."""
        from panda3d.core import (
            Camera,
            CardMaker,
            NodePath,
            OrthographicLens,
            SamplerState,
            Texture,
            TransparencyAttrib,
        )

        width, height = self.width, self.height
        self.output.set_clear_color((*_PANEL_RGB, 1.0))
        self.root = NodePath("overlay")
        self.root.set_depth_test(False)
        self.root.set_depth_write(False)
        self.root.set_transparency(TransparencyAttrib.M_alpha)
        lens = OrthographicLens()
        lens.set_film_size(width, height)
        lens.set_film_offset(width / 2, -height / 2)
        lens.set_near_far(-100, 100)
        camera = self.root.attach_new_node(Camera("overlay-camera", lens))
        region = self.output.make_display_region()
        region.set_camera(camera)

        view_height = width / 2
        self.view_height = view_height
        self._view_pixels = np.zeros((_VIEW_TEXTURE[1], _VIEW_TEXTURE[0], 3), np.uint8)
        self._view_texture = Texture("camera-view")
        self._view_texture.setup_2d_texture(*_VIEW_TEXTURE, Texture.T_unsigned_byte,
                                            Texture.F_rgb)
        self._view_texture.set_minfilter(SamplerState.FT_linear)
        self._view_texture.set_magfilter(SamplerState.FT_linear)
        self._view_texture.set_wrap_u(SamplerState.WM_clamp)
        self._view_texture.set_wrap_v(SamplerState.WM_clamp)
        self._view_texture.set_ram_image(self._view_pixels.tobytes())
        self.driving = self.root.attach_new_node("driving")
        self.view = _card(self.driving, "view", 0, width, -view_height, 0)
        self.view.set_texture(self._view_texture)
        self.view.set_bin("fixed", 0)

        # Steering bar: a track and a marker from its centre to the applied steering.
        bar_z = -view_height - 12
        self._bar_half_px = 220.0
        self._bar_centre_px = width - 30 - self._bar_half_px
        track = _card(self.driving, "steering-track", self._bar_centre_px - self._bar_half_px,
                      self._bar_centre_px + self._bar_half_px, bar_z - 4, bar_z + 4)
        track.set_color(0.25, 0.27, 0.3, 1)
        track.set_bin("fixed", 1)
        centre = _card(self.driving, "steering-zero", self._bar_centre_px - 1,
                       self._bar_centre_px + 1, bar_z - 7, bar_z + 7)
        centre.set_color(*_GREY)
        centre.set_bin("fixed", 3)
        cards = CardMaker("steering-marker")
        cards.set_frame(0, 1, bar_z - 4, bar_z + 4)
        self.steering_marker = self.driving.attach_new_node(cards.generate())
        self.steering_marker.set_color(*_CYAN)
        self.steering_marker.set_bin("fixed", 2)

        left = 14.0
        line_px = 1.3 * _FONT_PX
        first_line = -view_height - 26 - _FONT_PX
        self.status_text = _text(self.driving, "status", left, first_line, _FONT_PX, _WHITE)
        self.mode_text = _text(self.driving, "mode", left, first_line - line_px, _FONT_PX,
                               _CYAN)
        self.recording_text = _text(self.driving, "recording", left, first_line - 2 * line_px,
                                    _FONT_PX, _WHITE)
        self.message_text = _text(self.driving, "message", left, first_line - 3 * line_px,
                                  _SMALL_FONT_PX, _YELLOW)
        self.help_text = _text(self.driving, "help", left, -height + 9, _SMALL_FONT_PX, _GREY)
        self.rec_badge = _text(self.driving, "rec-badge", width - 16, -16 - 26, 26.0, _RED,
                               align_right=True)
        self.rec_badge.node().set_text("REC")
        for node in (self.status_text, self.mode_text, self.recording_text, self.message_text,
                     self.help_text, self.rec_badge):
            node.set_bin("fixed", 10)

        self.menu = self.root.attach_new_node("menu")
        self.menu_text = _text(self.menu, "menu", 48, -70, 26.0, _WHITE)
        self.menu_help = _text(self.menu, "menu-help", 48, -height + 16, _SMALL_FONT_PX, _GREY)
        self.map_node = self.menu.attach_new_node("map")
        self.map_text = _text(self.menu, "map-text", width * 0.55, -height + 60, _SMALL_FONT_PX,
                              _GREY)
        self.loading_text = _text(self.root, "loading", width / 2 - 120, -height / 2, 28.0,
                                  _YELLOW)

    # ------------------------------------------------------------------ input
    def process_input(self) -> None:
        """Forward the window's key presses, pointer position and gamepad axes to the session."""
        if not self.onscreen or self.closed:
            return
        from panda3d.core import ButtonEvent

        device = self.output.get_input_device(0)
        events = device.get_button_events()
        for index in range(events.get_num_events()):
            event = events.get_event(index)
            name = event.button.get_name()
            if name in _IGNORED_BUTTONS:
                continue
            if event.type in (ButtonEvent.T_down, ButtonEvent.T_resume_down):
                self.session.key_down(name)
            elif event.type == ButtonEvent.T_up:
                self.session.key_up(name)
        pointer = self.output.get_pointer(0)
        if pointer.in_window:
            self.session.pointer(2.0 * pointer.x / self.width - 1.0)
        else:
            self.session.pointer(None)
        if self._gamepads is not None:
            for axis, value in self._gamepads.changed_axes():
                self.session.gamepad_axis(axis, value)

    # ------------------------------------------------------------------ drawing
    def refresh(self) -> None:
        """Update the view and the text from the session's state."""
        session = self.session
        loading = session.loading
        self.loading_text.node().set_text(session.message if loading else "")
        in_menu = session.mode == MENU and not loading
        if in_menu or loading:
            self.driving.hide()
            if in_menu:
                self.menu.show()
            else:
                self.menu.hide()
            self._refresh_menu()
            return
        self.menu.hide()
        self.driving.show()
        obs = session.observation
        image = obs.images.get("center") if obs is not None else None
        if image is not None:
            self._show_image(image)
        hud = session.hud()
        self.status_text.node().set_text(hud.status)
        self.mode_text.node().set_text(hud.mode)
        self.recording_text.node().set_text(hud.recording)
        self.recording_text.node().set_text_color(*(_RED if session.recording else _WHITE))
        self.message_text.node().set_text(hud.message)
        self.help_text.node().set_text(hud.help)
        if session.recording:
            self.rec_badge.show()
        else:
            self.rec_badge.hide()
        steering = float(session.controls.steering)
        length = max(abs(steering) * self._bar_half_px, 0.5)
        start = self._bar_centre_px + min(steering, 0.0) * self._bar_half_px
        self.steering_marker.set_pos(start, 0, 0)
        self.steering_marker.set_sx(length)

    def _show_image(self, image_rgb: np.ndarray) -> None:
        import cv2

        width, height = _VIEW_TEXTURE
        scaled = cv2.resize(image_rgb, (width, height), interpolation=cv2.INTER_LINEAR)
        self._view_pixels[:] = scaled[::-1]  # Panda3D's textures start at the bottom row
        self._view_texture.set_ram_image_as(self._view_pixels.tobytes(), "RGB")

    def _refresh_menu(self) -> None:
        session = self.session
        self.menu_text.node().set_text("\n".join(session.menu_lines()))
        from clonedrive.manual.hud import HELP_MENU

        self.menu_help.node().set_text(HELP_MENU)
        item = session.menu_items[session.menu_index].track
        if item != self._map_track:
            self._draw_map(item)

    def _draw_map(self, track_name: str) -> None:
        """The chosen track's outline, fitted into the menu's right half, with the start."""
        from panda3d.core import LineSegs

        from clonedrive.world.catalog import load_track
        from clonedrive.world.track import TrackError

        self._map_track = track_name
        self.map_node.node().remove_all_children()
        try:
            track = load_track(track_name)
        except (TrackError, OSError) as error:
            self.map_text.node().set_text(str(error))
            return
        self.map_text.node().set_text(
            f"{track.name}: {track.length_m:.0f} m, road {float(track.width.mean()):.1f} m "
            f"wide, tightest radius {track.min_radius_m:.0f} m, climbs "
            f"{track.elevation_range_m:.0f} m\nred square: the start")
        xy = track.xyz[:, :2]
        low, high = xy.min(axis=0), xy.max(axis=0)
        box_left, box_top, box_size = self.width * 0.55, -90.0, min(self.width * 0.4, 400.0)
        scale = box_size / max(float((high - low).max()), 1.0)
        centre = (low + high) / 2
        points = (xy - centre) * scale
        lines = LineSegs("outline")
        lines.set_thickness(3.0)
        lines.set_color(0.75, 0.78, 0.8, 1)
        x0, z0 = box_left + box_size / 2, box_top - box_size / 2
        lines.move_to(x0 + points[0, 0], 0, z0 + points[0, 1])
        for x, y in points[1::4]:
            lines.draw_to(x0 + x, 0, z0 + y)
        lines.draw_to(x0 + points[0, 0], 0, z0 + points[0, 1])
        self.map_node.attach_new_node(lines.create())
        start_x, start_z = x0 + points[0, 0], z0 + points[0, 1]
        start = _card(self.map_node, "start", start_x - 5, start_x + 5, start_z - 5, start_z + 5)
        start.set_color(*_RED)

    def render(self) -> None:
        self.engine.render_frame()

    @property
    def window_closed(self) -> bool:
        """The user closed the window."""
        if not self.onscreen or self.closed:
            return self.closed
        return self.output.is_closed() or not self.output.is_valid()

    @property
    def renderer(self) -> str:
        gsg = self.output.get_gsg()
        name = ""
        if gsg is not None:
            name = gsg.get_driver_renderer() or gsg.get_driver_vendor() or ""
        kind = self.engine.pipe.get_type().get_name()
        pipe = self.engine.pipe.get_interface_name()
        if not self.onscreen:
            kind = "software, offscreen"
        return f"{pipe} ({kind}){': ' + name if name else ''}"

    def screenshot(self, path: str | os.PathLike) -> Path:
        """Save the latest frame as an image file (PNG or JPEG by extension), atomically."""
        import cv2

        from clonedrive.sim.engine import texture_rgb

        texture = self._texture if self._texture is not None else self.output.get_screenshot()
        if texture is None:
            raise RuntimeError("the window has no frame to save yet")
        image = texture_rgb(texture)
        path = Path(path)
        with atomic_path(path) as temporary:
            if not cv2.imwrite(str(temporary), image[:, :, ::-1]):
                raise RuntimeError(f"OpenCV could not write {path} (use .png or .jpg)")
        return path

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.root.remove_node()
        self.engine.close()

    def __enter__(self) -> DrivingWindow:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def run_window(session: DrivingSession, *, onscreen: bool = True, software: bool = False,
               track: str | None = None, reverse: bool = False, hold: Iterable[str] = (),
               record: bool = False, steps: int | None = None,
               screenshot: str | os.PathLike | None = None, realtime: bool | None = None
               ) -> WindowSummary:
    """Run the window until the user quits (Esc in the menu, or closing the window), or until
    ``steps`` control steps have been driven.

    ``track``: skip the menu and drive this track (``reverse``: backwards). ``hold``: keys held
    down from the start (e.g. ``("w",)``: full throttle), ``record``: start recording at once --
    both for scripted runs. ``screenshot``: save the last frame there. ``realtime``: pace the
    steps to the control rate (default: on screen only).
    """
    if realtime is None:
        realtime = onscreen
    driven = 0
    with DrivingWindow(session, onscreen=onscreen, software=software) as window:
        if track is not None:
            session.choose(track, reverse=reverse)
            window.refresh()
            window.render()
            session.step()
            for key in hold:
                session.key_down(key)
            if record:
                session.start_recording()
        period_s = 1.0 / session.sim_config.control_hz
        next_tick = time.monotonic()
        while not session.quit_requested and not window.window_closed:
            if steps is not None and driven >= steps:
                break
            window.process_input()
            if session.loading:
                window.refresh()
                window.render()
            if session.step() is not None:
                driven += 1
            window.refresh()
            window.render()
            if not onscreen and session.mode == MENU and not session.loading:
                break  # offscreen there is no input: the menu is drawn once
            if realtime:
                next_tick += period_s
                delay = next_tick - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                else:
                    next_tick = time.monotonic()  # behind: do not try to catch up
        shot = str(window.screenshot(screenshot)) if screenshot is not None else None
        renderer = window.renderer
        driven_track = session.track_name
        session.close()
    return WindowSummary(renderer=renderer, onscreen=onscreen, steps=driven,
                         rows_recorded=session.rows_recorded, folder_rows=session.folder_rows,
                         out_dir=str(session.out_dir), screenshot=shot, track=driven_track)


class _GamepadReader:
    """Reads the connected gamepads' axes through Panda3D's InputDeviceManager (Linux: evdev
    under /dev/input; nothing is read where that is missing)."""

    def __init__(self) -> None:
        self._manager = None
        self._last: dict[str, float] = {}
        if sys.platform.startswith("linux") and not Path("/dev/input").is_dir():
            return  # a container or remote session: no input devices to watch
        from panda3d.core import InputDeviceManager

        self._manager = InputDeviceManager.get_global_ptr()

    def changed_axes(self) -> list[tuple[str, float]]:
        """(axis, value) for every gamepad axis that moved since the last call."""
        if self._manager is None:
            return []
        from panda3d.core import InputDevice

        self._manager.update()
        changes = []
        for device in self._manager.get_devices(InputDevice.DeviceClass.gamepad):
            device.poll()
            for axis in GAMEPAD_AXES:
                state = device.find_axis(getattr(InputDevice.Axis, axis))
                if state is None or not state.known:
                    continue
                value = float(state.value)
                if abs(value - self._last.get(axis, 0.0)) > 1e-3:
                    self._last[axis] = value
                    changes.append((axis, value))
        return changes


def _card(parent, name: str, left: float, right: float, bottom: float, top: float):
    from panda3d.core import CardMaker

    maker = CardMaker(name)
    maker.set_frame(left, right, bottom, top)
    return parent.attach_new_node(maker.generate())


def _text(parent, name: str, x_px: float, z_px: float, size_px: float, colour,
          *, align_right: bool = False):
    """A text node with its baseline's left (or right) end at (x, z) [px]."""
    from panda3d.core import TextNode

    node = TextNode(name)
    node.set_text_color(*colour)
    node.set_shadow(0.06, 0.06)
    node.set_shadow_color(0, 0, 0, 0.9)
    if align_right:
        node.set_align(TextNode.A_right)
    path = parent.attach_new_node(node)
    path.set_pos(x_px, 0, z_px)
    path.set_scale(size_px)
    return path
