"""What a page may send, parsed and checked: JSON text messages become :class:`Command` values.

Every message is one JSON object with a ``type`` and an optional ``seq`` (an integer the page
counts up; each frame reports the last one applied before it, which is how the page measures
its input-to-frame latency)::

    {"type": "key", "key": "w", "down": true}        a driving key (Panda3D name) down or up
    {"type": "pointer", "x": 0.25}                    mouse/touch steering, -1..1 (null: let go)
    {"type": "axis", "axis": "left_x", "value": 0.3}  a gamepad axis
    {"type": "release"}                               every key and axis let go (page hidden)
    {"type": "mode", "mode": "takeover"}              manual | expert | model | takeover
    {"type": "track", "track": "lake", "reverse": false}
    {"type": "look", "look": "udacity"}               a recording look (sim/conditions.py)
    {"type": "view", "view": "three"}                 center | three
    {"type": "record", "on": true}
    {"type": "reset"}                                 put the car back on the road

Anything else raises :class:`MessageError` naming what is wrong; the server answers it with an
error message and keeps serving.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from clonedrive.manual.human_input import DRIVING_KEYS, GAMEPAD_AXES
from clonedrive.web.config import MODES, VIEWS, finite

#: Keys a page may press: the driving keys and M (mouse steering). Modes, recording and
#: put-back have messages of their own; Esc and P (the window's menu and drive server) do not
#: apply to the page.
PAGE_KEYS = DRIVING_KEYS | {"m"}
#: The longest track name accepted (a path or gen:<seed> is far shorter).
MAX_NAME = 200

_FIELDS = {
    "key": ("key", "down"), "pointer": ("x",), "axis": ("axis", "value"), "release": (),
    "mode": ("mode",), "track": ("track", "reverse"), "look": ("look",), "view": ("view",),
    "record": ("on",), "reset": (),
}


class MessageError(ValueError):
    """A message the page should not have sent; the text says what is wrong."""


@dataclass(frozen=True)
class Command:
    """One checked input: ``kind`` is the message type, ``value`` its main field, ``flag`` its
    boolean (key down, reverse, record on), ``seq`` the page's counter (0 when absent)."""

    kind: str
    value: object = None
    flag: bool = False
    seq: int = 0


def parse(text: str | bytes) -> Command:
    """The command a page's message holds, or :class:`MessageError`."""
    if isinstance(text, bytes):
        raise MessageError("binary messages are not accepted: send JSON text")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise MessageError(f"not JSON: {error}") from None
    if not isinstance(data, dict):
        raise MessageError(f"expected a JSON object, got {type(data).__name__}")
    kind = data.get("type")
    if kind not in _FIELDS:
        raise MessageError(f"unknown type {str(kind)[:40]!r}; expected one of "
                           f"{', '.join(_FIELDS)}")
    unknown = set(data) - {"type", "seq", *_FIELDS[kind]}
    if unknown:
        raise MessageError(f"{kind}: unknown field(s) {', '.join(sorted(map(str, unknown)))[:80]}")
    seq = data.get("seq", 0)
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 2**53:
        raise MessageError("seq must be a non-negative integer")
    return _PARSERS[kind](data, seq)


def _flag(data: dict, name: str, default: bool | None = None) -> bool:
    value = data.get(name, default)
    if not isinstance(value, bool):
        raise MessageError(f"{data['type']}: {name} must be true or false")
    return value


def _choice(data: dict, name: str, choices) -> str:
    value = data.get(name)
    if not isinstance(value, str) or value not in choices:
        raise MessageError(f"{data['type']}: {name} must be one of {', '.join(sorted(choices))}")
    return value


def _key(data: dict, seq: int) -> Command:
    key = data.get("key")
    if not isinstance(key, str) or key.lower() not in PAGE_KEYS:
        raise MessageError(f"key: {str(key)[:20]!r} is not a driving key "
                           f"({', '.join(sorted(PAGE_KEYS))})")
    return Command("key", key.lower(), _flag(data, "down"), seq)


def _pointer(data: dict, seq: int) -> Command:
    x = data.get("x")
    if x is not None and finite(x) is None:
        raise MessageError("pointer: x must be a number in [-1, 1] or null")
    return Command("pointer", None if x is None else min(max(float(x), -1.0), 1.0), seq=seq)


def _axis(data: dict, seq: int) -> Command:
    axis = _choice(data, "axis", GAMEPAD_AXES)
    value = finite(data.get("value"))
    if value is None or not -1.0 <= value <= 1.0:
        raise MessageError("axis: value must be a number in [-1, 1]")
    return Command("axis", (axis, value), seq=seq)


def _track(data: dict, seq: int) -> Command:
    track = data.get("track")
    if not isinstance(track, str) or not 0 < len(track) <= MAX_NAME:
        raise MessageError(f"track: give a track name (at most {MAX_NAME} characters)")
    return Command("track", track, _flag(data, "reverse", False), seq)


def _look(data: dict, seq: int) -> Command:
    from clonedrive.sim.conditions import TRAINING_LOOKS

    return Command("look", _choice(data, "look", TRAINING_LOOKS), seq=seq)


_PARSERS = {
    "key": _key,
    "pointer": _pointer,
    "axis": _axis,
    "release": lambda data, seq: Command("release", seq=seq),
    "mode": lambda data, seq: Command("mode", _choice(data, "mode", MODES), seq=seq),
    "track": _track,
    "look": _look,
    "view": lambda data, seq: Command("view", _choice(data, "view", VIEWS), seq=seq),
    "record": lambda data, seq: Command("record", flag=_flag(data, "on"), seq=seq),
    "reset": lambda data, seq: Command("reset", seq=seq),
}
