"""What ``R`` does in a manual session: one recording's folder, lock, rows and ``config.json``.

Recording writes the Udacity format (UDACITY.md) through
:class:`~clonedrive.data.row_sink.RowSink`, as ``clonedrive record`` does: one row per control
step, each image written (atomically) before its row, appended to an existing log with image
times continuing after its last one, and a session entry in ``config.json``. A row holds the
images taken at a step, the steering and throttle applied for that step (throttle clipped to
>= 0; a negative throttle above 5 mph is recorded as brake, as it brakes), and the speed when
the images were taken. The folder is locked while a recording runs, so two sessions cannot
interleave their rows.

:class:`SessionRecorder` keeps that bookkeeping -- the sink, the lock, the session entry, the
row counts -- apart from the session's modes, which only say when a recording starts and stops.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import timedelta
from pathlib import Path
from typing import TYPE_CHECKING

from clonedrive.base.udacity_spec import JPEG_QUALITY
from clonedrive.manual.config import ManualConfig
from clonedrive.manual.human_input import KEYBOARD
from clonedrive.world.vehicle import Controls

if TYPE_CHECKING:  # the simulator loads when a track opens, not when the CLI reads defaults
    from clonedrive.sim.simulator import SimObservation
    from clonedrive.world.track import Track

#: Below this speed a negative throttle reverses instead of braking (the Udacity car).
REVERSE_BELOW_MPH = 5.0


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


class SessionRecorder:
    """Records a session's steps into ``out_dir``, one recording at a time."""

    def __init__(self, out_dir: Path, config: ManualConfig) -> None:
        self.out_dir = out_dir
        self.config = config
        self.rows_recorded = 0  #: rows of the current (or latest) recording
        self.folder_rows = 0  #: rows in the output folder's log, including this recording's
        self._sink = None
        self._lock = None  # the recording folder's lock while recording
        self._session: dict | None = None
        self._takeovers_before = 0
        self._recording: ManualRecording | None = None
        self._track: Track | None = None

    @property
    def recording(self) -> bool:
        return self._sink is not None

    def start(self, recording: ManualRecording, track: Track, *, cameras: tuple[str, ...],
              time_s: float, takeovers: int) -> str | None:
        """Start recording ``track`` (the simulator's time now: ``time_s``; the session's
        takeovers so far: ``takeovers``). Returns why it cannot start, else None."""
        from clonedrive.data.driving_log import CAMERAS
        from clonedrive.data.recording_lock import RecordingLock, RecordingLockedError

        missing = [camera for camera in CAMERAS if camera not in cameras]
        if missing:
            return f"cannot record: no {', '.join(missing)} camera"
        lock = RecordingLock(self.out_dir)
        try:
            lock.acquire()
        except (RecordingLockedError, ValueError, OSError) as error:
            return f"cannot record: {error}"
        try:
            self._open_sink(recording, track, time_s)
        except BaseException:
            lock.release()
            raise
        self._lock = lock
        self._takeovers_before = takeovers
        return None

    def _open_sink(self, recording: ManualRecording, track: Track, time_s: float) -> None:
        """Start this recording's session in ``out_dir`` (its lock held) and open the sink."""
        from clonedrive import __version__
        from clonedrive.base.config import config_to_dict
        from clonedrive.data.log_folder import prepare_log_folder, write_session_config
        from clonedrive.data.row_sink import RowSink

        existing_rows, start = prepare_log_folder(self.out_dir)
        # Image names are start + simulated time: the first row's image is named ``start``.
        elapsed = timedelta(seconds=time_s)
        session = {"started": start.isoformat(timespec="milliseconds"), "rows": None,
                   **config_to_dict(recording)}
        write_session_config(self.out_dir, recording, track, __version__, session)
        config = self.config
        self._sink = RowSink(self.out_dir, start - elapsed, header=config.header,
                             relative_paths=config.relative_paths,
                             jpeg_quality=config.jpeg_quality)
        self._session = session
        self._recording = recording
        self._track = track
        self.rows_recorded = 0
        self.folder_rows = existing_rows

    def stop(self, takeovers: int) -> int:
        """Stop recording: every submitted row is written, and the session entry completed
        (rows, the takeovers since the start), before this returns. Returns the rows this
        recording wrote (0 when none was running)."""
        from clonedrive import __version__
        from clonedrive.data.log_folder import write_session_config

        if self._sink is None:
            return 0
        sink, self._sink = self._sink, None
        try:
            sink.close()
        finally:
            self._session["rows"] = sink.rows_written
            self._session["takeovers"] = takeovers - self._takeovers_before
            try:
                write_session_config(self.out_dir, self._recording, self._track, __version__,
                                     self._session)
            finally:
                lock, self._lock = self._lock, None
                if lock is not None:
                    lock.release()
        self.rows_recorded = sink.rows_written
        return sink.rows_written

    def record(self, obs: SimObservation, controls: Controls, takeovers: int) -> str | None:
        """Submit one step's row. A failed write stops the recording (driving goes on): returns
        what failed, else None."""
        try:
            self._sink.submit(obs, controls.steering, recorded_controls(controls, obs.speed_mph))
        except RuntimeError as error:
            try:
                self.stop(takeovers)
            except RuntimeError:
                pass  # the same error, raised again by the sink's close
            return str(error)
        self.rows_recorded += 1
        self.folder_rows += 1
        return None


def recorded_controls(controls: Controls, speed_mph: float) -> Controls:
    """The controls as a log row reports them: a negative throttle brakes above 5 mph."""
    brake = controls.brake
    if controls.throttle < 0 and speed_mph > REVERSE_BELOW_MPH:
        brake = max(brake, -controls.throttle)
    return replace(controls, throttle=max(controls.throttle, 0.0), brake=brake)
