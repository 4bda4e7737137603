"""The ``clonedrive sim`` window: a Panda3D shell around a manual ``DrivingSession``.

The window forwards Panda3D's key, pointer and gamepad input to the session, steps it at the
control rate (15 Hz of simulated time, paced to the wall clock), and draws what the session
exposes: the track menu with a map of the chosen track, or the center camera's image (the very
image a recording stores, scaled up) under a HUD with speed, steering (and a steering bar), CTE,
who drives, the recording state and row counts (that drawing is
:class:`~clonedrive.manual.overlay.Overlay`).

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

from clonedrive.base.config import atomic_path
from clonedrive.manual.human_input import GAMEPAD_AXES
from clonedrive.manual.overlay import Overlay
from clonedrive.manual.session import MENU, DrivingSession

#: Window size [px] (fixed): the camera view (2:1, like the 320x160 images) above a HUD panel.
WINDOW_SIZE = (960, 640)
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
            self.overlay = Overlay(self.output, self.width, self.height)
        except BaseException:
            self.engine.close()
            raise
        self._gamepads = _GamepadReader() if onscreen else None
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
        self.overlay.refresh(self.session)

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
        self.overlay.remove()
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
