"""Train/validation splits of samples.

Neighbouring frames of a recording are near-duplicates, so a purely random split puts
almost the same picture on both sides and flatters the validation loss. Three kinds:

- ``random``: a seeded shuffled split of CSV rows (``val_fraction`` of them to validation).
  All samples of one row -- its cameras and their flipped copies -- stay on the same side.
- ``blocks``: time is cut into contiguous blocks of ``block_s`` seconds per recording; whole
  blocks are drawn at random for validation until ``val_fraction`` of the rows is reached.
- ``recording``: whole recordings are drawn at random for validation until ``val_fraction``
  of the rows is reached (needs at least two recordings).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clonedrive.data.samples import Samples

SPLIT_KINDS = ("random", "blocks", "recording")
DEFAULT_BLOCK_S = 10.0


@dataclass(frozen=True)
class Split:
    """Indices (into the samples split) of the training and validation samples."""

    kind: str
    train: np.ndarray  # sorted int64
    val: np.ndarray  # sorted int64
    description: str  # one line for a person, names the kind


def split_samples(
    samples: Samples,
    kind: str,
    rng: np.random.Generator,
    *,
    val_fraction: float = 0.2,
    block_s: float = DEFAULT_BLOCK_S,
) -> Split:
    """Split ``samples`` into training and validation sets (see module doc for ``kind``)."""
    if kind not in SPLIT_KINDS:
        raise ValueError(f"unknown split {kind!r}; expected one of: {', '.join(SPLIT_KINDS)}")
    if not 0.0 < val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction}")
    if len(samples) == 0:
        raise ValueError("no samples to split")

    # A group is the unit that goes to one side: a row, a block of time or a recording.
    if kind == "random":
        keys = np.stack([samples.recording.astype(np.int64), samples.row], axis=1)
    elif kind == "blocks":
        if block_s <= 0:
            raise ValueError(f"block_s must be > 0, got {block_s}")
        block = np.floor(samples.time_s / block_s).astype(np.int64)
        keys = np.stack([samples.recording.astype(np.int64), block], axis=1)
    else:
        keys = samples.recording.astype(np.int64)[:, None]
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.reshape(-1)
    group_count = int(group.max()) + 1
    if group_count < 2:
        unit = {"random": "row", "blocks": "time block", "recording": "recording"}[kind]
        raise ValueError(
            f"split {kind!r} needs at least two of a {unit} to put one on each side; "
            f"found {group_count}"
        )

    # Rows per group (each row counts once, whatever its cameras and flips).
    row_keys = np.stack([samples.recording.astype(np.int64), samples.row], axis=1)
    _, first_of_row = np.unique(row_keys, axis=0, return_index=True)
    rows_per_group = np.bincount(group[first_of_row], minlength=group_count)
    wanted = val_fraction * rows_per_group.sum()

    order = rng.permutation(group_count)
    taken = np.cumsum(rows_per_group[order])
    # Smallest prefix of the shuffled groups that reaches the wanted rows, leaving >= 1 group.
    count = int(np.searchsorted(taken, wanted, side="left")) + 1
    count = min(max(count, 1), group_count - 1)
    is_val_group = np.zeros(group_count, dtype=bool)
    is_val_group[order[:count]] = True

    is_val = is_val_group[group]
    train, val = np.flatnonzero(~is_val), np.flatnonzero(is_val)
    val_rows = int(rows_per_group[is_val_group].sum())
    total_rows = int(rows_per_group.sum())
    what = {
        "random": "rows shuffled at random",
        "blocks": f"contiguous {block_s:g} s blocks of time",
        "recording": "whole recordings",
    }[kind]
    description = (
        f"split '{kind}' ({what}): {len(train)} training / {len(val)} validation samples; "
        f"{val_rows}/{total_rows} rows ({val_rows / total_rows:.1%}) in {count} of "
        f"{group_count} groups to validation"
    )
    if kind == "recording":
        names = sorted({samples.recording_names[int(index)] for index in samples.recording[val]})
        description += f" ({', '.join(names)})"
    return Split(kind=kind, train=train, val=val, description=description)
