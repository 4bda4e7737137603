"""``clonedrive bench``: drive models through a suite and write bench.json and a leaderboard.

:func:`bench` cuts the suite's episodes into batches (``batch`` episodes of one model each,
driven in lock-step by one worker), adds the expert's reference laps (one per track and speed
cap), runs them all on the worker pool (:mod:`clonedrive.base.workers`), scores every run against
its reference (:mod:`clonedrive.bench.scores`) and writes, under ``out``:

- ``bench.json``: the suite (id, splits, conditions), the settings, every run with its scores,
  per model and split figures, per method mean +- std, offline MSE and its correlation with
  closed-loop figures; rewritten as the batches finish (``"complete"`` says when all are in);
- ``leaderboard.md`` and ``leaderboard.html`` (self-contained) with ``bench_success.png`` and
  ``bench_lap_time.png`` (:mod:`clonedrive.bench.leaderboard`).

Models are given as ``PATH`` or ``LABEL=PATH``; models with the same label are one method
(for example trained with different seeds) and are reported as mean +- std.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

from clonedrive.base.config import config_to_dict, write_json_atomic
from clonedrive.base.udacity_spec import SPEED_KI, SPEED_KP
from clonedrive.bench import DEFAULT_SUITE, MAX_BATCH
from clonedrive.bench.scores import (
    dev_agreement,
    method_intervals,
    method_scores,
    offline_correlations,
    run_scores,
    split_scores,
)
from clonedrive.bench.suite import EpisodeSpec, Suite, load_suite, reference_name
from clonedrive.sim.engine import DEFAULT_RENDERER, check_renderer

if TYPE_CHECKING:
    from clonedrive.bench.driving import BatchTask

#: bench.json's format version.
BENCH_FORMAT = 1
#: Rows of held-out recordings used for the offline MSE, at most (evenly spaced).
MAX_OFFLINE_ROWS = 3000


@dataclass(frozen=True)
class BenchConfig:
    """What ``clonedrive bench`` runs."""

    models: tuple[str, ...]  #: PATH or LABEL=PATH per model
    suite: str = DEFAULT_SUITE  #: a built-in suite name or a suite .toml file
    splits: tuple[str, ...] = ()  #: only these splits (default: all)
    workers: int | None = None  #: local worker processes (default: one per CPU core)
    ray: str | None = None  #: "auto", a Ray cluster address, or "local"
    batch: int = 4  #: episodes one worker drives in lock-step
    # What stands between each network and the controls (network.driving_settings); None:
    # each model's own setting, stored in its file (drive.py's, all off, where it has none).
    slow_in_curves: bool | None = None  #: the network's target speed falls with |steering|
    steering_filter_s: float | None = None  #: low-pass on the predicted steering [s]
    steering_hold: float | None = None  #: hold the wheel through smaller steering jitter
    #: above this speed [mph] the prediction is scaled by it over the car's speed
    steering_scale_from_mph: float | None = None
    mirror_average: bool | None = None  #: average each frame's prediction with its mirror's
    speed_scale: float | None = None  #: a speed head's target speed times this
    full_speed_at: float | None = None  #: a speed head's targets from this fraction: full speed
    caution: float | None = None  #: slower where a frame and its mirror image disagree
    caution_from: float | None = None  #: the disagreement below which caution does not slow
    scenery: bool = True
    max_seconds: float | None = None  #: cap on simulated seconds per episode (quick checks)
    offline_data: tuple[str, ...] = ()  #: held-out recordings for the offline MSE
    trust_model: bool = False  #: allow Lambda layers (--trust-model; network.model_file)
    runtime: str = "auto"  #: "auto", "keras" or "onnx" (--runtime)
    renderer: str = DEFAULT_RENDERER  #: "auto", "software" or "egl" (sim/engine.py)
    #: render whole frames, not only the rows each model's crop keeps (network/crop.py)
    full_frame: bool = False

    def __post_init__(self) -> None:
        if not self.models:
            raise ValueError("give at least one model")
        for entry in self.models:
            _label_and_path(entry)
        if self.workers is not None and self.workers < 1:
            raise ValueError(f"workers must be at least 1, got {self.workers}")
        if self.runtime not in ("auto", "keras", "onnx"):
            raise ValueError(f"runtime {self.runtime!r}; expected auto, keras or onnx")
        check_renderer(self.renderer)
        if not 1 <= self.batch <= MAX_BATCH:
            raise ValueError(f"batch must be in [1, {MAX_BATCH}], got {self.batch}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds)
                                                 and self.max_seconds > 0):
            raise ValueError(f"max_seconds must be positive, got {self.max_seconds}")

    def policy_options(self) -> dict:
        """The NetworkPolicy options given for every model (as NetworkPolicy.options() names
        them); the ones not given are each model's own (load_policy reads them from its file),
        the rest keep their defaults: drive.py's PI gains. Each of DrivingSettings' fields is
        a field of this config by the same name."""
        from clonedrive.network.driving_settings import DrivingSettings

        given = {field.name: getattr(self, field.name)
                 for field in fields(DrivingSettings)}
        return {name: value for name, value in given.items() if value is not None}


def _curve_rule_text(slow_in_curves: bool | None) -> str:
    if slow_in_curves is None:
        return ", curve slowing as each model's file says (off where it says nothing)"
    return (", target speed reduced with |steering|" if slow_in_curves
            else ", no curve slowing (drive.py parity)")


def _model_settings(entry: str, config: BenchConfig) -> dict:
    """The driving settings a model of the bench drives with: its file's, then the options
    given for every model."""
    from clonedrive.network.driving_settings import DrivingSettings, stored_settings

    path = _label_and_path(entry)[1]
    stored = stored_settings(path) if Path(path).is_file() else None
    return {**(stored or DrivingSettings()).options(), **config.policy_options()}


def _label_and_path(entry: str) -> tuple[str, str]:
    label, sep, path = entry.partition("=")
    if not sep:
        path = entry
        p = Path(entry)
        label = p.parent.name if p.stem == "model" and p.parent.name else p.stem
    if not label or not path:
        raise ValueError(f"model {entry!r}: give PATH or LABEL=PATH")
    return label, path


def plan_tasks(suite: Suite, config: BenchConfig) -> tuple[list[BatchTask], list[EpisodeSpec]]:
    """The pool's tasks: expert reference batches first, then each model's batches; and the
    reference episodes (one per track, speed cap, direction and start, driven under the clear
    look)."""
    from dataclasses import replace

    from clonedrive.bench.driving import BatchTask
    from clonedrive.sim.conditions import Conditions

    episodes = suite.episodes(config.splits or None)
    references: dict[str, EpisodeSpec] = {}
    for spec in episodes:
        if spec.reference_key not in references:
            references[spec.reference_key] = replace(
                spec, split="expert", index=len(references), family="clear",
                conditions=Conditions())
    refs = list(references.values())
    common = {"max_seconds": config.max_seconds, "scenery": config.scenery,
              "renderer": config.renderer, "full_frame": config.full_frame}
    tasks = [BatchTask(kind="expert", episodes=tuple(refs[i:i + 16]), **common)
             for i in range(0, len(refs), 16)]
    for model in config.models:
        label, path = _label_and_path(model)
        for i in range(0, len(episodes), config.batch):
            tasks.append(BatchTask(kind="model", model=path, label=label, entry=model,
                                   policy_options=config.policy_options(),
                                   trust_model=config.trust_model, runtime=config.runtime,
                                   episodes=tuple(episodes[i:i + config.batch]), **common))
    return tasks, refs


def bench(config: BenchConfig, out_dir: str | Path, *, progress: bool = True,
          resume: bool = False) -> dict:
    """Run the benchmark and write its files; returns bench.json's content. ``resume``: keep
    the finished batches of an interrupted run of the same benchmark in ``out_dir``
    (:mod:`clonedrive.bench.resume`) and drive only the others."""
    from clonedrive.base.progress import progress_bar
    from clonedrive.base.workers import default_workers, run_tasks
    from clonedrive.bench.driving import drive_batch
    from clonedrive.bench.leaderboard import write_leaderboard
    from clonedrive.drivers.policy import PREDICTION
    from clonedrive.sim.engine import renderer_info

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite(config.suite)
    tasks, references = plan_tasks(suite, config)
    for model in config.models:
        path = Path(_label_and_path(model)[1])
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
    workers = config.workers or default_workers()
    report = {
        "format": BENCH_FORMAT,
        "suite": suite.to_dict(),
        "settings": {**config_to_dict(config), "workers": None if config.ray else workers},
        "speed_control": f"drive.py's PI (kp {SPEED_KP}, ki {SPEED_KI}) at the set speed"
                         + _curve_rule_text(config.slow_in_curves),
        "driving": {_label_and_path(model)[0]: _model_settings(model, config)
                    for model in config.models},
        "rendering": {**renderer_info(config.renderer), "full_frame": config.full_frame},
        "prediction": PREDICTION,
        "complete": False,
    }
    results = _resumed_results(out, report, tasks) if resume else {}
    pending = [index for index in range(len(tasks)) if index not in results]
    report.update(assemble(tasks, results, config, suite))
    report["complete"] = not pending
    write_json_atomic(out / "bench.json", report)  # a previous run's results are not this one's
    episodes = sum(len(task.episodes) for task in tasks)
    bar = progress_bar(total=episodes, unit="episode", desc="bench", enabled=progress,
                       initial=sum(len(result) for result in results.values()))

    def on_done(done: int, result: list[dict]) -> None:
        results[pending[done]] = result
        bar.update(len(result))
        report.update(assemble(tasks, results, config, suite))
        report["complete"] = len(results) == len(tasks)
        write_json_atomic(out / "bench.json", report)

    try:
        to_drive = [tasks[index] for index in pending]
        _add_portable_models(to_drive, config, workers)
        run_tasks(drive_batch, to_drive, workers=workers, ray=config.ray, on_done=on_done)
    finally:
        bar.close()
    if config.offline_data:
        add_offline(report, config)
        write_json_atomic(out / "bench.json", report)
    write_leaderboard(report, out)
    return report


def _resumed_results(out: Path, report: dict, tasks: list[BatchTask]) -> dict[int, list[dict]]:
    """The finished batches of the earlier run in ``out`` (none if it holds no bench.json)."""
    import dataclasses
    import sys

    from clonedrive.bench.resume import finished_batches, previous_report

    defaults = {f.name: f.default for f in dataclasses.fields(BenchConfig)
                if f.default is not dataclasses.MISSING}
    previous = previous_report(out, report, defaults)
    if previous is None:
        print(f"bench: nothing to resume in {out}; starting from the first batch",
              file=sys.stderr)
        return {}
    results = finished_batches(tasks, previous)
    print(f"bench: resuming {out}: {len(results)} of {len(tasks)} batches already driven",
          file=sys.stderr)
    return results


def _reference_of(run: dict) -> str:
    """The name of the expert reference a run (or a reference run) belongs to."""
    return reference_name(run["track"], run["speed_mph"], bool(run.get("reverse", False)),
                          float(run.get("start_fraction", 0.0)))


def assemble(tasks: list[BatchTask], results: dict[int, list[dict]], config: BenchConfig,
             suite: Suite) -> dict:
    """bench.json's reference, runs, models and methods from the finished tasks."""
    split_names = [s for s in suite.split_names() if not config.splits or s in config.splits]
    reference = {}
    for index, task in enumerate(tasks):
        if task.kind == "expert" and index in results:
            for run in results[index]:
                reference[_reference_of(run)] = run
    models: dict[str, dict] = {}
    for index, task in enumerate(tasks):
        if task.kind != "model":
            continue
        model = models.setdefault(task.entry, {"label": task.label, "path": task.model,
                                                  "runs": []})
        for run in results.get(index, []):
            ref = reference.get(_reference_of(run))
            model["runs"].append({**run, "scores": run_scores(run, ref)})
    methods = summarize(models, split_names)
    return {"reference": reference, "models": models, "methods": methods,
            "split_names": split_names, "dev_agreement": dev_agreement(models)}


