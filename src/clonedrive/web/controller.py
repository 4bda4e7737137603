"""The page's car: a :class:`~clonedrive.manual.session.DrivingSession` stepped at the control
rate, fed with the pages' checked commands, and turned into frames (a JPEG and a state).

Everything that touches the session (and so Panda3D) runs on the one thread that calls
:meth:`Controller.run`; pages only :meth:`Controller.submit` commands to a bounded queue.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from clonedrive.manual.session import AUTONOMOUS, MENU, DrivingSession
from clonedrive.web.config import EXPERT, MANUAL, MODEL, TAKEOVER, WebConfig
from clonedrive.web.messages import Command

logger = logging.getLogger("clonedrive.web")
#: Slower than this [mph], the car is parked: the HUD shows 0 and the first lap's clock waits.
PARKED_MPH = 0.2


@dataclass(frozen=True)
class Frame:
    """One step's picture (JPEG bytes) and everything the page's HUD shows (JSON-ready)."""

    number: int
    jpeg: bytes
    state: dict


class Controller:
    """Steps ``session`` on ``track`` for the pages. ``policy``: the model the model modes use
    (None: those modes are refused with a message)."""

    def __init__(self, session: DrivingSession, config: WebConfig, *, track: str,
                 reverse: bool = False, look: str | None = None, policy=None,
                 model_name: str = "model") -> None:
        self.session = session
        self.config = config
        self.view = config.view
        self.look = look or "clear"
        self.policy = policy
        self.model_name = model_name
        self.track_choices = _track_choices(track)
        self.pilot_mode = MANUAL
        self.frames = 0
        self.input_seq = 0  #: the latest page counter applied to the session
        self.rejected_inputs = 0
        self._commands: queue.Queue[Command] = queue.Queue(config.max_pending_inputs)
        self._laps_seen = 0
        self._lap_start_s = 0.0
        self._last_lap_s: float | None = None
        self._rolling = False  # the car has moved since the track was opened
        #: The track to fall back to when a chosen one fails to load (the last one driven, or
        #: the first one asked for, whose load a page's command can overtake), and direction.
        self._opened: tuple[str, bool] | None = (track, bool(reverse))
        self.set_look(self.look)
        session.choose(track, reverse=reverse)

    # ------------------------------------------------------------------ commands
    def submit(self, command: Command) -> bool:
        """Queue a page's command for the next step (any thread). False when too many wait."""
        try:
            self._commands.put_nowait(command)
        except queue.Full:
            self.rejected_inputs += 1
            return False
        return True

    def submit_release(self) -> None:
        """Let every control go (the last page left): a takeover or a held key ends."""
        self.submit(Command("release"))

    def _apply_pending(self) -> None:
        while True:
            try:
                command = self._commands.get_nowait()
            except queue.Empty:
                return
            self.apply(command)
            self.input_seq = max(self.input_seq, command.seq)

    def apply(self, command: Command) -> None:
        """Apply one command to the session (the stepping thread only)."""
        session, kind = self.session, command.kind
        if kind == "key":
            (session.key_down if command.flag else session.key_up)(command.value)
        elif kind == "pointer":
            if command.value is not None and session.steering_source != "mouse":
                session.toggle_mouse_steering()
            session.pointer(command.value)
        elif kind == "axis":
            session.gamepad_axis(*command.value)
        elif kind == "release":
            session.release_all()
        elif kind == "mode":
            self.set_mode(command.value)
        elif kind == "track":
            self.choose_track(command.value, reverse=command.flag)
        elif kind == "look":
            self.set_look(command.value)
            session.choose(session.track_name or self.track_choices[0], reverse=session.reverse)
        elif kind == "view":
            self.view = command.value
        elif kind == "record":
            if command.flag and not session.recording:
                session.start_recording()
            elif not command.flag and session.recording:
                session.stop_recording()
        elif kind == "reset":
            session.key_down("backspace")
            session.key_up("backspace")

    def choose_track(self, track: str, *, reverse: bool = False) -> None:
        from clonedrive.world.catalog import is_generated_name

        if track not in self.track_choices and not is_generated_name(track):
            self.session.message = f"unknown track {track[:40]!r}"
            return
        self.session.choose(track, reverse=reverse)

    def set_look(self, look: str) -> None:
        """Render the next track opened in ``look`` (a recording look, sim/conditions.py)."""
        from clonedrive.sim.conditions import FAMILIES

        conditions = None if look == "clear" else FAMILIES[look].sample(self.session.config.seed)
        self.session.sim_config = replace(self.session.sim_config, conditions=conditions)
        self.look = look

    def set_mode(self, mode: str) -> None:
        """Hand the car to ``mode``'s driver (manual: the person)."""
        session = self.session
        if mode in (MODEL, TAKEOVER) and self.policy is None:
            session.message = "no model: start clonedrive web with --model FILE"
            return
        if session.mode == AUTONOMOUS:
            session.stop_autonomous(f"{mode} driving" if mode == MANUAL else "switching pilots")
        self.pilot_mode = MANUAL
        if mode == MANUAL or session.sim is None:
            return
        from clonedrive.web.pilots import ExpertPilot, ModelPilot

        if mode == EXPERT:
            pilot = ExpertPilot(session.sim.track, reverse=session.reverse)
        else:
            pilot = ModelPilot(self.policy, self.model_name)
        if session.start_autonomous(pilot, takeover=mode == TAKEOVER,
                                    takeover_labels=mode == TAKEOVER):
            self.pilot_mode = mode

    # ------------------------------------------------------------------ stepping
    def step(self) -> Frame | None:
        """Apply the waiting commands, step the session once, and make its frame (None while
        no track is open)."""
        self._apply_pending()
        obs = self.session.step()
        if self.session.mode != AUTONOMOUS:
            self.pilot_mode = MANUAL  # the session left autonomous mode (a track change...)
        if obs is None and self._opened is not None and self.session.mode == MENU \
                and not self.session.loading:
            obs = self._reopen()
        if obs is None or "center" not in obs.images:
            return None
        self._opened = (self.session.track_name, self.session.reverse)
        self._track_laps(obs)
        self.frames += 1
        return Frame(self.frames, self._jpeg(obs.images), self.state())

    def run(self, publish: Callable[[Frame], None], stop: threading.Event,
            watched: Callable[[], bool] = lambda: True) -> None:
        """Step at the control rate until ``stop`` is set, publishing each frame; paused while
        nobody ``watched``. Closes the session (finishing a recording) at the end."""
        period_s = 1.0 / self.session.sim_config.control_hz
        try:
            next_tick = time.monotonic()
            while not stop.is_set():
                if not watched():
                    stop.wait(0.05)
                    next_tick = time.monotonic()
                    continue
                frame = self.step()
                if frame is not None:
                    publish(frame)
                if not self.config.realtime:
                    continue
                next_tick += period_s
                delay = next_tick - time.monotonic()
                if delay > 0:
                    stop.wait(delay)
                else:
                    next_tick = time.monotonic()  # behind: do not try to catch up
        finally:
            self.session.close()

    def _reopen(self):
        """A chosen track failed to load: back to the one driven before, saying why."""
        failure = self.session.message
        self.session.choose(*self._opened[:1], reverse=self._opened[1])
        obs = self.session.step()
        if obs is None:  # that one fails too: stay in the menu, saying why
            self._opened = None
        self.session.message = failure
        return obs

    def _track_laps(self, obs) -> None:
        if obs.laps < self._laps_seen or obs.time_s < self._lap_start_s:  # a new track
            self._laps_seen, self._lap_start_s, self._last_lap_s = 0, obs.time_s, None
            self._rolling = False
        if not self._rolling:  # the first lap's clock starts when the car first moves
            if abs(obs.speed_mph) < PARKED_MPH:
                self._lap_start_s = obs.time_s
            else:
                self._rolling = True
        if obs.laps > self._laps_seen:
            self._last_lap_s = obs.time_s - self._lap_start_s
            self._laps_seen, self._lap_start_s = obs.laps, obs.time_s

    def _jpeg(self, images: dict) -> bytes:
        import cv2

        if self.view == "three" and {"left", "right"} <= images.keys():
            rgb = np.hstack([images["left"], images["center"], images["right"]])
        else:
            rgb = images["center"]
        ok, data = cv2.imencode(".jpg", np.ascontiguousarray(rgb[:, :, ::-1]),
                                [cv2.IMWRITE_JPEG_QUALITY, self.config.jpeg_quality])
        if not ok:
            raise RuntimeError("OpenCV could not encode a frame as JPEG")
        return data.tobytes()

    def state(self) -> dict:
        """What the page's HUD and pickers show."""
        session, obs, controls = self.session, self.session.observation, self.session.controls
        hud = session.hud()
        return {
            "type": "state", "frame": self.frames, "input_seq": self.input_seq,
            "track": session.track_name, "reverse": session.reverse, "look": self.look,
            "view": self.view, "mode": self.pilot_mode, "hud_mode": hud.mode,
            "steering_source": session.steering_source,
            "speed_mph": 0.0 if abs(obs.speed_mph) < PARKED_MPH else round(obs.speed_mph, 2),
            "steering": round(controls.steering, 3),
            "throttle": round(controls.throttle, 3), "brake": round(controls.brake, 3),
            "laps": obs.laps, "lap_time_s": round(obs.time_s - self._lap_start_s, 1),
            "last_lap_s": None if self._last_lap_s is None else round(self._last_lap_s, 1),
            "cte_m": round(obs.cte_m, 2), "off_road": obs.off_road,
            "off_road_events": obs.off_road_events, "time_s": round(obs.time_s, 2),
            "recording": session.recording, "rows": session.rows_recorded,
            "folder_rows": session.folder_rows, "out_dir": str(session.out_dir),
            "takeovers": session.takeovers,
            "taking_over": session.taking_over,
            "message": hud.message, "model": self.policy is not None,
        }


def _track_choices(track: str) -> list[str]:
    from clonedrive.world.catalog import builtin_track_names

    names = builtin_track_names()
    return names if track in names else [track, *names]
