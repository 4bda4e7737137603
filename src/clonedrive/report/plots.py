"""Figures of the generated write-up (matplotlib Agg, no pyplot state): camera views, augmentation
examples, video stills and the frames the car saw when it left the road.

Every function takes uint8 RGB frames and labels, writes one PNG atomically (temp file +
rename) and returns its path. Track maps live in :mod:`clonedrive.evaluate.maps`, the loss curve
and steering histograms beside the code that makes them (``model.checkpoints.plot_loss``,
``data.balance.plot_histogram``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.base.config import atomic_path

#: Figure resolution, dots per inch.
DPI = 100


@dataclass(frozen=True)
class Panel:
    """One labelled picture of a figure."""

    image: np.ndarray  # uint8 RGB (H, W, 3)
    title: str


def save_figure(figure, path: str | os.PathLike) -> Path:
    """Write a matplotlib ``Figure`` as PNG via a temp file + rename; returns the path."""
    path = Path(path)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=DPI, bbox_inches="tight", pad_inches=0.12)
    return path


def panel_grid(panels: Sequence[Panel], path: str | os.PathLike, *, title: str,
               columns: int = 3, panel_width_in: float = 4.0, title_size: float = 10.0) -> Path:
    """Frames side by side (``columns`` per row), each under its own title, one overall title.

    Frames keep their aspect ratio; axes carry no ticks (they are pictures, not plots), so the
    titles say what each panel shows.
    """
    from matplotlib.figure import Figure

    if not panels:
        raise ValueError(f"{path}: no pictures to draw")
    columns = max(1, min(columns, len(panels)))
    rows = math.ceil(len(panels) / columns)
    height, width = panels[0].image.shape[:2]
    title_lines = max(panel.title.count("\n") + 1 for panel in panels)
    panel_height_in = panel_width_in * height / width + 0.22 * title_lines + 0.1
    figure = Figure(figsize=(columns * panel_width_in, rows * panel_height_in + 0.5))
    axes_grid = figure.subplots(rows, columns, squeeze=False)
    for index, axes in enumerate(axes_grid.flat):
        axes.set_axis_off()
        if index < len(panels):
            axes.imshow(panels[index].image, interpolation="bilinear")
            axes.set_title(panels[index].title, fontsize=title_size)
    figure.suptitle(title, fontsize=12, fontweight="bold")
    figure.tight_layout()
    return save_figure(figure, path)


def camera_views(images: dict[str, np.ndarray], labels: dict[str, float], path: str | os.PathLike,
                 *, title: str, notes: dict[str, str] | None = None) -> Path:
    """Left, center and right frames of one row, each titled with the steering label it trains
    with (``notes[camera]`` may say how the label was made)."""
    notes = notes or {}
    panels = []
    for camera in ("left", "center", "right"):
        if camera in images:
            text = f"{camera} camera: label {labels[camera]:+.3f}"
            if notes.get(camera):
                text += f"\n{notes[camera]}"
            panels.append(Panel(images[camera], text))
    return panel_grid(panels, path, title=title, columns=3)


def augmentation_examples(image: np.ndarray, steering: float, path: str | os.PathLike, *,
                          title: str, seed: int = 0) -> Path:
    """One frame through each training augmentation (:mod:`clonedrive.data.augment`) with the
    label it ends up with: original, flip, brightness, shadow, shift, and one random draw of
    all of them together (seeded)."""
    from clonedrive.data.augment import (
        STEERING_PER_PX,
        AugmentConfig,
        augment_batch,
        flip_horizontal,
        shade,
        shift_and_flip,
    )

    batch = image[None]
    label = np.array([steering], dtype=np.float32)
    width = image.shape[1]
    one = np.ones(1, dtype=np.float32)
    no = np.zeros(1, dtype=bool)
    yes = np.ones(1, dtype=bool)

    flipped, flipped_label = flip_horizontal(batch, label)
    darker = shade(batch, 0.55 * one, no, 0 * one, 0 * one, one, no)
    shadow = shade(batch, one, yes, np.array([0.35 * width], np.float32),
                   np.array([0.6 * width], np.float32), 0.55 * one, no)
    shift_px = 30
    shifted, shifted_label = shift_and_flip(batch, label, np.array([shift_px]), np.array([0]), no)
    random_image, random_label = augment_batch(batch, label, np.random.default_rng(seed),
                                               AugmentConfig(shadow_probability=1.0))
    panels = [
        Panel(image, f"original: label {steering:+.3f}"),
        Panel(flipped[0], f"flip (mirrored): label {float(flipped_label[0]):+.3f}"),
        Panel(darker[0], f"brightness x0.55: label {steering:+.3f}"),
        Panel(shadow[0], f"shadow (one side x0.55): label {steering:+.3f}"),
        Panel(shifted[0], f"shift {shift_px} px right: label {float(shifted_label[0]):+.3f}\n"
                          f"(+{shift_px} px x {STEERING_PER_PX:g} per px)"),
        Panel(random_image[0], f"random draw of all (seed {seed}): label "
                               f"{float(random_label[0]):+.3f}"),
    ]
    return panel_grid(panels, path, title=title, columns=3)


def video_stills(frames: Sequence[tuple[float, np.ndarray]], path: str | os.PathLike, *,
                 title: str) -> Path:
    """A strip of frames from one video, each titled with its time."""
    panels = [Panel(frame, f"t = {time_s:.1f} s") for time_s, frame in frames]
    return panel_grid(panels, path, title=title, columns=len(panels), panel_width_in=4.0)


def failure_frames(panels: Sequence[Panel], path: str | os.PathLike, *, title: str,
                   columns: int = 3) -> Path:
    """The frames the network saw when the car left the road, one titled panel per event."""
    return panel_grid(panels, path, title=title, columns=columns, panel_width_in=4.0,
                      title_size=9.5)
