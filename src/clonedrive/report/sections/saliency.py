"""Where the network looks: VisualBackProp (:mod:`clonedrive.model.saliency`) on the frames the
network saw when the car left the road and on an ordinary frame for comparison, and the
overlays ``clonedrive saliency`` already wrote into the run folder (``saliency.json`` in
``RUN_DIR/saliency/``, the training folder's ``saliency/`` or another folder one level down).
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.report import formatting as fmt
from clonedrive.report.context import (
    SECTION_TITLES,
    ReportContext,
    read_image_or_none,
    read_json_or_none,
)
from clonedrive.report.document import Figure, Paragraph, Section

#: Off-road frames shown at most (the first ones).
MAX_EVENT_FRAMES = 5
#: Recordings named by the training that are tried for an ordinary frame.
MAX_TRAINED_ON = 8
#: Overlays from ``clonedrive saliency`` shown at most (the first of its ``saliency.json``).
MAX_WRITTEN_OVERLAYS = 6


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["saliency"]
    computed, reason = _computed(ctx)
    written = _written(ctx)
    if not computed and not written:
        return ctx.missing(title, reason)
    return [Section(title, blocks=computed + written)]


def _computed(ctx: ReportContext) -> tuple[list, str]:
    """VisualBackProp on the run's own frames now: (blocks, why there are none)."""
    train = ctx.parts.train_dir
    model_path = train / "model.keras" if train else None
    if model_path is None or not model_path.is_file():
        return [], "No `model.keras`: no saliency maps."
    frames = _frames(ctx)
    if not frames:
        return [], ("No frame to look at: no off-road frames in the evaluation, no readable "
                    "recording (in the run folder's `data/`, or named by the training's "
                    "`dataset.json`), and no overlays from `clonedrive saliency`.")
    import numpy as np

    from clonedrive.model.saliency import VisualBackProp, overlay
    from clonedrive.network.model_file import load_model
    from clonedrive.report.plots import Panel, panel_grid

    try:
        saliency = VisualBackProp(load_model(model_path))
    except ValueError as error:
        return [], f"No saliency maps: {error}."
    images = np.stack([image for _, image in frames])
    masks = saliency.masks(images)
    panels = []
    for (label, image), mask in zip(frames, masks, strict=True):
        panels += [Panel(image, label), Panel(overlay(image, mask), "VisualBackProp")]
    path = panel_grid(panels, ctx.figures_dir / "saliency.png", columns=2,
                      title="where the network looks (green: VisualBackProp)")
    events = sum(1 for label, _ in frames if label.startswith("off road"))
    text = (
        "VisualBackProp (Bojarski et al. 2016) shows which pixels the convolutional layers "
        "respond to: each layer's feature maps are averaged, scaled back up through the "
        "layers above it and multiplied together, so a pixel lights up only if features at "
        "every depth are active there. A network that drives well looks at the road's edges "
        "and lines ahead. "
        + (f"The first {events} off-road frame(s) are shown above an ordinary frame: compare "
           "what lit up when the car left the road with what lights up when it drives well."
           if events else _no_event_text(ctx, frames)))
    return [Paragraph(text), Figure(path, "Each frame beside its VisualBackProp overlay.")], ""


def _no_event_text(ctx: ReportContext, frames: list) -> str:
    """What is shown when no off-road frame is, and why."""
    ordinary = next((label.removeprefix("ordinary: ") for label, _ in frames
                     if label.startswith("ordinary: ")), "")
    why = "No tyre left the road" if ctx.eval else "The run folder holds no evaluation"
    return f"{why}; an ordinary frame ({ordinary}) is shown."


