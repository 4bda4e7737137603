"""Real Udacity frames (open loop): the run's model on recorded Udacity logs, given with
``clonedrive report RUN_DIR --real-log DIR`` (repeatable).

For each log, :func:`clonedrive.evaluate.crosscheck.crosscheck` predicts the steering for every
centre image and compares it with the human's; its files go to ``OUT/crosscheck/<log>/`` and
its plot into the report. The section is only in the report when a log is given.
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.report import formatting as fmt
from clonedrive.report.context import OPTIONAL_SECTION_TITLES, ReportContext, copy_figure
from clonedrive.report.document import Figure, Paragraph, Section, Table


def build(ctx: ReportContext) -> list[Section]:
    logs = ctx.config.real_logs
    if not logs:
        return []
    title = OPTIONAL_SECTION_TITLES["realdata"]
    train = ctx.parts.train_dir
    model_path = train / "model.keras" if train is not None else None
    if model_path is None or not model_path.is_file():
        return ctx.missing(title, "No trained `model.keras`: the real Udacity logs were not "
                                  "checked.")
    from clonedrive.drivers.network import load_policy
    from clonedrive.evaluate.crosscheck import CrosscheckConfig, crosscheck
    from clonedrive.paths import safe_stem

    policy = load_policy(model_path)
    config = CrosscheckConfig()
    section = Section(title)
    section.blocks.append(Paragraph(
        "The network's steering on frames recorded by the Udacity simulator, open loop: for "
        "each centre image of a real log, the model's prediction against the human's "
        "steering. RMSE is beside two guesses that need no model: always 0 (straight ahead) and "
        "always the log's mean (the best constant; it peeks at the answers). *r* is the "
        "correlation with the human's steering smoothed over "
        f"{config.smoothing_frames} frames (keyboard steering is spiky), *r raw* with the "
        "recorded values."))
    rows, figures = [], []
    crosscheck_root = ctx.figures_dir.parent / "crosscheck"
    for log in logs:
        log = Path(log)
        stem = safe_stem(log.resolve().name)
        try:
            report = crosscheck(policy, log, crosscheck_root / stem, config,
                                model_path=str(model_path))
        except (FileNotFoundError, ValueError) as error:
            section.blocks.append(ctx.note(f"`{log.name}`: not checked ({error})."))
            continue
        rows.append((f"`{log.name}`", str(report["rows"]), fmt.num(report["rmse"], 3),
                     fmt.num(report["rmse_zero"], 3), fmt.num(report["rmse_mean"], 3),
                     fmt.num(report["correlation"], 2), fmt.num(report["correlation_raw"], 2)))
        figures.append(Figure(copy_figure(crosscheck_root / stem / report["files"]["plot"],
                                          ctx.figures_dir, f"crosscheck_{stem}.png"),
                              f"`{log.name}`: the human's steering, smoothed, and the model's."))
        ctx.headline(f"On real Udacity frames (`{log.name}`, open loop): r = "
                     f"{fmt.num(report['correlation'], 2)}, RMSE {fmt.num(report['rmse'], 3)} "
                     f"(always 0: {fmt.num(report['rmse_zero'], 3)}).")
    if rows:
        section.blocks.append(Table(("log", "rows", "RMSE", "always 0", "always the mean", "r",
                                     "r raw"), tuple(rows), align="lrrrrrr"))
    section.blocks += figures
    return [section]
