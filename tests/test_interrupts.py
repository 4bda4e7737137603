"""No SIGTERM or Ctrl-C is lost: one raised inside a destructor (where Python only prints
and drops exceptions) is raised again, and a lost SIGTERM is raised at the next safe point."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from clonedrive.base.interrupts import Terminated, interruptible, raise_if_lost

WAIT_S = 180.0  # the longest the test waits for the child (not a timing)

SWALLOWING_DESTRUCTOR = """
import signal, sys, time
from clonedrive.base.interrupts import Terminated, interruptible

class SignalledWhileCollected:
    def __del__(self):
        signal.raise_signal(signal.{name})  # its exception is raised here, and dropped

with interruptible():
    try:
        SignalledWhileCollected()
        print("destructor ran", flush=True)
        time.sleep(600)
        print("the interruption was lost")
    except Terminated:
        print("terminated")
    except KeyboardInterrupt:
        print("interrupted")
"""


@pytest.mark.parametrize(("name", "expected"), [("SIGTERM", "terminated"),
                                                ("SIGINT", "interrupted")])
def test_an_interruption_raised_in_a_destructor_is_raised_again(name: str, expected: str) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, "-c", SWALLOWING_DESTRUCTOR.format(name=name)],
                          env=env, capture_output=True, text=True, timeout=WAIT_S)
    assert done.stdout.splitlines() == ["destructor ran", expected], done.stderr
    assert done.returncode == 0
    assert "Exception ignored" not in done.stderr  # redelivered, not printed


def test_a_swallowed_sigterm_is_raised_at_the_next_safe_point() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with interruptible():
        raise_if_lost()  # nothing requested: nothing raised
        try:
            signal.raise_signal(signal.SIGTERM)
        except Terminated:
            pass  # as a destructor or a careless library would
        with pytest.raises(Terminated):
            raise_if_lost()
    raise_if_lost()  # outside, the request is forgotten
    assert signal.getsignal(signal.SIGTERM) is before


def test_interruptible_restores_the_handler_and_hook() -> None:
    handler, hook = signal.getsignal(signal.SIGTERM), sys.unraisablehook
    with interruptible():
        assert signal.getsignal(signal.SIGTERM) is not handler
        assert sys.unraisablehook is not hook
    assert signal.getsignal(signal.SIGTERM) is handler
    assert sys.unraisablehook is hook


def test_a_sigterm_in_a_deferred_block_is_raised_when_it_ends() -> None:
    from clonedrive.base.interrupts import deferred_termination

    finished = False
    with interruptible():
        with pytest.raises(Terminated):
            with deferred_termination():
                signal.raise_signal(signal.SIGTERM)  # waits ...
                finished = True  # ... so this still runs
        assert finished
        with deferred_termination():
            pass  # nothing pending: nothing raised
