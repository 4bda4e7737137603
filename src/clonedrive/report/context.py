"""What every section of the write-up shares: where the run's pieces are, the files read once
(training config, dataset report, eval.json), the notes on what was missing, and the small
helpers for reading pictures and copying figures.

The sections (``clonedrive.report.sections.*``) each take a :class:`ReportContext` and return
their :class:`~clonedrive.report.document.Section` s; ``clonedrive.report.writeup`` puts them
together.
"""

from __future__ import annotations

import logging
import os
import shutil
import stat
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.base.config import atomic_path
from clonedrive.base.config import read_json as read_json_file
from clonedrive.base.images import ImageDecodeError, read_rgb
from clonedrive.base.paths import safe_stem
from clonedrive.model.history import HISTORY_NAME
from clonedrive.report.document import Note, Section

logger = logging.getLogger("clonedrive.report.writeup")

#: Errors that turn a section into a note instead of stopping the report: unreadable or
#: malformed files (OSError, ValueError incl. JSON and TOML errors), missing or mistyped keys.
SECTION_ERRORS = (OSError, ValueError, KeyError, TypeError, IndexError)

#: The sections' titles; the write-up numbers the sections it holds in order.
SECTION_TITLES = {
    "data": "Data",
    "balance": "Balancing the steering",
    "network": "The network",
    "training": "Training",
    "results": "Closed-loop results",
    "expert": "Against the expert",
    "saliency": "Where the network looks",
    "timings": "Run timings",
}
#: Sections only in the report when asked for (``report --real-log``) or when the run has
#: them (``dagger.json``, ``bench.json``).
OPTIONAL_SECTION_TITLES = {"realdata": "Real Udacity frames (open and closed loop)",
                           "dagger": "DAgger", "bench": "Benchmark"}


@dataclass(frozen=True)
class ReportConfig:
    """What ``clonedrive report`` puts in."""

    max_failures: int = 12  #: off-road events shown with their frames
    stills_per_video: int = 3  #: frames taken from each evaluation video
    seed: int = 0  #: the random augmentation example's generator seed
    #: recorded Udacity logs to check the model on, open loop (report --real-log)
    real_logs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.max_failures < 0:
            raise ValueError(f"max_failures must be >= 0, got {self.max_failures}")
        if self.stills_per_video < 1:
            raise ValueError(f"stills_per_video must be >= 1, got {self.stills_per_video}")


@dataclass(frozen=True)
class RunParts:
    """Where the pieces of a run are (None / empty when absent)."""

    run_dir: Path
    recordings: tuple[Path, ...]  # folders holding driving_log.csv under RUN_DIR/data
    train_dir: Path | None
    eval_dir: Path | None
    demo_json: Path | None


def find_run_parts(run_dir: str | os.PathLike) -> RunParts:
    """Locate the recordings, training and evaluation folders of ``run_dir`` (see
    :mod:`clonedrive.report.writeup`)."""
    run = Path(run_dir)
    if not run.is_dir():
        raise FileNotFoundError(f"run folder {run} does not exist")
    data = run / "data"
    recordings: list[Path] = []
    if (data / "driving_log.csv").is_file():
        recordings.append(data)
    if data.is_dir():
        recordings += sorted(p for p in data.iterdir() if (p / "driving_log.csv").is_file())
    train_dir = next((d for d in (run / "train", run) if (d / "model.keras").is_file()
                      or (d / HISTORY_NAME).is_file()), None)
    eval_candidates = [run / "eval"] + ([train_dir / "eval"] if train_dir else []) + [run]
    eval_dir = next((d for d in eval_candidates if (d / "eval.json").is_file()), None)
    demo = run / "demo.json"
    return RunParts(run_dir=run, recordings=tuple(recordings), train_dir=train_dir,
                    eval_dir=eval_dir, demo_json=demo if demo.is_file() else None)


