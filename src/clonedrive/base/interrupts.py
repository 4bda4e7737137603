"""SIGTERM handled as Ctrl-C is, and no interruption lost on the way.

``clonedrive`` runs every verb inside :func:`interruptible`: SIGTERM raises
:class:`Terminated` (a ``KeyboardInterrupt``, so everything that cleans up after Ctrl-C
cleans up after it too) and the command ends with status 128 + 15.

Python runs a signal handler wherever the main thread happens to be. An exception raised
inside a destructor or a weakref callback is only printed ("Exception ignored in ...") and
dropped, so a SIGTERM or Ctrl-C arriving there would be lost and a long command would run
on. Two guards keep it:

- an unraisable-exception hook sends the same signal to the main thread again a moment
  later, from another thread, once it is out of the destructor;
- long loops call :func:`raise_if_lost` at safe points (training does after every batch):
  a SIGTERM requested and still not ended is raised there.

Work that must not be cut in half (starting a worker process: a child whose start-up data
stops halfway prints a traceback of its own) runs inside :func:`deferred_termination`: a
SIGTERM arriving there is raised when the block ends.
"""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager

REDELIVER_AFTER_S = 0.05  # how soon a swallowed interruption is raised again

_state = {"terminate_requested": False, "deferring": 0, "deferred": False}


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: handled as Ctrl-C is (what is written stays written, worker processes
    stop, temporary files go), with exit status 128 + 15."""


def _raise_terminated(signum: int, frame: object) -> None:
    _state["terminate_requested"] = True
    if _state["deferring"]:
        _state["deferred"] = True
        return
    raise Terminated


@contextmanager
def deferred_termination():
    """Within: a SIGTERM waits; it is raised as :class:`Terminated` when the block ends
    (outside :func:`interruptible` nothing changes: SIGTERM keeps its own handler)."""
    _state["deferring"] += 1
    try:
        yield
    finally:
        _state["deferring"] -= 1
    if not _state["deferring"] and _state["deferred"]:
        _state["deferred"] = False
        raise Terminated


def _redelivering_hook(previous_hook):
    """An unraisable-exception hook that raises a swallowed interruption again (see the
    module's docstring); other exceptions go to ``previous_hook``."""
    main_thread = threading.main_thread().ident

    def hook(unraisable) -> None:
        kind = unraisable.exc_type
        if kind is None or not issubclass(kind, KeyboardInterrupt):
            previous_hook(unraisable)
            return
        signum = signal.SIGTERM if issubclass(kind, Terminated) else signal.SIGINT
        timer = threading.Timer(REDELIVER_AFTER_S, signal.pthread_kill, (main_thread, signum))
        timer.daemon = True
        timer.start()

    return hook


@contextmanager
def interruptible():
    """Within: SIGTERM raises :class:`Terminated` in the main thread, and a SIGTERM or Ctrl-C
    swallowed by a destructor is raised again. Both as before afterwards. Does nothing
    outside the main thread, where signal handlers cannot be set."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous_handler = signal.signal(signal.SIGTERM, _raise_terminated)
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _redelivering_hook(previous_hook)
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        signal.signal(signal.SIGTERM, previous_handler)
        _state.update(terminate_requested=False, deferred=False)


def raise_if_lost() -> None:
    """Raise :class:`Terminated` if a SIGTERM arrived (inside :func:`interruptible`) and the
    program is still running normal code: its exception was swallowed on the way. For safe
    points of long loops, never for cleanup code."""
    if _state["terminate_requested"]:
        raise Terminated
