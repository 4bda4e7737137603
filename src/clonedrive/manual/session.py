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

This module is the session's state machine. Modes: ``menu`` (choose a track and direction) ->
``driving`` (a human steers) <-> ``autonomous`` (a pilot steers, by default a drive server,
exactly as the Udacity simulator's autonomous mode, :mod:`clonedrive.manual.pilot`; a human takes
over for as long as a steering or throttle key is held, a gamepad control is moved, or the
pointer steers (mouse steering: pressed on the page, inside the window), and the server is sent
the manual-mode telemetry meanwhile). Recording is independent of the mode
(:mod:`clonedrive.manual.recording`). Autonomous mode can also be given any
:class:`~clonedrive.manual.pilot.Pilot` (``start_autonomous(pilot)``: the expert or a model in
this process, as ``clonedrive web`` does), with or without takeover; each takeover is counted
(:attr:`DrivingSession.takeovers`), and with ``takeover_labels`` a recording keeps only the rows a
person drove, the labels of HG-DAgger (Kelly et al. 2019).

How keys, the pointer and a gamepad steer is :mod:`clonedrive.manual.human_input`; the HUD and
menu text, :mod:`clonedrive.manual.hud`. Keys the session itself handles: ``R`` starts/stops
recording, ``P`` starts/stops autonomous mode, ``M`` mouse steering, ``Backspace`` puts the car
back on the centreline, ``Esc`` goes back to the menu (and quits from the menu). ``A`` steers
left, so autonomous mode is ``P`` (pilot).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

from clonedrive.episode.rules import EpisodeRules
from clonedrive.manual.config import DEFAULT_OUT_DIR, ManualConfig
from clonedrive.manual.hud import Hud, MenuItem, driving_hud, menu_lines
from clonedrive.manual.human_input import KEYBOARD, MOUSE, STEER_KEYS, HumanInput
from clonedrive.manual.pilot import Pilot
from clonedrive.manual.recording import ManualRecording, SessionRecorder
from clonedrive.world.vehicle import Controls

if TYPE_CHECKING:  # the simulator loads when a track opens, not when the CLI reads defaults
    from clonedrive.sim.simulator import SimConfig, SimObservation

