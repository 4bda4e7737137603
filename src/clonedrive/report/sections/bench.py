"""Benchmark (only when the run has a ``bench.json``): the leaderboard of ``clonedrive bench``,
one subsection per bench run found, with its success and lap-time plots.

A run folder's bench runs are ``RUN_DIR/bench.json``, ``RUN_DIR/bench/bench.json`` and
``RUN_DIR/bench/<name>/bench.json`` (for example one run at drive.py parity and one with curve
slowing, as docs/benchmark.md shows).
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.base.paths import safe_stem
from clonedrive.bench.board import shipped_board
from clonedrive.bench.leaderboard import tables
from clonedrive.report import formatting as fmt
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


#: The columns of the table that sets a run's bench beside the board's methods.
BOARD_HEAD = ("method", "split", "success %", "driving score", "lap-time ratio",
              "smoothness ratio")


def _beside_the_board(report: dict, board: dict) -> list:
    """A paragraph and a table: this run's models and the repository leaderboard's methods on
    the splits this run drove (nothing when the board is of another suite or lacks them)."""
    suite = (report.get("suite") or {}).get("id")
    splits = [split for split in report.get("split_names", [])
              if any(split in method for method in (board.get("methods") or {}).values())]
    if not splits or board.get("suite") != suite:
        return []
    rows = []
    for split in splits:
        for entry, model in (report.get("models") or {}).items():
            figures = (model.get("splits") or {}).get(split)
            if figures:
                rows.append((f"**{model.get('label', entry)}** (this run)", split,
                             *_figures(figures)))
        for label, method in board["methods"].items():
            if split in method:
                count = method[split].get("models")
                rows.append((f"{label} ({count} models)" if count else label, split,
                             *_figures(method[split])))
    return [Paragraph(f"The same split{'s' if len(splits) > 1 else ''} of suite `{suite}` on "
                      "the repository's leaderboard (each method's mean over its models; "
                      f"lap-time ratios over clean laps only, {fmt.MISSING} where none was "
                      "clean):"),
            Table(BOARD_HEAD, tuple(rows), align="ll" + "r" * (len(BOARD_HEAD) - 2))]


def _figures(figures: dict) -> tuple[str, ...]:
    return (fmt.num(figures.get("success_pct"), 1), fmt.num(figures.get("driving_score")),
            fmt.num(figures.get("lap_time_ratio"), 3),
            fmt.num(figures.get("smoothness_ratio")))


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
    blocks += _beside_the_board(report, shipped_board())
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
