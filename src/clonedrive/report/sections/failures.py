"""The failure analysis (part of 5.): each off-road event, where on the road it happened, the
frame the network saw, and what the pattern suggests.
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.report import formatting as fmt
from clonedrive.report.context import ReportContext, read_image_or_none
from clonedrive.report.document import Figure, Paragraph, Table

#: |curvature| below this [1/m] (radius above 400 m) counts as a straight.
STRAIGHT_CURVATURE = 1.0 / 400.0

def failure_analysis(ctx: ReportContext, runs: list[dict], eval_dir: Path) -> list:
    """The failure analysis's blocks for the runs of ``eval_dir``'s ``eval.json``."""
    from clonedrive.report.plots import Panel, failure_frames

    events = [(run, event) for run in runs for event in run.get("off_road_events") or []]
    if not events:
        return [Paragraph("No tyre left the road in any run: nothing to analyse.")]
    tracks: dict = {}
    described = [(run, event, _where(run.get("track"), event, tracks))
                 for run, event in events]
    blocks: list = [Paragraph(_failure_summary(described))]
    shown = described[: ctx.config.max_failures]
    if len(described) > len(shown):
        blocks.append(Paragraph(f"The first {len(shown)} of {len(described)} events:"))
    rows = []
    panels = []
    for number, (run, event, where) in enumerate(shown, start=1):
        cte = float(event.get("cte_m", 0.0))
        side = "right" if cte > 0 else "left"
        rows.append((str(number), fmt.track_label(run), fmt.num(run.get("speed_mph"), 0),
                     str(int(event.get("lap", 0)) + 1), fmt.num(event.get("time_s"), 1),
                     fmt.num(event.get("s_m"), 0), fmt.signed(cte), f"{side} edge", where["text"]))
        frame = event.get("frame_png")
        source = ctx.run_file(eval_dir, frame) if frame else None
        image = read_image_or_none(source) if source is not None else None
        if image is not None:
            lap = int(event.get("lap", 0)) + 1
            panels.append(Panel(image, f"#{number} {fmt.run_label(run)}, lap {lap}\n"
                                       f"s {fmt.num(event.get('s_m'), 0)} m, CTE {cte:+.2f} m, "
                                       f"{where['short']}"))
    blocks.append(Table(("#", "track", "mph", "lap", "time s", "s m", "CTE m", "off the",
                         "road there"), tuple(rows), align="rlrrrrrll"))
    if panels:
        path = failure_frames(panels, ctx.figures_dir / "failures.png",
                              title="what the network saw when the car left the road")
        blocks.append(Figure(path, "The center-camera frame at each off-road event "
                                   "(numbers as in the table)."))
    else:
        blocks.append(ctx.note("The off-road frames are missing from the evaluation "
                               "folder."))
    return blocks


def _where(track_name: str | None, event: dict, tracks: dict) -> dict:
    """The road where an event happened: a left or right bend (with radius) or a straight.
    ``tracks`` caches loaded tracks by name."""
    from clonedrive.world.catalog import load_track
    from clonedrive.world.track import TrackError

    unknown = {"text": "–", "short": "", "bend": None, "outside": None}
    if not track_name:
        return unknown
    try:
        if track_name not in tracks:
            tracks[track_name] = load_track(track_name)
        track = tracks[track_name]
    except (TrackError, OSError, ValueError):
        return unknown
    curvature = float(track.curvature(float(event.get("s_m", 0.0))))
    if abs(curvature) < STRAIGHT_CURVATURE:
        return {"text": "straight", "short": "straight", "bend": None, "outside": None}
    bend = "left" if curvature > 0 else "right"
    cte = float(event.get("cte_m", 0.0))
    outside = (cte > 0) == (curvature > 0)  # a left bend's outside is on the right
    radius = 1.0 / abs(curvature)
    return {"text": f"{bend} bend, radius {radius:.0f} m ({'outside' if outside else 'inside'})",
            "short": f"{bend} bend R {radius:.0f} m", "bend": bend, "outside": outside}


def _failure_summary(described: list[tuple[dict, dict, dict]]) -> str:
    total = len(described)
    runs = len({id(run) for run, _, _ in described})
    in_bends = [w for _, _, w in described if w["bend"] is not None]
    outside = sum(1 for w in in_bends if w["outside"])
    straights = sum(1 for _, _, w in described if w["text"] == "straight")
    text = (f"The car left the road **{fmt.plural(total, 'time')}** in {fmt.plural(runs, 'run')}. ")
    inside = len(in_bends) - outside
    if in_bends:
        text += (f"{len(in_bends)} happened in bends ({outside} on the outside: the network "
                 f"steered too little; {inside} on the inside: it cut the corner)"
                 + (f", {straights} on straights. " if straights else ". "))
    elif straights:
        text += f"All {straights} happened on straights. " if straights > 1 else (
            "It happened on a straight. ")
    if in_bends and outside >= inside:
        text += ("Running wide in bends points to too few strongly-steered samples "
                 "(more curve and recovery data, less balancing of the straight bin) or to "
                 "too much speed for the bends (try slowing in curves). ")
    elif in_bends:
        text += ("Cutting corners points to over-steering: labels of side cameras or edge "
                 "laps that are too strong, or too much shift augmentation. ")
    if straights > len(in_bends):
        text += ("Leaving the road on a straight means the car drifted to one side without "
                 "steering back: a steering bias, or too little recovery data (edge laps, "
                 "side cameras) to learn from. ")
    text += "Each event is listed with where it happened and the frame the network saw."
    return text
