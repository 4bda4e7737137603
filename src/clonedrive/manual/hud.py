"""The text a manual session shows: the driving HUD and the track menu.

Both the Panda3D window (:mod:`clonedrive.manual.window`) and the browser page
(:mod:`clonedrive.web`) draw these lines as they are, so what a person reads while driving is
written once, here, from the session's state, and tested without a display.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from clonedrive.manual.session import DrivingSession

HELP_DRIVING = ("W/S: throttle/brake  A/D: steer (or arrows)  M: mouse steering  Space: brake  "
                "R: record  P: autonomous  Backspace: reset  Esc: menu")
HELP_MENU = ("Up/Down: track  Left/Right: direction  G: another generated track  "
             "Enter: drive  Esc: quit")


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


def driving_hud(session: DrivingSession) -> Hud:
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


def _mode_line(session: DrivingSession) -> str:
    if session.pilot is None:
        return f"MANUAL: {session.steering_source} steering"
    who = "manual override" if session.taking_over else "the pilot drives"
    takeovers = f"   takeovers {session.takeovers}" if session.takeover else ""
    return f"AUTONOMOUS ({session.pilot.name}): {who}{takeovers}"


def _recording_line(session: DrivingSession) -> str:
    if session.recording:
        return (f"REC  {session.rows_recorded} rows  ({session.folder_rows} in "
                f"{session.out_dir.name}/)")
    return f"not recording: R records into {session.out_dir}"


def menu_lines(session: DrivingSession) -> list[str]:
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
