"""A recipe's training, in stages.

A recipe's ``[train]`` table is the first stage. An optional ``[finetune]`` table is a second
stage that starts from the first stage's best model, with ``[finetune]``'s settings over
``[train]``'s (the lab notes' recipe: a plain start, then a short fine-tune with the
consistency penalty at a lower learning rate). ``[[finetune]]`` tables instead make one stage
each, in order, each from the best model of the one before and with its settings over that
stage's. The first stage's run folder is ``OUT/base/``, the last one's ``OUT/`` itself (so
``OUT/model.keras`` is always the model) and those between ``OUT/stage2/``, ``OUT/stage3/``, ...

A stage whose run folder holds a finished run (``state.json`` with all its epochs) is reused;
one with fewer epochs done is resumed from its ``last.keras``.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Iterator
from pathlib import Path

#: Where the first stage of a recipe with a fine-tune trains, inside the training folder.
BASE_STAGE_DIR = "base"
#: Where stage N (2, 3, ...) trains when it is not the last: f"{MIDDLE_STAGE_DIR}{N}".
MIDDLE_STAGE_DIR = "stage"


def train_stages(recipe, **overrides) -> list:
    """The TrainConfig of each stage of ``recipe``: ``[train]`` with ``overrides`` on top,
    then each fine-tune table over the stage before it (a stage's ``init_from`` is set when the
    stage before it has run)."""
    stages = [recipe.train_config(**overrides)]
    for number, table in enumerate(recipe.finetune, start=1):
        try:
            stages.append(dataclasses.replace(stages[-1], **table))
        except (TypeError, ValueError) as error:
            where = "[finetune]" if len(recipe.finetune) == 1 else f"[[finetune]] #{number}"
            raise ValueError(f"{recipe.source}: {where}: {error}") from None
    return stages


def stage_dirs(out_dir: str | Path, count: int) -> list[Path]:
    """The run folder of each of ``count`` stages trained into ``out_dir``: ``base/``, then
    ``stage2/`` ... for the stages between, and ``out_dir`` itself for the last."""
    out = Path(out_dir)
    return [*itertools.islice(earlier_stage_dirs(out), count - 1), out]


def earlier_stage_dirs(out_dir: str | Path) -> Iterator[Path]:
    """The run folders, in order and without end, of the stages before the last of a training
    into ``out_dir``: ``base/``, ``stage2/``, ``stage3/`` ... (a reader stops at the first one
    that holds no run)."""
    out = Path(out_dir)
    yield out / BASE_STAGE_DIR
    for number in itertools.count(2):
        yield out / f"{MIDDLE_STAGE_DIR}{number}"


def run_stages(stages: list, data, out_dir: str | Path, *, notes: dict | None = None,
               progress: bool = True):
    """Train every stage into its folder (:func:`stage_dirs`), each from the one before;
    reuses finished stages and resumes interrupted ones. A stage reuses the images the stage
    before it decoded when its data set is the same (:class:`ImageHandoff`). Returns the last
    stage's TrainResult, or None when every stage was already finished."""
    from clonedrive.data.dataset import ImageHandoff
    from clonedrive.model.train import train

    result = None
    previous: Path | None = None
    handoff = ImageHandoff()
    try:
        for number, (config, folder) in enumerate(zip(stages, stage_dirs(out_dir, len(stages)),
                                                      strict=True), start=1):
            if previous is not None:
                config = dataclasses.replace(config, init_from=str(previous / "model.keras"))
            done = _epochs_done(folder)
            previous = folder
            if done >= config.epochs and (folder / "model.keras").is_file():
                _say(progress, f"[train] stage {number} of {len(stages)}: already trained, "
                               "reused")
                continue
            _say(progress, f"[train] stage {number} of {len(stages)}: {config.model} for "
                           f"{config.epochs} epoch(s)" + (f", consistency {config.consistency:g}"
                                                          if config.consistency else ""))
            result = train(config, data, folder, resume=done > 0, progress=progress,
                           notes=notes, handoff=handoff)
    finally:
        handoff.close()
    return result


def _epochs_done(folder: Path) -> int:
    state = folder / "state.json"
    if not state.is_file():
        return 0
    try:
        return int(json.loads(state.read_text(encoding="utf-8")).get("epochs_done", 0))
    except (ValueError, OSError, AttributeError):
        return 0


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, flush=True)
