"""The generated write-up: ``report.md`` + a self-contained ``report.html`` from a run folder.

``write_report(run_dir, out_dir)`` reads what the stages wrote and describes it the way the
Udacity Behavioral Cloning write-up does (data, balancing, network, training, closed-loop
results), with figures made from the run. It finds, each optional:

- recordings: folders under ``RUN_DIR/data/`` holding ``driving_log.csv`` (and the recordings
  the training recipe names), each with the recorder's ``config.json`` if there is one;
- the training folder: ``RUN_DIR/train/``, or ``RUN_DIR`` itself if it holds ``model.keras``
  (``model.keras``, ``history.csv``, ``loss.png``, ``config.json``, ``recipe.toml``,
  ``dataset.json``, ``steering_before.png`` / ``steering_after.png``; see ``model.train``);
- the evaluation folder: ``RUN_DIR/eval/``, ``<training folder>/eval/`` or ``RUN_DIR`` itself,
  holding ``eval.json`` (see ``evaluate.rollout``) with its maps, off-road frames and videos;
- ``RUN_DIR/demo.json``: stage timings, ``{"stages": {"record": 12.5, ...}}`` or
  ``{"stages": [{"name": "record", "seconds": 12.5}, ...]}`` (``timings`` / ``timings_s``
  are read too).

A section whose inputs are missing (or unreadable) keeps its heading and says why in one line;
the report is written whatever the run holds. Figures go to ``OUT/report/*.png``, which
``report.md`` links; ``report.html`` embeds them as ``data:`` URIs and references no file.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from clonedrive.config import atomic_path, write_text_atomic
from clonedrive.report.document import (
    Bullets,
    Document,
    Figure,
    Gallery,
    Note,
    Paragraph,
    Section,
    Table,
    to_html,
    to_markdown,
)
from clonedrive.udacity_spec import CONTROL_HZ

logger = logging.getLogger(__name__)

MARKDOWN_NAME = "report.md"
HTML_NAME = "report.html"
FIGURES_DIR = "report"
#: Errors that turn a section into a note instead of stopping the report: unreadable or
#: malformed files (OSError, ValueError incl. JSON and TOML errors), missing or mistyped keys.
SECTION_ERRORS = (OSError, ValueError, KeyError, TypeError, IndexError)
#: |curvature| below this [1/m] (radius above 400 m) counts as a straight.
STRAIGHT_CURVATURE = 1.0 / 400.0

SECTION_TITLES = {
    "data": "1. Data",
    "balance": "2. Balancing the steering",
    "network": "3. The network",
    "training": "4. Training",
    "results": "5. Closed-loop results",
    "timings": "6. Run timings",
}


@dataclass(frozen=True)
class ReportConfig:
    """What ``clonedrive report`` puts in."""

    max_failures: int = 12  #: off-road events shown with their frames
    stills_per_video: int = 3  #: frames taken from each evaluation video
    seed: int = 0  #: the random augmentation example's generator seed


@dataclass(frozen=True)
class RunParts:
    """Where the pieces of a run are (None / empty when absent)."""

    run_dir: Path
    recordings: tuple[Path, ...]  # folders holding driving_log.csv under RUN_DIR/data
    train_dir: Path | None
    eval_dir: Path | None
    demo_json: Path | None


@dataclass
class ReportResult:
    markdown_path: Path
    html_path: Path
    figures: list[Path]
    sections: list[str]  # section titles, in order
    notes: list[str] = field(default_factory=list)  # what was missing or skipped, one line each


def find_run_parts(run_dir: str | os.PathLike) -> RunParts:
    """Locate the recordings, training and evaluation folders of ``run_dir`` (module doc)."""
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
                      or (d / "history.csv").is_file()), None)
    eval_candidates = [run / "eval"] + ([train_dir / "eval"] if train_dir else []) + [run]
    eval_dir = next((d for d in eval_candidates if (d / "eval.json").is_file()), None)
    demo = run / "demo.json"
    return RunParts(run_dir=run, recordings=tuple(recordings), train_dir=train_dir,
                    eval_dir=eval_dir, demo_json=demo if demo.is_file() else None)


def write_report(run_dir: str | os.PathLike, out_dir: str | os.PathLike | None = None,
                 config: ReportConfig | None = None, *, progress: bool = False) -> ReportResult:
    """Write ``report.md``, ``report.html`` and ``report/*.png`` into ``out_dir`` (default:
    ``run_dir``) describing the run in ``run_dir``."""
    from clonedrive.progress import progress_bar

    config = config or ReportConfig()
    parts = find_run_parts(run_dir)
    out = Path(out_dir) if out_dir is not None else parts.run_dir
    figures_dir = out / FIGURES_DIR
    figures_dir.mkdir(parents=True, exist_ok=True)
    writer = _Writeup(parts, figures_dir, config)

    steps: list[tuple[str, Callable[[], list[Section]]]] = [
        ("data", writer.data_sections),
        ("balance", writer.balance_sections),
        ("network", writer.network_sections),
        ("training", writer.training_sections),
        ("results", writer.results_sections),
        ("timings", writer.timing_sections),
    ]
    document = Document(title=f"Behavioral Cloning: run {parts.run_dir.resolve().name}")
    bar = progress_bar(total=len(steps), desc="report", unit="section", enabled=progress)
    try:
        for key, build in steps:
            document.sections += writer.guarded(SECTION_TITLES[key], build)
            bar.update(1)
    finally:
        bar.close()
    document.intro = writer.intro()

    markdown_path = write_text_atomic(out / MARKDOWN_NAME, to_markdown(document, out))
    html_path = write_text_atomic(out / HTML_NAME, to_html(document))
    figures = [figure.path for figure in document.figures()]
    _remove_stale_figures(figures_dir, figures)
    return ReportResult(markdown_path=markdown_path, html_path=html_path, figures=figures,
                        sections=[s.title for s in document.sections], notes=writer.notes)


# --- reading helpers ----------------------------------------------------------------------------


def _read_json(path: Path) -> dict:
    with open(path, encoding="utf-8") as handle:
        data = json.load(handle)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return data


def _read_json_or_none(path: Path, errors: dict[str, str] | None = None) -> dict | None:
    """The object in ``path``, or None if there is none or it is unreadable (logged, and the
    reason put into ``errors[path.name]``)."""
    if not path.is_file():
        return None
    try:
        return _read_json(path)
    except (OSError, ValueError) as error:
        logger.warning("ignoring %s: %s", path, error)
        if errors is not None:
            errors[path.name] = f"`{path}` is unreadable ({error})"
        return None


def read_history(path: Path) -> list[dict]:
    """history.csv rows as dicts of floats (``epoch`` an int); unparsable cells become NaN."""
    rows = []
    with open(path, encoding="utf-8", newline="") as handle:
        for row in csv.DictReader(handle):
            parsed: dict = {}
            for key, value in row.items():
                if key is None:
                    continue
                try:
                    parsed[key] = float(value)
                except (TypeError, ValueError):
                    parsed[key] = math.nan
            if math.isfinite(parsed.get("epoch", math.nan)):
                parsed["epoch"] = int(parsed["epoch"])
                rows.append(parsed)
    return rows


def read_image_rgb(path: str | os.PathLike) -> np.ndarray | None:
    """A picture file as uint8 RGB, or None if it is missing or does not decode."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return None
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def read_stills(video_path: str | os.PathLike, count: int = 3) -> list[tuple[float, np.ndarray]]:
    """``count`` frames spread over a video (at 1/6, 1/2 and 5/6 of its length for three), as
    (time [s], uint8 RGB); empty if the video cannot be read.

    Frames are reached by seeking; if the decoder does not land on the asked frame, the video
    is read again from the start, skipping frames up to each one.
    """
    import cv2

    capture = cv2.VideoCapture(str(video_path))
    try:
        if not capture.isOpened():
            return []
        fps = capture.get(cv2.CAP_PROP_FPS) or CONTROL_HZ
        total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if total <= 0:
            return []
        wanted = sorted({min(total - 1, int((i + 0.5) * total / count)) for i in range(count)})
        stills = []
        for target in wanted:
            capture.set(cv2.CAP_PROP_POS_FRAMES, target)
            ok, frame = capture.read()
            if not ok or int(capture.get(cv2.CAP_PROP_POS_FRAMES)) != target + 1:
                break
            stills.append((target / fps, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)))
        else:
            return stills
    finally:
        capture.release()
    return _read_stills_in_order(video_path, wanted, fps)


def _read_stills_in_order(video_path: str | os.PathLike, wanted: list[int], fps: float
                          ) -> list[tuple[float, np.ndarray]]:
    import cv2

    capture = cv2.VideoCapture(str(video_path))
    try:
        stills = []
        index = 0
        for target in wanted:
            while index < target:  # grab() decodes but does not convert: cheaper than read()
                if not capture.grab():
                    return stills
                index += 1
            ok, frame = capture.read()
            index += 1
            if not ok:
                break
            stills.append((target / fps, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)))
        return stills
    finally:
        capture.release()


def _remove_stale_figures(figures_dir: Path, keep: list[Path]) -> None:
    """Delete PNGs an earlier report left in ``figures_dir`` that this one does not use."""
    kept = {path.resolve() for path in keep}
    for path in figures_dir.glob("*.png"):
        if path.resolve() not in kept:
            path.unlink(missing_ok=True)


def _copy_figure(source: Path, figures_dir: Path, name: str) -> Path:
    target = figures_dir / name
    with atomic_path(target) as temporary:
        shutil.copyfile(source, temporary)
    return target


def _safe_name(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


# --- formatting helpers -------------------------------------------------------------------------


def _num(value, digits: int = 2, missing: str = "–") -> str:
    if value is None:
        return missing
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not math.isfinite(number):
        return missing
    return f"{number:,.{digits}f}"


def _signed(value: float, digits: int = 2) -> str:
    return f"{value:+.{digits}f}"


def _count(value) -> str:
    return f"{int(value):,}" if value is not None else "–"


def _shape(shape) -> str:
    dims = [d for d in tuple(shape)[1:]]
    return " × ".join("?" if d is None else str(d) for d in dims) or "scalar"


def _track_label(run: dict) -> str:
    return f"{run.get('track', '?')}" + (" (unseen)" if run.get("unseen") else "")


def _run_label(run: dict) -> str:
    return f"{_track_label(run)} at {float(run.get('speed_mph', 0)):g} mph"


# --- the write-up ---------------------------------------------------------------------------------


@dataclass
class _Recording:
    name: str
    path: Path
    spec: object | None  # RecordingSpec from the training recipe
    recorder: dict | None  # the recorder's config.json
    log: object | None  # DrivingLog
    error: str | None = None


class _Writeup:
    """Builds each section from the run's files; remembers what was missing."""

    def __init__(self, parts: RunParts, figures_dir: Path, config: ReportConfig) -> None:
        self.parts = parts
        self.figures_dir = figures_dir
        self.config = config
        self.notes: list[str] = []
        self.facts: dict = {}  # headline figures gathered on the way, for the intro
        self.unreadable: dict[str, str] = {}  # file name -> why it could not be read
        train = parts.train_dir
        self.train_config = (_read_json_or_none(train / "config.json", self.unreadable)
                             if train else None)
        self.dataset = (_read_json_or_none(train / "dataset.json", self.unreadable)
                        if train else None)
        self.eval = (_read_json_or_none(parts.eval_dir / "eval.json", self.unreadable)
                     if parts.eval_dir else None)

    # -- plumbing

    def note(self, text: str) -> Note:
        self.notes.append(text)
        return Note(text)

    def guarded(self, title: str, build: Callable[[], list[Section]]) -> list[Section]:
        """The sections ``build`` makes, or the heading with a note if it failed on bad input."""
        try:
            return build()
        except SECTION_ERRORS as error:
            logger.warning("report section %r skipped: %s", title, error)
            return [Section(title, blocks=[self.note(
                f"This section could not be generated: {type(error).__name__}: {error}")])]

    def missing(self, title: str, text: str) -> list[Section]:
        return [Section(title, blocks=[self.note(text)])]

    # -- intro

    def intro(self) -> list:
        from clonedrive import __version__

        parts = self.parts
        found = []
        if parts.recordings or self.facts.get("recordings"):
            found.append(f"recordings: {self.facts.get('recordings', len(parts.recordings))}")
        if parts.train_dir:
            found.append(f"training: `{_relative(parts.train_dir, parts.run_dir)}`")
        if parts.eval_dir:
            found.append(f"evaluation: `{_relative(parts.eval_dir, parts.run_dir)}`")
        blocks: list = [Paragraph(
            f"Generated by `clonedrive report` (clonedrive {__version__}) on "
            f"{datetime.now().strftime('%Y-%m-%d %H:%M')} from the run folder "
            f"`{parts.run_dir}` ({'; '.join(found) or 'nothing found'}). Every table and "
            "figure below is computed from the files of the run. Steering is in [-1, 1] "
            "(wheel angle / 25°, + = right); CTE is the car's distance from the centre line "
            "(+ = right of it).")]
        headline = self.facts.get("headline", [])
        if headline:
            blocks += [Paragraph("**In short:**"), Bullets(tuple(headline))]
        return blocks

    # -- 1. data

    def recordings(self) -> list[_Recording]:
        """The training recipe's recordings, then data folders the recipe does not name."""
        from clonedrive.data.driving_log import read_driving_log

        specs = []
        train = self.parts.train_dir
        if train and (train / "recipe.toml").is_file():
            from clonedrive.data.recipe import load_recipe

            specs = list(load_recipe(train / "recipe.toml").recordings)
        found: list[_Recording] = []
        used: set[Path] = set()
        data_dirs = {p.name: p for p in self.parts.recordings}
        for spec in specs:
            path = spec.path
            if not (path / "driving_log.csv").is_file():  # the run folder was moved
                path = data_dirs.get(spec.name) or data_dirs.get(spec.path.name) or path
            found.append(_Recording(spec.name, path, spec, None, None))
            used.add(path.resolve())
        for path in self.parts.recordings:
            if path.resolve() not in used:
                found.append(_Recording(path.name, path, None, None, None))
        for item in found:
            item.recorder = _read_json_or_none(item.path / "config.json")
            try:
                item.log = read_driving_log(item.path, verify_images="exists")
            except (OSError, ValueError) as error:
                item.error = str(error)
        return found

    def data_sections(self) -> list[Section]:
        title = SECTION_TITLES["data"]
        recordings = self.recordings()
        if not recordings:
            return self.missing(title, "No recordings found (no `data/*/driving_log.csv` and no "
                                       "training `recipe.toml`): data section skipped.")
        self.facts["recordings"] = len(recordings)
        section = Section(title)
        section.blocks += self._data_text(recordings)
        section.blocks.append(self._recordings_table(recordings))
        skipped = self._skipped_rows(recordings)
        if skipped:
            section.blocks.append(skipped)
        sections = [section]
        sample = next(((r, r.log.rows[len(r.log.rows) // 2]) for r in recordings
                       if r.log is not None and r.log.rows), None)
        views = Section("Camera views", level=3)
        augment = Section("Augmentation", level=3)
        sections += [views, augment]
        if sample is None:
            views.blocks.append(self.note("No recording has a usable row: no sample frames."))
            augment.blocks.append(self.note("No sample frame: no augmentation examples."))
            return sections
        recording, row = sample
        views.blocks += self._camera_views(recording, row)
        augment.blocks += self._augmentation(recording, row)
        return sections

    def _data_text(self, recordings: list[_Recording]) -> list:
        logs = [r.log for r in recordings if r.log is not None]
        rows = sum(len(log.rows) for log in logs)
        tracks = sorted({_recorder_track(r.recorder) for r in recordings if r.recorder})
        trained = [r for r in recordings if r.spec is not None]
        text = (f"The data set has **{_plural(len(recordings), 'recording')}** with "
                f"**{rows:,} usable rows**"
                + (f" on {_plural(len(tracks), 'track')} ({', '.join(tracks)})" if tracks else "")
                + ". ")
        self.facts.setdefault("headline", []).append(
            f"Data: {_plural(len(recordings), 'recording')}, {rows:,} usable rows"
            + (f" ({', '.join(tracks)})" if tracks else "") + ".")
        if any(r.recorder for r in recordings):
            meanings = {"center": "`center` keeps the middle of the road",
                        "left": "`left` holds a line near the left edge",
                        "right": "`right` holds a line near the right edge",
                        "turns": "`turns` keeps only the rows in curves",
                        "weave": "`weave` swings from side to side"}
            styles = [str(r.recorder.get("style")) for r in recordings if r.recorder]
            described = [meanings[style] for style in dict.fromkeys(styles) if style in meanings]
            everyone = all(r.recorder for r in recordings)
            text += (("They were" if everyone else "Those made with `clonedrive record` were")
                     + " driven by the expert driver (pure pursuit on a target line)"
                     + (": " + "; ".join(described) if described else "") + ". ")
        if any(r.recorder is None and r.log is not None for r in recordings):
            text += ("Recordings without a recorder `config.json` (for example from the "
                     "Udacity simulator) show '–' for what only the recorder knows. ")
        blocks: list = [Paragraph(text)]
        if trained:
            side = [r for r in trained if getattr(r.spec, "cameras", "") == "all"]
            offsets = [r for r in trained if getattr(r.spec, "steering_offset", 0.0)]
            flips = [r for r in trained if getattr(r.spec, "flip", False)]
            points = []
            of = f" of {len(trained)}"
            if side:
                corrections = sorted({r.spec.correction for r in side})
                points.append(
                    f"**Side cameras** ({len(side)}{of} recordings): the left and right cameras "
                    "see the road as if the car stood off centre, so their labels get a "
                    "correction of " + " / ".join(f"±{c:g}" for c in corrections) + " (steer "
                    "back towards the middle), which teaches recovery without recording it.")
            if offsets:
                points.append(
                    f"**Steering offsets** ({len(offsets)}{of} recordings): edge laps are "
                    "relabelled so that the label steers back to the centre (the write-up's "
                    "recovery data, without the swerves).")
            if flips:
                points.append(
                    f"**Mirrored copies** ({len(flips)}{of} recordings): every sample is also "
                    "used flipped (image mirrored, steering negated), which evens out left and "
                    "right bends.")
            if points:
                blocks.append(Bullets(tuple(points)))
        else:
            blocks.append(self.note("No training recipe found: cameras, offsets, flips and "
                                    "weights are unknown."))
        return blocks

    def _recordings_table(self, recordings: list[_Recording]) -> Table:
        headers = ("recording", "track", "style", "direction", "laps", "set speed mph",
                   "rows (usable / total)", "cameras", "steering offset", "flip", "weight")
        rows = []
        total_usable = total_rows = 0
        for item in recordings:
            recorder = item.recorder or {}
            spec = item.spec
            if item.log is not None:
                usable, total = len(item.log.rows), item.log.total_rows
                total_usable += usable
                total_rows += total
                row_text = f"{usable:,} / {total:,}"
            else:
                row_text = f"unreadable: {item.error}"
            style = str(recorder.get("style", "–"))
            if recorder.get("noise"):
                style += f" (noise {float(recorder['noise']):g})"
            if spec is None:
                cameras, offset, flip, weight = "not in training recipe", "–", "–", "–"
            else:
                cameras = ("center + left/right (±" + f"{spec.correction:g})"
                           if spec.cameras == "all" else "center")
                offset = _signed(spec.steering_offset)
                flip = "yes" if spec.flip else "no"
                weight = f"{spec.weight:g}"
            direction = "–"
            if "reverse" in recorder:
                direction = "reverse" if recorder["reverse"] else "forward"
            speed = recorder.get("speed_mph")
            rows.append((item.name, _recorder_track(recorder) if recorder else "–", style,
                         direction, _recorder_laps(recorder), _num(speed, 0) if speed else "–",
                         row_text, cameras, offset, flip, weight))
        if len(recordings) > 1:
            rows.append(("total", "", "", "", "", "", f"{total_usable:,} / {total_rows:,}",
                         "", "", "", ""))
        return Table(headers, tuple(rows), align="llllrrrlrlr",
                     total_rows=(len(rows) - 1,) if len(recordings) > 1 else ())

    def _skipped_rows(self, recordings: list[_Recording]) -> Paragraph | None:
        counts: dict[str, int] = {}
        for item in recordings:
            if item.log is None:
                continue
            for skipped in item.log.skipped:
                counts[skipped.reason] = counts.get(skipped.reason, 0) + 1
        if not counts:
            return None
        return Paragraph("Rows the log reader skipped (and why): " + ", ".join(
            f"{count:,} {reason.replace('_', ' ')}" for reason, count in counts.items()) + ".")

    def _camera_views(self, recording: _Recording, row) -> list:
        from clonedrive.data.recipe import DEFAULT_CORRECTION
        from clonedrive.report.plots import camera_views

        spec = recording.spec
        correction = spec.correction if spec is not None else DEFAULT_CORRECTION
        offset = spec.steering_offset if spec is not None else 0.0
        base = row.steering + offset
        labels = {"center": base, "left": base + correction, "right": base - correction}
        labels = {camera: float(np.clip(value, -1.0, 1.0)) for camera, value in labels.items()}
        notes = {"center": f"recorded steering {row.steering:+.3f}"
                           + (f" + offset {offset:+.2f}" if offset else ""),
                 "left": f"center label + correction {correction:g}",
                 "right": f"center label - correction {correction:g}"}
        images = {}
        for camera in ("left", "center", "right"):
            image = read_image_rgb(row.image(camera))
            if image is not None:
                images[camera] = image
        if not images:
            return [self.note(f"The images of row {row.row} of {recording.name} do not decode.")]
        path = camera_views(images, labels, self.figures_dir / "data_cameras.png",
                            title=f"recording {recording.name}, CSV row {row.row}: the three "
                                  "cameras at the same moment", notes=notes)
        return [Paragraph(
            "Each row of `driving_log.csv` holds three pictures taken at the same moment. The "
            "network drives from the center camera alone; the side cameras are extra training "
            "views whose labels say 'steer back'."),
            Figure(path, f"Left, center and right camera of {recording.name}, row {row.row}, "
                         "with the steering label each one trains with.")]

    def _augmentation(self, recording: _Recording, row) -> list:
        from clonedrive.report.plots import augmentation_examples

        image = read_image_rgb(row.center)
        if image is None:
            return [self.note(f"{row.center} does not decode: no augmentation examples.")]
        offset = recording.spec.steering_offset if recording.spec is not None else 0.0
        label = float(np.clip(row.steering + offset, -1.0, 1.0))
        augmented = (self.train_config or {}).get("augment")
        path = augmentation_examples(
            image, label, self.figures_dir / "data_augmentation.png", seed=self.config.seed,
            title=f"training augmentation of one center frame ({recording.name}, row {row.row})")
        used = {True: "This run trained with augmentation on: each training batch draws these "
                      "at random (validation images are left as they are).",
                False: "This run trained with augmentation **off**; the examples show what it "
                       "would add."}.get(augmented, "")
        return [Paragraph(
            "Augmentation makes new training pictures from recorded ones: a mirrored frame "
            "(steering negated), brightness changes, a shadow across the road, and a sideways "
            "shift that looks like the car standing off centre, labelled to steer back "
            f"({_augment_rate()} per pixel). {used}"),
            Figure(path, "One frame through each augmentation, titled with the label it ends "
                         "up with.")]

    # -- 2. balancing

    def balance_sections(self) -> list[Section]:
        title = SECTION_TITLES["balance"]
        train = self.parts.train_dir
        if train is None:
            return self.missing(title, "No training folder: balancing section skipped.")
        section = Section(title)
        dataset = self.dataset
        figures = []
        for stage in ("before", "after"):
            source = train / f"steering_{stage}.png"
            if source.is_file():
                figures.append(_copy_figure(source, self.figures_dir, source.name))
            elif dataset and "balance" in dataset:
                from clonedrive.data.balance import plot_histogram

                balance = dataset["balance"]
                figures.append(plot_histogram(
                    np.asarray(balance[f"counts_{stage}"]), np.asarray(balance["bin_edges"]),
                    self.figures_dir / source.name, title=f"steering {stage} balancing",
                    target=balance.get("target_per_bin")))
        if dataset is None and not figures:
            return self.missing(title, f"No `dataset.json` or steering histograms in "
                                       f"`{train}`: balancing section skipped.")
        if dataset is not None:
            balance = dataset.get("balance", {})
            before = dataset.get("samples_before_balance")
            after = dataset.get("samples_after_balance")
            text = ("Driving is mostly straight ahead, so most labels sit near 0 and a network "
                    "trained on them learns to go straight. ")
            if balance.get("enabled", True):
                bins = max(len(balance.get("bin_edges", [])) - 1, 0)
                text += (f"The write-up's balancing puts the labels into {bins} equal bins and "
                         "keeps a sample of an over-full bin with probability target / count, "
                         f"where the target is the mean count per bin "
                         f"({_num(balance.get('target_per_bin'), 1)}).")
            else:
                text += "This run trained with balancing **off**."
            section.blocks.append(Paragraph(text))
            rows = [("usable CSV rows", _count(dataset.get("rows_read"))),
                    ("samples (cameras × flips) before balancing", _count(before)),
                    ("samples after balancing", _count(after))]
            if before:
                rows.append(("kept", f"{100.0 * (after or 0) / before:.1f} %"))
            rows += [("training samples", _count(dataset.get("train_samples"))),
                     ("validation samples", _count(dataset.get("val_samples")))]
            skipped_rows = dataset.get("skipped_rows") or {}
            skipped_images = dataset.get("skipped_images") or {}
            if skipped_rows:
                rows.append(("skipped rows", ", ".join(f"{v} {k}" for k, v
                                                       in skipped_rows.items())))
            if skipped_images:
                rows.append(("skipped images", ", ".join(f"{v} {k}" for k, v
                                                         in skipped_images.items())))
            section.blocks.append(Table(("", "count"), tuple(rows), align="lr"))
        else:
            section.blocks.append(self.note(f"No `dataset.json` in `{train}`: counts unknown."))
        if figures:
            section.blocks.append(Gallery(tuple(
                Figure(path, f"Steering labels {stage} balancing; dashed line: the target per "
                             "bin.")
                for path, stage in zip(figures, ("before", "after")[:len(figures)],
                                       strict=True))))
        return [section]

    # -- 3. network

    def network_sections(self) -> list[Section]:
        title = SECTION_TITLES["network"]
        train = self.parts.train_dir
        model_path = train / "model.keras" if train else None
        if model_path is None or not model_path.is_file():
            return self.missing(title, "No `model.keras`: network section skipped.")
        import keras

        model = keras.saving.load_model(model_path, safe_mode=True, compile=False)
        rows = []
        for layer in model.layers:
            try:
                shape = _shape(layer.output.shape)
            except (AttributeError, ValueError):
                shape = "?"
            rows.append((layer.name, type(layer).__name__, shape, f"{layer.count_params():,}"))
        total = model.count_params()
        trainable = sum(int(np.prod(w.shape)) for w in model.trainable_weights)
        rows.append(("total", "", "", f"{total:,}"))
        architecture = (self.train_config or {}).get("model", model.name)
        preprocessing = []
        for layer in model.layers:
            if layer.count_params() > 0:
                break
            if type(layer).__name__ != "InputLayer":
                preprocessing.append(f"{type(layer).__name__} `{layer.name}`")
        self.facts["params"] = total
        self.facts.setdefault("headline", []).append(
            f"Network: `{architecture}`, {len(model.layers)} layers, {total:,} parameters.")
        text = (f"The network is the `{architecture}` architecture (Keras model "
                f"`{model.name}`), read from `{_relative(model_path, self.parts.run_dir)}`. It "
                f"takes the raw {_shape(model.input_shape)} RGB camera frame and outputs one "
                "steering value. ")
        if preprocessing:
            text += ("Pre-processing is part of the model (" + ", ".join(preprocessing) + "), "
                     "so training and driving cannot prepare pictures differently. ")
        text += (f"It has **{total:,} parameters** ({trainable:,} trainable).")
        return [Section(title, blocks=[
            Paragraph(text),
            Table(("layer", "type", "output shape", "parameters"), tuple(rows), align="lllr",
                  total_rows=(len(rows) - 1,)),
        ])]

    # -- 4. training

    def training_sections(self) -> list[Section]:
        title = SECTION_TITLES["training"]
        train = self.parts.train_dir
        if train is None:
            return self.missing(title, "No training folder: training section skipped.")
        settings = self.train_config
        history_path = train / "history.csv"
        history = read_history(history_path) if history_path.is_file() else []
        if settings is None and not history:
            return self.missing(title, f"No `config.json` or `history.csv` in `{train}`: "
                                       "training section skipped.")
        section = Section(title)
        split = (self.dataset or {}).get("split") or {}
        kind = split.get("kind") or (settings or {}).get("split")
        if settings is not None:
            rows = [
                ("architecture", f"`{settings.get('model', '?')}`"),
                ("optimiser", f"Adam, learning rate {settings.get('learning_rate', '?')}"),
                ("loss", f"{settings.get('loss', 'mse')} on the steering label"),
                ("batch size", str(settings.get("batch_size", "?"))),
                ("epochs", f"{len(history)} trained ({settings.get('epochs', '?')} configured)"
                           + (f", early stopping after {settings['early_stopping_patience']} "
                              "epochs without improvement"
                              if settings.get("early_stopping_patience") else "")),
                ("balancing", "on" if settings.get("balance") else "off"),
                ("augmentation", "on" if settings.get("augment") else "off"),
                ("dropout", str(settings.get("dropout", 0.0))),
                ("split", f"**{kind}**, {_num(100 * settings.get('val_fraction', 0.2), 0)} % "
                          "for validation"
                          + (f" (blocks of {settings.get('block_s')} s)" if kind == "blocks"
                             else "")),
                ("seed", str(settings.get("seed", "?"))),
            ]
            section.blocks.append(Table(("setting", "value"), tuple(rows)))
        else:
            section.blocks.append(self.note(f"No `config.json` in `{train}`: settings unknown."))
        section.blocks.append(Paragraph(_split_text(kind, split.get("description"))))

        if history:
            best = min(history, key=lambda r: r.get("val_loss", math.inf)
                       if math.isfinite(r.get("val_loss", math.nan)) else math.inf)
            self.facts.setdefault("headline", []).append(
                f"Training: {_plural(len(history), 'epoch')}, best validation loss "
                f"{_num(best.get('val_loss'), 4)} at epoch {best['epoch']} ({kind} split).")
            columns = [c for c in ("loss", "val_loss", "mse", "val_mse", "seconds")
                       if any(c in row for row in history)]
            headers = ("epoch", *[{"loss": "training loss", "val_loss": "validation loss",
                                   "mse": "training MSE", "val_mse": "validation MSE",
                                   "seconds": "seconds"}[c] for c in columns], "")
            table_rows = tuple(
                (str(row["epoch"]),
                 *[_num(row.get(c), 1 if c == "seconds" else 4) for c in columns],
                 "best" if row is best else "")
                for row in history)
            section.blocks.append(Paragraph(
                "Loss per epoch (training loss is measured on augmented pictures while the "
                "weights change, validation loss on untouched pictures after the epoch; "
                "`model.keras` is the epoch with the lowest validation loss):"))
            section.blocks.append(Table(headers, table_rows, align="l" + "r" * len(columns) + "l"))
        else:
            section.blocks.append(self.note(f"No `history.csv` in `{train}`: no loss table."))
        loss_png = train / "loss.png"
        if loss_png.is_file():
            figure_path = _copy_figure(loss_png, self.figures_dir, "loss.png")
        elif history:
            from clonedrive.model.train import plot_loss

            figure_path = plot_loss(history, self.figures_dir / "loss.png")
        else:
            figure_path = None
        if figure_path is not None:
            section.blocks.append(Figure(figure_path, "Training and validation loss per epoch."))
        return [section]

    # -- 5. closed loop

    def results_sections(self) -> list[Section]:
        title = SECTION_TITLES["results"]
        report = self.eval
        if report is None and "eval.json" in self.unreadable:
            return self.missing(title, self.unreadable["eval.json"] + ": closed-loop results "
                                                                      "skipped.")
        if report is None:
            return self.missing(title, "No `eval.json` (from `clonedrive evaluate`): closed-loop "
                                       "results skipped.")
        runs = list(report.get("runs") or [])
        if not runs:
            return self.missing(title, "`eval.json` lists no runs: closed-loop results skipped.")
        eval_dir = self.parts.eval_dir
        section = Section(title)
        model = report.get("model")
        section.blocks.append(Paragraph(
            "The trained network drives the simulator in closed loop, headless: it sees the "
            "center camera at 15 frames per second and sets the steering; a speed controller "
            "sets the throttle. Whenever a tyre leaves the road (an **intervention**) the car "
            "is put back on the centre line and driving goes on. A lap counts only if no tyre "
            "left the road during it. Autonomy % = (1 − interventions × 6 s / time driven) × "
            "100 (NVIDIA's definition); smoothness is the mean |change of steering| per second "
            "(lower is smoother)."
            + (f" Model: `{model}`." if model else "")))
        section.blocks.append(self._results_table(runs, report.get("totals") or {}))
        if any(run.get("timed_out") for run in runs):
            section.blocks.append(Paragraph(
                "† stopped at the time limit before the target laps were driven."))
        for key, label in (("builtin", "built-in tracks"), ("unseen", "unseen tracks")):
            total = (report.get("totals") or {}).get(key)
            if total:
                self.facts.setdefault("headline", []).append(
                    f"Closed loop, {label}: {total['laps_completed']}/{total['laps_target']} "
                    f"laps ({_num(total.get('laps_completed_pct'), 0)} %), "
                    f"{total['interventions']} interventions.")
        speed = Section("Speed control", level=3)
        speed.blocks.append(Paragraph(_speed_text(report)))
        maps = Section("Track maps", level=3)
        maps.blocks += self._maps(runs, eval_dir)
        stills = Section("Stills from the videos", level=3)
        stills.blocks += self._stills(runs, eval_dir)
        failures = Section("Failure analysis", level=3)
        failures.blocks += self._failures(runs, eval_dir)
        return [section, speed, maps, stills, failures]

    def _results_table(self, runs: list[dict], totals: dict) -> Table:
        headers = ("track", "speed mph", "laps", "interventions", "autonomy %", "mean |CTE| m",
                   "max |CTE| m", "smoothness /s", "mean speed mph", "distance m", "time s")
        rows = []
        for run in runs:
            laps = f"{run.get('laps_completed', 0)}/{run.get('laps_target', '?')}"
            if run.get("timed_out"):
                laps += " †"
            rows.append((_track_label(run), _num(run.get("speed_mph"), 0), laps,
                         _count(run.get("interventions")), _num(run.get("autonomy_pct"), 1),
                         _num(run.get("mean_abs_cte_m")), _num(run.get("max_abs_cte_m")),
                         _num(run.get("smoothness")), _num(run.get("mean_speed_mph"), 1),
                         _num(run.get("distance_m"), 0), _num(run.get("elapsed_s"), 1)))
        first_total = len(rows)
        groups = [("built-in tracks", [r for r in runs if not r.get("unseen")], "builtin"),
                  ("unseen tracks", [r for r in runs if r.get("unseen")], "unseen")]
        if all(group for _, group, _ in groups):
            groups.append(("all", runs, "all"))
        for label, group, key in groups:
            if group:
                rows.append(_total_row(label, group, totals.get(key)))
        return Table(headers, tuple(rows), align="lrrrrrrrrrr",
                     total_rows=tuple(range(first_total, len(rows))))

    def _maps(self, runs: list[dict], eval_dir: Path) -> list:
        """Built-in tracks' maps one under the other, unseen tracks' side by side."""
        builtin: list[Figure] = []
        unseen: list[Figure] = []
        for run in runs:
            source = run.get("map_png")
            if source and (eval_dir / source).is_file():
                path = _copy_figure(eval_dir / source, self.figures_dir,
                                    f"map_{_safe_name(Path(source).stem)}.png")
                caption = (f"{_run_label(run)}: the driven path coloured by |CTE|; red crosses "
                           "mark off-road events.")
                if run.get("unseen"):
                    unseen.append(Figure(path, caption))
                else:
                    builtin.append(Figure(path, caption, max_width_px=820))
        if not builtin and not unseen:
            return [self.note("No track maps in the evaluation folder.")]
        blocks: list = list(builtin)
        if unseen:
            blocks += [Paragraph("Unseen (generated) tracks, never used for recording:"),
                       Gallery(tuple(unseen))]
        return blocks

    def _stills(self, runs: list[dict], eval_dir: Path) -> list:
        from clonedrive.report.plots import video_stills

        blocks: list = []
        videos = [run for run in runs if run.get("video")]
        if not videos:
            return [self.note("No videos in this evaluation (run `clonedrive evaluate "
                              "--video`): no stills.")]
        for run in videos:
            video = eval_dir / run["video"]
            stills = read_stills(video, self.config.stills_per_video) if video.is_file() else []
            if not stills:
                blocks.append(self.note(f"`{run['video']}` is missing or unreadable: no stills "
                                        f"for {_run_label(run)}."))
                continue
            path = video_stills(stills, self.figures_dir / f"stills_{_safe_name(video.stem)}.png",
                                title=f"{_run_label(run)} ({run['video']})")
            blocks.append(Figure(path, f"{_run_label(run)}: frames from `{run['video']}` with "
                                       "the heads-up display (steering bar, speed, CTE, lap, "
                                       "interventions)."))
        return blocks

    def _failures(self, runs: list[dict], eval_dir: Path) -> list:
        from clonedrive.report.plots import Panel, failure_frames

        events = [(run, event) for run in runs for event in run.get("off_road_events") or []]
        if not events:
            return [Paragraph("No tyre left the road in any run: nothing to analyse.")]
        tracks: dict = {}
        described = [(run, event, _where(run.get("track"), event, tracks))
                     for run, event in events]
        blocks: list = [Paragraph(_failure_summary(described))]
        shown = described[: self.config.max_failures]
        if len(described) > len(shown):
            blocks.append(Paragraph(f"The first {len(shown)} of {len(described)} events:"))
        rows = []
        panels = []
        for number, (run, event, where) in enumerate(shown, start=1):
            cte = float(event.get("cte_m", 0.0))
            side = "right" if cte > 0 else "left"
            rows.append((str(number), _track_label(run), _num(run.get("speed_mph"), 0),
                         str(int(event.get("lap", 0)) + 1), _num(event.get("time_s"), 1),
                         _num(event.get("s_m"), 0), _signed(cte), f"{side} edge", where["text"]))
            frame = event.get("frame_png")
            image = read_image_rgb(eval_dir / frame) if frame else None
            if image is not None:
                lap = int(event.get("lap", 0)) + 1
                panels.append(Panel(image, f"#{number} {_run_label(run)}, lap {lap}\n"
                                           f"s {_num(event.get('s_m'), 0)} m, CTE {cte:+.2f} m, "
                                           f"{where['short']}"))
        blocks.append(Table(("#", "track", "mph", "lap", "time s", "s m", "CTE m", "off the",
                             "road there"), tuple(rows), align="rlrrrrrll"))
        if panels:
            path = failure_frames(panels, self.figures_dir / "failures.png",
                                  title="what the network saw when the car left the road")
            blocks.append(Figure(path, "The center-camera frame at each off-road event "
                                       "(numbers as in the table)."))
        else:
            blocks.append(self.note("The off-road frames are missing from the evaluation "
                                    "folder."))
        return blocks

    # -- 6. timings

    def timing_sections(self) -> list[Section]:
        title = SECTION_TITLES["timings"]
        if self.parts.demo_json is None:
            return self.missing(title, "No `demo.json` (written by `clonedrive demo`): no stage "
                                       "timings.")
        demo = _read_json(self.parts.demo_json)
        stages = _stage_seconds(demo)
        if not stages:
            return self.missing(title, "`demo.json` holds no stage timings.")
        stage_total = sum(stages.values())
        wall = demo.get("total_seconds")
        total = stage_total
        if isinstance(wall, int | float) and wall >= stage_total:
            total = float(wall)
        rows = [(name, _num(seconds, 1), _num(seconds / 60.0, 1),
                 f"{100.0 * seconds / total:.0f} %" if total > 0 else "–",
                 _stage_details(demo, name))
                for name, seconds in stages.items()]
        rows.append(("total" + (" (wall clock)" if total > stage_total else ""), _num(total, 1),
                     _num(total / 60.0, 1), "100 %", ""))
        text = f"Wall-clock time of each stage of the run, from `{self.parts.demo_json.name}`."
        if "report" not in stages:
            text += " (The report stage is timed after this report was written.)"
        blocks: list = [Paragraph(text),
                        Table(("stage", "seconds", "minutes", "share", "details"), tuple(rows),
                              align="lrrrl", total_rows=(len(rows) - 1,))]
        settings = demo.get("config")
        extras = [f"{key} = {value}" for key, value in
                  (settings.items() if isinstance(settings, dict) else ())
                  if isinstance(value, str | int | float | bool) or value is None]
        extras += [f"{key} = {value}" for key, value in demo.items()
                   if isinstance(value, str | int | float | bool)
                   and key not in (*_STAGE_KEYS, "total_seconds")]
        if extras:
            blocks.append(Paragraph("Settings: " + ", ".join(f"`{item}`" for item in extras)
                                    + "."))
        return [Section(title, blocks=blocks)]


