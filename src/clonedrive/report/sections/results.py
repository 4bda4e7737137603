"""Closed-loop results: the table per run with totals, speed control, track maps, video
stills and (from :mod:`clonedrive.report.sections.failures`) the failure analysis.
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.evaluate.video import read_stills
from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext, copy_figure, figure_name
from clonedrive.report.document import Figure, Gallery, Paragraph, Section, Table
from clonedrive.report.sections.failures import failure_analysis
from clonedrive.report.sections.recipe import lead, quick_lead, recipe_blocks


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["results"]
    report = ctx.eval
    if report is None and "eval.json" in ctx.unreadable:  # there, but broken: say so in place
        return [Section(title, blocks=[ctx.note(ctx.unreadable["eval.json"]
                                                + ": closed-loop results skipped.")])]
    if report is None:
        return ctx.missing(title, "No `eval.json` (from `clonedrive evaluate`): closed-loop "
                                  "results skipped.")
    runs = list(report.get("runs") or [])
    if not runs:
        return ctx.missing(title, "`eval.json` lists no runs: closed-loop results skipped.")
    eval_dir = ctx.parts.eval_dir
    section = Section(title)
    model = report.get("model")
    section.blocks.append(Paragraph(
        "The trained network drives the simulator in closed loop, headless: it sees the "
        f"center camera at {CONTROL_HZ:g} frames per second and sets the steering; a speed "
        "controller sets the throttle. Whenever a tyre leaves the road (an **intervention**) "
        "the car is put back on the centre line and driving goes on. A lap counts only if no "
        "tyre left the road during it. Autonomy % = (1 − interventions × 6 s / time driven) × "
        "100 (NVIDIA's definition); smoothness is the mean |change of steering| per second "
        "(lower is smoother)."
        + (f" Model: `{model}`." if model else "")))
    section.blocks.append(_results_table(ctx, runs, report.get("totals") or {}))
    if any(run.get("timed_out") for run in runs):
        section.blocks.append(Paragraph(
            "† stopped at the time limit before the target laps were driven."))
    if ctx.quick:  # a check that every stage runs: nothing here measures driving
        ctx.facts["lead"] = quick_lead(runs)
        section.blocks += recipe_blocks(ctx, runs, compare=False)
    else:
        ctx.facts["lead"] = lead(runs, report.get("recipe"))
        section.blocks += recipe_blocks(ctx, runs)
        _closed_loop_headlines(ctx, report.get("totals") or {})
    speed = Section("Speed control", level=3)
    speed.blocks.append(Paragraph(_speed_text(report)))
    maps = Section("Track maps", level=3)
    maps.blocks += _maps(ctx, runs, eval_dir)
    stills = Section("Stills from the videos", level=3)
    stills.blocks += _stills(ctx, runs, eval_dir)
    failures = Section("Failure analysis", level=3)
    failures.blocks += failure_analysis(ctx, runs, eval_dir)
    return [section, speed, maps, stills, failures]


def _closed_loop_headlines(ctx: ReportContext, totals: dict) -> None:
    for key, label in (("builtin", "built-in tracks"), ("unseen", "unseen tracks")):
        total = totals.get(key)
        if total:
            ctx.headline(
                f"Closed loop, {label}: {total['laps_completed']}/{total['laps_target']} "
                f"laps ({fmt.num(total.get('laps_completed_pct'), 0)} %), "
                f"{fmt.plural(total['interventions'], 'intervention')}.")


def _results_table(ctx: ReportContext, runs: list[dict], totals: dict) -> Table:
    headers = ("track", "speed mph", "laps", "interventions", "autonomy %", "mean |CTE| m",
               "max |CTE| m", "smoothness /s", "mean speed mph", "distance m", "time s")
    rows = []
    for run in runs:
        laps = f"{run.get('laps_completed', 0)}/{run.get('laps_target', '?')}"
        if run.get("timed_out"):
            laps += " †"
        rows.append((fmt.track_label(run), fmt.num(run.get("speed_mph"), 0), laps,
                     fmt.count(run.get("interventions")), fmt.num(run.get("autonomy_pct"), 1),
                     fmt.num(run.get("mean_abs_cte_m")), fmt.num(run.get("max_abs_cte_m")),
                     fmt.num(run.get("smoothness")), fmt.num(run.get("mean_speed_mph"), 1),
                     fmt.num(run.get("distance_m"), 0), fmt.num(run.get("elapsed_s"), 1)))
    first_total = len(rows)
    groups = [("built-in tracks", [r for r in runs if not r.get("unseen")], "builtin"),
              ("unseen tracks", [r for r in runs if r.get("unseen")], "unseen")]
    if all(group for _, group, _ in groups):
        groups.append(("all", runs, "all"))
    for label, group, key in groups:
        if group:
            rows.append(_total_row(label, group, totals.get(key)))
    return Table(headers, tuple(rows), align="lrrrrrrrrrr",
                 total_rows=tuple(range(first_total, len(rows))))


def _maps(ctx: ReportContext, runs: list[dict], eval_dir: Path) -> list:
    """Built-in tracks' maps one under the other, unseen tracks' side by side."""
    builtin: list[Figure] = []
    unseen: list[Figure] = []
    for run in runs:
        source = ctx.run_file(eval_dir, run["map_png"]) if run.get("map_png") else None
        if source is not None:
            path = copy_figure(source, ctx.figures_dir, figure_name(source.stem, "map"))
            caption = (f"{fmt.run_label(run)}: the driven path coloured by |CTE| (the scale "
                       "tops out just above the run's largest); red crosses mark off-road "
                       "events, blue arrows the driving direction.")
            if run.get("unseen"):
                unseen.append(Figure(path, caption))
            else:
                builtin.append(Figure(path, caption, max_width_px=820))
    if not builtin and not unseen:
        return [ctx.note("No track maps in the evaluation folder.")]
    blocks: list = list(builtin)
    if unseen:
        blocks += [Paragraph("Unseen (generated) tracks, never used for recording:"),
                   Gallery(tuple(unseen))]
    return blocks


def _stills(ctx: ReportContext, runs: list[dict], eval_dir: Path) -> list:
    from clonedrive.report.plots import video_stills

    blocks: list = []
    videos = [run for run in runs if run.get("video")]
    if not videos:
        return [ctx.note("No videos in this evaluation (run `clonedrive evaluate "
                         "--video`): no stills.")]
    for run in videos:
        video = ctx.run_file(eval_dir, run["video"])
        stills = read_stills(video, ctx.config.stills_per_video) if video is not None else []
        if not stills:
            blocks.append(ctx.note(f"`{run['video']}` is missing or unreadable: no stills "
                                   f"for {fmt.run_label(run)}."))
            continue
        path = video_stills(stills, ctx.figures_dir / figure_name(video.stem, "stills"),
                            title=f"{fmt.run_label(run)} ({run['video']})")
        blocks.append(Figure(path, f"{fmt.run_label(run)}: frames from `{run['video']}` with "
                                   "the heads-up display (steering bar, speed, CTE, lap, "
                                   "interventions)."))
    return blocks


def _speed_text(report: dict) -> str:
    control = report.get("speed_control") or "a PI controller on the set speed"
    if report.get("slow_in_curves"):
        text = (f"Speed control: {control}. **Slowing in curves was on**: the target speed "
                "falls as the predicted steering grows, so the car takes bends slower than the "
                "set speed shown in the table.")
    else:
        text = (f"Speed control: {control}. Slowing in curves was **off**: the controller "
                "holds the set speed everywhere, bends included; the network steers alone.")
    return text + _steering_text(report)


def _steering_text(report: dict) -> str:
    """What stood between the network's steering and the wheel (nothing, as drive.py)."""
    steps = []
    if report.get("mirror_average"):
        steps.append("averaged with the mirrored frame's")
    scale_from = float(report.get("steering_scale_from_mph") or 0.0)
    if scale_from > 0.0:
        steps.append(f"multiplied above {scale_from:g} mph by {scale_from:g} mph over the "
                     "car's speed")
    if float(report.get("steering_filter_s") or 0.0) > 0.0:
        steps.append(f"low-passed with a {float(report['steering_filter_s']):g} s time constant")
    if float(report.get("steering_hold") or 0.0) > 0.0:
        steps.append(f"held while the prediction stayed within "
                     f"{float(report['steering_hold']):g} of the wheel")
    if not steps:
        return ""
    return (" **The steering was smoothed**: the network's prediction was " + fmt.listed(steps)
            + " (so the smoothness figures are not drive.py's).")


