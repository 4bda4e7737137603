"""Training: the settings, the split and what it means, the loss per epoch.
"""

from __future__ import annotations

import math

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.model.history import HISTORY_NAME, read_history
from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext, copy_figure
from clonedrive.report.document import Figure, Paragraph, Section, Table


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["training"]
    train = ctx.parts.train_dir
    if train is None:
        return ctx.missing(title, "No training folder: training section skipped.")
    settings = ctx.train_config
    history = read_history(train / HISTORY_NAME)
    if settings is None and not history:
        return ctx.missing(title, f"No `config.json` or `history.csv` in `{train}`: "
                                  "training section skipped.")
    section = Section(title)
    split = (ctx.dataset or {}).get("split") or {}
    kind = split.get("kind") or (settings or {}).get("split")
    earlier = _earlier_stages(train)
    if settings is not None:
        from clonedrive.model.train_config import TrainConfig

        val_fraction = settings.get("val_fraction", TrainConfig().val_fraction)
        rows = [
            ("architecture", f"`{settings.get('model', '?')}`"),
            ("optimiser", f"Adam, learning rate {settings.get('learning_rate', '?')}"),
            ("loss", f"{settings.get('loss', 'mse')} on the steering label"
                     + (f", plus {float(settings['consistency']):g} x the squared "
                        "difference of neighbouring frames' errors (consistency)"
                        if settings.get("consistency") else "")),
            ("batch size", str(settings.get("batch_size", "?"))),
            ("epochs", _epochs_text(earlier, history, settings)
                       + (f", early stopping after {settings['early_stopping_patience']} "
                          "epochs without improvement"
                          if settings.get("early_stopping_patience") else "")),
            ("balancing", "on" if settings.get("balance") else "off"),
            ("augmentation", "on" if settings.get("augment") else "off"),
            ("dropout", str(settings.get("dropout", 0.0))),
            ("split", f"**{kind}**, {fmt.num(100 * val_fraction, 0)} % "
                      "for validation"
                      + (f" (blocks of {settings.get('block_s')} s)" if kind == "blocks"
                         else "")),
            ("seed", str(settings.get("seed", "?"))),
        ]
        section.blocks.append(Table(("setting", "value"), tuple(rows)))
    else:
        section.blocks.append(ctx.note(f"No `config.json` in `{train}`: settings unknown."))
    section.blocks.append(Paragraph(_split_text(kind, split.get("description"))))

    base_history = [row for _, rows in earlier for row in rows]
    base = len(earlier[0][1]) if earlier else 0  # the first stage's epochs
    history = _numbered_on(base_history, history)  # one numbering for headline, table and plot
    if history:
        best = min(history, key=lambda r: r.get("val_loss", math.inf)
                   if math.isfinite(r.get("val_loss", math.nan)) else math.inf)
        stages = (f"{fmt.plural(base, 'epoch')} from scratch (`base/`), then "
                  + _fine_tunes([len(rows) for _, rows in earlier[1:]] + [len(history)])
                  if base else fmt.plural(len(history), 'epoch'))
        ctx.headline(
            f"Training: {stages}, best validation loss "
            f"{fmt.num(best.get('val_loss'), 4)} at epoch {best['epoch']} ({kind} split).")
        if base:
            section.blocks.append(Paragraph(_stages_text(earlier)))
        columns = [c for c in ("loss", "val_loss", "mse", "val_mse", "seconds")
                   if any(c in row for row in base_history + history)]
        headers = ("epoch", *[{"loss": "training loss", "val_loss": "validation loss",
                               "mse": "training MSE", "val_mse": "validation MSE",
                               "seconds": "seconds"}[c] for c in columns], "")
        table_rows = tuple(
            (f"{row['epoch']} (stage {number})", *[_cell(row, c) for c in columns], "")
            for number, (_, rows) in enumerate(earlier, start=1) for row in rows) + tuple(
            (str(row["epoch"]) + (f" (stage {len(earlier) + 1})" if base else ""),
             *[_cell(row, c) for c in columns], "best" if row is best else "")
            for row in history)
        whose = "the fine-tune's epoch" if base else "the epoch"
        section.blocks.append(Paragraph(
            "Loss per epoch (training loss is measured on augmented pictures while the "
            "weights change, validation loss on untouched pictures after the epoch; "
            f"`model.keras` is {whose} with the lowest validation loss):"))
        section.blocks.append(Table(headers, table_rows, align="l" + "r" * len(columns) + "l"))
    else:
        section.blocks.append(ctx.note(f"No `history.csv` in `{train}`: no loss table."))
    figure_path = _loss_figure(ctx, train, base_history, base, history, settings)
    if figure_path is not None:
        section.blocks.append(Figure(figure_path, "Training and validation loss per epoch."))
    return [section]