# --- section helpers ------------------------------------------------------------------------------

_STAGE_KEYS = ("stages", "timings", "timings_s", "stage_seconds")


def _stage_seconds(demo: dict) -> dict[str, float]:
    """Stage name -> seconds from the first timing table ``demo.json`` holds."""
    for key in _STAGE_KEYS:
        table = demo.get(key)
        stages: dict[str, float] = {}
        if isinstance(table, dict):
            for name, value in table.items():
                seconds = _seconds_of(value)
                if seconds is not None:
                    stages[str(name)] = seconds
        elif isinstance(table, list):
            for item in table:
                if isinstance(item, dict):
                    name = item.get("name") or item.get("stage")
                    seconds = _seconds_of(item)
                    if name is not None and seconds is not None:
                        stages[str(name)] = seconds
        if stages:
            return stages
    return {}


def _stage_details(demo: dict, name: str) -> str:
    """A stage's other scalar entries in ``demo.json`` ("rows 1234, model fast")."""
    for key in _STAGE_KEYS:
        table = demo.get(key)
        if isinstance(table, dict) and isinstance(table.get(name), dict):
            return ", ".join(f"{k} {v}" for k, v in table[name].items()
                             if k != "seconds" and isinstance(v, str | int | float | bool))
    return ""


def _seconds_of(value) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, dict):
        for key in ("seconds", "wall_s", "elapsed_s", "wall_seconds", "time_s"):
            if isinstance(value.get(key), int | float):
                return float(value[key])
    return None


