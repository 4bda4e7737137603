"""The report's Benchmark section on bench.json files it cannot read: a note each, no crash."""

from __future__ import annotations

from pathlib import Path

import pytest

from clonedrive.report.writeup import write_report


@pytest.mark.parametrize("content, says", [
    ("not json {", "not valid JSON"),
    ('{"suite": 3}', "'suite' is int, not an object"),
    ('{"suite": {"id": "v1"}, "methods": 3}', "not a bench.json this report can read"),
    ("[1, 2]", "expected a JSON object"),
])
def test_an_unreadable_bench_json_is_a_note_in_the_report(tmp_path: Path, content: str,
                                                          says: str) -> None:
    run = tmp_path / "run"
    (run / "bench" / "odd").mkdir(parents=True)
    (run / "bench" / "odd" / "bench.json").write_text(content, encoding="utf-8")
    result = write_report(run, tmp_path / "out")
    markdown = result.markdown_path.read_text(encoding="utf-8")
    section = markdown[markdown.index(". Benchmark\n"):]
    assert "### `bench/odd`" in section and says in section
    assert any(says in note for note in result.notes)
    assert sorted(p.name for p in (run / "bench" / "odd").iterdir()) == ["bench.json"]


def _run_report(suite: str = "v4") -> dict:
    figures = {"runs": 12, "success_pct": 100.0, "driving_score": 1.0, "lap_time_ratio": 1.03,
               "smoothness_ratio": 1.0}
    return {"suite": {"id": suite}, "split_names": ["dev"],
            "models": {"best=/x/model.keras": {"label": "best", "splits": {"dev": figures}}}}


BOARD = {"suite": "v4", "methods": {
    "writeup": {"dev": {"success_pct": 77.8, "driving_score": 0.9, "lap_time_ratio": 1.145,
                        "smoothness_ratio": 2.6, "models": 3},
                "hard-30": {"success_pct": 100.0}},
    "center": {"dev": {"success_pct": 0.0, "driving_score": 0.01, "lap_time_ratio": None,
                       "smoothness_ratio": 4.6, "models": 3}},
    "other": {"hard-30": {"success_pct": 10.0}}}}


def test_a_runs_bench_is_set_beside_the_boards_methods_on_its_splits() -> None:
    from clonedrive.report.sections.bench import _beside_the_board

    paragraph, table = _beside_the_board(_run_report(), BOARD)
    assert "suite `v4`" in paragraph.text
    assert [row[0] for row in table.rows] == ["**best** (this run)", "writeup (3 models)",
                                              "center (3 models)"]
    assert table.rows[0][2:] == ("100.0", "1.00", "1.030", "1.00")
    assert table.rows[2][4] == "–"  # no clean lap: no lap-time ratio
    assert all(row[1] == "dev" for row in table.rows)  # only the splits this run drove
    assert _beside_the_board(_run_report("v3"), BOARD) == []  # another suite's board
    assert _beside_the_board(_run_report(), {}) == []
