"""The main job: from nothing to a driving model, measured, with a write-up.

``run_demo(DemoConfig(), "runs/demo")``:

1. records the write-up's data with the expert (centred laps, left/right edge laps relabelled
   with +-0.25, the sharp turns, the mountain track both ways, its sharp turns and its hairpin)
   into ``runs/demo/data/<name>/``;
2. balances, splits and trains (``runs/demo/train/``);
3. evaluates in closed loop (``runs/demo/eval/``): lake at 15 and 30 mph, mountain at 15 and
   25 mph, and unseen generated tracks at 20 mph, with videos for the built-in tracks. The set
   speed is a maximum: the policy slows as its predicted steering grows (``slow_in_curves``),
   because the mountain's 10.5 m hairpin cannot be taken at 25 mph (it would need ~1.2 g);

4. writes ``report.md`` / ``report.html``.

Each stage writes its folder and ``config.json``; ``demo.json`` holds stage timings. Running the
demo again on the same folder reuses finished stages (recordings with their rows, a trained
model), so an interrupted demo continues where it stopped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

from clonedrive.config import save_config, write_json_atomic
from clonedrive.udacity_spec import STEERING_CORRECTION

#: Where ``clonedrive demo`` writes its run by default.
DEFAULT_RUN_DIR = "runs/demo"
#: Architectures the demo can train (model.architectures.MODEL_NAMES, fast first).
DEMO_MODELS = ("fast", "seed", "pilotnet")


@dataclass(frozen=True)
class DemoConfig:
    """What ``clonedrive demo`` runs (the stages' own configs come from :func:`demo_plan`)."""

    quick: bool = False  #: small data, few epochs, one short evaluation (about a minute)
    epochs: int | None = None  #: override the training epochs
    unseen: int | None = None  #: override the number of unseen generated tracks
    model: str = "fast"  #: architecture: fast trains in minutes on 2 CPU cores
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
        if self.model not in DEMO_MODELS:
            raise ValueError(f"model must be one of {', '.join(DEMO_MODELS)}, got {self.model!r}")


@dataclass(frozen=True)
class DemoRecording:
    name: str
    track: str
    style: str
    laps: int
    speed_mph: float
    reverse: bool = False
    noise: float = 0.0
    seconds: float | None = None
    turn_curvature_per_m: float | None = None  #: turns style: record only tighter curves


#: The write-up's data (folder names of data.recipe.WRITEUP_FOLDERS), recorded by the expert.
#: Noise on the centred laps makes the car wander and the clean labels show the recovery.
DEFAULT_RECORDINGS = (
    DemoRecording("middle", "lake", "center", 3, 30.0, noise=0.15),
    DemoRecording("left", "lake", "left", 1, 25.0),
    DemoRecording("right", "lake", "right", 1, 25.0),
    DemoRecording("turns", "lake", "turns", 1, 30.0, noise=0.15),
    DemoRecording("mountain", "mountain", "center", 1, 30.0, noise=0.15),
    DemoRecording("mountain_reverse", "mountain", "center", 1, 30.0, reverse=True, noise=0.15),
    DemoRecording("mountain_turns", "mountain", "turns", 1, 30.0, noise=0.1,
                  turn_curvature_per_m=1 / 40),
    DemoRecording("hairpin", "mountain", "turns", 1, 30.0, reverse=True,
                  turn_curvature_per_m=1 / 20),
)

#: --quick: enough to exercise every stage, not to drive well.
QUICK_RECORDINGS = (
    DemoRecording("middle", "lake", "center", 1, 30.0, noise=0.15, seconds=20.0),
)


def demo_plan(config: DemoConfig):
    """(recordings, TrainConfig, EvalConfig) the demo runs for ``config``."""
    from clonedrive.evaluate.rollout import EvalConfig
    from clonedrive.model.train import TrainConfig

    if config.quick:
        recordings = QUICK_RECORDINGS
        train = TrainConfig(model=config.model, epochs=config.epochs or 2, batch_size=64,
                            learning_rate=1e-3, seed=config.seed)
        evaluation = EvalConfig(tracks=("lake",), speeds_mph=(15.0,), laps=1,
                                unseen=config.unseen or 0, video=config.video,
                                max_seconds=10.0, slow_in_curves=True,
                                workers=config.workers)
    else:
        recordings = DEFAULT_RECORDINGS
        train = TrainConfig(model=config.model, epochs=config.epochs or 8, batch_size=128,
                            learning_rate=1e-3, seed=config.seed)
        # The base of _evaluation_groups (which sets each group's tracks and speeds).
        evaluation = EvalConfig(tracks=(), speeds_mph=(20.0,), laps=2, video=config.video,
                                unseen=10 if config.unseen is None else config.unseen,
                                unseen_speed_mph=20.0, unseen_laps=1, slow_in_curves=True,
                                workers=config.workers)
    return recordings, train, evaluation


def _record_stage(recordings, data_dir: Path, seed: int, progress: bool,
                  workers: int | None = None) -> list[dict]:
    """Record what is not recorded yet, the recordings spread over worker processes (each
    recording is seeded by its place in the list, so the data do not depend on the workers)."""
    from clonedrive.data.driving_log import read_driving_log
    from clonedrive.data.recorder import RecordConfig
    from clonedrive.workers import default_workers, run_tasks

    done: dict[int, dict] = {}
    tasks = []
    for index, spec in enumerate(recordings):
        out = data_dir / spec.name
        if (out / "driving_log.csv").is_file():
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
                                     **options)
        tasks.append({"index": index, "name": spec.name, "config": record_config,
                      "out": str(out)})
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