def _plural(count: int, word: str) -> str:
    return f"{count:,} {word}{'' if count == 1 else 's'}"


def _relative(path: Path, base: Path) -> str:
    try:
        return path.resolve().relative_to(base.resolve()).as_posix() or "."
    except ValueError:
        return str(path)


def _recorder_track(recorder: dict) -> str:
    return str(recorder.get("track_name") or recorder.get("track") or "–")


def _recorder_laps(recorder: dict) -> str:
    """Laps over every recording session (a folder recorded into twice has two)."""
    sessions = recorder.get("sessions")
    if isinstance(sessions, list) and len(sessions) > 1:
        laps = [s.get("laps") for s in sessions if isinstance(s, dict)]
        if all(isinstance(value, int) for value in laps):
            return f"{sum(laps)} ({len(laps)} sessions)"
    laps = recorder.get("laps")
    if laps is None:
        return "–"
    seconds = recorder.get("seconds")
    return f"{laps} (max {float(seconds):g} s)" if isinstance(seconds, int | float) else str(laps)


def _augment_rate() -> str:
    from clonedrive.data.augment import STEERING_PER_PX

    return f"{STEERING_PER_PX:g} steering"


def _split_text(kind: str | None, description: str | None) -> str:
    caveat = ("Neighbouring frames are 1/15 s apart and nearly identical, so a **random split** "
              "puts a near-twin of almost every validation frame into the training set: it "
              "flatters the validation loss, which then says little about driving.")
    texts = {
        "random": f"**Split used: random** (samples drawn at random). {caveat} The closed-loop "
                  "results below are the real test.",
        "blocks": "**Split used: blocks**: whole stretches of driving go to validation, so "
                  f"validation frames have no near-twins in training. {caveat} Blocks avoid "
                  "that; the validation loss is still measured on the same tracks.",
        "recording": "**Split used: recording**: whole recordings are held out for validation, "
                     f"the most honest of the three. {caveat}",
    }
    text = texts.get(kind or "", f"**Split used: {kind or 'unknown'}**. {caveat}")
    if description:
        text += f" This run: {description}."
    return text


