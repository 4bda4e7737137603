"""Counts on the command line, each with a stated maximum, refused while the command line is
parsed (exit 2, argparse's message naming the option and the limit) -- before a list of runs,
a batch or a frame buffer is sized from them. ``evaluate --unseen 1000000000`` once tried to
build a billion runs; every verb's counts are held to the same kind of limit here.

The maxima are defined once: evaluate's in :data:`clonedrive.evaluate.config.MAX_COUNTS`
(shared by the verbs that drive the same runs), training's in
:data:`clonedrive.model.train.MAX_COUNTS` (a recipe file sets them too), the others below.
Lower bounds (at least 1, odd, ...) stay with each stage's config, which states them.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from clonedrive.base.udacity_spec import IMAGE_HEIGHT
from clonedrive.data.line_count import MAX_LOG_ROWS
from clonedrive.evaluate.config import MAX_COUNTS as EVALUATE_MAX
from clonedrive.evaluate.video import FPS_RANGE
from clonedrive.model.train_config import MAX_COUNTS as TRAIN_MAX
from clonedrive.world.vehicle import check_set_speed

#: Laps of one run (record, autonomous, dagger's recording and evaluation laps).
MAX_LAPS = EVALUATE_MAX["laps"]
#: Generated tracks never used in recording (demo, dagger).
MAX_UNSEEN = EVALUATE_MAX["unseen"]
#: Worker processes or threads.
MAX_WORKERS = EVALUATE_MAX["workers"]
#: Runs driven in lock-step.
MAX_RUN_BATCH = EVALUATE_MAX["batch"]
#: Training epochs (train's, also dagger's and demo's).
MAX_EPOCHS = TRAIN_MAX["epochs"]
#: Epochs without a best before training stops early.
MAX_PATIENCE = TRAIN_MAX["early_stopping_patience"]
#: Frames per training batch.
MAX_BATCH_SIZE = TRAIN_MAX["batch_size"]
#: Threads that feed training batches.
MAX_TRAIN_WORKERS = TRAIN_MAX["workers"]
#: Training stages of a recipe that ``train --stages`` keeps (a recipe has a handful).
MAX_STAGES = 100
#: DAgger iterations (each records, trains and evaluates).
MAX_ITERATIONS = 1_000
#: Off-road events before a recording stops.
MAX_OFF_ROAD_EVENTS = 10_000
#: Simulator steps of a scripted ``sim`` session (one per frame: 4.6 hours at 60 Hz).
MAX_STEPS = 1_000_000
#: Off-road events shown in a report; frames of a moving average (crosscheck).
MAX_SHOWN = 10_000
#: Rows crosscheck predicts: as many as a driving log may hold.
MAX_ROWS = MAX_LOG_ROWS
#: Clients a drive server serves at once.
MAX_CONNECTIONS = 1_024
#: Rows cut from the top of a camera image: fewer than the image has.
MAX_CROP_TOP_PX = IMAGE_HEIGHT - 1
#: Frames per second of a video (the writer's own range, evaluate.video.FPS_RANGE).
MAX_FPS = FPS_RANGE[1]


def count(most: int) -> Callable[[str], int]:
    """An argparse ``type``: a whole number, refused above ``most``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value > most:
            raise argparse.ArgumentTypeError(f"must be at most {most:,}, got {value:,}")
        return value

    parse.most = most  # --help states it (cli._HelpFormatter)
    return parse


def speed_flag_error(args: argparse.Namespace, *flags: str) -> str | None:
    """The first of ``flags`` (``--speed``; a repeatable one's every value) whose set speed is
    not in (0, the car's top speed], as one line naming the flag; None if all are. A config
    would refuse the same value naming its field, which is not what the user typed."""
    for flag in flags:
        value = getattr(args, flag.lstrip("-").replace("-", "_"), None)
        for speed in value if isinstance(value, list | tuple) else [value]:
            if speed is None:
                continue
            try:
                check_set_speed(speed, flag)
            except ValueError as error:
                return str(error)
    return None


def rate(most: float) -> Callable[[str], float]:
    """An argparse ``type``: a finite number, refused above ``most``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value) or value > most:
            raise argparse.ArgumentTypeError(f"must be at most {most:g}, got {text}")
        return value

    parse.most = most
    return parse
