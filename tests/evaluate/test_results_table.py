"""The printed evaluation table's totals: one line per group only where the groups differ."""

from __future__ import annotations

from clonedrive.evaluate.results import format_table, totals


def _run(track: str, unseen: bool, laps: int) -> dict:
    return {"track": track, "speed_mph": 30.0, "laps_completed": laps, "laps_target": 1,
            "interventions": 1 - laps, "autonomy_pct": 100.0, "mean_abs_cte_m": 0.2,
            "max_abs_cte_m": 0.5, "smoothness": 0.1, "mean_speed_mph": 29.0,
            "distance_m": 900.0, "unseen": unseen}


def _totals_lines(runs: list[dict], **options) -> list[str]:
    table = format_table({"runs": runs, "totals": totals(runs)}, **options)
    return [line for line in table.splitlines() if line.split(":")[0] in
            ("all", "builtin", "unseen")]


def test_built_in_tracks_alone_print_one_total():
    lines = _totals_lines([_run("lake", False, 1), _run("mountain", False, 0)])
    assert lines == ["all: 1/2 laps (50 %), 1 intervention"]


def test_built_in_and_unseen_tracks_print_each_group():
    lines = _totals_lines([_run("lake", False, 1), _run("gen:1000", True, 0)])
    assert [line.split(":")[0] for line in lines] == ["all", "builtin", "unseen"]
    assert lines[2] == "unseen: 0/1 laps (0 %), 1 intervention"


def test_a_table_without_totals():
    assert _totals_lines([_run("lake", False, 0)], with_totals=False) == []
