"""The report's open-loop section on real Udacity logs (report --real-log)."""

from __future__ import annotations

import shutil
from pathlib import Path

from clonedrive.cli import main
from clonedrive.report.context import OPTIONAL_SECTION_TITLES, ReportConfig
from clonedrive.report.writeup import write_report

FIXTURES = Path(__file__).parents[1] / "fixtures" / "udacity"


def test_real_logs_get_a_section_only_when_given(tmp_path: Path, tiny_model_path: Path) -> None:
    run = tmp_path / "run"
    (run / "train").mkdir(parents=True)
    shutil.copy(tiny_model_path, run / "train" / "model.keras")
    title = OPTIONAL_SECTION_TITLES["realdata"]
    plain = write_report(run).markdown_path.read_text(encoding="utf-8")
    assert title not in plain
    logs = (str(FIXTURES / "mountain_windows_paths"), str(FIXTURES / "lake_posix_mixed_columns"),
            str(tmp_path / "no_such_log"))
    result = write_report(run, tmp_path / "out", ReportConfig(real_logs=logs))
    markdown = result.markdown_path.read_text(encoding="utf-8")
    section = markdown[markdown.index(f". {title}\n"):]
    assert "| `mountain_windows_paths` | 70 |" in section
    assert "| `lake_posix_mixed_columns` | 70 |" in section
    assert "`no_such_log`: not checked" in section
    assert "On real Udacity frames (`mountain_windows_paths`, open loop): r = " in markdown
    names = {path.name for path in result.figures}
    assert {"crosscheck_mountain_windows_paths.png", "crosscheck_lake_posix_mixed_columns.png"} \
        <= names
    checked = tmp_path / "out" / "crosscheck" / "mountain_windows_paths"
    assert (checked / "crosscheck.json").is_file()
    _assert_replayed(tmp_path / "out", section, markdown, names)
    assert main(["report", str(run), "--out", str(tmp_path / "cli"), "--json", "--real-log",
                 logs[0]]) == 0
    assert title in (tmp_path / "cli" / "report.md").read_text(encoding="utf-8")


def _assert_replayed(out: Path, section: str, markdown: str, names: set[str]) -> None:
    """The closed-loop half: the replayable log's row, figures and plot, from replay.json; the
    lake slice (6.5 m driven) and the missing log are named as not replayed, and why."""
    import json

    log = "mountain_windows_paths"
    report = json.loads((out / "replay" / log / "replay.json").read_text(encoding="utf-8"))
    totals = report["totals"]
    assert totals["frames"] == 70
    row = next(line for line in section.splitlines()
               if line.startswith(f"| `{log}` | {totals['episodes']} |"))
    assert f"| {totals['interventions']} |" in row
    assert f"replay_{log}.png" in names
    assert f"Closed loop on real Udacity frames (`{log}`, replay): autonomy " in markdown
    assert "`lake_posix_mixed_columns`: not replayed (" in section
    assert "stationary" in section
    assert "`no_such_log`: not replayed" in section
    assert not (out / "replay" / "lake_posix_mixed_columns").exists()