def summarize(models: dict[str, dict], split_names: list[str]) -> dict[str, dict]:
    """Fill in each model's per-split and overall figures from its scored runs; returns the
    methods (models by label) with their mean +- std and hierarchical intervals."""
    for model in models.values():
        model["splits"] = {}
        for split in split_names:
            runs = [r for r in model["runs"] if r["split"] == split]
            if runs:
                model["splits"][split] = split_scores(runs)
        model["overall"] = split_scores(model["runs"]) if model["runs"] else {}
    methods: dict[str, dict] = {}
    for entry, model in models.items():
        methods.setdefault(model["label"], {"models": []})["models"].append(entry)
    for method in methods.values():
        members = [models[e] for e in method["models"]]
        complete = [m for m in members if set(m["splits"]) == set(split_names)]
        method["scores"] = method_scores(complete, split_names) if complete else {}
        method["ci"] = method_intervals(complete, split_names) if complete else {}
    return methods


def add_offline(report: dict, config: BenchConfig) -> None:
    """Each model's MSE on held-out recordings, and its correlation with closed-loop figures."""
    rows = offline_rows(config.offline_data)
    for model in report["models"].values():
        model["offline_mse"] = offline_mse(model["path"], rows, trust=config.trust_model,
                                           runtime=config.runtime)
    report["offline"] = {"data": list(config.offline_data), "rows": len(rows),
                         **offline_correlations(list(report["models"].values()))}


