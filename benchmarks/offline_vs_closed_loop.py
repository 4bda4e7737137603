"""Does offline error predict driving? Validation MSE against closed-loop figures, over models.

Codevilla et al. (2018) found a network's offline error a poor predictor of how it drives. This
script asks the same of ours: for every model of a `clonedrive dagger` run (the base model, each
DAgger iteration, and plain cloning with as many extra labels, at each iteration's count too
with ``--plain-each``) it computes the steering MSE on
held-out expert recordings and sets it beside the model's closed-loop figures from the same
dagger.json (clean-lap success % and interventions per km, per split), with their Pearson and
Spearman correlations (`clonedrive.bench.scores.correlation`).

The held-out recordings are the expert driving the benchmark split's own tracks (never recorded
for training: DAgger and plain cloning collect on other seeds), with steering noise so that the
car also visits states off the centreline, and clean labels; they are recorded into --data
unless it already holds them.

Run: python benchmarks/offline_vs_closed_loop.py DAGGER_DIR [--data DIR] [--split NAME]
Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

#: Held-out recordings: the expert on these tracks at this cap, with this steering noise.
TRACKS = ("gen2:hard:2000", "gen2:hard:2001", "gen2:medium:2000")
SPEED_MPH = 20.0
NOISE = 0.15
SECONDS = 60.0


def held_out(folder: Path) -> list[Path]:
    from clonedrive.base.paths import safe_stem
    from clonedrive.data.recorder import RecordConfig, record

    folders = []
    for index, track in enumerate(TRACKS):
        out = folder / safe_stem(track)
        if not (out / "driving_log.csv").is_file():
            record(RecordConfig(track=track, seconds=SECONDS, speed_mph=SPEED_MPH, noise=NOISE,
                                seed=900 + index, relative_paths=True,
                                start_time="2026-01-01T12:00:00"), out, progress=False)
        folders.append(out)
    return folders


def main() -> int:
    from clonedrive.bench.run import offline_mse, offline_rows
    from clonedrive.bench.scores import correlation

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dagger", type=Path, help="a clonedrive dagger --out folder")
    parser.add_argument("--data", type=Path, default=None,
                        help="held-out recordings (recorded here if missing; default: a "
                             "temporary folder)")
    parser.add_argument("--split", default=None,
                        help="closed-loop split to correlate with (default: every split)")
    args = parser.parse_args()
    report = json.loads((args.dagger / "dagger.json").read_text(encoding="utf-8"))
    models = [(f"iteration {row['iteration']}" if row["method"] != "base" else "base",
               row) for row in report["iterations"]]
    # --plain-each: plain cloning at each earlier iteration's label count too.
    models += [(f"plain cloning, it. {row['iteration']}", row)
               for row in report.get("plain_each") or []]
    if report.get("plain"):
        models.append(("plain cloning", report["plain"]))
    with tempfile.TemporaryDirectory() as temporary:
        data = args.data or Path(temporary)
        rows = offline_rows(tuple(str(f) for f in held_out(data)))
        mse = {}
        for name, row in models:
            if not Path(row["model"]).is_file():
                sys.exit(f"{row['model']}: model file not found")
            mse[name] = offline_mse(row["model"], rows)
    splits = sorted({s for _, row in models for s in row["eval"]})
    if args.split:
        splits = [args.split]
    print(f"offline steering MSE on {len(rows)} held-out rows ({', '.join(TRACKS)}, expert at "
          f"{SPEED_MPH:g} mph with noise {NOISE})")
    head = f"{'model':<22}{'offline MSE':>12}" + "".join(
        f"{s[:22]:>24}" for s in splits)
    print(head + "\n" + " " * 34 + "".join(f"{'success % / int. per km':>24}" for _ in splits))
    for name, row in models:
        cells = []
        for split in splits:
            figures = row["eval"].get(split) or {}
            cells.append(f"{figures.get('success_pct')} / {figures.get('interventions_per_km')}")
        print(f"{name:<22}{mse[name]:>12.5f}" + "".join(f"{c:>24}" for c in cells))
    result = {"rows": len(rows), "models": {name: {"offline_mse": mse[name]} for name, _ in models},
              "correlation": {}}
    for split in splits:
        values = [mse[name] for name, _ in models]
        success = [(row["eval"].get(split) or {}).get("success_pct") for _, row in models]
        km = [(row["eval"].get(split) or {}).get("interventions_per_km") for _, row in models]
        result["correlation"][split] = {"vs_success_pct": correlation(values, success),
                                        "vs_interventions_per_km": correlation(values, km)}
        c = result["correlation"][split]
        print(f"{split}: MSE vs success % Pearson {c['vs_success_pct']['pearson']}, Spearman "
              f"{c['vs_success_pct']['spearman']}; vs interventions/km Pearson "
              f"{c['vs_interventions_per_km']['pearson']}, Spearman "
              f"{c['vs_interventions_per_km']['spearman']} (n = {c['vs_success_pct']['n']})")
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
