"""Manual driving, the logic of the ``clonedrive sim`` window: like the Udacity simulator's
training mode, without the window.

:class:`DrivingSession` takes input events -- keys pressed and released (Panda3D button names:
``arrow_left``, ``a``, ``escape``...), the mouse pointer's horizontal position in [-1, 1], gamepad
axes -- and steps a :class:`~clonedrive.sim.simulator.Simulator` one control period (1/15 s of
simulated time) per :meth:`DrivingSession.step`, through the episode runner
(:mod:`clonedrive.episode`) with the session as its driver (:data:`MANUAL_RULES`: off-road events
are counted, not intervened; Backspace is the runner's intervention, at rest). The Panda3D window
(:mod:`clonedrive.manual.window`) only forwards events and draws what the session exposes, so all of
this runs, and is tested, without a display.

Modes: ``menu`` (choose a track and direction) -> ``driving`` (a human steers) <->
``autonomous`` (a drive server steers, through
:class:`~clonedrive.udacity.client.SimulatorClient`, exactly as the Udacity simulator's autonomous
mode; a human takes over for as long as a steering or throttle key is held, a gamepad control is
moved, or the pointer steers (mouse steering: pressed on the page, inside the window), and the
server is sent the manual-mode telemetry meanwhile). Recording is independent of the mode.
Autonomous mode can also be given any :class:`Pilot` (``start_autonomous(pilot)``: the expert or a
model in this process, as ``clonedrive web`` does), with or without takeover; each takeover is
counted (:attr:`DrivingSession.takeovers`), and with ``takeover_labels`` a recording keeps only
the rows a person drove, the labels of HG-DAgger (Kelly et al. 2019).

Steering that gives good labels (UDACITY.md: keyboard steering in the Udacity simulator gives
mostly 0 and then +-1 spikes):

- **keyboard** (arrows or A/D): a held key turns the wheel at ``keyboard_steer_rate_per_s``
  toward full lock; released, the wheel returns to the centre at ``keyboard_return_rate_per_s``.
  One 1/15 s step moves steering by at most ~0.1: ramps, not spikes.
- **mouse** (``M`` toggles): steering follows the pointer's horizontal position, -1 at the
  window's left edge, +1 at its right edge (times ``mouse_gain``, clipped).
- **gamepad**: the left stick's x axis steers, the right trigger drives and the left trigger
  brakes; moving the stick or a trigger beyond ``gamepad_dead_zone`` selects it.

Throttle (W / up arrow) and brake-then-reverse (S / down arrow) ramp at ``throttle_rate_per_s``;
Space brakes fully. Other keys: ``R`` starts/stops recording, ``P`` starts/stops autonomous mode,
``M`` mouse steering, ``Backspace`` puts the car back on the centreline, ``Esc`` goes back to the
menu (and quits from the menu). ``A`` steers left, so autonomous mode is ``P`` (pilot).

Recording writes the Udacity format (UDACITY.md) through
:class:`~clonedrive.data.recorder.RowSink`, as ``clonedrive record`` does: one row per control
step, each image written (atomically) before its row, appended to an existing log with image
times continuing after its last one, and a session entry in ``config.json``. A row holds the
images taken at a step, the steering and throttle applied for that step (throttle clipped to
>= 0; a negative throttle above 5 mph is recorded as brake, as it brakes), and the speed when
the images were taken.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from datetime import timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from clonedrive.episode.rules import EpisodeRules
from clonedrive.udacity_spec import JPEG_QUALITY, PORT
from clonedrive.world.vehicle import Controls

if TYPE_CHECKING:  # the simulator loads when a track opens, not when the CLI reads defaults
    from clonedrive.sim.simulator import SimConfig, SimObservation

#: Modes of a session.
MENU, DRIVING, AUTONOMOUS = "menu", "driving", "autonomous"
#: Steering sources.
KEYBOARD, MOUSE, GAMEPAD = "keyboard", "mouse", "gamepad"

STEER_LEFT_KEYS = frozenset({"arrow_left", "a"})
STEER_RIGHT_KEYS = frozenset({"arrow_right", "d"})
THROTTLE_KEYS = frozenset({"arrow_up", "w"})
REVERSE_KEYS = frozenset({"arrow_down", "s"})
BRAKE_KEYS = frozenset({"space"})
DRIVING_KEYS = STEER_LEFT_KEYS | STEER_RIGHT_KEYS | THROTTLE_KEYS | REVERSE_KEYS | BRAKE_KEYS
#: Gamepad axes the session reads (Panda3D ``InputDevice.Axis`` names).
GAMEPAD_AXES = ("left_x", "right_trigger", "left_trigger")
#: Below this speed a negative throttle reverses instead of braking (the Udacity car).
REVERSE_BELOW_MPH = 5.0
#: Where ``R`` records unless told otherwise.
DEFAULT_OUT_DIR = "data/manual"
#: A status message stays on the HUD this long [s of simulated time].
MESSAGE_SECONDS = 4.0

HELP_DRIVING = ("W/S: throttle/brake  A/D: steer (or arrows)  M: mouse steering  Space: brake  "
                "R: record  P: autonomous  Backspace: reset  Esc: menu")
#: A person drives where they like: an off-road event is counted, not intervened; no lap
#: target, no time limit. A person holds no set speed, so Backspace (the runner's intervention)
#: puts the car back on the centreline at rest.
MANUAL_RULES = EpisodeRules(laps=None, set_speed_mph=0.0, off_road="continue")

HELP_MENU = ("Up/Down: track  Left/Right: direction  G: another generated track  "
             "Enter: drive  Esc: quit")


@dataclass(frozen=True)
class ManualConfig:
    """How manual driving feels and where autonomous mode connects."""

    keyboard_steer_rate_per_s: float = 1.2  #: steering change per s while a steer key is held
    keyboard_return_rate_per_s: float = 2.5  #: ... back toward 0 when released or reversing
    keyboard_max_steering: float = 1.0  #: the most a held key steers (|steering|)
    throttle_rate_per_s: float = 2.5  #: throttle change per s toward the key's target
    mouse_gain: float = 1.0  #: steering = gain x pointer x (pointer x in [-1, 1])
    gamepad_dead_zone: float = 0.08  #: stick/trigger values below this count as 0
    scenery: bool = True  #: trees, rocks... (off: road and terrain only, quicker to load)
    seed: int = 0  #: the scene's seed
    generated_seed: int = 1  #: the menu's generated track is gen:<this>, G picks the next
    header: bool = False  #: recording: write the header line (the simulator writes none)
    relative_paths: bool = False  #: recording: IMG/<name> instead of absolute paths
    jpeg_quality: int = JPEG_QUALITY  #: recording: JPEG quality 1-100
    server_host: str = "127.0.0.1"  #: autonomous mode: the drive server
    server_port: int = PORT
    connect_timeout_s: float = 2.0  #: give up connecting after this long (the window waits)
    reply_timeout_s: float = 10.0  #: a drive server silent this long ends autonomous mode

    def __post_init__(self) -> None:
        for name in ("keyboard_steer_rate_per_s", "keyboard_return_rate_per_s",
                     "throttle_rate_per_s", "mouse_gain", "connect_timeout_s",
                     "reply_timeout_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {getattr(self, name)}")
        if not 0 < self.keyboard_max_steering <= 1:
            raise ValueError(
                f"keyboard_max_steering must be in (0, 1], got {self.keyboard_max_steering}")
        if not 0 <= self.gamepad_dead_zone < 1:
            raise ValueError(f"gamepad_dead_zone must be in [0, 1), got {self.gamepad_dead_zone}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {self.jpeg_quality}")
        if not 0 <= self.server_port <= 65535:
            raise ValueError(f"server_port must be in 0..65535, got {self.server_port}")


@dataclass(frozen=True)
class ManualRecording:
    """What a manual recording session writes to ``config.json`` (next to the recorder's)."""

    track: str
    reverse: bool
    style: str = "manual"
    steering_input: str = KEYBOARD  #: the steering source when recording started
    scenery: bool = True
    seed: int = 0
    header: bool = False
    relative_paths: bool = False
    jpeg_quality: int = JPEG_QUALITY


class Pilot(Protocol):
    """Who drives in autonomous mode: a drive server (the default) or anything that decides from
    the observation."""

    name: str  #: shown on the HUD

    def controls(self, obs: SimObservation) -> Controls | None:
        """This step's controls; None: the car rolls on as it is."""
        ...

    def manual(self) -> None:
        """A person has the car this step."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class MenuItem:
    label: str
    track: str  #: a name for load_track


@dataclass(frozen=True)
class Hud:
    """The text the window shows while driving."""

    status: str  #: track, speed, steering, throttle, CTE, laps
    mode: str  #: who drives and with what
    recording: str  #: recording state and row counts
    message: str  #: the latest status message ('' when none)
    help: str


def move_toward(value: float, target: float, max_change: float) -> float:
    """``value`` moved toward ``target`` by at most ``max_change`` (>= 0)."""
    if value < target:
        return min(value + max_change, target)
    return max(value - max_change, target)


def _dead_zone(value: float, zone: float) -> float:
    """0 inside ``zone``, rescaled so that the output still reaches +-1 outside it."""
    magnitude = abs(value)
    if magnitude <= zone:
        return 0.0
    return math.copysign(min((magnitude - zone) / (1.0 - zone), 1.0), value)


class DrivingSession:
    """Manual driving without a window: feed input events, call :meth:`step` at the control
    rate, read :attr:`observation`, :meth:`hud` and :meth:`menu_lines`.

    ``out_dir``: where ``R`` records (created when recording starts). ``sim_config``: the
    simulator's configuration (default: the three Udacity cameras, ``config.scenery``);
    recording needs all three cameras, autonomous mode the center one.
    """

    def __init__(self, config: ManualConfig | None = None,
                 out_dir: str | os.PathLike = DEFAULT_OUT_DIR, *,
                 sim_config: SimConfig | None = None) -> None:
        self.config = config or ManualConfig()
        self.out_dir = Path(out_dir).absolute()
        from clonedrive.sim.simulator import SimConfig

        self.sim_config = sim_config or SimConfig(scenery=self.config.scenery)
        self.mode = MENU
        self.quit_requested = False
        self.menu_index = 0
        self.reverse = False
        self.generated_seed = self.config.generated_seed
        self.steering_source = KEYBOARD
        self.sim = None
        self._episode = None
        self._runner = None
        self.track_name = ""
        self.observation: SimObservation | None = None
        self.controls = Controls()  #: the controls applied in the latest step
        self.message = ""
        self.rows_recorded = 0  #: rows of the current (or latest) recording
        self.folder_rows = 0  #: rows in the output folder's log, including this recording's
        self._message_until_s = math.inf
        self._held: set[str] = set()
        self._key_steering = 0.0
        self._key_throttle = 0.0
        self._pointer_x: float | None = None
        self._axes = dict.fromkeys(GAMEPAD_AXES, 0.0)
        self._pending: tuple[str, bool] | None = None
        self._sink = None
        self._lock = None  # the recording folder's lock while recording
        self._session: dict | None = None
        self._takeovers_before = 0
        self._recording_config: ManualRecording | None = None
        self._client: Pilot | None = None
        self.takeover = True  #: in autonomous mode, a held control takes over
        self.takeover_labels = False  #: ... and a recording then keeps only the person's rows
        self.takeovers = 0  #: takeovers since the session began
        self._taking_over = False

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> DrivingSession:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop recording (every row written), leave autonomous mode, close the simulator."""
        self._leave_track()
        self._pending = None

    @property
    def recording(self) -> bool:
        return self._sink is not None

    @property
    def taking_over(self) -> bool:
        """A person holds the car in autonomous mode (a takeover)."""
        return self.mode == AUTONOMOUS and self._taking_over

    @property
    def menu_items(self) -> list[MenuItem]:
        seed = self.generated_seed
        return [MenuItem("Lake", "lake"), MenuItem("Mountain", "mountain"),
                MenuItem(f"Generated track (seed {seed})", f"gen:{seed}")]

    @property
    def loading(self) -> bool:
        """A track was chosen and opens on the next :meth:`step`."""
        return self._pending is not None

    # ------------------------------------------------------------------ input events
    def key_down(self, key: str) -> None:
        """A key (Panda3D button name) was pressed."""
        key = key.lower()
        if key in self._held:
            return  # auto-repeat
        self._held.add(key)
        if self.mode == MENU:
            self._menu_key(key)
            return
        if key in STEER_LEFT_KEYS | STEER_RIGHT_KEYS and self.steering_source != KEYBOARD:
            self._key_steering = self.controls.steering  # take over where the wheel is
            self.steering_source = KEYBOARD
        if key == "escape":
            self._leave_track()
            self._say("back in the menu")
        elif key == "r":
            if self.recording:
                self.stop_recording()
            else:
                self.start_recording()
        elif key == "p":
            if self.mode == AUTONOMOUS:
                self.stop_autonomous()
            else:
                self.start_autonomous()
        elif key == "m":
            self.toggle_mouse_steering()
        elif key == "backspace" and self._episode is not None:
            self.observation = self._episode.intervene()
            self._key_steering = self._key_throttle = 0.0
            self._say("back on the centreline")

    def key_up(self, key: str) -> None:
        """A key was released."""
        self._held.discard(key.lower())

    def pointer(self, x: float | None) -> None:
        """The mouse pointer's horizontal position: -1 at the window's left edge, +1 at its right
        edge; None when the pointer is outside the window (steering then stays)."""
        self._pointer_x = None if x is None else min(max(float(x), -1.0), 1.0)

    def gamepad_axis(self, axis: str, value: float) -> None:
        """A gamepad axis value: ``left_x`` in [-1, 1], ``right_trigger``/``left_trigger`` in
        [0, 1]. Moving one beyond the dead zone makes the gamepad the steering source."""
        if axis not in self._axes:
            return
        self._axes[axis] = float(value)
        if abs(value) > self.config.gamepad_dead_zone and self.steering_source != GAMEPAD:
            self.steering_source = GAMEPAD
            self._say("gamepad steering")

    def release_all(self) -> None:
        """Every key, the pointer and the gamepad let go (the input window lost focus)."""
        self._held.clear()
        self._pointer_x = None
        self._axes = dict.fromkeys(GAMEPAD_AXES, 0.0)

    def toggle_mouse_steering(self) -> None:
        if self.steering_source == MOUSE:
            self._key_steering = self.controls.steering
            self.steering_source = KEYBOARD
            self._say("keyboard steering")
        else:
            self.steering_source = MOUSE
            self._say("mouse steering: the pointer's horizontal position steers")

    def _menu_key(self, key: str) -> None:
        items = self.menu_items
        if key in ("arrow_up", "w"):
            self.menu_index = (self.menu_index - 1) % len(items)
        elif key in ("arrow_down", "s"):
            self.menu_index = (self.menu_index + 1) % len(items)
        elif key in ("arrow_left", "arrow_right", "a", "d"):
            self.reverse = not self.reverse
        elif key == "g":
            self.generated_seed += 1
            self.menu_index = len(items) - 1
        elif key in ("1", "2", "3"):
            self.menu_index = int(key) - 1
        elif key in ("enter", "space"):
            self.choose(items[self.menu_index].track, reverse=self.reverse)
        elif key == "escape":
            self.quit_requested = True

    # ------------------------------------------------------------------ modes
    def choose(self, track: str, *, reverse: bool = False) -> None:
        """Leave the menu for ``track`` (a load_track name); it opens on the next step."""
        self._leave_track()
        self._pending = (track, bool(reverse))
        direction = " in reverse" if reverse else ""
        self._say(f"loading {track}{direction}...")

    def _open_pending(self) -> None:
        from clonedrive.episode.runner import Episode, PerCar, Runner
        from clonedrive.sim.simulator import Simulator
        from clonedrive.world.catalog import load_track
        from clonedrive.world.track import TrackError

        track_name, reverse = self._pending
        self._pending = None
        try:
            track = load_track(track_name)
        except (TrackError, OSError) as error:
            self._say(f"cannot load track {track_name}: {error}", forever=True)
            return
        self.sim = Simulator(track, self.sim_config)
        self._episode = Episode(self.sim, MANUAL_RULES, track=track_name, seed=self.config.seed,
                                options={"reverse": reverse}, trace=False)
        self._runner = Runner([self._episode], PerCar([_SessionDriver(self)]))
        try:
            (self.observation,) = self._runner.reset()
        except BaseException:
            self.sim.close()
            self.sim = None
            self._episode = self._runner = None
            raise
        self.track_name = track_name
        self.reverse = reverse
        self.mode = DRIVING
        self.controls = Controls()
        self._key_steering = self._key_throttle = 0.0
        self._say(f"driving {track.name}{' in reverse' if reverse else ''}: "
                  "R records, P hands over to a drive server")

    def _leave_track(self) -> None:
        if self.recording:
            self.stop_recording()
        if self.mode == AUTONOMOUS:
            self.stop_autonomous()
        if self.sim is not None:
            self.sim.close()
            self.sim = None
        self._episode = self._runner = None
        self.observation = None
        self.mode = MENU

    def start_autonomous(self, pilot: Pilot | None = None, *, takeover: bool = True,
                         takeover_labels: bool = False) -> bool:
        """Let ``pilot`` drive (default: connect to the drive server). ``takeover``: a person
        holding a control drives meanwhile; ``takeover_labels``: a recording keeps only those
        steps. False (and a message) if it cannot start."""
        if self.sim is None or self.mode != DRIVING:
            return False
        if self.observation is None or "center" not in self.observation.images:
            self._say("autonomous mode needs the center camera")
            return False
        if pilot is None:
            pilot = self._connect_server()
            if pilot is None:
                return False
        self._client = pilot
        self.takeover, self.takeover_labels = takeover, takeover and takeover_labels
        self._taking_over = False
        self.mode = AUTONOMOUS
        hint = "hold a control to take over, " if takeover else ""
        self._say(f"autonomous: {pilot.name} drives; {hint}P to stop")
        return True

    def _connect_server(self) -> Pilot | None:
        from clonedrive.udacity.client import ClientConfig, DriveServerError, SimulatorClient

        client = SimulatorClient(ClientConfig(
            host=self.config.server_host, port=self.config.server_port,
            connect_timeout_s=self.config.connect_timeout_s,
            reply_timeout_s=self.config.reply_timeout_s))
        try:
            client.connect()
        except DriveServerError as error:
            self._say(f"autonomous mode off: {error}")
            return None
        return _ServerPilot(client)

    def stop_autonomous(self, reason: str = "manual driving") -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        self._taking_over = False
        if self.mode == AUTONOMOUS:
            self.mode = DRIVING
            self._key_steering = self.controls.steering
            self._key_throttle = max(self.controls.throttle, 0.0)
            self._say(reason)

    # ------------------------------------------------------------------ recording
    def start_recording(self) -> bool:
        """Start recording into ``out_dir`` (appending to a log already there)."""
        from clonedrive.data.driving_log import CAMERAS
        from clonedrive.data.recording_lock import RecordingLock, RecordingLockedError

        if self.sim is None or self.recording:
            return False
        missing = [camera for camera in CAMERAS if camera not in self.sim_config.cameras]
        if missing:
            self._say(f"cannot record: no {', '.join(missing)} camera")
            return False
        lock = RecordingLock(self.out_dir)
        try:
            lock.acquire()
        except (RecordingLockedError, ValueError, OSError) as error:
            self._say(f"cannot record: {error}")
            return False
        try:
            self._open_sink()
        except BaseException:
            lock.release()
            raise
        self._lock = lock
        self._say(f"recording into {self.out_dir}")
        return True

    def _open_sink(self) -> None:
        """Start this recording's session in ``out_dir`` (its lock held) and open the sink."""
        from clonedrive import __version__
        from clonedrive.config import config_to_dict
        from clonedrive.data.recorder import RowSink, prepare_log_folder, write_session_config

        existing_rows, start = prepare_log_folder(self.out_dir)
        # Image names are start + simulated time: the first row's image is named ``start``.
        elapsed = timedelta(seconds=self.observation.time_s)
        recording = ManualRecording(
            track=self.track_name, reverse=self.reverse, steering_input=self.steering_source,
            scenery=self.sim_config.scenery, seed=self.config.seed, header=self.config.header,
            relative_paths=self.config.relative_paths, jpeg_quality=self.config.jpeg_quality)
        session = {"started": start.isoformat(timespec="milliseconds"), "rows": None,
                   **config_to_dict(recording)}
        write_session_config(self.out_dir, recording, self.sim.track, __version__, session)
        self._sink = RowSink(self.out_dir, start - elapsed, header=self.config.header,
                             relative_paths=self.config.relative_paths,
                             jpeg_quality=self.config.jpeg_quality)
        self._session = session
        self._takeovers_before = self.takeovers
        self._recording_config = recording
        self.rows_recorded = 0
        self.folder_rows = existing_rows

    def stop_recording(self) -> int:
        """Stop recording: every submitted row is written before this returns. Returns the rows
        this recording wrote."""
        from clonedrive import __version__
        from clonedrive.data.recorder import write_session_config

        if self._sink is None:
            return 0
        sink, self._sink = self._sink, None
        try:
            sink.close()
        finally:
            self._session["rows"] = sink.rows_written
            self._session["takeovers"] = self.takeovers - self._takeovers_before
            try:
                write_session_config(self.out_dir, self._recording_config, self.sim.track,
                                     __version__, self._session)
            finally:
                lock, self._lock = self._lock, None
                if lock is not None:
                    lock.release()
        self.rows_recorded = sink.rows_written
        self._say(f"recorded {sink.rows_written} rows into {self.out_dir}")
        return sink.rows_written

    def _record(self, obs: SimObservation, controls: Controls) -> None:
        try:
            self._sink.submit(obs, controls.steering, _recorded(controls, obs.speed_mph))
        except RuntimeError as error:  # a failed write: stop recording, keep driving
            try:
                self.stop_recording()
            except RuntimeError:
                pass  # the same error, raised again by the sink's close
            self._say(f"recording stopped: {error}", forever=True)
            return
        self.rows_recorded += 1
        self.folder_rows += 1

    # ------------------------------------------------------------------ stepping
    def step(self) -> SimObservation | None:
        """One control period of the episode runner: the driver (human or server) decides
        (:meth:`decide`), the simulator advances, the step is recorded if recording. Opens a
        chosen track first. Returns the new observation (None in the menu)."""
        if self._pending is not None:
            self._open_pending()
            return self.observation
        if self._runner is None:
            return None
        (step,) = self._runner.step()
        controls = step.decision.controls
        if self._sink is not None and (self._taking_over or not self._labels_only()):
            self._record(step.seen, controls)
        self.controls = controls
        self.observation = self._episode.observation
        if self.observation.time_s >= self._message_until_s:
            self.message = ""
        return self.observation

    def decide(self) -> Controls:
        """This step's controls: the person's input, or in autonomous mode the drive server's
        command unless a person takes over."""
        dt_s = 1.0 / self.sim.config.control_hz
        human = self._human_controls(dt_s)
        if self.mode == AUTONOMOUS:
            return self._server_controls(human)
        return human

    def _labels_only(self) -> bool:
        return self.mode == AUTONOMOUS and self.takeover_labels

    def _human_active(self) -> bool:
        zone = self.config.gamepad_dead_zone
        pointing = self.steering_source == MOUSE and self._pointer_x is not None
        return pointing or bool(self._held & DRIVING_KEYS) or any(
            abs(value) > zone for value in self._axes.values())

    def _human_controls(self, dt_s: float) -> Controls:
        config = self.config
        held = self._held
        # Keyboard steering: ramp toward the held side, return to the centre when released.
        target = (float(bool(held & STEER_RIGHT_KEYS)) - float(bool(held & STEER_LEFT_KEYS))
                  ) * config.keyboard_max_steering
        steering = self._key_steering
        toward_centre = target == 0.0 or target * steering < 0.0
        rate = config.keyboard_return_rate_per_s if toward_centre else \
            config.keyboard_steer_rate_per_s
        self._key_steering = move_toward(steering, target, rate * dt_s)
        if self.steering_source == MOUSE and self._pointer_x is not None:
            steering = min(max(config.mouse_gain * self._pointer_x, -1.0), 1.0)
        elif self.steering_source == MOUSE:
            steering = self.controls.steering  # pointer outside the window: hold the wheel
        elif self.steering_source == GAMEPAD:
            steering = _dead_zone(self._axes["left_x"], config.gamepad_dead_zone)
        else:
            steering = self._key_steering
        # Throttle: keys ramp it; the gamepad's triggers set it directly.
        key_target = float(bool(held & THROTTLE_KEYS)) - float(bool(held & REVERSE_KEYS))
        self._key_throttle = move_toward(self._key_throttle, key_target,
                                         config.throttle_rate_per_s * dt_s)
        throttle = self._key_throttle
        if self.steering_source == GAMEPAD and not held & (THROTTLE_KEYS | REVERSE_KEYS):
            throttle = (_dead_zone(self._axes["right_trigger"], config.gamepad_dead_zone)
                        - _dead_zone(self._axes["left_trigger"], config.gamepad_dead_zone))
        brake = 1.0 if held & BRAKE_KEYS else 0.0
        return Controls(steering=steering, throttle=throttle, brake=brake).clipped()

    def _server_controls(self, human: Controls) -> Controls:
        """The drive server's command for this step, or the human's while one takes over
        (the server then gets the manual-mode telemetry, as from the Udacity simulator)."""
        from clonedrive.udacity.client import DriveServerError

        taking_over = self.takeover and self._human_active()
        if taking_over and not self._taking_over:
            self.takeovers += 1
        self._taking_over = taking_over
        try:
            if taking_over:
                self._client.manual()
                return human
            reply = self._client.controls(self.observation)
        except DriveServerError as error:
            self.stop_autonomous(f"autonomous mode ended: {error}")
            return human
        if reply is None:  # "manual": the server lets the car roll on as it is
            return self.controls
        self._key_steering = reply.steering  # a human taking over starts from here
        return reply.clipped()

    # ------------------------------------------------------------------ display text
    def _say(self, text: str, *, forever: bool = False) -> None:
        self.message = text
        now = self.observation.time_s if self.observation is not None else 0.0
        self._message_until_s = math.inf if forever or self.sim is None else \
            now + MESSAGE_SECONDS

    def hud(self) -> Hud:
        """The driving HUD's text (meaningful while a track is open)."""
        obs = self.observation
        if obs is None:
            return Hud(status="", mode="", recording="", message=self.message, help=HELP_MENU)
        controls = self.controls
        direction = " (reverse)" if self.reverse else ""
        status = (f"{self.track_name}{direction}   {obs.speed_mph:5.1f} mph   "
                  f"steering {controls.steering:+.2f}   throttle {controls.throttle:+.2f}"
                  f"{'  brake' if controls.brake > 0 else ''}   CTE {obs.cte_m:+.2f} m   "
                  f"laps {obs.laps}   off-road {obs.off_road_events}"
                  f"{'   OFF ROAD' if obs.off_road else ''}")
        if self.mode == AUTONOMOUS:
            who = "manual override" if self._taking_over else "the pilot drives"
            takeovers = f"   takeovers {self.takeovers}" if self.takeover else ""
            mode = f"AUTONOMOUS ({self._client.name}): {who}{takeovers}"
        else:
            mode = f"MANUAL: {self.steering_source} steering"
        if self.recording:
            recording = (f"REC  {self.rows_recorded} rows  ({self.folder_rows} in "
                         f"{self.out_dir.name}/)")
        else:
            recording = f"not recording: R records into {self.out_dir}"
        return Hud(status=status, mode=mode, recording=recording, message=self.message,
                   help=HELP_DRIVING)

    def hud_lines(self) -> list[str]:
        hud = self.hud()
        return [line for line in (hud.status, hud.mode, hud.recording, hud.message, hud.help)
                if line]

    def menu_lines(self) -> list[str]:
        """The menu: a title, one line per track (the chosen one marked), the direction."""
        lines = ["clonedrive: choose a track", ""]
        for index, item in enumerate(self.menu_items):
            marker = ">" if index == self.menu_index else " "
            lines.append(f"{marker} {index + 1}  {item.label}")
        lines += ["", f"direction: {'reverse' if self.reverse else 'forward'}",
                  f"recordings go to {self.out_dir}"]
        if self.message:
            lines += ["", self.message]
        return lines


class _ServerPilot:
    """A drive server as the pilot, through the Udacity simulator's side of the protocol."""

    def __init__(self, client) -> None:
        self.client = client
        self.name = client.url

    def controls(self, obs: SimObservation) -> Controls | None:
        return self.client.controls_for(obs.images["center"], obs.steering, obs.throttle,
                                        obs.speed_mph)

    def manual(self) -> None:
        self.client.manual()

    def close(self) -> None:
        self.client.close()


class _SessionDriver:
    """The session as the episode runner's driver of its one car: a person (or, in autonomous
    mode, the drive server the session talks to) decides from the input events it received."""

    def __init__(self, session: DrivingSession) -> None:
        self.session = session

    def reset(self) -> None:
        """The input state stays as it is: the person's hands are where they are."""

    def act(self, obs: SimObservation) -> Controls:
        return self.session.decide()

    def intervened(self, obs: SimObservation) -> None:
        """Nothing to forget."""


def _recorded(controls: Controls, speed_mph: float) -> Controls:
    """The controls as a log row reports them: a negative throttle brakes above 5 mph."""
    brake = controls.brake
    if controls.throttle < 0 and speed_mph > REVERSE_BELOW_MPH:
        brake = max(brake, -controls.throttle)
    return replace(controls, throttle=max(controls.throttle, 0.0), brake=brake)