def offline_rows(folders: tuple[str, ...]) -> list:
    from clonedrive.data.driving_log import read_driving_log

    rows = []
    for folder in folders:
        rows += read_driving_log(folder, verify_images="exists").rows
    if len(rows) > MAX_OFFLINE_ROWS:
        step = len(rows) / MAX_OFFLINE_ROWS
        rows = [rows[int(i * step)] for i in range(MAX_OFFLINE_ROWS)]
    if not rows:
        raise ValueError(f"no usable rows in {', '.join(folders)}")
    return rows


#: A model's batches per worker from which its checked traces are made here first: loading the
#: model in this process costs about 6.5 s (Keras's import, the model, its traces) and spares
#: each batch's fresh worker process about 3 s (it imports PyTorch alone).
PORTABLE_FROM_BATCHES_PER_WORKER = 3


def _add_portable_models(tasks: list[BatchTask], config: BenchConfig, workers: int) -> None:
    """Give each model's batches the model's checked traces (``task.portable``, see
    :meth:`NetworkPolicy.portable`), for the models with enough batches to gain from it; the
    others' workers load the model file, as do the batches of a model that does not trace."""
    from dataclasses import replace

    from clonedrive.drivers.policy import load_policy

    counts: dict[str, int] = {}
    for task in tasks:
        if task.kind == "model":
            counts[task.model] = counts.get(task.model, 0) + 1
    for path, count in counts.items():
        if count < PORTABLE_FROM_BATCHES_PER_WORKER * workers or config.runtime == "onnx" \
                or Path(path).suffix.lower() == ".onnx":
            continue
        policy = load_policy(path, trust=config.trust_model, runtime=config.runtime,
                             **config.policy_options())
        portable = policy.portable()
        for index, task in enumerate(tasks):
            if task.kind == "model" and task.model == path:
                tasks[index] = replace(task, portable=portable)


def offline_mse(model_path: str, rows: list, *, trust: bool = False,
                runtime: str = "auto") -> float:
    """Mean squared error of the model's steering on the center images of ``rows``."""
    import numpy as np

    from clonedrive.base.images import read_rgb
    from clonedrive.drivers.policy import load_policy

    policy = load_policy(model_path, trust=trust, runtime=runtime)
    errors = []
    for start in range(0, len(rows), 64):
        chunk = rows[start:start + 64]
        frames = np.stack([read_rgb(row.center) for row in chunk])
        predicted = policy.predict_steering(frames)
        errors += [(float(p) - row.steering) ** 2 for p, row in zip(predicted, chunk,
                                                                    strict=True)]
    return round(float(np.mean(errors)), 6)
