"""Run ``clonedrive`` as a real process, as a user would, and read what it said."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"
#: Longest a probed command may run [s]; the probes themselves take seconds.
PROCESS_TIMEOUT_S = 300


def run_clonedrive(*argv: object, cwd: Path | None = None,
                   stdin: str | None = None) -> subprocess.CompletedProcess:
    """``python -m clonedrive.cli ARGV`` with this tree's sources first on the path."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SRC), *sys.path]))
    return subprocess.run([sys.executable, "-m", "clonedrive.cli", *map(str, argv)],
                          env=env, cwd=cwd, capture_output=True, text=True, input=stdin,
                          timeout=PROCESS_TIMEOUT_S)


def refused(result: subprocess.CompletedProcess, verb: str, status: int) -> str:
    """The one-line error of a refused command, after checking its status and that it printed
    ``clonedrive VERB: ...`` and no traceback."""
    assert result.returncode == status, (result.returncode, result.stderr[-2000:])
    assert "Traceback" not in result.stderr, result.stderr[-2000:]
    lines = [line for line in result.stderr.splitlines() if line.startswith(f"clonedrive {verb}")]
    assert lines, result.stderr[-2000:]
    return lines[-1]
