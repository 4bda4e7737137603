"""The samples a recipe expands into: flat per-sample arrays, one entry per camera image
(and mirrored copy) that training sees.

:func:`clonedrive.data.recipe.expand` makes them; balancing, splitting
(:mod:`clonedrive.data.split`), the next-frame partners (:mod:`clonedrive.data.neighbours`)
and the batches (:mod:`clonedrive.data.batches`) take subsets of them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Samples:
    """Flat per-sample arrays; sample ``i`` is camera ``driving_log.CAMERAS[camera[i]]`` of CSV line
    ``row[i]`` of recording ``recording_names[recording[i]]``, mirrored if ``flip[i]``.

    ``image_paths`` index into ``unique_paths`` (``image_index``) so that a picture used by
    several samples (a flipped copy) is decoded and cached once.
    """

    unique_paths: list[Path]  # every distinct image file
    image_index: np.ndarray  # (n,) int64 index into unique_paths
    camera: np.ndarray  # (n,) int8 index into CAMERAS
    steering: np.ndarray  # (n,) float32 label, [-1, 1], after correction, offset and flip
    flip: np.ndarray  # (n,) bool: mirror the image horizontally
    recording: np.ndarray  # (n,) int32 index into recording_names
    row: np.ndarray  # (n,) int64 1-based CSV line of the sample
    time_s: np.ndarray  # (n,) float64 seconds since the recording's first row
    weight: np.ndarray  # (n,) float32 loss weight
    #: (n,) float32 the speed label [mph]: the expert's target speed where the log has one
    #: (``target_speed.csv``), else the recorded speed (human and Udacity logs)
    target_speed_mph: np.ndarray
    recorded_speed_mph: np.ndarray  #: (n,) float32 the row's recorded speed [mph]
    recording_names: tuple[str, ...]
    skipped: dict[str, int]  # reason -> rows skipped by the log reader, all recordings
    skipped_details: list[str]  # "recording: detail" for every skipped row
    rows_read: int  # usable CSV rows over all recordings
    side_images_missing: int = 0  # of those, rows with a side camera off (its image missing)
    rows_with_target_speed: int = 0  # of those, rows with the expert's target speed

    def __len__(self) -> int:
        return int(self.steering.shape[0])

    def image_path(self, index: int) -> Path:
        return self.unique_paths[int(self.image_index[index])]

    def subset(self, indices: np.ndarray) -> Samples:
        """The samples at ``indices`` (the image table is shared, not copied)."""
        indices = np.asarray(indices, dtype=np.int64)
        return dataclasses.replace(
            self,
            image_index=self.image_index[indices],
            camera=self.camera[indices],
            steering=self.steering[indices],
            flip=self.flip[indices],
            recording=self.recording[indices],
            row=self.row[indices],
            time_s=self.time_s[indices],
            weight=self.weight[indices],
            target_speed_mph=self.target_speed_mph[indices],
            recorded_speed_mph=self.recorded_speed_mph[indices],
        )

    def compact(self) -> Samples:
        """The same samples with ``unique_paths`` cut down to the images they use."""
        used, inverse = np.unique(self.image_index, return_inverse=True)
        return dataclasses.replace(
            self,
            unique_paths=[self.unique_paths[int(index)] for index in used],
            image_index=inverse.reshape(-1).astype(np.int64),
        )

    def drop_images(self, bad_images: Iterable[int]) -> tuple[Samples, int]:
        """Drop samples whose image (index into ``unique_paths``) is in ``bad_images``;
        returns the remaining samples and the number dropped."""
        bad = np.zeros(len(self.unique_paths), dtype=bool)
        bad[np.fromiter(bad_images, dtype=np.int64)] = True
        keep = np.flatnonzero(~bad[self.image_index])
        return self.subset(keep), len(self) - len(keep)
