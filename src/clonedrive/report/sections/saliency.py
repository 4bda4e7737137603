"""7. Where the network looks: VisualBackProp (:mod:`clonedrive.model.saliency`) on the frames the
network saw when the car left the road, and on an ordinary frame for comparison.
"""

from __future__ import annotations

from clonedrive.report.context import SECTION_TITLES, ReportContext, read_image_or_none
from clonedrive.report.document import Figure, Paragraph, Section

#: Off-road frames shown at most (the first ones).
MAX_EVENT_FRAMES = 5


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["saliency"]
    train = ctx.parts.train_dir
    model_path = train / "model.keras" if train else None
    if model_path is None or not model_path.is_file():
        return ctx.missing(title, "No `model.keras`: no saliency maps.")
    frames = _frames(ctx)
    if not frames:
        return ctx.missing(title, "No frame to look at: neither off-road frames in the "
                                  "evaluation nor a recording.")
    import numpy as np

    from clonedrive.drivers.network import load_model
    from clonedrive.model.saliency import VisualBackProp, overlay
    from clonedrive.report.plots import Panel, panel_grid

    try:
        saliency = VisualBackProp(load_model(model_path))
    except ValueError as error:
        return ctx.missing(title, f"No saliency maps: {error}.")
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
           if events else "No tyre left the road; an ordinary frame is shown."))
    return [Section(title, blocks=[Paragraph(text), Figure(path, "Each frame beside its "
                                                                 "VisualBackProp overlay.")])]


def _frames(ctx: ReportContext) -> list[tuple[str, object]]:
    frames = []
    eval_dir = ctx.parts.eval_dir
    if eval_dir is not None and ctx.eval:
        for run in ctx.eval.get("runs") or []:
            for event in run.get("off_road_events") or []:
                frame = event.get("frame_png")
                image = read_image_or_none(eval_dir / frame) if frame else None
                if image is not None and len(frames) < MAX_EVENT_FRAMES:
                    frames.append((f"off road: {run.get('track')} s {event.get('s_m', 0):.0f} m",
                                   image))
    normal = _ordinary_frame(ctx)
    if normal is not None:
        frames.append(normal)
    return frames


def _ordinary_frame(ctx: ReportContext):
    """The center frame in the middle of the first recording, as (label, image)."""
    from clonedrive.data.driving_log import DrivingLogError, read_driving_log

    for folder in ctx.parts.recordings:
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
