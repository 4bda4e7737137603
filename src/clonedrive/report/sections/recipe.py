"""The run's recipe and its lead: clean laps at what speed, how calm, how fast.

The lead opens the report's summary. The recipe comes from ``eval.json`` (the model file's
notes; see :mod:`clonedrive.network.driving_settings`). Where the recipe names another to
compare with (``compare_with``), the figures that recipe's file stores (``[measured]``,
measured once) stand beside this run's in a short table.
"""

from __future__ import annotations

import numpy as np

from clonedrive.report import formatting as fmt
from clonedrive.report.context import ReportContext
from clonedrive.report.document import Paragraph, Table

#: The figures of the comparison table: (key in a recipe's [measured], label, how to read it).
COMPARED = (
    ("clean_laps", "clean laps", "more is better"),
    ("interventions", "interventions", "fewer is better"),
    ("lap_time_ratio", "lap time vs expert", "1.0 = the expert's; lower is faster"),
    ("steering_rate_ratio", "steering rate vs expert", "1.0 = as calm as the expert"),
    ("lateral_jerk_ratio", "lateral jerk vs expert", "1.0 = as smooth as the expert"),
    ("mean_abs_cte_m", "mean |CTE| m", "distance from the centre line"),
)


def run_figures(runs: list[dict]) -> dict:
    """This run's figures under :data:`COMPARED`'s keys (means over runs for the ratios)."""
    def mean(key: str) -> float | None:
        values = [float(run[key]) for run in runs if isinstance(run.get(key), int | float)]
        return float(np.mean(values)) if values else None

    laps = sum(int(run.get("laps_completed", 0)) for run in runs)
    target = sum(int(run.get("laps_target", 0)) for run in runs)
    return {"clean_laps": f"{laps}/{target}",
            "interventions": sum(int(run.get("interventions", 0)) for run in runs),
            "lap_time_ratio": mean("lap_time_ratio"),
            "steering_rate_ratio": mean("steering_rate_per_s_ratio"),
            "lateral_jerk_ratio": mean("lateral_jerk_mps3_ratio"),
            "mean_abs_cte_m": mean("mean_abs_cte_m")}


def lead(runs: list[dict], recipe: dict | None = None) -> str:
    """One sentence: clean laps at what speed, how calm, how fast (and the recipe)."""
    figures = run_figures(runs)
    speeds = sorted({float(run["speed_mph"]) for run in runs
                     if isinstance(run.get("speed_mph"), int | float)})
    caps = fmt.listed([f"{speed:g}" for speed in speeds]) if speeds else "?"
    text = (f"**{figures['clean_laps']} laps clean** "
            f"({fmt.plural(figures['interventions'], 'intervention')}) "
            f"at set speeds of {caps} mph")
    calm = figures["steering_rate_ratio"]
    if calm is not None:
        text += (f"; **calm:** the wheel moves {fmt.num(calm)}× as much as the expert's "
                 f"(1.0 = as calm as the expert)")
    fast = figures["lap_time_ratio"]
    if fast is not None:
        text += f"; **fast:** laps take {fmt.num(fast)}× the expert's time"
    if isinstance(recipe, dict) and recipe.get("name"):
        text += (f" (recipe {_safe(str(recipe['name']))} "
                 f"v{_safe(str(recipe.get('version')))})")
    return text + "."


def quick_lead(runs: list[dict]) -> str:
    """The lead of ``clonedrive demo --quick``'s report: a check that every stage runs, with
    what its short evaluation drove and no lap count to read as a result."""
    metres = sum(float(run.get("distance_m") or 0.0) for run in runs)
    seconds = sum(float(run.get("elapsed_s") or 0.0) for run in runs)
    interventions = sum(int(run.get("interventions") or 0) for run in runs)
    return (f"**Quick check passed: every stage ran**, each at a small size (`clonedrive demo "
            f"--quick`). Its evaluation stops after {fmt.num(seconds, 0)} s, before a lap is "
            f"done: the model drove {fmt.num(metres, 0)} m "
            f"({fmt.plural(interventions, 'intervention')}). This checks the installation, "
            f"not the driving: `clonedrive demo` trains and measures the recipe's model.")


def recipe_blocks(ctx: ReportContext, runs: list[dict], *, compare: bool = True) -> list:
    """The recipe that made the model, and (with ``compare``) the comparison table where it
    names another."""
    recipe = (ctx.eval or {}).get("recipe")
    if not isinstance(recipe, dict) or not recipe.get("name"):
        return []
    from clonedrive.recipes.book import BUILT_IN, load_recipe_file

    name, version = _safe(str(recipe["name"])), _safe(str(recipe.get("version")))
    label = f"{name} v{version}"
    blocks: list = [Paragraph(f"The model was trained and is driven with the recipe "
                              f"**{_safe(label)}** (stored in the model file).")]
    if name not in BUILT_IN or not compare:
        return blocks
    own = load_recipe_file(name)
    other_name = own.compare_with
    if not other_name or other_name not in BUILT_IN:
        return blocks
    other = load_recipe_file(other_name)
    if not other.measured:
        return blocks
    blocks += _comparison(run_figures(runs), label, other)
    ctx.headline(f"Recipe {label}; beside it the {other.label()} recipe's figures, measured "
                 f"{other.measured.get('date', 'once')}.")
    return blocks


def _comparison(figures: dict, label: str, other) -> list:
    measured = other.measured
    rows = []
    for key, name, meaning in COMPARED:
        if key in measured or figures.get(key) is not None:
            rows.append((name, _cell(figures.get(key)), _cell(measured.get(key)), meaning))
    where = measured.get("command", f"clonedrive demo --recipe {other.name}")
    return [Paragraph(f"This run beside the {other.label()} recipe, as measured on "
                      f"{measured.get('date', '?')} at commit {measured.get('commit', '?')} "
                      f"(`{where}`; {measured.get('runs', '?')}):"),
            Table(("figure", f"this run ({label})", other.label(), "how to read it"),
                  tuple(rows), align="lrrl")]


def _safe(text: str) -> str:
    """A recipe name as the report shows it: letters, digits, ``_.-`` and spaces only (a user's
    file could name its recipe with Markdown or HTML)."""
    return "".join(char for char in text if char.isalnum() or char in "_.- ")[:80]


def _cell(value) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return fmt.num(value)
    return str(value)
