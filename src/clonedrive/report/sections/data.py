"""Data: the recordings (table, cameras, offsets, flips), one row's three camera views and
the augmentation examples.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.report import formatting as fmt
from clonedrive.report.context import (
    SECTION_TITLES,
    ReportContext,
    read_image_or_none,
    read_json_or_none,
)
from clonedrive.report.document import Bullets, Figure, Paragraph, Section, Table


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["data"]
    recordings = _recordings(ctx)
    if not recordings:
        return ctx.missing(title, "No recordings found (no `data/*/driving_log.csv` and no "
                                  "training `recipe.toml`): data section skipped.")
    ctx.facts["recordings"] = len(recordings)
    section = Section(title)
    section.blocks += _data_text(ctx, recordings)
    section.blocks.append(_recordings_table(ctx, recordings))
    skipped = _skipped_rows(ctx, recordings)
    if skipped:
        section.blocks.append(skipped)
    sections = [section]
    sample = next(((r, r.log.rows[len(r.log.rows) // 2]) for r in recordings
                   if r.log is not None and r.log.rows), None)
    views = Section("Camera views", level=3)
    augment = Section("Augmentation", level=3)
    sections += [views, augment]
    if sample is None:
        views.blocks.append(ctx.note("No recording has a usable row: no sample frames."))
        augment.blocks.append(ctx.note("No sample frame: no augmentation examples."))
        return sections
    recording, row = sample
    views.blocks += _camera_views(ctx, recording, row)
    augment.blocks += _augmentation(ctx, recording, row)
    return sections


@dataclass
class _Recording:
    name: str
    path: Path
    spec: object | None  # RecordingSpec from the training recipe
    recorder: dict | None  # the recorder's config.json
    log: object | None  # DrivingLog
    error: str | None = None


def _recordings(ctx: ReportContext) -> list[_Recording]:
    """The training recipe's recordings, then data folders the recipe does not name."""
    from clonedrive.data.driving_log import read_driving_log

    specs = []
    train = ctx.parts.train_dir
    if train and (train / "recipe.toml").is_file():
        from clonedrive.data.recipe import load_recipe

        specs = list(load_recipe(train / "recipe.toml").recordings)
    found: list[_Recording] = []
    used: set[Path] = set()
    data_dirs = {p.name: p for p in ctx.parts.recordings}
    for spec in specs:
        path = _recording_folder(spec, data_dirs)
        found.append(_Recording(spec.name, path, spec, None, None))
        used.add(path.resolve())
    for path in ctx.parts.recordings:
        if path.resolve() not in used:
            found.append(_Recording(path.name, path, None, None, None))
    for item in found:
        item.recorder = read_json_or_none(item.path / "config.json")
        try:
            item.log = read_driving_log(item.path, verify_images="exists")
        except (OSError, ValueError) as error:
            item.error = str(error)
    return found


def _recording_folder(spec, data_dirs: dict[str, Path]) -> Path:
    """Where a training recipe's recording is: the run folder's own copy of it (``data/``)
    where the recipe's path is gone (the run folder was moved) or holds the same log (the run
    folder was copied), else the recipe's path."""
    own = data_dirs.get(spec.name) or data_dirs.get(spec.path.name)
    if own is None or own.resolve() == spec.path.resolve():
        return spec.path
    if not (spec.path / "driving_log.csv").is_file():
        return own
    return own if _same_file(own / "driving_log.csv", spec.path / "driving_log.csv") else spec.path


def _same_file(first: Path, second: Path) -> bool:
    import filecmp

    try:
        return filecmp.cmp(first, second, shallow=False)
    except OSError:
        return False


def _data_text(ctx: ReportContext, recordings: list[_Recording]) -> list:
    logs = [r.log for r in recordings if r.log is not None]
    rows = sum(len(log.rows) for log in logs)
    tracks = sorted({_recorder_track(r.recorder) for r in recordings if r.recorder})
    trained = [r for r in recordings if r.spec is not None]
    text = (f"The data set has **{fmt.plural(len(recordings), 'recording')}** with "
            f"**{rows:,} usable rows**"
            + (f" on {fmt.plural(len(tracks), 'track')} ({', '.join(tracks)})" if tracks else "")
            + ". ")
    ctx.headline(
        f"Data: {fmt.plural(len(recordings), 'recording')}, {rows:,} usable rows"
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
                 + " driven by the expert (pure pursuit on a target line)"
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
        blocks.append(ctx.note("No training recipe found: cameras, offsets, flips and "
                               "weights are unknown."))
    return blocks


def _recordings_table(ctx: ReportContext, recordings: list[_Recording]) -> Table:
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
            offset = fmt.signed(spec.steering_offset)
            flip = "yes" if spec.flip else "no"
            weight = f"{spec.weight:g}"
        direction = "–"
        if "reverse" in recorder:
            direction = "reverse" if recorder["reverse"] else "forward"
        speed = recorder.get("speed_mph")
        rows.append((item.name, _recorder_track(recorder) if recorder else "–", style,
                     direction, _recorder_laps(recorder), fmt.num(speed, 0) if speed else "–",
                     row_text, cameras, offset, flip, weight))
    if len(recordings) > 1:
        rows.append(("total", "", "", "", "", "", f"{total_usable:,} / {total_rows:,}",
                     "", "", "", ""))
    return Table(headers, tuple(rows), align="llllrrrlrlr",
                 total_rows=(len(rows) - 1,) if len(recordings) > 1 else ())


def _skipped_rows(ctx: ReportContext, recordings: list[_Recording]) -> Paragraph | None:
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


def _camera_views(ctx: ReportContext, recording: _Recording, row) -> list:
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
        image = read_image_or_none(row.image(camera))
        if image is not None:
            images[camera] = image
    if not images:
        return [ctx.note(f"The images of row {row.row} of {recording.name} do not decode.")]
    path = camera_views(images, labels, ctx.figures_dir / "data_cameras.png",
                        title=f"recording {recording.name}, CSV row {row.row}: the three "
                              "cameras at the same moment", notes=notes)
    return [Paragraph(
        "Each row of `driving_log.csv` holds three pictures taken at the same moment. The "
        "network drives from the center camera alone; the side cameras are extra training "
        "views whose labels say 'steer back'."),
            Figure(path, f"Left, center and right camera of {recording.name}, row {row.row}, "
                   "with the steering label each one trains with.")]


def _augmentation(ctx: ReportContext, recording: _Recording, row) -> list:
    from clonedrive.report.plots import augmentation_examples

    image = read_image_or_none(row.center)
    if image is None:
        return [ctx.note(f"{row.center} does not decode: no augmentation examples.")]
    offset = recording.spec.steering_offset if recording.spec is not None else 0.0
    label = float(np.clip(row.steering + offset, -1.0, 1.0))
    augmented = (ctx.train_config or {}).get("augment")
    path = augmentation_examples(
        image, label, ctx.figures_dir / "data_augmentation.png", seed=ctx.config.seed,
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
