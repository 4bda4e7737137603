"""``clonedrive train``: train a steering network on recordings."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from clonedrive.commands.counts import (
    MAX_BATCH_SIZE,
    MAX_CROP_TOP_PX,
    MAX_EPOCHS,
    MAX_PATIENCE,
    MAX_STAGES,
    MAX_TRAIN_WORKERS,
    count,
)
from clonedrive.model.losses import SPEED_LOSSES

MODEL_CHOICES = ("seed", "pilotnet", "fast")

HELP = "train a Keras steering network on recordings (folders, with a recipe's settings)"
DESCRIPTION = (
    "Train a network that predicts steering (and with a speed head the expert's target speed) "
    "from one 160x320 RGB camera frame. The settings come from a recipe (--recipe, default "
    "'best'; 'writeup' is the seed write-up's): the network, "
    "epochs, learning rate, crop, side-camera correction, and how the model is to be driven, "
    "which is stored in the model file. Options override it one by one. Data comes from "
    "recording folders DIR ... (center + side cameras, mirrored copies), from the recipe's own "
    "recordings (--data FOLDER holding them by name, as `clonedrive demo` records them), or "
    "from a data recipe file (--recipe "
    "data.toml: recordings with per-recording cameras, steering offset, flips, weight). "
    "Steering may be balanced (the write-up's 20-bin method), is split "
    "into training and validation sets (--split random|blocks|recording), augmented for "
    "training, and fitted with Adam on MSE (with --speed-head also on the expert's target "
    "speed, from target_speed.csv, or the recorded speed for logs without one). The --out "
    "folder receives model.keras (best "
    "validation loss), last.keras (every epoch), model.h5, history.csv, loss.png, config.json, "
    "recipe.toml, dataset.json and steering_before/after.png. An interrupted run continues "
    "with --resume --out FOLDER. A recipe may train in stages, each from the model of the one "
    "before ('best': 3 epochs, then fine-tune stages of 2 and 1 epochs with the consistency "
    "penalty): the options set the first stage, and the later stages take them too except the "
    "settings their own tables set ('best': epochs, learning rate, consistency). --stages N "
    "trains the first N stages only. The plan is printed before training starts."
)
#: Example command lines, shown at the end of ``clonedrive train --help``.
EXAMPLES = (
    "clonedrive train data/middle data/weave --out runs/x      # recipe 'best'",
    "clonedrive train --recipe best --data runs/demo/data --out runs/y   # the demo's model",
    "clonedrive train data/middle --recipe writeup --epochs 3 --out runs/z",
    "clonedrive train data/middle --epochs 1 --stages 1 --out runs/v   # one epoch, no fine-tune",
    "clonedrive train --recipe runs/demo/train/recipe.toml --out runs/w   # a data recipe",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.model.train_config import TrainConfig
    from clonedrive.recipes.book import recipe_choices_text

    d = TrainConfig()
    r = "default: the recipe's, else"  # an option left out takes the recipe's value
    given = argparse.SUPPRESS  # an option not given leaves no attribute (see _overrides)
    parser.add_argument("dirs", nargs="*", metavar="DIR",
                        help="recording folders (driving_log.csv + IMG/), default recipe each")
    parser.add_argument("--recipe", default=None, metavar="NAME|FILE",
                        help=f"a built-in recipe ({recipe_choices_text()}) or a recipe file: the "
                             "training and driving settings, and with no DIRs the data "
                             "(default: best); or a data recipe file (its recordings, with "
                             "best's settings)")
    parser.add_argument("--data", type=Path, default=None, metavar="FOLDER",
                        help="the folder holding a recipe's recordings by name (no DIRs)")
    parser.add_argument("--out", type=Path, required=True, help="run folder to write")
    parser.add_argument("--model", default=given, choices=MODEL_CHOICES,
                        help=f"architecture ({r} {d.model})")
    parser.add_argument("--epochs", type=count(MAX_EPOCHS), default=given,
                        help=f"epochs of the first stage ({r} {d.epochs}); a recipe's "
                             "fine-tune stages add their own ('best': 3, then 2 + 1)")
    parser.add_argument("--lr", dest="learning_rate", type=float, default=given,
                        help=f"Adam learning rate of the first stage ({r} "
                             f"{d.learning_rate:g}); a fine-tune stage that sets its own keeps it")
    parser.add_argument("--batch-size", type=count(MAX_BATCH_SIZE), default=given,
                        help=f"batch size ({r} {d.batch_size})")
    parser.add_argument("--split", default=given, choices=("random", "blocks", "recording"),
                        help=f"train/validation split ({r} {d.split})")
    parser.add_argument("--val-fraction", type=float, default=given,
                        help=f"share of rows for validation ({r} {d.val_fraction})")
    parser.add_argument("--block-s", type=float, default=given,
                        help=f"block length of --split blocks, seconds ({r} {d.block_s:g})")
    parser.add_argument("--correction", type=float, default=given,
                        help=f"side-camera steering correction for DIRs ({r} {d.correction})")
    parser.add_argument("--no-balance", dest="balance", action="store_false", default=given,
                        help="keep every sample (no steering histogram balancing)")
    parser.add_argument("--no-augment", dest="augment", action="store_false", default=given,
                        help="no training augmentation")
    parser.add_argument("--shift-steering", dest="shift_steering_per_px", type=float,
                        default=given, metavar="S",
                        help=f"label change per pixel of the augmentation's horizontal shift "
                             f"({r} {d.shift_steering_per_px:g}); a shift of the picture "
                             "looks like a heading error, so S sets the heading gain the "
                             "network learns")
    parser.add_argument("--augment-looks", type=float, default=given, metavar="P",
                        help=f"share of training frames restyled: a colour cast, lower "
                             f"contrast, haze, blur, noise ({r} {d.augment_looks:g})")
    parser.add_argument("--looks-saturation", type=float, default=given, metavar="S",
                        help=f"a restyled frame's colour saturation is drawn in [S, 1]: 0 "
                             f"allows grey frames ({r} {d.looks_saturation:g}: colours kept)")
    parser.add_argument("--early-stopping", dest="early_stopping_patience",
                        type=count(MAX_PATIENCE), default=given, metavar="PATIENCE",
                        help="stop after PATIENCE epochs without a better validation loss")
    parser.add_argument("--dropout", type=float, default=given,
                        help=f"dropout rate, 0 = off ({r} {d.dropout})")
    parser.add_argument("--seed", type=int, default=given,
                        help=f"random seed ({r} {d.seed})")
    parser.add_argument("--workers", type=count(MAX_TRAIN_WORKERS), default=given,
                        help=f"batch-preparing threads ({r} {d.workers})")
    parser.add_argument("--cache", default=given, choices=("auto", "memory", "memmap"),
                        help=f"where decoded images live ({r} {d.cache})")
    parser.add_argument("--speed-head", action="store_true", default=given,
                        help="also learn the expert's target speed (a second output, "
                             "'target_speed'); drive, evaluate and bench then use it, capped "
                             "by the set speed. Udacity's own drive.py expects one output")
    parser.add_argument("--speed-loss-weight", type=float, default=given,
                        help=f"weight of the speed loss ({r} {d.speed_loss_weight:g})")
    parser.add_argument("--speed-loss", default=given, choices=SPEED_LOSSES,
                        help=f"the speed head's loss ({r} {d.speed_loss}); censored: a "
                             "label at the top speed (every straight) means 'at least that', so "
                             "predicting above it costs nothing")
    parser.add_argument("--speed-headroom", type=float, default=given, metavar="H",
                        help=f"speed labels at the top speed (every straight) continue the "
                             f"expert's braking profile above it, up to H times it, H in [1, 2] "
                             f"({r} {d.speed_headroom:g}: off). The policy caps the learned "
                             "speed at the set speed, so the head's scatter on a straight lands "
                             "above the cap, not below (see data/speed_labels.py)")
    parser.add_argument("--crop-top", dest="crop_top_px", type=count(MAX_CROP_TOP_PX),
                        default=given, metavar="PX",
                        help=f"rows cut from the top of the frame ({r} {d.crop_top_px}: the "
                             "road 2-7 m ahead; 60 sees about 36 m, bends a speed head must "
                             "brake for)")
    parser.add_argument("--consistency", type=float, default=given, metavar="W",
                        help=f"train each sample beside its next frame (1/15 s later) and add W "
                             f"times the squared difference of their errors to the steering "
                             f"loss: less frame-to-frame noise in the predicted steering, a "
                             f"steadier wheel, in the first stage ({r} {d.consistency:g}: off; "
                             "'best' sets it in its fine-tune stages). Each step then takes "
                             "twice the images (see model/consistency.py)")
    parser.add_argument("--stages", type=count(MAX_STAGES), default=None, metavar="N",
                        help="train the recipe's first N stages only (default: all; 1: the "
                             "first stage alone, no fine-tune)")
    parser.add_argument("--init-from", type=str, default=given, metavar="MODEL",
                        help="start from this model's weights (layers matched by name)")
    parser.add_argument("--no-h5", dest="export_h5", action="store_false", default=given,
                        help="do not write model.h5")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in --out from its last.keras (its recipe.toml "
                             "and config.json; only --epochs/--early-stopping/--workers change)")
    parser.add_argument("--json", action="store_true",
                        help="no progress output; print one JSON object at the end")


def _overrides(args: argparse.Namespace, config_class) -> dict:
    """The options given on the command line that are fields of ``config_class`` (options left
    out stay unset, so a resumed run keeps its own settings)."""
    import dataclasses

    return {field.name: getattr(args, field.name) for field in dataclasses.fields(config_class)
            if hasattr(args, field.name)}


def run(args: argparse.Namespace) -> int:
    from clonedrive.model.train_config import TrainConfig

    try:  # the options alone first, so that a refused value is named as the command line's
        _settings(lambda: TrainConfig(**_overrides(args, TrainConfig)), source="command line")
    except _BadOption as error:
        print(f"clonedrive train: {error}", file=sys.stderr)
        return 2
    missing = _missing_input(args)
    if missing:  # before Keras loads, which takes seconds
        print(f"clonedrive train: {missing}", file=sys.stderr)
        return 1
    from clonedrive.data.output_lock import claim_output

    out: Path = args.out
    try:
        stages, source, notes = _plan(args)
    except _BadOption as error:  # refused before anything is read
        print(f"clonedrive train: {error}", file=sys.stderr)
        return 2
    except (ValueError, FileNotFoundError) as error:
        print(f"clonedrive train: {error}", file=sys.stderr)
        return 1
    if not args.json:
        print(plan_text(stages), flush=True)
    try:
        inputs = [*args.dirs, *([args.recipe] if _is_file(args.recipe) else [])]
        with claim_output("train", out, inputs=inputs):
            result = _train(stages, source, out, args, notes)
    except (ValueError, FileNotFoundError, FileExistsError) as error:
        print(f"clonedrive train: {error}", file=sys.stderr)
        return 1

    summary = {
        "out_dir": str(result.out_dir),
        "model": str(result.model_path),
        "epochs_done": result.epochs_done,
        "best_epoch": result.best_epoch,
        "best_val_loss": result.best_val_loss,
        "stopped_early": result.stopped_early,
        "split": result.dataset["split"]["kind"],
        "train_samples": result.dataset["train_samples"],
        "val_samples": result.dataset["val_samples"],
        "skipped_rows": result.dataset["skipped_rows"],
        "skipped_images": result.dataset["skipped_images"],
        "stages": len(stages),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        stage = f" of stage {len(stages)}" if len(stages) > 1 else ""
        print(
            f"best epoch {result.best_epoch} of {result.epochs_done}{stage}: val_loss "
            f"{result.best_val_loss:.5f} ({summary['split']} split) -> {result.model_path}"
        )
    return 0


def plan_text(stages: list) -> str:
    """What a training will run, before it starts: each stage's epochs and what it changes."""
    lines = [f"[plan] {len(stages)} stage(s), {sum(c.epochs for c in stages)} epoch(s) in all:"]
    for number, config in enumerate(stages, start=1):
        start = "from scratch" if number == 1 and config.init_from is None else (
            "from the stage before" if number > 1 else f"from {config.init_from}")
        extra = f", consistency {config.consistency:g}" if config.consistency else ""
        lines.append(f"  stage {number}: {config.model}, {config.epochs} epoch(s) {start}, "
                     f"learning rate {config.learning_rate:g}{extra}")
    return "\n".join(lines)


