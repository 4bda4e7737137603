"""Against the expert: each run's lap time and smoothness over the expert's on the same
track and speed cap (eval.json's ``expert`` and ``*_ratio`` figures; see
:mod:`clonedrive.evaluate.reference`).
"""

from __future__ import annotations

import numpy as np

from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext
from clonedrive.report.document import Bullets, Paragraph, Section, Table

#: (eval.json key of the ratio, column title).
RATIOS = (
    ("lap_time_ratio", "lap time"),
    ("steering_rate_per_s_ratio", "steering rate"),
    ("steering_jerk_per_s2_ratio", "steering jerk"),
    ("lateral_accel_rms_mps2_ratio", "lat. accel RMS"),
    ("lateral_jerk_mps3_ratio", "lat. jerk"),
)
#: The ratios the report's summary names: (key, label).
HEADLINE = (("lap_time_ratio", "lap time"), ("steering_rate_per_s_ratio", "steering rate"),
            ("lateral_jerk_mps3_ratio", "lateral jerk"))
#: The project's targets for a calm driver at speed, as ratios to the expert: (key, mean at
#: most, no run above). A ratio with no entry has no target.
TARGETS = {
    "lap_time_ratio": (1.05, 1.05),
    "steering_rate_per_s_ratio": (1.5, 2.0),
    "lateral_jerk_mps3_ratio": (1.5, None),
}
#: What each ratio measures, for the sentence under the table.
MEANINGS = {
    "lap_time_ratio": "the time of a clean lap; above 1 the network is slower than the "
                      "expert",
    "steering_rate_per_s_ratio": "how much the wheel moves per second; above 1 the network "
                                 "steers more nervously than the expert",
    "steering_jerk_per_s2_ratio": "how abruptly the wheel changes direction; it grows with "
                                  "frame-to-frame noise in the predictions, so it is far above "
                                  "1 for most networks",
    "lateral_accel_rms_mps2_ratio": "the sideways acceleration passengers feel in bends; "
                                    "above 1 the network's line through the bends is rougher, "
                                    "below 1 it takes them more gently (often: slower)",
    "lateral_jerk_mps3_ratio": "how suddenly that sideways push changes, which passengers feel "
                               "as jolts; above 1 the ride is jerkier than the expert's",
}


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["expert"]
    runs = list((ctx.eval or {}).get("runs") or [])
    compared = [run for run in runs if isinstance(run.get("expert"), dict)]
    if not compared:
        return ctx.missing(title, "No run in `eval.json` carries the expert's reference "
                                  "figures (evaluate writes them): no comparison.")
    rows = []
    for run in compared:
        expert = run["expert"]
        rows.append((fmt.track_label(run), fmt.num(run.get("speed_mph"), 0),
                     fmt.num(run.get("lap_time_s"), 1), fmt.num(expert.get("lap_time_s"), 1),
                     *(fmt.num(run.get(key)) for key, _ in RATIOS),
                     fmt.sig(run.get("steering_rate_per_s")),
                     fmt.sig(expert.get("steering_rate_per_s"))))
    means = {key: _mean(run.get(key) for run in compared) for key, _ in RATIOS}
    rows.append(("mean", "", "", "", *(fmt.num(means[key]) for key, _ in RATIOS), "", ""))
    text = (
        "The expert (the autopilot that recorded the data, no steering noise) drove each "
        "evaluated track from the same start at the same speed cap. Each figure is the "
        "network's run over the expert's (1.00 = the same; lower lap time is faster, lower "
        "smoothness figures are calmer). Steering rate is the mean |change of steering| per "
        "second, steering jerk the mean |second difference| per s², lateral acceleration "
        "v × (rate of turn of the direction of travel), lateral jerk its mean |change| per "
        "second; no difference spans an intervention. The lap time counts only a first lap "
        "driven clean (from a standing start), so a run that left the road has none.")
    blocks: list = [Paragraph(text), Table(
        ("track", "mph", "lap s", "expert lap s", *(name for _, name in RATIOS),
         "steering rate /s", "expert's /s"),
        tuple(rows), align="lrrr" + "r" * len(RATIOS) + "rr", total_rows=(len(rows) - 1,)),
        Paragraph("What the means say (1.0 = the expert's figure on the same tracks and caps):"),
        Bullets(tuple(_meaning(key, name, means[key], compared) for key, name in RATIOS))]
    shown = [f"{label} {fmt.num(means[key])}×" for key, label in HEADLINE
             if means[key] is not None]
    if shown and not ctx.quick:  # a quick check's 10 s from a standing start measure nothing
        ctx.headline(f"Against the expert (1.0 = the expert): {', '.join(shown)} "
                     "(mean over runs).")
    return [Section(title, blocks=blocks)]


def _meaning(key: str, name: str, mean: float | None, runs: list[dict]) -> str:
    """One plain sentence on a ratio: what it measures, the run's figure and its target."""
    if mean is None:
        return f"**{name}**: no run has this figure ({MEANINGS[key]})."
    sentence = f"**{name} {fmt.num(mean)}×**: {MEANINGS[key]}."
    if key not in TARGETS:
        return sentence + " No target is set for it."
    limit, worst_limit = TARGETS[key]
    values = [float(run[key]) for run in runs if isinstance(run.get(key), int | float)]
    met = mean <= limit and (worst_limit is None or max(values) <= worst_limit)
    target = f"at most {limit:g}× on average" + (
        f", no run above {worst_limit:g}×" if worst_limit is not None else "")
    return sentence + f" Target: {target}; {'met' if met else 'missed'}" + (
        f" (the largest run: {fmt.num(max(values))}×)." if worst_limit is not None else ".")


def _mean(values) -> float | None:
    kept = [float(value) for value in values if isinstance(value, int | float)]
    return float(np.mean(kept)) if kept else None
