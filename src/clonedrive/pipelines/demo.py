"""The main job: from nothing to a driving model, measured, with a write-up.

``run_demo(DemoConfig(), "runs/demo")`` follows a whole recipe (:mod:`clonedrive.recipes.book`;
``best`` unless ``DemoConfig.recipe`` names another or a file):

1. records the recipe's recordings with the expert into ``runs/demo/data/<name>/``;
2. trains on them with the recipe's settings (``runs/demo/train/``, a first stage in
   ``train/base/`` where the recipe fine-tunes; see :mod:`clonedrive.recipes.training`); the
   model file carries the recipe's driving settings and its name and version;
3. evaluates in closed loop (``runs/demo/eval/``) the recipe's groups of runs, driving the
   model with its own settings, with videos for the built-in tracks;
4. where the recipe has a ``[bench]`` table, benches the model on those splits of a built-in
   suite (``runs/demo/bench/<splits>/bench.json``): the hard tracks, not only the demo's own;
5. writes ``report.md`` / ``report.html`` (the bench beside the repository's leaderboard).

The recipe file is copied to ``runs/demo/recipe.toml`` and the training data's recipe (with
absolute paths) to ``runs/demo/train/recipe.toml``. Each stage writes its folder;
``demo.json`` holds stage timings. Running the demo again on the same folder reuses finished
stages (recordings with their rows, a trained model), so an interrupted demo continues where it
stopped.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, replace
from pathlib import Path

from clonedrive.base.config import save_config, write_json_atomic, write_text_atomic
from clonedrive.recipes.book import DEFAULT_RECIPE, RecipeFile, RecordSpec, load_recipe_file
from clonedrive.recipes.training import run_stages, stage_dirs, train_stages

#: Where ``clonedrive demo`` writes its run by default.
DEFAULT_RUN_DIR = "runs/demo"
#: Where ``clonedrive demo --quick`` writes its run by default: its own folder, so the full demo
#: run after it (the README's order) does not meet the quick run's smaller recordings.
QUICK_RUN_DIR = "runs/demo-quick"
#: Architectures the demo can train (model.architectures.MODEL_NAMES, fast first).
DEMO_MODELS = ("fast", "seed", "pilotnet")
#: --quick: the recipe's first recording, this long [s], trained this many epochs.
QUICK_SECONDS = 20.0
QUICK_EPOCHS = 2


#: Beside each recording: the recipe's spec it was recorded from (a reused folder must match).
RECORDING_SPEC_FILE = "recipe_recording.json"


class DemoFolderError(ValueError):
    """The run folder holds stages of another recipe, which the demo would otherwise reuse."""


@dataclass(frozen=True)
class DemoConfig:
    """What ``clonedrive demo`` runs (the stages' own configs come from :func:`demo_plan`)."""

    recipe: str = DEFAULT_RECIPE  #: a built-in recipe name or a recipe file
    quick: bool = False  #: small data, few epochs, one short evaluation (about a minute)
    epochs: int | None = None  #: override the recipe's training epochs
    unseen: int | None = None  #: override the number of unseen generated tracks
    model: str | None = None  #: override the recipe's architecture
    video: bool = True  #: mp4s of the built-in-track runs
    seed: int = 0
    workers: int | None = None  #: processes recording and evaluation use (None: one per core)

    def __post_init__(self) -> None:
        if self.epochs is not None and (isinstance(self.epochs, bool) or self.epochs < 1):
            raise ValueError(f"epochs must be at least 1, got {self.epochs}")
        if self.unseen is not None and (isinstance(self.unseen, bool) or self.unseen < 0):
            raise ValueError(f"unseen must be >= 0, got {self.unseen}")
        if self.workers is not None and (isinstance(self.workers, bool) or self.workers < 1):
            raise ValueError(f"workers must be at least 1, got {self.workers}")
        if self.model is not None and self.model not in DEMO_MODELS:
            raise ValueError(f"model must be one of {', '.join(DEMO_MODELS)}, got {self.model!r}")


def demo_plan(config: DemoConfig, recipe: RecipeFile | None = None):
    """(recordings, [TrainConfig per training stage], [EvalConfig per group]) the demo runs
    for ``config`` (recipes.training: one stage, or a start and a fine-tune)."""
    from clonedrive.evaluate.rollout import EvalConfig

    recipe = recipe or load_recipe_file(config.recipe)
    overrides = {"seed": config.seed}
    if config.model is not None:
        overrides["model"] = config.model
    if config.quick:
        first = recipe.recordings[0]
        recordings = (replace(first, laps=1, seconds=QUICK_SECONDS),)
        train = train_stages(recipe, **overrides, epochs=config.epochs or QUICK_EPOCHS,
                             batch_size=64)
        groups = [EvalConfig(tracks=("lake",), speeds_mph=(15.0,), laps=1,
                             unseen=config.unseen or 0, video=config.video, max_seconds=10.0,
                             workers=config.workers)]
        return recordings, train, groups
    if config.epochs is not None:
        overrides["epochs"] = config.epochs
    train = train_stages(recipe, **overrides)
    groups = []
    for values in recipe.evaluation:
        group = EvalConfig(**values)
        unseen = group.unseen if config.unseen is None or not group.unseen else config.unseen
        if not group.tracks and not unseen:  # --unseen 0 empties a group of unseen tracks
            continue
        groups.append(replace(group, video=group.video and config.video, unseen=unseen,
                              workers=config.workers))
    return recipe.recordings, train, groups


def bench_plan(config: DemoConfig, recipe: RecipeFile, model_path: Path):
    """The :class:`~clonedrive.bench.run.BenchConfig` of the recipe's ``[bench]`` for the model
    at ``model_path`` (None without one, and for ``--quick``). ``SuiteError`` now, before any
    work, when the suite does not exist or lacks a split."""
    from clonedrive.bench.run import BenchConfig
    from clonedrive.bench.suite import load_suite

    if recipe.bench is None or config.quick:
        return None
    bench = BenchConfig(models=(f"{recipe.name}={model_path}",), splits=recipe.bench.splits,
                        workers=config.workers,
                        **({"suite": recipe.bench.suite} if recipe.bench.suite else {}))
    load_suite(bench.suite).episodes(bench.splits)  # SuiteError naming an unknown split
    return bench


def _record_stage(recordings, data_dir: Path, seed: int, progress: bool,
                  workers: int | None = None) -> list[dict]:
    """Record what is not recorded yet, the recordings spread over worker processes (each
    recording is seeded by its place in the list, so the data do not depend on the workers)."""
    from clonedrive.base.workers import default_workers, run_tasks
    from clonedrive.data.driving_log import read_driving_log
    from clonedrive.data.recorder import RecordConfig

    done: dict[int, dict] = {}
    tasks = []
    for index, spec in enumerate(recordings):
        out = data_dir / spec.name
        if (out / "driving_log.csv").is_file():
            _check_same_recording(out, spec, seed + index)
            rows = len(read_driving_log(out, verify_images="none").rows)
            if rows > 0:
                _say(progress, f"[record] {spec.name}: {rows} rows already recorded, reused")
                done[index] = {"name": spec.name, "rows": rows, "reused": True}
                continue
        options = {}
        if spec.turn_curvature_per_m is not None:
            options["turn_curvature_per_m"] = spec.turn_curvature_per_m
        record_config = RecordConfig(track=spec.track, style=spec.style, laps=spec.laps,
                                     speed_mph=spec.speed_mph, reverse=spec.reverse,
                                     noise=spec.noise, seconds=spec.seconds,
                                     seed=seed + index, start_time="2026-01-01T12:00:00",
                                     look=spec.look, **options)
        tasks.append({"index": index, "name": spec.name, "config": record_config,
                      "out": str(out), "spec": _spec_record(spec, seed + index)})
    workers = workers or default_workers()
    if tasks:
        _say(progress, f"[record] {len(tasks)} recording(s) on {min(workers, len(tasks))} "
                       "worker process(es): " + ", ".join(task["name"] for task in tasks))

    def on_done(_: int, result: dict) -> None:
        done[result.pop("index")] = result
        _say(progress, f"[record] {result['name']}: {result['rows']} rows "
                       f"({result['off_road_events']} off-road events)")

    if workers == 1:
        for task in tasks:
            on_done(0, _record_task(task))
    else:
        run_tasks(_record_task, tasks, workers=workers, on_done=on_done)
    return [done[index] for index in sorted(done)]


def _spec_record(spec: RecordSpec, seed: int) -> dict:
    """What ``recipe_recording.json`` holds: the spec and its seed (no ``look`` when it has
    none, as folders recorded before recipes could set one)."""
    record = {**dataclasses.asdict(spec), "seed": seed}
    if record["look"] is None:
        del record["look"]
    return record


def _check_same_recording(folder: Path, spec: RecordSpec, seed: int) -> None:
    """:class:`DemoFolderError` if ``folder`` was recorded from another recipe's spec (a
    folder recorded before specs were kept is taken as it is)."""
    path = folder / RECORDING_SPEC_FILE
    if path.is_file() and _read_json(path) != _spec_record(spec, seed):
        raise DemoFolderError(f"{folder} was recorded with other settings than this recipe's "
                              f"{spec.name!r} ({path}): give the demo another --out")


def _record_task(task: dict) -> dict:
    """One recording of the demo (in a worker process of :mod:`clonedrive.base.workers`)."""
    from clonedrive.data.recorder import record

    summary = record(task["config"], task["out"], progress=False)
    write_json_atomic(Path(task["out"]) / RECORDING_SPEC_FILE, task["spec"])
    return {"index": task["index"], "name": task["name"], "rows": summary.rows,
            "off_road_events": summary.off_road_events, "reused": False}


def run_demo(config: DemoConfig, out_dir: str | Path, *, progress: bool = True) -> dict:
    """Run every stage into ``out_dir``; returns the summary written to ``demo.json``."""
    from clonedrive.report.writeup import write_report

    out = Path(out_dir).absolute()
    out.mkdir(parents=True, exist_ok=True)
    recipe = load_recipe_file(config.recipe)
    save_config(config, out / "config.json")
    write_text_atomic(out / "recipe.toml", recipe.text)
    recordings, stages, groups = demo_plan(config, recipe)
    benched = bench_plan(config, recipe, out / "train" / "model.keras")
    summary: dict = {"config": config.__dict__, "recipe": recipe.identity(), "stages": {}}
    started = time.perf_counter()

    def stage(name: str, seconds: float, **extra) -> None:
        summary["stages"][name] = {"seconds": round(seconds, 1), **extra}
        write_json_atomic(out / "demo.json", summary)

    _say(progress, f"[recipe] {recipe.label()}: {recipe.summary or recipe.source}")
    t0 = time.perf_counter()
    recorded = _record_stage(recordings, out / "data", config.seed, progress, config.workers)
    stage("record", time.perf_counter() - t0, recordings=recorded,
          rows=sum(r["rows"] for r in recorded))

    t0 = time.perf_counter()
    data = recipe.data_recipe(out / "data")
    if config.quick:  # only the first recording was recorded
        data = replace(data, recordings=data.recordings[:1])
    for folder in stage_dirs(out / "train", len(stages)):
        _check_same_recipe(folder, recipe)
    run_stages(stages, data, out / "train", notes=recipe.notes(), progress=progress)
    stage("train", time.perf_counter() - t0, model=stages[0].model,
          epochs=[config.epochs for config in stages])

    t0 = time.perf_counter()
    report = _evaluate_stage(out, groups, progress, config.quick)
    stage("evaluate", time.perf_counter() - t0, totals=report["totals"])

    if benched is not None:
        t0 = time.perf_counter()
        bench_report = _bench_stage(out, benched, progress)
        stage("bench", time.perf_counter() - t0, splits=list(benched.splits),
              runs=sum(len(model["runs"]) for model in bench_report["models"].values()))

    t0 = time.perf_counter()
    written = write_report(out, progress=progress)
    stage("report", time.perf_counter() - t0,
          files=[str(written.markdown_path), str(written.html_path)])
    summary["total_seconds"] = round(time.perf_counter() - started, 1)
    write_json_atomic(out / "demo.json", summary)
    return summary


def _check_same_recipe(train_dir: Path, recipe: RecipeFile) -> None:
    """A run folder holds one recipe's model: :class:`DemoFolderError` if the model already
    there (to be reused or resumed) was made with another recipe or version."""
    from clonedrive.network.driving_settings import read_notes

    for name in ("model.keras", "last.keras"):
        if (train_dir / name).is_file():
            made_with = read_notes(train_dir / name).get("recipe")
            if made_with != recipe.identity():
                found = (f"{made_with.get('name')} v{made_with.get('version')}"
                         if isinstance(made_with, dict) else "no recipe")
                raise DemoFolderError(
                    f"{train_dir / name} was trained with {found}, not {recipe.label()}: give "
                    "the demo another --out, or remove that training folder")


def _evaluate_stage(out: Path, groups, progress: bool, quick: bool = False) -> dict:
    """Drive the trained model, with its own settings, through every group of runs (``quick``:
    a short drive that checks the stage runs, and says so instead of counting laps)."""
    from clonedrive.drivers.policy import load_policy
    from clonedrive.evaluate.results import format_table
    from clonedrive.evaluate.rollout import evaluate

    model_path = out / "train" / "model.keras"
    policy = load_policy(model_path)
    for runs in groups:
        _say(progress, "[evaluate] " + ", ".join(
            f"{t} at {v:g} mph" for t in runs.tracks for v in runs.speeds_mph)
             + (f"{', ' if runs.tracks else ''}{runs.unseen} unseen tracks at "
                f"{runs.unseen_speed_mph or runs.speeds_mph[0]:g} mph" if runs.unseen else ""))
    _say(progress, f"[evaluate] driven as the model file says: "
                   f"{policy.driving_settings().describe()}")
    report = evaluate(policy, groups, out / "eval", progress=progress,
                      model_path=str(model_path))
    _say(progress, format_table(report, with_totals=not quick))
    if quick:
        metres = sum(run["distance_m"] for run in report["runs"])
        _say(progress, f"quick check: the model drove {metres:.0f} m (the quick evaluation "
                       "stops before a lap: no lap counts; `clonedrive demo` measures driving)")
    return report


def _bench_stage(out: Path, config, progress: bool) -> dict:
    """Bench the trained model on the recipe's splits into ``bench/<splits>/``."""
    from clonedrive.bench.leaderboard import methods_text
    from clonedrive.bench.run import bench

    folder = out / "bench" / "+".join(config.splits)
    _say(progress, f"[bench] suite {config.suite}: {', '.join(config.splits)}, driven as "
                   "the model file says")
    report = bench(config, folder, progress=progress)
    _say(progress, methods_text(report))
    return report


def _read_json(path: Path) -> dict:
    import json

    return json.loads(path.read_text(encoding="utf-8"))


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, flush=True)