def _train(stages: list, source, out: Path, args: argparse.Namespace, notes: dict | None):
    """One stage as ``train`` always did; a recipe with a fine-tune as two (recipes.training),
    into a folder that holds no run unless ``--resume``."""
    from clonedrive.model.train import train

    if len(stages) == 1:
        return train(stages[0], source, out, resume=args.resume, progress=not args.json,
                     notes=notes)
    from clonedrive.recipes.training import run_stages, stage_dirs

    if not args.resume and any((folder / "state.json").exists()
                               for folder in stage_dirs(out, len(stages))):
        raise FileExistsError(f"{out} already holds a training run; resume it (--resume) or "
                              "choose another --out")
    result = run_stages(stages, source, out, notes=notes, progress=not args.json)
    if result is None:
        raise FileExistsError(f"{out}: every stage is already trained")
    return result


class _BadOption(ValueError):
    """An option value TrainConfig refuses (exit status 2, as argparse's own)."""


def _settings(make, *, source: str | None = None):
    try:
        return make()
    except ValueError as error:
        raise _BadOption(f"{source}: {error}" if source else str(error)) from None


def _plan(args: argparse.Namespace):
    """([TrainConfig per stage], the data, the notes the model files carry) from the command
    line: the recipe's settings with the options given on top (on its first stage; a
    fine-tune's own settings stay); a resumed one-stage run keeps its own."""
    import dataclasses

    from clonedrive.model.train import load_run_config
    from clonedrive.model.train_config import TrainConfig
    from clonedrive.recipes.book import DEFAULT_RECIPE, is_whole_recipe, load_recipe_file

    if args.resume and (args.out / "config.json").is_file():
        source = (Path(args.recipe) if _is_file(args.recipe) and not is_whole_recipe(args.recipe)
                  else None) or (args.dirs or None) or args.out / "recipe.toml"
        base = load_run_config(args.out)
        return ([_settings(lambda: dataclasses.replace(base, **_overrides(args, TrainConfig)))],
                source, None)
    if not args.recipe and not args.dirs:
        raise ValueError("nothing to train on: give DIR [DIR ...], --recipe FILE, or "
                         "--recipe NAME --data FOLDER")
    whole = args.recipe and is_whole_recipe(args.recipe)
    recipe = load_recipe_file(args.recipe if whole else DEFAULT_RECIPE)
    from clonedrive.recipes.training import train_stages

    stages = _settings(lambda: train_stages(recipe, **_overrides(args, TrainConfig)))
    if args.stages is not None and not 1 <= args.stages <= len(stages):
        raise _BadOption(f"--stages {args.stages}: recipe {recipe.name} has {len(stages)} "
                         f"stage(s); give 1 to {len(stages)}")
    stages = stages[:args.stages or len(stages)]
    if args.dirs:
        if args.recipe and not whole:
            raise ValueError("give either a data recipe file or DIRs, not both")
        source = recipe.folders_recipe(args.dirs, correction=getattr(args, "correction", None))
        stages = [dataclasses.replace(config, correction=source.recordings[0].correction)
                  for config in stages]
    elif whole:
        source = recipe.data_recipe(args.data) if args.data else recipe.data_recipe_without_data()
    else:
        source = Path(args.recipe)
    return stages, source, recipe.notes()


