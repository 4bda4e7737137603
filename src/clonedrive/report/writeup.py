"""The generated write-up: ``report.md`` + a self-contained ``report.html`` from a run folder.

``write_report(run_dir, out_dir)`` reads what the stages wrote and describes it the way the
Udacity Behavioral Cloning write-up does (data, balancing, network, training, closed-loop
results), with figures made from the run. It finds, each optional:

- recordings: folders under ``RUN_DIR/data/`` holding ``driving_log.csv`` (and the recordings
  the training recipe names), each with the recorder's ``config.json`` if there is one;
- the training folder: ``RUN_DIR/train/``, or ``RUN_DIR`` itself if it holds ``model.keras``
  (``model.keras``, ``history.csv``, ``loss.png``, ``config.json``, ``recipe.toml``,
  ``dataset.json``, ``steering_before.png`` / ``steering_after.png``; see ``model.train``);
- the evaluation folder: ``RUN_DIR/eval/``, ``<training folder>/eval/`` or ``RUN_DIR`` itself,
  holding ``eval.json`` (see ``evaluate.rollout``) with its maps, off-road frames and videos;
- ``RUN_DIR/bench.json``, ``RUN_DIR/bench/bench.json`` or ``RUN_DIR/bench/*/bench.json``:
  ``clonedrive bench``'s leaderboards (section "Benchmark");
- ``RUN_DIR/demo.json``: stage timings, ``{"stages": {"record": 12.5, ...}}`` or
  ``{"stages": [{"name": "record", "seconds": 12.5}, ...]}`` (``timings`` / ``timings_s``
  are read too).

A section whose inputs are missing is left out, and the introduction lists it with the reason
in one line; a section that failed on bad input (an unreadable ``eval.json``, a corrupt model)
keeps its heading and says why. The sections shown are numbered in order. The report is
written whatever the run holds. Figures go to ``OUT/report/*.png``, which
``report.md`` links; ``report.html`` embeds them as ``data:`` URIs and references no file.

This module puts the document together; each section is a module of
:mod:`clonedrive.report.sections` (``data``, ``balance``, ``network``, ``training``,
``results`` with ``failures``, ``expert``, ``saliency``, ``dagger``, ``bench``, ``timings``,
and ``intro``, built last from what the others found), sharing a
:class:`~clonedrive.report.context.ReportContext`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from clonedrive.base.config import write_text_atomic
from clonedrive.report.context import (
    OPTIONAL_SECTION_TITLES,
    SECTION_TITLES,
    ReportConfig,
    ReportContext,
    RunParts,
    find_run_parts,
)
from clonedrive.report.document import Document, Section, to_html, to_markdown
from clonedrive.report.sections import (
    balance,
    bench,
    dagger,
    data,
    expert,
    intro,
    network,
    realdata,
    results,
    saliency,
    timings,
    training,
)

__all__ = ["SECTION_TITLES", "ReportConfig", "ReportResult", "RunParts", "find_run_parts",
           "write_report"]

MARKDOWN_NAME = "report.md"
HTML_NAME = "report.html"
FIGURES_DIR = "report"

#: (key of SECTION_TITLES, the module's build function), in the report's order.
SECTIONS: tuple[tuple[str, Callable[[ReportContext], list[Section]]], ...] = (
    ("data", data.build),
    ("balance", balance.build),
    ("network", network.build),
    ("training", training.build),
    ("results", results.build),
    ("expert", expert.build),
    ("saliency", saliency.build),
    ("realdata", realdata.build),
    ("dagger", dagger.build),
    ("bench", bench.build),
    ("timings", timings.build),
)


@dataclass
class ReportResult:
    markdown_path: Path
    html_path: Path
    figures: list[Path]
    sections: list[str]  # section titles, in order
    notes: list[str] = field(default_factory=list)  # what was missing or skipped, one line each


def write_report(run_dir: str | os.PathLike, out_dir: str | os.PathLike | None = None,
                 config: ReportConfig | None = None, *, progress: bool = False) -> ReportResult:
    """Write ``report.md``, ``report.html`` and ``report/*.png`` into ``out_dir`` (default:
    ``run_dir``) describing the run in ``run_dir``."""
    from clonedrive.base.progress import progress_bar

    config = config or ReportConfig()
    parts = find_run_parts(run_dir)
    out = Path(out_dir) if out_dir is not None else parts.run_dir
    figures_dir = out / FIGURES_DIR
    figures_dir.mkdir(parents=True, exist_ok=True)
    context = ReportContext(parts, figures_dir, config)

    document = Document(title=f"Behavioral Cloning: run {parts.run_dir.resolve().name}")
    bar = progress_bar(total=len(SECTIONS), desc="report", unit="section", enabled=progress)
    try:
        for key, build in SECTIONS:
            title = SECTION_TITLES.get(key) or OPTIONAL_SECTION_TITLES[key]
            document.sections += context.guarded(title, build)
            bar.update(1)
    finally:
        bar.close()
    top_level = [section for section in document.sections if section.level == 2]
    for number, section in enumerate(top_level, start=1):
        section.title = f"{number}. {section.title}"
    document.intro = intro.build(context)

    markdown_path = write_text_atomic(out / MARKDOWN_NAME, to_markdown(document, out))
    html_path = write_text_atomic(out / HTML_NAME, to_html(document))
    figures = [figure.path for figure in document.figures()]
    _remove_stale_figures(figures_dir, figures)
    return ReportResult(markdown_path=markdown_path, html_path=html_path, figures=figures,
                        sections=[s.title for s in document.sections], notes=context.notes)


def _remove_stale_figures(figures_dir: Path, keep: list[Path]) -> None:
    """Delete PNGs an earlier report left in ``figures_dir`` that this one does not use."""
    kept = {path.resolve() for path in keep}
    for path in figures_dir.glob("*.png"):
        if path.resolve() not in kept:
            path.unlink(missing_ok=True)