def _speed_text(report: dict) -> str:
    control = report.get("speed_control") or "a PI controller on the set speed"
    if report.get("slow_in_curves"):
        return (f"Speed control: {control}. **Slowing in curves was on**: the target speed "
                "falls as the predicted steering grows, so the car takes bends slower than the "
                "set speed shown in the table.")
    return (f"Speed control: {control}. Slowing in curves was **off**: the controller holds "
            "the set speed everywhere, bends included; the network steers alone.")


def _total_row(label: str, runs: list[dict], totals: dict | None) -> tuple[str, ...]:
    laps_target = sum(int(r.get("laps_target", 0)) for r in runs)
    laps = sum(min(int(r.get("laps_completed", 0)), int(r.get("laps_target", 0))) for r in runs)
    interventions = sum(int(r.get("interventions", 0)) for r in runs)
    if totals:
        laps, laps_target = totals.get("laps_completed", laps), totals.get("laps_target",
                                                                              laps_target)
        interventions = totals.get("interventions", interventions)
    elapsed = sum(float(r.get("elapsed_s", 0.0)) for r in runs)
    distance = sum(float(r.get("distance_m", 0.0)) for r in runs)
    autonomy = (max(0.0, 1.0 - interventions * 6.0 / elapsed) * 100.0 if elapsed > 0 else None)
    weighted = (sum(float(r.get("mean_abs_cte_m", 0.0)) * float(r.get("elapsed_s", 0.0))
                    for r in runs) / elapsed if elapsed > 0 else None)
    max_cte = max((float(r.get("max_abs_cte_m", 0.0)) for r in runs), default=None)
    pct = f" ({100.0 * laps / laps_target:.0f} %)" if laps_target else ""
    return (f"{label} ({len(runs)} runs)", "", f"{laps}/{laps_target}{pct}", _count(interventions),
            _num(autonomy, 1), _num(weighted), _num(max_cte), "", "", _num(distance, 0),
            _num(elapsed, 1))


