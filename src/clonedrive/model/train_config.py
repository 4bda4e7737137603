"""Training settings: :class:`TrainConfig`, every default of ``clonedrive train`` defined once
and checked, and the largest values training accepts."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from clonedrive.base.config import check_field_types
from clonedrive.data.augment import STEERING_PER_PX
from clonedrive.data.balance import DEFAULT_BINS
from clonedrive.data.dataset import DatasetConfig
from clonedrive.data.recipe import CORRECTION_RANGE, DEFAULT_CORRECTION
from clonedrive.data.split import DEFAULT_BLOCK_S
from clonedrive.network.crop import CROP_TOP_PX

#: The largest learning rate training accepts: above it Adam only diverges.
MAX_LEARNING_RATE = 1.0
#: The largest steering change per pixel of the shift augmentation: at it the largest shift
#: (40 px) moves a label by 0.8, most of the wheel's range.
MAX_SHIFT_STEERING_PER_PX = 0.02
#: The largest count each setting takes, from the command line or a recipe file alike: a
#: batch, a worker pool or a history is sized from them before training starts.
MAX_COUNTS = {"epochs": 10_000, "batch_size": 65_536, "early_stopping_patience": 10_000,
              "workers": 1_024, "balance_bins": 10_000}


@dataclass(frozen=True)
class TrainConfig:
    """Training settings; defaults are the write-up's."""

    model: str = "seed"  # seed | pilotnet | fast (see model.architectures)
    learning_rate: float = 1e-4  # Adam
    loss: str = "mse"
    batch_size: int = 256
    epochs: int = 7  # total epochs, counting any done before a resume
    correction: float = DEFAULT_CORRECTION  # side-camera correction of a DIR-only recipe
    balance: bool = True  # the write-up's steering histogram balancing
    balance_bins: int = DEFAULT_BINS
    split: str = "random"  # random | blocks | recording (see data.split)
    val_fraction: float = 0.2
    block_s: float = DEFAULT_BLOCK_S  # block length of the "blocks" split, seconds
    augment: bool = True  # training-only augmentation (see data.augment)
    shift_steering_per_px: float = STEERING_PER_PX  # label change per pixel of augment's shift
    augment_looks: float = 0.0  # share of training frames restyled: cast, haze, blur, noise
    looks_saturation: float = 1.0  # a restyled frame's colour saturation drawn in [this, 1]
    seed: int = 0
    early_stopping_patience: int | None = None  # stop after this many epochs without a best
    dropout: float = 0.0  # 0 = off
    workers: int = 1  # PyDataset worker threads
    cache: str = "auto"  # decoded images: memory | memmap (a file in out_dir) | auto
    cache_memory_limit_mb: int = 2048  # "auto" uses a memmap above this size
    export_h5: bool = True  # also write model.h5
    speed_head: bool = False  # also learn the expert's target speed (output "target_speed")
    speed_loss_weight: float = 1.0  # weight of the speed MSE beside the steering MSE
    speed_loss: str = "mse"  # or "censored": labels at the top speed are lower bounds
    speed_headroom: float = 1.0  # labels at the top speed rise up to this multiple of it
    init_from: str | None = None  # start from this model's weights (layers matched by name)
    crop_top_px: int = CROP_TOP_PX  # rows the model cuts from the top (drivers.crop)
    consistency: float = 0.0  # weight of the next-frame consistency penalty (model.consistency)

    def __post_init__(self) -> None:
        check_field_types(self)  # epochs = 2.5, batch_size = true... named before anything
        if self.seed < 0:
            raise ValueError(f"seed must be at least 0, got {self.seed}")
        self.dataset_config()  # checks split and cache
        if self.batch_size < 1 or self.epochs < 1:
            raise ValueError("batch_size and epochs must be >= 1")
        low, high = CORRECTION_RANGE
        if not (math.isfinite(self.correction) and low <= self.correction <= high):
            raise ValueError(f"correction must be in [{low:g}, {high:g}], got {self.correction}")
        if not (math.isfinite(self.block_s) and self.block_s > 0):
            raise ValueError(f"block_s must be a positive number of seconds, got {self.block_s}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:  # also NaN and infinity
            raise ValueError(f"learning_rate must be in (0, {MAX_LEARNING_RATE:g}], got "
                             f"{self.learning_rate}")
        if not 0.0 <= self.shift_steering_per_px <= MAX_SHIFT_STEERING_PER_PX:  # also NaN
            raise ValueError(f"shift_steering_per_px must be in [0, "
                             f"{MAX_SHIFT_STEERING_PER_PX:g}], got {self.shift_steering_per_px}")
        if not 0.0 <= self.augment_looks <= 1.0:  # also NaN
            raise ValueError(f"augment_looks must be in [0, 1], got {self.augment_looks}")
        if not 0.0 <= self.looks_saturation <= 1.0:  # also NaN
            raise ValueError(f"looks_saturation must be in [0, 1], got {self.looks_saturation}")
        if not 0.0 <= self.dropout < 1.0:  # also NaN
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        if self.early_stopping_patience is not None and self.early_stopping_patience < 1:
            raise ValueError("early_stopping_patience must be >= 1 or None")
        for name, most in MAX_COUNTS.items():
            value = getattr(self, name)
            if value is not None and value > most:
                raise ValueError(f"{name} must be at most {most:,}, got {value:,}")
        if not (self.speed_loss_weight >= 0 and math.isfinite(self.speed_loss_weight)):
            raise ValueError(f"speed_loss_weight must be >= 0, got {self.speed_loss_weight}")
        from clonedrive.model.losses import SPEED_LOSSES

        if self.speed_loss not in SPEED_LOSSES:
            raise ValueError(f"speed_loss {self.speed_loss!r}; expected one of: "
                             f"{', '.join(SPEED_LOSSES)}")
        if not (math.isfinite(self.speed_headroom) and 1.0 <= self.speed_headroom <= 2.0):
            raise ValueError(f"speed_headroom must be in [1, 2], got {self.speed_headroom}")
        if not (math.isfinite(self.consistency) and self.consistency >= 0):
            raise ValueError(f"consistency must be >= 0, got {self.consistency}")
        if self.consistency and self.loss != "mse":
            raise ValueError(f"consistency adds to the mse loss, not to {self.loss!r}")

    def dataset_config(self) -> DatasetConfig:
        """The settings that make the data set (data.dataset)."""
        return DatasetConfig(**{setting.name: getattr(self, setting.name)
                                for setting in dataclasses.fields(DatasetConfig)})
