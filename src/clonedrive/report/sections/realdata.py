"""Real Udacity frames: the run's model on recorded Udacity logs, given with
``clonedrive report RUN_DIR --real-log DIR`` (repeatable), open loop and closed loop.

For each log, :func:`clonedrive.evaluate.crosscheck.crosscheck` predicts the steering for every
centre image and compares it with the human's (open loop; files in ``OUT/crosscheck/<log>/``),
and :func:`clonedrive.replay.output.replay` drives the model through the log by viewpoint
synthesis (closed loop; files in ``OUT/replay/<log>/``). Both plots go into the report. The
section is only in the report when a log is given.
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
    from clonedrive.base.paths import safe_stem
    from clonedrive.drivers.policy import load_policy
    from clonedrive.evaluate.crosscheck import CrosscheckConfig, crosscheck

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
    named = [(Path(log), safe_stem(Path(log).resolve().name)) for log in logs]
    for log, stem in named:
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
    from clonedrive.replay.episode import ReplayConfig

    replay_config = ReplayConfig()
    replayed = [_replay(ctx, policy, model_path, log, stem, section, replay_config)
                for log, stem in named]
    replayed = [entry for entry in replayed if entry is not None]
    if replayed:
        section.blocks += _replay_blocks(replayed, replay_config)
    return [section]


def _replay(ctx: ReportContext, policy, model_path: Path, log: Path, stem: str,
            section: Section, config) -> tuple[str, dict, Figure] | None:
    """Replay the model through ``log`` into ``OUT/replay/<stem>/``: (log name, the figures
    over the log, the offset plot), or None after a note saying why it could not."""
    from clonedrive.data.driving_log import DrivingLogError
    from clonedrive.replay.output import replay

    out = ctx.figures_dir.parent / "replay" / stem
    try:
        report = replay(policy, [log], out, config, model_path=str(model_path))
    except (FileNotFoundError, ValueError, DrivingLogError) as error:
        section.blocks.append(ctx.note(f"`{log.name}`: not replayed ({error})."))
        return None
    figures = report["totals"]
    plot = Figure(copy_figure(out / report["files"]["plot"], ctx.figures_dir,
                              f"replay_{stem}.png"),
                  f"`{log.name}`, closed loop: the car's offset from the human's path.")
    ctx.headline(f"Closed loop on real Udacity frames (`{log.name}`, replay): autonomy "
                 f"{fmt.num(figures['autonomy_pct'], 1)} %, "
                 f"{fmt.num(figures['interventions_per_km'], 1)} interventions per km.")
    return log.name, figures, plot


def _replay_blocks(replayed: list[tuple[str, dict, Figure]], config) -> list:
    """The closed-loop paragraph (``config``: the replays' ReplayConfig), its table and the
    offset plots."""
    rows = tuple(
        (f"`{name}`", str(figures["episodes"]), fmt.num(figures["distance_m"], 0),
         fmt.num(figures["autonomy_pct"], 1), str(figures["interventions"]),
         fmt.num(figures["interventions_per_km"], 1), fmt.num(figures["mean_abs_offset_m"], 2),
         f"{fmt.num(figures['jitter_per_s'], 2)} ({fmt.num(figures['human_jitter_per_s'], 2)})")
        for name, figures, _ in replayed)
    return [
        Paragraph(
            "Closed loop on the same logs (`clonedrive replay`): the car starts on the human's "
            "path and is moved each frame by the difference between the model's steering and "
            "the human's; the model sees the recorded frame re-rendered for the car's offset "
            "and heading (flat road below the horizon). Beyond "
            f"{config.max_offset_m:g} m from the path an intervention puts it back. Autonomy "
            f"= (1 - interventions x {config.intervention_penalty_s:g} s / elapsed) x 100, as "
            "NVIDIA's PilotNet paper measured it: 100 % is no help needed; it reaches 0 % at "
            f"one intervention per {config.intervention_penalty_s:g} s of driving. Jitter is "
            "the steering's mean change per second; the human's is in brackets."),
        Table(("log", "episodes", "distance m", "autonomy %", "interventions", "per km",
               "mean |offset| m", "jitter /s (human)"), rows, align="lrrrrrrr"),
        *(figure for _, _, figure in replayed),
    ]