#: Modes of a session.
MENU, DRIVING, AUTONOMOUS = "menu", "driving", "autonomous"
#: A status message stays on the HUD this long [s of simulated time].
MESSAGE_SECONDS = 4.0
#: A person drives where they like: an off-road event is counted, not intervened; no lap
#: target, no time limit. A person holds no set speed, so Backspace (the runner's intervention)
#: puts the car back on the centreline at rest.
MANUAL_RULES = EpisodeRules(laps=None, set_speed_mph=0.0, off_road="continue")


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
        self.sim = None
        self._episode = None
        self._runner = None
        self.track_name = ""
        self.observation: SimObservation | None = None
        self.controls = Controls()  #: the controls applied in the latest step
        self.message = ""
        self._message_until_s = math.inf
        self._input = HumanInput(self.config)
        self._pending: tuple[str, bool] | None = None
        self._recorder = SessionRecorder(self.out_dir, self.config)
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
        return self._recorder.recording

    @property
    def rows_recorded(self) -> int:
        """Rows of the current (or latest) recording."""
        return self._recorder.rows_recorded

    @property
    def folder_rows(self) -> int:
        """Rows in the output folder's log, including this recording's."""
        return self._recorder.folder_rows

    @property
    def steering_source(self) -> str:
        """``keyboard``, ``mouse`` or ``gamepad``."""
        return self._input.source

    @property
    def pilot(self) -> Pilot | None:
        """Who drives in autonomous mode (None outside it)."""
        return self._client

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
        if not self._input.press(key):
            return  # auto-repeat
        if self.mode == MENU:
            self._menu_key(key)
            return
        if key in STEER_KEYS and self.steering_source != KEYBOARD:
            self._input.use_keyboard(self.controls.steering)  # take over where the wheel is
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
            self._input.hold(0.0, 0.0)
            self._say("back on the centreline")

    def key_up(self, key: str) -> None:
        """A key was released."""
        self._input.release(key.lower())

    def pointer(self, x: float | None) -> None:
        """The mouse pointer's horizontal position: -1 at the window's left edge, +1 at its right
        edge; None when the pointer is outside the window (steering then stays)."""
        self._input.point(x)

    def gamepad_axis(self, axis: str, value: float) -> None:
        """A gamepad axis value: ``left_x`` in [-1, 1], ``right_trigger``/``left_trigger`` in
        [0, 1]. Moving one beyond the dead zone makes the gamepad the steering source."""
        if self._input.move_axis(axis, value):
            self._say("gamepad steering")

    def release_all(self) -> None:
        """Every key, the pointer and the gamepad let go (the input window lost focus)."""
        self._input.release_all()

    def toggle_mouse_steering(self) -> None:
        if self.steering_source == MOUSE:
            self._input.use_keyboard(self.controls.steering)
            self._say("keyboard steering")
        else:
            self._input.source = MOUSE
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
        self._input.hold(0.0, 0.0)
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
        from clonedrive.manual.pilot import connect_server
        from clonedrive.udacity.client import DriveServerError

        try:
            return connect_server(self.config)
        except DriveServerError as error:
            self._say(f"autonomous mode off: {error}")
            return None

    def stop_autonomous(self, reason: str = "manual driving") -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        self._taking_over = False
        if self.mode == AUTONOMOUS:
            self.mode = DRIVING
            self._input.hold(self.controls.steering, max(self.controls.throttle, 0.0))
            self._say(reason)

    # ------------------------------------------------------------------ recording
    def start_recording(self) -> bool:
        """Start recording into ``out_dir`` (appending to a log already there)."""
        if self.sim is None or self.recording:
            return False
        recording = ManualRecording(
            track=self.track_name, reverse=self.reverse, steering_input=self.steering_source,
            scenery=self.sim_config.scenery, seed=self.config.seed, header=self.config.header,
            relative_paths=self.config.relative_paths, jpeg_quality=self.config.jpeg_quality)
        refused = self._recorder.start(recording, self.sim.track,
                                       cameras=self.sim_config.cameras,
                                       time_s=self.observation.time_s, takeovers=self.takeovers)
        if refused is not None:
            self._say(refused)
            return False
        self._say(f"recording into {self.out_dir}")
        return True

    def stop_recording(self) -> int:
        """Stop recording: every submitted row is written before this returns. Returns the rows
        this recording wrote."""
        if not self.recording:
            return 0
        rows = self._recorder.stop(self.takeovers)
        self._say(f"recorded {rows} rows into {self.out_dir}")
        return rows

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
        if self.recording and (self._taking_over or not self._labels_only()):
            failed = self._recorder.record(step.seen, controls, self.takeovers)
            if failed is not None:  # a failed write: recording stopped, driving goes on
                self._say(f"recording stopped: {failed}", forever=True)
        self.controls = controls
        self.observation = self._episode.observation
        if self.observation.time_s >= self._message_until_s:
            self.message = ""
        return self.observation

    def decide(self) -> Controls:
        """This step's controls: the person's input, or in autonomous mode the drive server's
        command unless a person takes over."""
        dt_s = 1.0 / self.sim.config.control_hz
        human = self._input.controls(dt_s, self.controls.steering)
        if self.mode == AUTONOMOUS:
            return self._server_controls(human)
        return human

    def _labels_only(self) -> bool:
        return self.mode == AUTONOMOUS and self.takeover_labels

    def _server_controls(self, human: Controls) -> Controls:
        """The drive server's command for this step, or the human's while one takes over
        (the server then gets the manual-mode telemetry, as from the Udacity simulator)."""
        from clonedrive.udacity.client import DriveServerError

        taking_over = self.takeover and self._input.active()
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
        self._input.key_steering = reply.steering  # a human taking over starts from here
        return reply.clipped()

    # ------------------------------------------------------------------ display text
    def _say(self, text: str, *, forever: bool = False) -> None:
        self.message = text
        now = self.observation.time_s if self.observation is not None else 0.0
        self._message_until_s = math.inf if forever or self.sim is None else \
            now + MESSAGE_SECONDS

    def hud(self) -> Hud:
        """The driving HUD's text (meaningful while a track is open)."""
        return driving_hud(self)

    def hud_lines(self) -> list[str]:
        hud = self.hud()
        return [line for line in (hud.status, hud.mode, hud.recording, hud.message, hud.help)
                if line]

    def menu_lines(self) -> list[str]:
        """The menu: a title, one line per track (the chosen one marked), the direction."""
        return menu_lines(self)


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
