"""What an evaluation adds up to: eval.json's totals, the printed table, and a finiteness
check of its figures."""

from __future__ import annotations

import math


def totals(results: list[dict]) -> dict:
    """eval.json's ``totals``: laps and interventions of all runs, the built-in tracks' and
    the unseen ones'."""
    def group(rows):
        laps_target = sum(r["laps_target"] for r in rows)
        laps = sum(min(r["laps_completed"], r["laps_target"]) for r in rows)
        return {
            "runs": len(rows),
            "laps_completed": laps,
            "laps_target": laps_target,
            "laps_completed_pct": round(100.0 * laps / laps_target, 1) if laps_target else 0.0,
            "interventions": sum(r["interventions"] for r in rows),
        }

    seen = [r for r in results if not r["unseen"]]
    unseen = [r for r in results if r["unseen"]]
    totals = {"all": group(results)}
    if seen:
        totals["builtin"] = group(seen)
    if unseen:
        totals["unseen"] = group(unseen)
    return totals


def format_table(report: dict, *, with_totals: bool = True) -> str:
    """The printed results table; ``lap/exp`` and ``rate/exp``: lap time and steering rate over
    the expert's on the same track and cap. Then (``with_totals``) the laps of all runs, and of
    the built-in and unseen tracks apart where there are both."""
    head = (f"{'track':<10}{'mph':>5}{'laps':>7}{'interv.':>9}{'auton.%':>9}{'mean|CTE|':>10}"
            f"{'max|CTE|':>9}{'smooth':>8}{'speed':>7}{'dist m':>8}{'lap/exp':>8}{'rate/exp':>9}")
    lines = [head, "-" * len(head)]

    def ratio(value) -> str:
        return "-" if value is None else f"{value:.2f}"

    for r in report["runs"]:
        laps = f"{r['laps_completed']}/{r['laps_target']}"
        lines.append(
            f"{r['track']:<10}{r['speed_mph']:>5g}{laps:>7}{r['interventions']:>9}"
            f"{r['autonomy_pct']:>9.1f}{r['mean_abs_cte_m']:>10.2f}{r['max_abs_cte_m']:>9.2f}"
            f"{r['smoothness']:>8.2f}{r['mean_speed_mph']:>7.1f}{r['distance_m']:>8.0f}"
            f"{ratio(r.get('lap_time_ratio')):>8}{ratio(r.get('steering_rate_per_s_ratio')):>9}")
    nan_runs = [r for r in report["runs"] if r.get("nan_predictions")]
    for r in nan_runs:
        lines.append(f"warning: {r['track']} at {r['speed_mph']:g} mph: the model predicted NaN "
                     f"or infinite steering on {r['nan_predictions']} frame(s) (driven straight)")
    shown = report["totals"] if with_totals else {}
    if set(shown) != {"all", "builtin", "unseen"}:  # one group: its line repeats "all"
        shown = {key: total for key, total in shown.items() if key == "all"}
    for key, total in shown.items():
        lines.append(f"{key}: {total['laps_completed']}/{total['laps_target']} laps "
                     f"({total['laps_completed_pct']:.0f} %), {total['interventions']} "
                     f"intervention{'' if total['interventions'] == 1 else 's'}")
    return "\n".join(lines)


def is_finite_report(report: dict) -> bool:
    """True when every figure in the report is a finite number (a sanity check for tests)."""
    for run in report["runs"]:
        for key in ("autonomy_pct", "mean_abs_cte_m", "max_abs_cte_m", "smoothness"):
            if not math.isfinite(run[key]):
                return False
    return True
