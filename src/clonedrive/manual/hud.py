"""The text a manual session shows: the driving HUD and the track menu.

Both the Panda3D window (:mod:`clonedrive.manual.window`) and the browser page
(:mod:`clonedrive.web`) draw these lines as they are, so what a person reads while driving is
written once, here, from the session's state, and tested without a display.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

HELP_DRIVING = ("W/S: throttle/brake  A/D: steer (or arrows)  M: mouse steering  Space: brake  "
                "R: record  P: autonomous  Backspace: reset  Esc: menu")
HELP_MENU = ("Up/Down: track  Left/Right: direction  G: another generated track  "
             "Enter: drive  Esc: quit")


@dataclass(frozen=True)
class MenuItem:
    label: str
    track: str  #: a name for load_track


class SessionState(Protocol):
    """What the text is made from: the state a :class:`~clonedrive.manual.session.DrivingSession`
    keeps (named here, so that this module needs nothing from the session's)."""

    observation: Any  #: the car's SimObservation, None with no track open
    controls: Any  #: the controls applied last
    message: str
    reverse: bool
    track_name: str
    pilot: Any  #: the autonomous pilot (with a ``name``), None when a person drives
    steering_source: str
    taking_over: bool
    takeover: bool
    takeovers: int
    recording: bool
    rows_recorded: int
    folder_rows: int
    out_dir: Path
    menu_items: Sequence[MenuItem]
    menu_index: int


@dataclass(frozen=True)
class Hud:
    """The text the window shows while driving."""

    status: str  #: track, speed, steering, throttle, CTE, laps
    mode: str  #: who drives and with what
    recording: str  #: recording state and row counts
    message: str  #: the latest status message ('' when none)
    help: str


def driving_hud(session: SessionState) -> Hud:
    """The driving HUD's text (meaningful while a track is open)."""
    obs = session.observation
    if obs is None:
        return Hud(status="", mode="", recording="", message=session.message, help=HELP_MENU)
    controls = session.controls
    direction = " (reverse)" if session.reverse else ""
    status = (f"{session.track_name}{direction}   {obs.speed_mph:5.1f} mph   "
              f"steering {controls.steering:+.2f}   throttle {controls.throttle:+.2f}"
              f"{'  brake' if controls.brake > 0 else ''}   CTE {obs.cte_m:+.2f} m   "
              f"laps {obs.laps}   off-road {obs.off_road_events}"
              f"{'   OFF ROAD' if obs.off_road else ''}")
    return Hud(status=status, mode=_mode_line(session), recording=_recording_line(session),
               message=session.message, help=HELP_DRIVING)


def _mode_line(session: SessionState) -> str:
    if session.pilot is None:
        return f"MANUAL: {session.steering_source} steering"
    who = "manual override" if session.taking_over else "the pilot drives"
    takeovers = f"   takeovers {session.takeovers}" if session.takeover else ""
    return f"AUTONOMOUS ({session.pilot.name}): {who}{takeovers}"


def _recording_line(session: SessionState) -> str:
    if session.recording:
        return (f"REC  {session.rows_recorded} rows  ({session.folder_rows} in "
                f"{session.out_dir.name}/)")
    return f"not recording: R records into {session.out_dir}"


def menu_lines(session: SessionState) -> list[str]:
    """The menu: a title, one line per track (the chosen one marked), the direction."""
    lines = ["clonedrive: choose a track", ""]
    for index, item in enumerate(session.menu_items):
        marker = ">" if index == session.menu_index else " "
        lines.append(f"{marker} {index + 1}  {item.label}")
    lines += ["", f"direction: {'reverse' if session.reverse else 'forward'}",
              f"recordings go to {session.out_dir}"]
    if session.message:
        lines += ["", session.message]
    return lines
