"""The leaderboard of a bench run: ``leaderboard.md``, a self-contained ``leaderboard.html`` and
two plots (success per split per model, lap-time ratio per split per model)."""

from __future__ import annotations

import base64
import html
from pathlib import Path

from clonedrive.base.config import atomic_path, write_text_atomic


def _pm(figure: dict, digits: int = 1, scale: float = 1.0) -> str:
    if not figure or figure.get("mean") is None:
        return "-"
    mean = figure["mean"] * scale
    if figure.get("std") is None:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {figure['std'] * scale:.{digits}f} (n={figure['n']})"


def _value(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _ci(value, interval: dict | None, digits: int = 2) -> str:
    """A figure with its 95 % interval, ``0.83 [0.71, 0.92]`` (the figure alone without one)."""
    if value is None:
        return "-"
    if not interval or interval.get("low") is None:
        return _value(value, digits)
    return f"{value:.{digits}f} [{interval['low']:.{digits}f}, {interval['high']:.{digits}f}]"


def tables(report: dict) -> tuple[list[str], list[list[str]], list[str], list[list[str]]]:
    """(method header, method rows, model header, model rows) of the leaderboard."""
    splits = report.get("split_names", [])
    method_head = ["method", *[f"{s} success %" for s in splits], "driving score [95 % CI]",
                   "interv./km", "lap-time ratio", "smoothness ratio"]
    method_rows = []
    for label, method in report.get("methods", {}).items():
        scores = method.get("scores") or {}
        overall = scores.get("overall", {})
        score = (method.get("ci") or {}).get("overall", {}).get("driving_score", {})
        method_rows.append([label, *[_pm(scores.get(s, {}).get("success_pct", {}))
                                     for s in splits],
                            _ci(score.get("value"), score),
                            _pm(overall.get("interventions_per_km", {}), 2),
                            _pm(overall.get("lap_time_ratio", {}), 3),
                            _pm(overall.get("smoothness_ratio", {}), 2)])
    model_head = ["model", "split", "runs", "success % [95 % CI]", "driving score [95 % CI]",
                  "interv./km [95 % CI]", "autonomy %", "mean |CTE| m", "lap-time ratio",
                  "smoothness ratio"]
    model_rows = []
    for entry, model in report.get("models", {}).items():
        for split, s in model.get("splits", {}).items():
            ci = s.get("ci") or {}
            model_rows.append([entry, split, str(s["runs"]),
                               _ci(s["success_pct"], ci.get("success_pct"), 1),
                               _ci(s.get("driving_score"), ci.get("driving_score")),
                               _ci(s["interventions_per_km"], ci.get("interventions_per_km")),
                               _value(s["autonomy_pct"], 1), _value(s["mean_abs_cte_m"]),
                               _value(s["lap_time_ratio"], 3), _value(s["smoothness_ratio"])])
        if "offline_mse" in model:
            model_rows.append([entry, "offline MSE", "", _value(model["offline_mse"], 5),
                               "", "", "", "", "", ""])
    return method_head, method_rows, model_head, model_rows


def methods_text(report: dict) -> str:
    """The leaderboard's method table as aligned plain text, for a terminal."""
    head, rows, _, _ = tables(report)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True))
                     for row in [head, *rows])


def _md(text: object) -> str:
    """``text`` as literal Markdown on one line: suite files and model labels are the user's
    text, and a ``|``, ``*``, ``<`` or newline in them must not restructure the page."""
    flat = " ".join(str(text).split())
    return "".join("\\" + char if char in _MARKDOWN_SPECIALS else char for char in flat)


_MARKDOWN_SPECIALS = set("\\`*_{}[]<>()#+!|~")


def _markdown_table(head: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(map(_md, head)) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(map(_md, row)) + " |" for row in rows]
    return lines


