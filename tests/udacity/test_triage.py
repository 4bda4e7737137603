"""What each received message calls for, decided from its framing alone."""

from __future__ import annotations

import pytest

from clonedrive.udacity import protocol
from clonedrive.udacity.triage import (
    ANSWER,
    CLOSE,
    IGNORE,
    MANUAL,
    PING,
    SAFE,
    TELEMETRY,
    triage,
)

LIMIT = 1000


@pytest.mark.parametrize(("message", "outcome", "frame"), [
    ("2probe", PING, "3probe"),
    ("3", ANSWER, None),
    ("40", ANSWER, protocol.CONNECT_FRAME),
    ("1", CLOSE, None),
    ("41", CLOSE, None),
    (protocol.TELEMETRY_MANUAL_FRAME, MANUAL, None),
])
def test_protocol_frames(message, outcome, frame) -> None:
    assert (triage(message, LIMIT).outcome, triage(message, LIMIT).frame) == (outcome, frame)


def test_telemetry_carries_its_payload() -> None:
    what = triage('42["telemetry",{"speed":"1"}]', LIMIT)
    assert what.outcome == TELEMETRY and what.payload == {"speed": "1"}


@pytest.mark.parametrize(("message", "outcome", "reason"), [
    (b"\x00\x01", IGNORE, "binary"),
    ("42" + "x" * LIMIT, SAFE, "oversized"),
    ("4" + "x" * LIMIT, IGNORE, "oversized"),
    ("hello", IGNORE, "garbage"),
    ("0{}", IGNORE, "garbage"),
    ("42[not json", SAFE, "not_json"),
    ('42/admin,["telemetry",{}]', IGNORE, "namespace"),
    ('42["steer",{}]', IGNORE, "unknown_event"),
])
def test_unusable_frames_are_answered_safe_or_ignored(message, outcome, reason) -> None:
    what = triage(message, LIMIT)
    assert (what.outcome, what.reason) == (outcome, reason) and what.detail