def _written(ctx: ReportContext) -> list:
    """The overlays ``clonedrive saliency`` wrote into the run folder, as one figure."""
    from clonedrive.report.plots import Panel, panel_grid

    for folder in _saliency_folders(ctx):
        listing = read_json_or_none(folder / "saliency.json", ctx.unreadable)
        entries = listing.get("frames") if isinstance(listing, dict) else None
        panels = [panel for panel in map(lambda e: _written_panel(folder, e), entries or [])
                  if panel is not None][:MAX_WRITTEN_OVERLAYS]
        if not panels:
            continue
        where = fmt.relative(folder, ctx.parts.run_dir)
        path = panel_grid([Panel(image, label) for label, image in panels],
                          ctx.figures_dir / "saliency_written.png", columns=3,
                          title=f"overlays from clonedrive saliency ({where})")
        text = (f"`clonedrive saliency` wrote {len(entries)} overlay(s) into `{where}`; the "
                f"first {len(panels)} are shown, each titled with the frame it was made from "
                "and the steering the network predicted for it.")
        return [Paragraph(text), Figure(path, f"VisualBackProp overlays found in `{where}`.")]
    return []


def _saliency_folders(ctx: ReportContext) -> list[Path]:
    """Folders holding a ``saliency.json``: the run's and the training folder's ``saliency/``
    first, then any other folder one level down."""
    run, train = ctx.parts.run_dir, ctx.parts.train_dir
    preferred = [run / "saliency"] + ([train / "saliency"] if train else [])
    others = sorted(path.parent for path in run.glob("*/saliency.json"))
    folders = []
    for folder in preferred + others:
        listing = folder / "saliency.json"
        if folder not in folders and listing.is_file() and not listing.is_symlink():
            folders.append(folder)
    return folders


def _written_panel(folder: Path, entry) -> tuple[str, object] | None:
    """(label, overlay image) for one ``saliency.json`` entry, or None for an entry that names
    anything but a plain picture file in ``folder`` itself."""
    name = entry.get("overlay") if isinstance(entry, dict) else None
    if not isinstance(name, str) or Path(name).name != name or name in ("", ".", ".."):
        return None
    path = folder / name
    if path.is_symlink() or not path.is_file():
        return None
    image = read_image_or_none(path)
    if image is None:
        return None
    steering = entry.get("steering")
    label = Path(str(entry.get("source", name))).name
    if isinstance(steering, int | float):
        label += f"\nsteering {steering:+.2f}"
    return label, image


def _frames(ctx: ReportContext) -> list[tuple[str, object]]:
    frames = []
    eval_dir = ctx.parts.eval_dir
    if eval_dir is not None and ctx.eval:
        for run in ctx.eval.get("runs") or []:
            for event in run.get("off_road_events") or []:
                frame = event.get("frame_png")
                source = ctx.run_file(eval_dir, frame) if frame else None
                image = read_image_or_none(source) if source is not None else None
                if image is not None and len(frames) < MAX_EVENT_FRAMES:
                    frames.append((f"off road: {run.get('track')} s {event.get('s_m', 0):.0f} m",
                                   image))
    normal = _ordinary_frame(ctx)
    if normal is not None:
        frames.append(normal)
    return frames


def _ordinary_frame(ctx: ReportContext):
    """The center frame in the middle of the first recording (the run folder's, else the first
    the training names), as (label, image)."""
    from clonedrive.data.driving_log import DrivingLogError, read_driving_log

    for folder in [*ctx.parts.recordings, *_trained_on(ctx)]:
        try:
            rows = read_driving_log(folder, verify_images="exists").rows
        except (DrivingLogError, OSError, ValueError):
            continue
        if rows:
            row = rows[len(rows) // 2]
            image = read_image_or_none(row.center)
            if image is not None:
                return (f"ordinary: {folder.name}, row {row.row}", image)
    return None


def _trained_on(ctx: ReportContext) -> list[Path]:
    """The recording folders ``dataset.json`` says the training read (first few)."""
    recordings = (ctx.dataset or {}).get("recordings")
    if not isinstance(recordings, list):
        return []
    paths = [entry.get("path") for entry in recordings[:MAX_TRAINED_ON]
             if isinstance(entry, dict)]
    return [Path(path) for path in paths if isinstance(path, str) and path]
