"""Balancing the steering: the histograms before and after, and the sample counts.
"""

from __future__ import annotations

import numpy as np

from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext, copy_figure
from clonedrive.report.document import Figure, Gallery, Paragraph, Section, Table


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["balance"]
    train = ctx.parts.train_dir
    if train is None:
        return ctx.missing(title, "No training folder: balancing section skipped.")
    section = Section(title)
    dataset = ctx.dataset
    figures = []
    for stage in ("before", "after"):
        source = ctx.run_file(train, f"steering_{stage}.png")
        if source is not None:
            figures.append(copy_figure(source, ctx.figures_dir, source.name))
        elif dataset and "balance" in dataset:
            from clonedrive.data.balance import plot_histogram

            balance = dataset["balance"]
            figures.append(plot_histogram(
                np.asarray(balance[f"counts_{stage}"]), np.asarray(balance["bin_edges"]),
                ctx.figures_dir / f"steering_{stage}.png", title=f"steering {stage} balancing",
                target=balance.get("target_per_bin")))
    if dataset is None and not figures:
        return ctx.missing(title, f"No `dataset.json` or steering histograms in "
                                  f"`{train}`: balancing section skipped.")
    if dataset is not None:
        balance = dataset.get("balance", {})
        before = dataset.get("samples_before_balance")
        after = dataset.get("samples_after_balance")
        text = ("Driving is mostly straight ahead, so most labels sit near 0 and a network "
                "trained on them learns to go straight. ")
        if balance.get("enabled", True):
            bins = max(len(balance.get("bin_edges", [])) - 1, 0)
            text += (f"The write-up's balancing puts the labels into {bins} equal bins and "
                     "keeps a sample of an over-full bin with probability target / count, "
                     f"where the target is the mean count per bin "
                     f"({fmt.num(balance.get('target_per_bin'), 1)}).")
        else:
            text += "This run trained with balancing **off**."
        section.blocks.append(Paragraph(text))
        rows = [("usable CSV rows", fmt.count(dataset.get("rows_read"))),
                ("samples (cameras × flips) before balancing", fmt.count(before)),
                ("samples after balancing", fmt.count(after))]
        if before:
            rows.append(("kept", f"{100.0 * (after or 0) / before:.1f} %"))
        rows += [("training samples", fmt.count(dataset.get("train_samples"))),
                 ("validation samples", fmt.count(dataset.get("val_samples")))]
        skipped_rows = dataset.get("skipped_rows") or {}
        skipped_images = dataset.get("skipped_images") or {}
        if skipped_rows:
            rows.append(("skipped rows", ", ".join(f"{v} {k}" for k, v
                                                   in skipped_rows.items())))
        if skipped_images:
            rows.append(("skipped images", ", ".join(f"{v} {k}" for k, v
                                                     in skipped_images.items())))
        section.blocks.append(Table(("", "count"), tuple(rows), align="lr"))
    else:
        section.blocks.append(ctx.note(f"No `dataset.json` in `{train}`: counts unknown."))
    balanced = (dataset or {}).get("balance", {}).get("enabled", True)
    if figures and not balanced:  # one histogram: balancing kept every sample
        section.blocks.append(Figure(figures[0], "Steering labels of the training samples "
                                                 "(balancing off: every sample kept)."))
    elif figures:
        section.blocks.append(Gallery(tuple(
            Figure(path, f"Steering labels {stage} balancing; dashed line: the target per "
                         "bin.")
            for path, stage in zip(figures, ("before", "after")[:len(figures)],
                                   strict=True))))
    return [section]