def plot(report: dict, out: Path) -> list[Path]:
    """``bench_success.png`` and ``bench_lap_time.png``: grouped bars, one group per split."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    splits = report.get("split_names", [])
    series = _plot_series(report)
    paths = []
    for figure, name, ylabel in (("success_pct", "bench_success.png", "clean-lap success %"),
                                 ("lap_time_ratio", "bench_lap_time.png",
                                  "lap time / expert's (clean laps)")):
        per_split = max(1.4, 0.3 * len(series))  # room for every bar's label
        fig, ax = plt.subplots(figsize=(max(6.0, per_split * len(splits) + 2), 4.0))
        width = 0.8 / max(1, len(series))
        x = np.arange(len(splits))
        for i, (legend, figures) in enumerate(series.items()):
            values = [figures.get(s, {}).get(figure, (None, None))[0] for s in splits]
            spreads = [figures.get(s, {}).get(figure, (None, None))[1] for s in splits]
            heights = [np.nan if v is None else v for v in values]
            errors = [0.0 if e is None else e for e in spreads]
            where = x + (i - (len(series) - 1) / 2) * width
            bars = ax.bar(where, heights, width, label=legend,
                          yerr=errors if any(errors) else None, capsize=2)
            ax.bar_label(bars, labels=["" if v is None else f"{v:.0f}" if figure == "success_pct"
                                       else f"{v:.2f}" for v in values], fontsize=7)
            for position, value in zip(where, values, strict=True):
                if value is None:  # no bar to label: say there is no figure (no clean lap)
                    ax.text(position, 0.0, "-", ha="center", va="bottom", fontsize=7)
        ax.set_xticks(x, splits, rotation=20, ha="right")
        ax.set_ylabel(ylabel)
        if figure == "success_pct":
            ax.set_ylim(0, 105)
        else:
            ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_title(f"suite {report['suite']['id']}: {ylabel}")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        fig.tight_layout()
        path = out / name
        with atomic_path(path) as temporary:  # never through a link at the name
            fig.savefig(temporary, dpi=100)
        plt.close(fig)
        paths.append(path)
    return paths


def _plot_series(report: dict) -> dict[str, dict[str, dict[str, tuple]]]:
    """What the plots draw: name -> split -> figure -> (value, spread). Per method (mean and
    std over its models, named with their count) when some method has several models and
    every method has figures; else per model."""
    methods = report.get("methods", {})
    grouped = any(len(m.get("models", [])) > 1 for m in methods.values())
    if grouped and all(m.get("scores") for m in methods.values()):
        return {f"{label} ({len(m['models'])} models)" if len(m["models"]) > 1 else label:
                {split: {f: (v.get("mean"), v.get("std")) for f, v in figures.items()}
                 for split, figures in m["scores"].items()}
                for label, m in methods.items()}
    return {entry: {split: {f: (v, None) for f, v in figures.items() if f != "ci"}
                    for split, figures in model.get("splits", {}).items()}
            for entry, model in report.get("models", {}).items()}


def _mixed_prediction(report: dict) -> str:
    """A sentence where a merged run's inputs predicted in different ways (bench.json's
    ``prediction``, :func:`clonedrive.bench.merge.merge_reports`), else ``""``."""
    value = report.get("prediction")
    if not isinstance(value, str) or not value.startswith("mixed: "):
        return ""
    return (f"Not every run was driven alike ({value.removeprefix('mixed: ')}): runs made one "
            "way differ from the other's by the last bits of each prediction, as between "
            "machines.")


def markdown(report: dict, images: list[str]) -> str:
    suite = report["suite"]
    method_head, method_rows, model_head, model_rows = tables(report)
    mixed = _mixed_prediction(report)
    lines = [f"# Benchmark: suite {_md(suite['id'])}", "", _md(suite.get("description", "")), "",
             f"Speed control: {_md(report['speed_control'])}. "
             f"{'Complete.' if report.get('complete') else 'INCOMPLETE: runs still missing.'}"
             + (f" {_md(mixed)}" if mixed else ""),
             "", "## Methods (mean ± std over the models of a method)", ""]
    lines += _markdown_table(method_head, method_rows)
    lines += ["", "## Models by split", ""]
    lines += _markdown_table(model_head, model_rows)
    offline = report.get("offline")
    if offline:
        lines += ["", "## Offline against closed loop", "",
                  f"Offline MSE on {offline['rows']} held-out rows. Correlation over "
                  f"{offline['vs_success_pct']['n']} models: with success % Pearson "
                  f"{_value(offline['vs_success_pct']['pearson'])}, Spearman "
                  f"{_value(offline['vs_success_pct']['spearman'])}; with interventions/km "
                  f"Pearson {_value(offline['vs_interventions_per_km']['pearson'])}, Spearman "
                  f"{_value(offline['vs_interventions_per_km']['spearman'])}"
                  + (f"; with the driving score Pearson "
                     f"{_value(offline['vs_driving_score']['pearson'])}, Spearman "
                     f"{_value(offline['vs_driving_score']['spearman'])}"
                     if "vs_driving_score" in offline else "") + "."]
    lines += _agreement_lines(report.get("dev_agreement"))
    settings = report.get("settings") or {}
    merged = settings.get("merged_from")
    if merged:
        lines += ["", f"Merged from {len(merged)} bench runs: "
                  + ", ".join(f"`{_md(name)}`" for name in merged) + "."]
    for name, splits in (settings.get("left_out") or {}).items():
        lines += ["", f"Carried into suite {_md(suite['id'])} from `{_md(name)}`, without its "
                  f"split(s) {_md(', '.join(splits))}, which this suite defines otherwise."]
    lines += ["", "## Splits", ""]
    lines += [f"- **{_md(s['name'])}**: {_md(s['description'])} ({len(s['tracks'])} tracks x "
              f"{', '.join(f'{v:g}' for v in s['speeds_mph'])} mph x "
              f"{_md(', '.join(s['conditions']))})" for s in suite["splits"]]
    lines += [""] + [f"![{_md(name)}]({name})" for name in images] + [""]
    return "\n".join(lines)


def _agreement_lines(agreement: dict | None) -> list[str]:
    """The dev tier's ranking of the models against their other episodes' (two or more)."""
    if not agreement:
        return []
    score, success = agreement["driving_score"], agreement["success_pct"]
    return ["", "## The dev tier against the rest", "",
            f"Over {agreement['models']} models, the dev tier's driving score against the "
            f"driving score on every other episode: Spearman {_value(score['spearman'])}, "
            f"Pearson {_value(score['pearson'])}; success %: Spearman "
            f"{_value(success['spearman'])}, Pearson {_value(success['pearson'])}. "
            "(Spearman 1.0: the dev tier ranks the models as the rest of the suite does.)"]


def _html(report: dict, images: list[Path]) -> str:
    method_head, method_rows, model_head, model_rows = tables(report)

    def table(head, rows):
        cells = "".join(f"<th>{html.escape(h)}</th>" for h in head)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                       for row in rows)
        return f"<table><tr>{cells}</tr>{body}</table>"

    pictures = "".join(
        f'<img alt="{html.escape(p.name)}" src="data:image/png;base64,'
        f'{base64.b64encode(p.read_bytes()).decode()}">' for p in images)
    suite = report["suite"]
    mixed = _mixed_prediction(report)
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>clonedrive bench {html.escape(suite['id'])}</title><style>"
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
        "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;"
        "padding:3px 8px;font-size:13px}img{max-width:100%}</style></head><body>"
        f"<h1>Benchmark: suite {html.escape(suite['id'])}</h1>"
        f"<p>{html.escape(suite.get('description', ''))}</p>"
        f"<p>Speed control: {html.escape(report['speed_control'])}."
        f"{' ' + html.escape(mixed) if mixed else ''}</p>"
        "<h2>Methods (mean ± std over the models of a method)</h2>"
        f"{table(method_head, method_rows)}<h2>Models by split</h2>"
        f"{table(model_head, model_rows)}{pictures}</body></html>")


def write_leaderboard(report: dict, out: str | Path) -> dict:
    """Write the plots, ``leaderboard.md`` and ``leaderboard.html``; returns their paths."""
    out = Path(out)
    images = plot(report, out)
    md = write_text_atomic(out / "leaderboard.md", markdown(report, [p.name for p in images]))
    page = write_text_atomic(out / "leaderboard.html", _html(report, images))
    return {"markdown": md, "html": page, "plots": images}
