"""A real ``clonedrive`` process, started from a small launcher that reports the command's
own peak memory (a child forked from the test process would count the test's pages as its
own until it execs)."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass

_LAUNCHER = ("import resource, subprocess, sys\n"
             "status = subprocess.run(sys.argv[1:]).returncode\n"
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr)\n"
             "sys.exit(status)\n")


@dataclass(frozen=True)
class Finished:
    """What a measured command left: exit status, its stderr, its peak memory [MB]."""

    rc: int
    stderr: str
    peak_rss_mb: float


def run_measured(*argv: object) -> Finished:
    """Run ``clonedrive ARGV`` (this interpreter, this ``sys.path``) and wait for it."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    command = [sys.executable, "-c", _LAUNCHER, sys.executable, "-m", "clonedrive.cli",
               *map(str, argv)]
    process = subprocess.run(command, env=env, capture_output=True, text=True)
    *lines, peak_kib = process.stderr.strip().splitlines()
    return Finished(process.returncode, "\n".join(lines), int(peak_kib) / 1024)
