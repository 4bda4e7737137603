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