def _is_file(recipe: str | None) -> bool:
    return bool(recipe) and Path(recipe).is_file()


def _missing_input(args: argparse.Namespace) -> str | None:
    """What the command line names that does not exist (a recipe file, a recording folder)."""
    from clonedrive.recipes.book import BUILT_IN

    if args.recipe and args.recipe not in BUILT_IN and not Path(args.recipe).is_file():
        return (f"recipe not found: {args.recipe} (a recipe file, or one of the built-in "
                f"recipes: {', '.join(BUILT_IN)})")
    if args.data is not None and not Path(args.data).is_dir():
        return f"--data {args.data}: no such folder"
    for folder in args.dirs or ():
        path = Path(folder)
        if not path.exists():
            return (f"no driving log at {folder}: expected a folder holding driving_log.csv "
                    "and IMG/")
        if path.is_dir() and not (path / "driving_log.csv").is_file():
            return f"no driving log in {folder}: {_recordings_hint(path)}"
    return None


def _recordings_hint(folder: Path) -> str:
    """Where the recordings are when ``folder`` holds them rather than being one."""
    inside = sorted(str(child) for child in folder.iterdir()
                    if (child / "driving_log.csv").is_file())[:6]
    if inside:
        return f"it holds recordings; give them: clonedrive train {' '.join(inside)} ..."
    return "expected a folder holding driving_log.csv and IMG/"
