"""A DAgger model's closed-loop figures: per split of the benchmark or of evaluate, against
the expert's reference laps."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from clonedrive.bench.suite import reference_name
from clonedrive.pipelines.dagger.config import DaggerConfig


def evaluate_model(model_path: Path, config: DaggerConfig, out: Path, references: dict, *,
                   progress: bool = False) -> dict:
    """Closed-loop figures of the model at ``model_path`` per split: the benchmark's
    (``bench_splits``, ``out/../bench/``) or evaluate's (:func:`split_figures`, ``out``);
    reused when the folder holds a finished run."""
    import json

    from clonedrive.drivers.policy import load_policy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    if config.bench_splits:
        return _bench_model(model_path, config, out.parent / "bench", progress=progress)
    eval_json = out / "eval.json"
    if eval_json.is_file():
        report = json.loads(eval_json.read_text(encoding="utf-8"))
    else:
        eval_config = EvalConfig(tracks=config.eval_tracks, speeds_mph=(config.speed_mph,),
                                 laps=config.eval_laps, unseen=config.eval_unseen,
                                 unseen_speed_mph=config.speed_mph, unseen_laps=config.eval_laps,
                                 scenery=config.scenery, max_seconds=config.max_seconds,
                                 renderer=config.renderer, full_frame=config.full_frame)
        report = evaluate(load_policy(model_path), eval_config, out, progress=progress,
                          model_path=str(model_path))
    return split_figures(report["runs"], references)


def _bench_model(model_path: Path, config: DaggerConfig, out: Path, *, progress: bool) -> dict:
    import json

    from clonedrive.bench.run import BenchConfig, bench

    bench_json = out / "bench.json"
    report = json.loads(bench_json.read_text(encoding="utf-8")) if bench_json.is_file() \
        else None
    if report is None or not report.get("complete"):
        report = bench(BenchConfig(models=(f"model={model_path}",), suite=config.bench_suite,
                                   splits=config.bench_splits, workers=config.workers,
                                   scenery=config.scenery, max_seconds=config.max_seconds,
                                 renderer=config.renderer, full_frame=config.full_frame),
                       out, progress=progress)
    model = next(iter(report["models"].values()))
    return {**model["splits"], "overall": model["overall"]}


def split_figures(runs: Sequence[dict], references: dict) -> dict:
    """Per split (``builtin``, ``unseen``) and overall: runs, success % (every lap clean),
    interventions per km, mean lap-time ratio over the clean runs (against ``references``:
    ``{(track, speed): expert lap time s}``) and mean steering-rate ratio."""
    def figures(rows):
        km = sum(r["distance_m"] for r in rows) / 1000.0
        clean = [r for r in rows if r["laps_completed"] >= r["laps_target"]]
        ref = {id(r): references.get(reference_name(r["track"], r["speed_mph"])) or {}
               for r in rows}
        ratios = [r["lap_time_s"] / ref[id(r)]["lap_time_s"] for r in clean
                  if r.get("lap_time_s") and ref[id(r)].get("lap_time_s")]
        smooth = [r["smoothness"] / ref[id(r)]["smoothness"] for r in rows
                  if ref[id(r)].get("smoothness")]
        return {
            "runs": len(rows),
            "success_pct": round(100.0 * len(clean) / len(rows), 1) if rows else None,
            "interventions": sum(r["interventions"] for r in rows),
            "interventions_per_km": round(sum(r["interventions"] for r in rows) / km, 3)
            if km else None,
            "lap_time_ratio": round(float(np.mean(ratios)), 4) if ratios else None,
            "smoothness_ratio": round(float(np.mean(smooth)), 4) if smooth else None,
        }

    splits = {"overall": figures(list(runs))}
    for name, unseen in (("builtin", False), ("unseen", True)):
        rows = [r for r in runs if bool(r.get("unseen")) == unseen]
        if rows:
            splits[name] = figures(rows)
    return splits


def expert_references(config: DaggerConfig) -> dict:
    """The expert's figures on every evaluation (track, speed): its lap time and smoothness
    (:func:`clonedrive.evaluate.reference.expert_reference`); the benchmark brings its own."""
    from clonedrive.evaluate.config import UNSEEN_SEED_BASE
    from clonedrive.evaluate.reference import expert_reference

    if config.bench_splits:
        return {}
    names = list(config.eval_tracks) + [f"gen:{UNSEEN_SEED_BASE + index}"
                                        for index in range(config.eval_unseen)]
    return {reference_name(name, config.speed_mph):
            expert_reference(name, config.speed_mph, laps=config.eval_laps,
                             max_seconds=config.max_seconds)
            for name in names}