def _where(track_name: str | None, event: dict, tracks: dict) -> dict:
    """The road where an event happened: a left or right bend (with radius) or a straight.
    ``tracks`` caches loaded tracks by name."""
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    unknown = {"text": "–", "short": "", "bend": None, "outside": None}
    if not track_name:
        return unknown
    try:
        if track_name not in tracks:
            tracks[track_name] = load_track(track_name)
        track = tracks[track_name]
    except (TrackError, OSError, ValueError):
        return unknown
    curvature = float(track.curvature(float(event.get("s_m", 0.0))))
    if abs(curvature) < STRAIGHT_CURVATURE:
        return {"text": "straight", "short": "straight", "bend": None, "outside": None}
    bend = "left" if curvature > 0 else "right"
    cte = float(event.get("cte_m", 0.0))
    outside = (cte > 0) == (curvature > 0)  # a left bend's outside is on the right
    radius = 1.0 / abs(curvature)
    return {"text": f"{bend} bend, radius {radius:.0f} m ({'outside' if outside else 'inside'})",
            "short": f"{bend} bend R {radius:.0f} m", "bend": bend, "outside": outside}


def _failure_summary(described: list[tuple[dict, dict, dict]]) -> str:
    total = len(described)
    runs = len({id(run) for run, _, _ in described})
    in_bends = [w for _, _, w in described if w["bend"] is not None]
    outside = sum(1 for w in in_bends if w["outside"])
    straights = sum(1 for _, _, w in described if w["text"] == "straight")
    text = (f"The car left the road **{_plural(total, 'time')}** in {_plural(runs, 'run')}. ")
    inside = len(in_bends) - outside
    if in_bends:
        text += (f"{len(in_bends)} happened in bends ({outside} on the outside: the network "
                 f"steered too little; {inside} on the inside: it cut the corner)"
                 + (f", {straights} on straights. " if straights else ". "))
    elif straights:
        text += f"All {straights} happened on straights. " if straights > 1 else (
            "It happened on a straight. ")
    if in_bends and outside >= inside:
        text += ("Running wide in bends points to too few strongly-steered samples "
                 "(more curve and recovery data, less balancing of the straight bin) or to "
                 "too much speed for the bends (try slowing in curves). ")
    elif in_bends:
        text += ("Cutting corners points to over-steering: labels of side cameras or edge "
                 "laps that are too strong, or too much shift augmentation. ")
    if straights > len(in_bends):
        text += ("Leaving the road on a straight means the car drifted to one side without "
                 "steering back: a steering bias, or too little recovery data (edge laps, "
                 "side cameras) to learn from. ")
    text += "Each event is listed with where it happened and the frame the network saw."
    return text