class ReportContext:
    """The run's shared inputs, read once, and what the sections found missing."""

    def __init__(self, parts: RunParts, figures_dir: Path, config: ReportConfig) -> None:
        self.parts = parts
        self.figures_dir = figures_dir
        self.config = config
        self.notes: list[str] = []
        self.left_out: list[tuple[str, str]] = []  # (section title, why), sections not shown
        self.facts: dict = {}  # headline figures gathered on the way, for the intro
        self.unreadable: dict[str, str] = {}  # file name -> why it could not be read
        train = parts.train_dir
        self.train_config = (read_json_or_none(train / "config.json", self.unreadable)
                             if train else None)
        self.dataset = (read_json_or_none(train / "dataset.json", self.unreadable)
                        if train else None)
        self.eval = (read_json_or_none(parts.eval_dir / "eval.json", self.unreadable)
                     if parts.eval_dir else None)
        demo = (read_json_or_none(parts.demo_json, self.unreadable)
                if parts.demo_json else None)
        demo_config = demo.get("config") if isinstance(demo, dict) else None
        #: The run is ``clonedrive demo --quick``'s: every stage small, no measure of driving.
        self.quick = isinstance(demo_config, dict) and demo_config.get("quick") is True

    def note(self, text: str) -> Note:
        """A one-line note in the report, also kept in :attr:`notes`."""
        self.notes.append(text)
        return Note(text)

    def guarded(self, title: str, build: Callable[[ReportContext], list[Section]]
                ) -> list[Section]:
        """The sections ``build(self)`` makes, or the heading with a note if it failed on bad
        input."""
        try:
            return build(self)
        except SECTION_ERRORS as error:
            logger.warning("report section %r skipped: %s", title, error)
            return [Section(title, blocks=[self.note(
                f"This section could not be generated: {type(error).__name__}: {error}")])]

    def missing(self, title: str, text: str) -> list[Section]:
        """No section: its inputs are missing. The report's introduction says which sections
        it left out and why (``text``, also kept in :attr:`notes`)."""
        self.notes.append(text)
        self.left_out.append((title, text))
        return []

    def run_file(self, folder: Path, name: object) -> Path | None:
        """``folder / name`` (``folder``: the run folder or one inside it, ``name`` as a run's
        file names it) if it is a regular file inside the run folder, reached without a link;
        None if it is missing, and None with a note naming it (kept in :attr:`notes`) if it is
        an absolute path, leads out with ``..``, is or passes through a symbolic link, or is
        not a regular file: a shared run folder must not make a report carry files from
        elsewhere."""
        problem = _outside_problem(self.parts.run_dir, folder, name)
        if problem is not None:
            text = f"Refused to embed `{name}` named in `{folder}`: {problem}."
            if text not in self.notes:
                self.notes.append(text)
                logger.warning("%s", text)
            return None
        path = folder / str(name)
        return path if path.is_file() else None

    def headline(self, text: str) -> None:
        """One line for the report's "In short" list (in the order the sections run)."""
        self.facts.setdefault("headline", []).append(text)


def _outside_problem(run_dir: Path, folder: Path, name: object) -> str | None:
    """Why ``folder / name`` may not be embedded (see :meth:`ReportContext.run_file`), or
    None."""
    if not isinstance(name, str) or not name or "\0" in name:
        return "not a file name"
    relative_name = Path(name)
    if relative_name.is_absolute() or name.startswith(("/", "\\")):
        return "an absolute path"
    if ".." in relative_name.parts or ".." in Path(name.replace("\\", "/")).parts:
        return "it leads out of the run folder (`..`)"
    try:
        inside = (folder / relative_name).relative_to(run_dir)
    except ValueError:
        return "it is outside the run folder"
    path = run_dir
    for part in inside.parts:
        path = path / part
        try:
            mode = path.lstat().st_mode
        except OSError:
            return None  # missing: not embedded, and nothing to refuse
        if stat.S_ISLNK(mode):
            return f"`{path}` is a symbolic link"
    return None if stat.S_ISREG(mode) else "not a regular file"


def read_json(path: Path) -> dict:
    """The JSON object in ``path`` (read by :func:`clonedrive.base.config.read_json`: bounded, one
    line naming the file for anything unreadable); ``ValueError`` if it holds something else."""
    data = read_json_file(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return data


def read_json_or_none(path: Path, errors: dict[str, str] | None = None) -> dict | None:
    """The object in ``path``, or None if there is none or it is unreadable (logged, and the
    reason put into ``errors[path.name]``)."""
    if not path.is_file():
        return None
    try:
        return read_json(path)
    except (OSError, ValueError) as error:
        logger.warning("ignoring %s: %s", path, error)
        if errors is not None:
            errors[path.name] = f"`{path}` is unreadable ({error})"
        return None


def read_image_or_none(path: str | os.PathLike) -> np.ndarray | None:
    """A picture file as uint8 RGB (:func:`clonedrive.base.images.read_rgb`), or None if it is
    missing or does not decode (the section then says so)."""
    try:
        return read_rgb(path)
    except ImageDecodeError:
        return None


def copy_figure(source: Path, figures_dir: Path, name: str) -> Path:
    """Copy a picture a stage made into the report's figures (atomically)."""
    target = figures_dir / name
    with atomic_path(target) as temporary:
        shutil.copyfile(source, temporary)
    return target


def figure_name(stem: str, prefix: str) -> str:
    """``<prefix>_<stem>.png``, with ``stem`` (from a run's or track's name) made safe."""
    return f"{prefix}_{safe_stem(stem)}.png"
