"""Benchmark (only when the run has a ``bench.json``): the leaderboard of ``clonedrive bench``,
one subsection per bench run found, with its success and lap-time plots.

A run folder's bench runs are ``RUN_DIR/bench.json``, ``RUN_DIR/bench/bench.json`` and
``RUN_DIR/bench/<name>/bench.json`` (for example one run at drive.py parity and one with curve
slowing, as docs/benchmark.md shows).
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.base.paths import safe_stem
from clonedrive.bench.leaderboard import tables
from clonedrive.report.context import (
    OPTIONAL_SECTION_TITLES,
    ReportContext,
    copy_figure,
    read_json,
)
from clonedrive.report.document import Figure, Paragraph, Section, Table

#: The leaderboard's plots, as ``clonedrive bench`` names them, with their captions.
PLOTS = (("bench_success.png", "Clean-lap success per split and model."),
         ("bench_lap_time.png", "Lap time against the expert's on the same track and cap "
                                "(clean laps; 1.0 = the expert's)."))


def find_bench_jsons(run_dir: Path) -> list[Path]:
    """The run's ``bench.json`` files (see the module doc), in name order."""
    found = [run_dir / "bench.json", run_dir / "bench" / "bench.json"]
    bench = run_dir / "bench"
    if bench.is_dir():
        found += sorted(bench.glob("*/bench.json"))
    return [path for path in found if path.is_file()]


def build(ctx: ReportContext) -> list[Section]:
    paths = find_bench_jsons(ctx.parts.run_dir)
    if not paths:
        return []
    title = OPTIONAL_SECTION_TITLES["bench"]
    sections = [Section(title, blocks=[Paragraph(
        "`clonedrive bench` drove the model(s) through every split of a versioned suite: the "
        "training tracks, new generated tracks at three difficulties and held-out conditions, "
        "one lap per episode from a standing start. A run is a success when the lap is "
        "completed without an intervention; the expert drove each track and speed cap once "
        "as the reference for lap time and smoothness.")])]
    for path in paths:
        sections.append(_subsection(ctx, path))
    return sections


def _subsection(ctx: ReportContext, path: Path) -> Section:
    name = path.parent.relative_to(ctx.parts.run_dir).as_posix()
    name = "bench" if name == "." else name
    try:
        report = read_json(path)
        suite = report["suite"]
        if not isinstance(suite, dict):
            raise ValueError(f"'suite' is {type(suite).__name__}, not an object")
        method_head, method_rows, model_head, model_rows = tables(report)
    except (OSError, KeyError, TypeError, AttributeError, ValueError) as error:
        return Section(f"`{name}`", level=3, blocks=[ctx.note(
            f"`{path}` is not a bench.json this report can read ({error}).")])
    blocks: list = [Paragraph(
        f"Suite `{suite.get('id', '?')}`; speed control: {report.get('speed_control', '?')}."
        + ("" if report.get("complete") else " **Incomplete**: some runs are missing."))]
    if method_rows:
        blocks.append(Table(tuple(method_head), tuple(tuple(row) for row in method_rows),
                            align="l" + "r" * (len(method_head) - 1)))
    if model_rows:
        blocks.append(Table(tuple(model_head), tuple(tuple(row) for row in model_rows),
                            align="ll" + "r" * (len(model_head) - 2)))
    for plot, caption in PLOTS:
        source = ctx.run_file(path.parent, plot)
        if source is not None:
            target = copy_figure(source, ctx.figures_dir,
                                 f"{safe_stem(name.replace('/', '_'))}_{plot}")
            blocks.append(Figure(target, caption))
    for label, method in (report.get("methods") or {}).items():
        overall = ((method.get("scores") or {}).get("overall") or {})
        success = (overall.get("success_pct") or {}).get("mean")
        if success is not None:
            ctx.headline(f"Benchmark `{name}` ({suite.get('id', '?')}): {label} "
                         f"{success:.0f} % clean laps over all splits.")
    return Section(f"`{name}`", level=3, blocks=blocks)
