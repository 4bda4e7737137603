"""Run timings: the stages' wall-clock times from ``demo.json``.
"""

from __future__ import annotations

from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext, read_json
from clonedrive.report.document import Paragraph, Section, Table

#: Keys of demo.json that may hold the stage timings, in the order they are looked for.
_STAGE_KEYS = ("stages", "timings", "timings_s", "stage_seconds")


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["timings"]
    if ctx.parts.demo_json is None:
        return ctx.missing(title, "No `demo.json` (written by `clonedrive demo`): no stage "
                                  "timings.")
    demo = read_json(ctx.parts.demo_json)
    stages = _stage_seconds(demo)
    if not stages:
        return ctx.missing(title, "`demo.json` holds no stage timings.")
    stage_total = sum(stages.values())
    wall = demo.get("total_seconds")
    total = stage_total
    if isinstance(wall, int | float) and wall >= stage_total:
        total = float(wall)
    rows = [(name, fmt.num(seconds, 1), fmt.num(seconds / 60.0, 1),
             f"{100.0 * seconds / total:.0f} %" if total > 0 else "–",
             _stage_details(demo, name))
            for name, seconds in stages.items()]
    rows.append(("total" + (" (wall clock)" if total > stage_total else ""), fmt.num(total, 1),
                 fmt.num(total / 60.0, 1), "100 %", ""))
    text = f"Wall-clock time of each stage of the run, from `{ctx.parts.demo_json.name}`."
    if "report" not in stages:
        text += " (The report stage is timed after this report was written.)"
    blocks: list = [Paragraph(text),
                    Table(("stage", "seconds", "minutes", "share", "details"), tuple(rows),
                          align="lrrrl", total_rows=(len(rows) - 1,))]
    settings = demo.get("config")
    extras = [f"{key} = {value}" for key, value in
              (settings.items() if isinstance(settings, dict) else ())
              if isinstance(value, str | int | float | bool) or value is None]
    extras += [f"{key} = {value}" for key, value in demo.items()
               if isinstance(value, str | int | float | bool)
               and key not in (*_STAGE_KEYS, "total_seconds")]
    if extras:
        blocks.append(Paragraph("Settings: " + ", ".join(f"`{item}`" for item in extras)
                                + "."))
    return [Section(title, blocks=blocks)]


def _stage_seconds(demo: dict) -> dict[str, float]:
    """Stage name -> seconds from the first timing table ``demo.json`` holds."""
    for key in _STAGE_KEYS:
        table = demo.get(key)
        stages: dict[str, float] = {}
        if isinstance(table, dict):
            for name, value in table.items():
                seconds = _seconds_of(value)
                if seconds is not None:
                    stages[str(name)] = seconds
        elif isinstance(table, list):
            for item in table:
                if isinstance(item, dict):
                    name = item.get("name") or item.get("stage")
                    seconds = _seconds_of(item)
                    if name is not None and seconds is not None:
                        stages[str(name)] = seconds
        if stages:
            return stages
    return {}


def _stage_details(demo: dict, name: str) -> str:
    """A stage's other scalar entries in ``demo.json`` ("rows 1234, model fast")."""
    for key in _STAGE_KEYS:
        table = demo.get(key)
        if isinstance(table, dict) and isinstance(table.get(name), dict):
            return ", ".join(f"{k} {v}" for k, v in table[name].items()
                             if k != "seconds" and isinstance(v, str | int | float | bool))
    return ""


def _seconds_of(value) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, dict):
        for key in ("seconds", "wall_s", "elapsed_s", "wall_seconds", "time_s"):
            if isinstance(value.get(key), int | float):
                return float(value[key])
    return None