def _epochs_text(earlier: list[tuple[str, list[dict]]], history: list[dict],
                 settings: dict) -> str:
    """How many epochs ran: one stage's against its setting, or every stage's."""
    if not earlier:
        return f"{len(history)} trained ({settings.get('epochs', '?')} configured)"
    counts = [len(rows) for _, rows in earlier] + [len(history)]
    return (f"{sum(counts)} trained in {len(counts)} stages ({' + '.join(map(str, counts))}); "
            f"the last stage's settings here")


def _split_text(kind: str | None, description: str | None) -> str:
    caveat = (f"Neighbouring frames are 1/{CONTROL_HZ:g} s apart and nearly identical, so a "
              "**random split** puts a near-twin of almost every validation frame into the "
              "training set: it flatters the validation loss, which then says little about "
              "driving.")
    texts = {
        "random": f"**Split used: random** (samples drawn at random). {caveat} The closed-loop "
                  "results below are the real test.",
        "blocks": "**Split used: blocks**: whole stretches of driving go to validation, so "
                  f"validation frames have no near-twins in training. {caveat} Blocks avoid "
                  "that; the validation loss is still measured on the same tracks.",
        "recording": "**Split used: recording**: whole recordings are held out for validation, "
                     f"the most honest of the three. {caveat}",
    }
    text = texts.get(kind or "", f"**Split used: {kind or 'unknown'}**. {caveat}")
    if description:
        text += f" This run: {description}."
    return text


def _fine_tunes(epochs: list[int]) -> str:
    """``a fine-tune of 2 epochs``, or ``2 fine-tune stages of 2 + 1 epochs``."""
    if len(epochs) == 1:
        return f"a fine-tune of {fmt.plural(epochs[0], 'epoch')}"
    return f"{len(epochs)} fine-tune stages of {' + '.join(map(str, epochs))} epochs"


def _stages_text(earlier: list[tuple[str, list[dict]]]) -> str:
    """What a multi-stage training did, for the stages before the last ``earlier``."""
    into = [f"{len(rows)} epoch(s) into `{name}/`" for name, rows in earlier]
    tables = "`[finetune]`" if len(earlier) == 1 else "`[[finetune]]` tables"
    return (f"Training ran in {len(earlier) + 1} stages (the recipe's {tables}): "
            f"{fmt.listed(into)}, each stage from the best model of the one before, the last "
            "with the settings above. The table and the plot number the epochs of all stages "
            "in a row.")


def _loss_figure(ctx: ReportContext, train, base_history: list[dict], base: int,
                 history: list[dict], settings: dict | None):
    """The loss plot: training's own ``loss.png`` for one stage; for more, a plot of every
    stage's epochs in a row (``base_history``: the stages before the last; training's plot
    holds the last stage only), the fine-tune marked where it starts, after the first stage's
    ``base`` epochs; None without a history."""
    loss_png = ctx.run_file(train, "loss.png")
    if loss_png is not None and not (base_history and history):
        return copy_figure(loss_png, ctx.figures_dir, "loss.png")
    if not history:
        return None
    from clonedrive.model.checkpoints import plot_loss

    return plot_loss(base_history + history, ctx.figures_dir / "loss.png",
                     consistency=bool((settings or {}).get("consistency")),
                     second_stage_from=base + 1 if base else None)


def _numbered_on(base_history: list[dict], history: list[dict]) -> list[dict]:
    """``history`` (the last stage's epochs) numbered on from the first stage's last epoch:
    unchanged without a first stage."""
    offset = max((row["epoch"] for row in base_history), default=0)
    return [{**row, "epoch": offset + row["epoch"]} for row in history] if offset else history


def _cell(row: dict, column: str) -> str:
    return fmt.num(row.get(column), 1 if column == "seconds" else 4)


def _earlier_stages(train) -> list[tuple[str, list[dict]]]:
    """``(folder name, epochs)`` of each training stage before the last (recipes.training):
    ``TRAIN/base/``, then ``TRAIN/stage2/``, ``TRAIN/stage3/`` ..., up to the first one with
    no readable epochs, the epochs numbered on in a row; [] without a first stage."""
    from clonedrive.recipes.training import earlier_stage_dirs

    stages: list[tuple[str, list[dict]]] = []
    done: list[dict] = []
    for folder in earlier_stage_dirs(train):
        try:
            rows = read_history(folder / HISTORY_NAME)
        except (OSError, ValueError):
            rows = []
        if not rows:
            break
        rows = _numbered_on(done, rows)
        done += rows
        stages.append((folder.name, rows))
    return stages
