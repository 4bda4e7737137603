"""A DAgger run's figures for people: ``dagger.png`` and the printed table."""

from __future__ import annotations

import math
from pathlib import Path


def plot_dagger(report: dict, path: Path) -> Path:
    """Per iteration: interventions per km and success % per split, collection takeovers per
    km, and the plain-cloning comparison as dashed lines."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from clonedrive.base.config import atomic_path

    rows = report["iterations"]
    curve = _plain_rows(report)
    figure = Figure(figsize=(11, 3.8), dpi=100)
    axes = figure.subplots(1, 3)
    iterations = [row["iteration"] for row in rows]
    # evaluate's splits (builtin, unseen) or the benchmark's, in the order they first appear.
    splits = list(dict.fromkeys(name for row in rows for name in row["eval"]))
    if len(splits) == 2 and "overall" in splits:  # "overall" of one split is that split
        splits.remove("overall")
    palette = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:olive", "tab:cyan")
    colours = {name: palette[index % len(palette)]
               for index, name in enumerate(s for s in splits if s != "overall")}
    colours["overall"] = "tab:green"
    for index, (figure_key, title) in enumerate((("interventions_per_km",
                                                  "evaluation: interventions per km"),
                                                 ("success_pct", "evaluation: success %"))):
        ax = axes[index]
        for split in splits:
            values = [row["eval"].get(split, {}).get(figure_key) for row in rows]
            values = [math.nan if value is None else value for value in values]
            ax.plot(iterations, values, "o-", color=colours[split], label=f"DAgger, {split}")
            points = [(row["iteration"], row["eval"][split].get(figure_key)) for row in curve
                      if split in row["eval"] and row["eval"][split].get(figure_key) is not None]
            if len(points) > 1:  # plain cloning at each iteration's label count
                ax.plot(*zip(*points, strict=True), "x--", color=colours[split],
                        label=f"plain cloning (as many labels), {split}")
            elif points:
                ax.axhline(points[0][1], color=colours[split], linestyle="--",
                           label=f"plain cloning, {split}")
        ax.set_title(title)
        ax.set_xlabel("iteration (0 = base model)")
        ax.grid(True, alpha=0.3)
    axes[1].set_ylim(-5, 105)
    axes[0].legend(fontsize=7)
    ax = axes[2]
    dagger_rows = [row for row in rows if row.get("collect")]
    ax.bar([row["iteration"] for row in dagger_rows],
           [row["collect"]["takeovers_per_km"] or 0.0 for row in dagger_rows],
           color="tab:red", alpha=0.7, label="takeovers per km")
    ax.set_title("collection: safety takeovers per km")
    ax.set_xlabel("iteration")
    twin = ax.twinx()
    twin.plot([row["iteration"] for row in dagger_rows],
              [row["labels_total"] for row in dagger_rows], "k.-", label="labels in total")
    twin.set_ylabel("expert labels collected (total)")
    ax.grid(True, alpha=0.3)
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png")
    return path


def _plain_rows(report: dict) -> list[dict]:
    """The plain-cloning rows of a report, by iteration (an older report's one has none)."""
    rows = list(report.get("plain_each") or []) + ([report["plain"]] if report.get("plain")
                                                   else [])
    return [dict(row, iteration=row.get("iteration", report["config"]["iterations"]))
            for row in rows]


def format_table(report: dict) -> str:
    """The printed table: one row per iteration (and plain cloning), figures per split."""
    rows = list(report["iterations"]) + _plain_rows(report)
    splits = sorted({name for row in rows for name in row["eval"] if name != "overall"})
    splits.append("overall")
    head = f"{'iter':<6}{'method':<8}{'beta':>6}{'labels':>8}{'tko/km':>8}"
    for split in splits:
        head += f"  {split[:18]:>18} succ% int/km lap/exp"
    lines = [head, "-" * len(head)]

    def num(value, digits=2) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    for row in rows:
        collect = row.get("collect") or {}
        line = (f"{str(row.get('iteration', '-')):<6}{row['method']:<8}"
                f"{num(row.get('beta')):>6}{row.get('labels_total', 0):>8}"
                f"{num(collect.get('takeovers_per_km')):>8}")
        for split in splits:
            figures = row["eval"].get(split) or {}
            line += (f"  {'':>18} {num(figures.get('success_pct'), 0):>5}"
                     f" {num(figures.get('interventions_per_km')):>6}"
                     f" {num(figures.get('lap_time_ratio')):>7}")
        lines.append(line)
    return "\n".join(lines)
