"""DAgger (only when the run has a ``dagger.json``): per iteration the labels the expert
added, safety takeovers, and the closed-loop figures per split, beside plain cloning given as
many extra labels.
"""

from __future__ import annotations

from pathlib import Path

from clonedrive.report import formatting as fmt
from clonedrive.report.context import (
    OPTIONAL_SECTION_TITLES,
    ReportContext,
    copy_figure,
    read_json,
)
from clonedrive.report.document import Figure, Paragraph, Section, Table


def find_dagger_json(run_dir: Path) -> Path | None:
    """``RUN_DIR/dagger.json`` or ``RUN_DIR/dagger/dagger.json``, if either exists."""
    for path in (run_dir / "dagger.json", run_dir / "dagger" / "dagger.json"):
        if path.is_file():
            return path
    return None


def build(ctx: ReportContext) -> list[Section]:
    title = OPTIONAL_SECTION_TITLES["dagger"]
    path = find_dagger_json(ctx.parts.run_dir)
    if path is None:
        return []
    report = read_json(path)
    rows_in = list(report.get("iterations") or [])
    plain = report.get("plain")
    if not rows_in:
        return ctx.missing(title, f"`{path.name}` lists no iteration.")
    splits = sorted({name for row in rows_in for name in (row.get("eval") or {})
                     if name != "overall"})
    headers = ["iteration", "beta", "labels (total)", "takeovers /km"]
    for split in splits:
        headers += [f"{split} success %", f"{split} int./km", f"{split} lap time ×"]
    rows = []
    plains = [*(report.get("plain_each") or []), *([plain] if plain else [])]
    for row in [*rows_in, *plains]:
        collect = row.get("collect") or {}
        name = (f"plain cloning ({row.get('epochs', '?')} epochs)" if row.get("method") == "plain"
                else str(row.get("iteration")))
        cells = [name, fmt.num(row.get("beta")), fmt.count(row.get("labels_total")),
                 fmt.num(collect.get("takeovers_per_km"))]
        for split in splits:
            figures = (row.get("eval") or {}).get(split) or {}
            cells += [fmt.num(figures.get("success_pct"), 0),
                      fmt.num(figures.get("interventions_per_km")),
                      fmt.num(figures.get("lap_time_ratio"))]
        rows.append(tuple(cells))
    config = report.get("config") or {}
    text = (
        "DAgger (Ross, Gordon & Bagnell 2011): from the base model (iteration 0), each "
        "iteration the network drove the collection tracks "
        f"({', '.join(config.get('tracks') or [])}), mixed with the expert (share beta), "
        "while the expert labelled every frame; a safety takeover by the expert stopped the "
        "car before it left the road (counted per km of collection). The labels were added "
        "to the training data and the network retrained from its previous weights. Plain "
        "cloning got the same number of extra expert labels, recorded by the expert driving "
        "the same tracks, for comparison"
        + (", at every iteration's label count." if report.get("plain_each") else "."))
    blocks: list = [Paragraph(text), Table(tuple(headers), tuple(rows),
                                           align="l" + "r" * (len(headers) - 1))]
    png = ctx.run_file(path.parent, "dagger.png")
    if png is not None:
        blocks.append(Figure(copy_figure(png, ctx.figures_dir, "dagger.png"),
                             "Per iteration: evaluation figures per split, takeovers per km."))
    last = rows_in[-1].get("eval", {}).get("overall", {})
    if plain and last:
        other = (plain.get("eval") or {}).get("overall", {})
        ctx.headline(
            f"DAgger after {rows_in[-1].get('iteration')} iteration(s): "
            f"{fmt.num(last.get('success_pct'), 0)} % success, "
            f"{fmt.num(last.get('interventions_per_km'))} interventions/km; plain cloning "
            f"with as many labels: {fmt.num(other.get('success_pct'), 0)} %, "
            f"{fmt.num(other.get('interventions_per_km'))}/km.")
    return [Section(title, blocks=blocks)]