def _total_row(label: str, runs: list[dict], totals: dict | None) -> tuple[str, ...]:
    laps_target = sum(int(r.get("laps_target", 0)) for r in runs)
    laps = sum(min(int(r.get("laps_completed", 0)), int(r.get("laps_target", 0))) for r in runs)
    interventions = sum(int(r.get("interventions", 0)) for r in runs)
    if totals:
        laps, laps_target = totals.get("laps_completed", laps), totals.get("laps_target",
                                                                           laps_target)
        interventions = totals.get("interventions", interventions)
    elapsed = sum(float(r.get("elapsed_s", 0.0)) for r in runs)
    distance = sum(float(r.get("distance_m", 0.0)) for r in runs)
    autonomy = (max(0.0, 1.0 - interventions * 6.0 / elapsed) * 100.0 if elapsed > 0 else None)
    weighted = (sum(float(r.get("mean_abs_cte_m", 0.0)) * float(r.get("elapsed_s", 0.0))
                    for r in runs) / elapsed if elapsed > 0 else None)
    max_cte = max((float(r.get("max_abs_cte_m", 0.0)) for r in runs), default=None)
    pct = f" ({100.0 * laps / laps_target:.0f} %)" if laps_target else ""
    return (f"{label} ({len(runs)} runs)", "", f"{laps}/{laps_target}{pct}",
            fmt.count(interventions), fmt.num(autonomy, 1), fmt.num(weighted), fmt.num(max_cte),
            "", "", fmt.num(distance, 0), fmt.num(elapsed, 1))