def _record_task(task: dict) -> dict:
    """One recording of the demo (in a worker process of :mod:`clonedrive.workers`)."""
    from clonedrive.data.recorder import record

    summary = record(task["config"], task["out"], progress=False)
    return {"index": task["index"], "name": task["name"], "rows": summary.rows,
            "off_road_events": summary.off_road_events, "reused": False}


def _recipe_text(recordings, data_dir: Path) -> str:
    from clonedrive.data.recipe import WRITEUP_FOLDERS, writeup_recipe_text

    names = [spec.name for spec in recordings]
    if sorted(names) == sorted(WRITEUP_FOLDERS):
        return writeup_recipe_text({name: data_dir / name for name in names})
    lines = ["# clonedrive demo --quick: centre driving only", "[defaults]",
             'cameras = "all"', f"correction = {STEERING_CORRECTION}", "flip = true", ""]
    for name in names:
        lines += ["[[recording]]", f'name = "{name}"', f'path = "{(data_dir / name).as_posix()}"',
                  ""]
    return "\n".join(lines)


def run_demo(config: DemoConfig, out_dir: str | Path, *, progress: bool = True) -> dict:
    """Run every stage into ``out_dir``; returns the summary written to ``demo.json``."""
    from clonedrive.data.recipe import load_recipe
    from clonedrive.drivers.network import load_policy
    from clonedrive.evaluate.rollout import evaluate, format_table
    from clonedrive.model.train import train
    from clonedrive.report.writeup import write_report

    out = Path(out_dir).absolute()
    out.mkdir(parents=True, exist_ok=True)
    save_config(config, out / "config.json")
    recordings, train_config, eval_config = demo_plan(config)
    summary: dict = {"config": config.__dict__, "stages": {}}
    started = time.perf_counter()

    def stage(name: str, seconds: float, **extra) -> None:
        summary["stages"][name] = {"seconds": round(seconds, 1), **extra}
        write_json_atomic(out / "demo.json", summary)

    t0 = time.perf_counter()
    recorded = _record_stage(recordings, out / "data", config.seed, progress, config.workers)
    stage("record", time.perf_counter() - t0, recordings=recorded,
          rows=sum(r["rows"] for r in recorded))

    t0 = time.perf_counter()
    recipe_path = out / "recipe.toml"
    recipe_path.write_text(_recipe_text(recordings, out / "data"), encoding="utf-8")
    train_dir = out / "train"
    if (train_dir / "model.keras").is_file() and (train_dir / "state.json").is_file():
        state = _read_json(train_dir / "state.json")
        resume = state.get("epochs_done", 0) < train_config.epochs
    else:
        resume = False
    if not (train_dir / "model.keras").is_file() or resume:
        _say(progress, f"[train] {train_config.model} for {train_config.epochs} epochs")
        train(train_config, load_recipe(recipe_path), train_dir, resume=resume,
              progress=progress)
    else:
        _say(progress, "[train] model already trained, reused")
    stage("train", time.perf_counter() - t0, model=train_config.model,
          epochs=train_config.epochs)

    t0 = time.perf_counter()
    policy = load_policy(train_dir / "model.keras", slow_in_curves=eval_config.slow_in_curves)
    parts = _evaluation_groups(config, eval_config)
    for runs in parts:
        _say(progress, "[evaluate] " + ", ".join(
            f"{t} at {v:g} mph" for t in runs.tracks for v in runs.speeds_mph)
             + (f"{', ' if runs.tracks else ''}{runs.unseen} unseen tracks at "
                f"{runs.unseen_speed_mph or runs.speeds_mph[0]:g} mph" if runs.unseen else ""))
    report = evaluate(policy, parts, out / "eval", progress=progress,
                      model_path=str(train_dir / "model.keras"))
    stage("evaluate", time.perf_counter() - t0, totals=report["totals"])
    _say(progress, format_table(report))

    t0 = time.perf_counter()
    written = write_report(out, progress=progress)
    stage("report", time.perf_counter() - t0,
          files=[str(written.markdown_path), str(written.html_path)])
    summary["total_seconds"] = round(time.perf_counter() - started, 1)
    write_json_atomic(out / "demo.json", summary)
    return summary


def _evaluation_groups(config: DemoConfig, base):
    """The demo's runs: lake 15/30 (2 laps), mountain 15/25 (1 lap), unseen at 20 mph."""
    if config.quick:
        return [base]
    return [
        replace(base, tracks=("lake",), speeds_mph=(15.0, 30.0), laps=2, unseen=0),
        replace(base, tracks=("mountain",), speeds_mph=(15.0, 25.0), laps=1, unseen=0),
        replace(base, tracks=(), speeds_mph=(20.0,), laps=1, video=False),
    ]


def _read_json(path: Path) -> dict:
    import json

    return json.loads(path.read_text(encoding="utf-8"))


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, flush=True)
