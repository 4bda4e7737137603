"""Temporal neighbours: which sample shows the next frame of the same camera.

A recording is a sequence of frames 1/15 s apart, and the expert's steering changes little from
one frame to the next. A network that answers two such frames far more differently than their
labels differ is reacting to noise in the picture (aliasing, a tree popping in), and that noise
is what makes a cloned car's wheel jitter. ``train --consistency`` trains on each sample together
with its next frame and penalises the difference of the two predictions that the labels do not
explain (:mod:`clonedrive.model.consistency`).
"""

from __future__ import annotations

import numpy as np

from clonedrive.data.samples import Samples


def next_frames(samples: Samples) -> np.ndarray:
    """``(n,)`` int64: for sample ``i`` the index of the sample showing the next CSV line of the
    same recording through the same camera, mirrored the same way; ``i`` itself where there is
    none among ``samples`` (the last line, or a neighbour balancing or the split left out)."""
    count = len(samples)
    keys = np.stack([samples.recording.astype(np.int64), samples.camera.astype(np.int64),
                     samples.flip.astype(np.int64), samples.row.astype(np.int64)], axis=1)
    order = np.lexsort(keys.T[::-1])  # by recording, camera, flip, then row
    ordered = keys[order]
    result = np.arange(count, dtype=np.int64)
    if count < 2:
        return result
    same_stream = np.all(ordered[1:, :3] == ordered[:-1, :3], axis=1)
    next_row = ordered[1:, 3] == ordered[:-1, 3] + 1
    linked = np.flatnonzero(same_stream & next_row)
    result[order[linked]] = order[linked + 1]
    return result
