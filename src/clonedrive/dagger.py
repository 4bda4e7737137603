"""DAgger (Ross, Gordon & Bagnell 2011): the network drives, the expert labels what it sees.

Behaviour cloning only sees the states the expert visits; a network that drifts off the
expert's line meets states it never saw and does not know how to leave them. DAgger lets the
network drive and has the expert label every frame the network's own driving reaches, then
trains on all the labels gathered so far. ``run_dagger(config, base_run, out_dir)`` starts from
a trained run folder (``clonedrive train --out BASE``: its model, config and recipe) and, per
iteration ``k = 1..iterations``:

1. **collects**: on each of ``config.tracks`` one car drives ``laps`` lap(s) at up to
   ``speed_mph``. Each step the expert's controls are applied with probability
   ``beta_k = beta * beta_decay ** (k - 1)``, the network's otherwise (Ross et al.'s mixture
   policy). A **safety takeover** hands the car to the expert when it is about to leave the road
   (its side, now or ``takeover_preview_s`` ahead on its heading, within ``takeover_margin_m`` of
   an edge) until it is back near the centreline, heading along the road; takeovers are
   counted (per km, below), not hidden. The expert
   (:class:`~clonedrive.episode.drivers.ExpertDriver` as the runner's **labeller**) labels
   every visited frame with its steering and its target speed; every frame is written as a
   recording, ``iter_k/data/<track>/`` (``driving_log.csv``
   + ``IMG/`` + ``target_speed.csv``: the steering column holds the expert's label, throttle,
   brake and speed what the car did);
2. **aggregates** the base recipe and every iteration's recordings so far (center camera and
   its mirror image: the labels are the expert's for exactly that view);
3. **retrains** the network from the previous iteration's weights (``epochs`` epochs,
   ``iter_k/train/``);
4. **evaluates** it in closed loop: on the benchmark's ``bench_splits`` of ``bench_suite``
   (``clonedrive bench``, ``iter_k/bench/bench.json``), or with no bench splits on
   ``eval_tracks`` and ``eval_unseen`` generated tracks (evaluate's unseen tracks, never used
   for collection; ``iter_k/eval/eval.json``, splits ``builtin`` and ``unseen``).

**Human takeovers** (HG-DAgger, Kelly et al. 2019): ``human`` lists recordings made in
``clonedrive web``'s takeover mode, where a model drove and a person took the car whenever it
went wrong; such a recording holds only the person's rows, the labels. They are aggregated with
the expert's from iteration 1 on (center camera and its mirror image, like them).

Iteration 0 is the base model's evaluation. With ``plain`` the comparison DAgger needs is run
too: **plain cloning with as many extra expert labels** -- the expert itself drives the same
tracks (with ``plain_noise`` steering noise, its labels clean) until it has recorded as many
rows as DAgger collected in all, and the base model is retrained on base + those rows for as
many epochs as DAgger trained in all (``plain/``). So any difference comes from *where* the
labels are, not how many. With ``plain_each`` it is also run at every earlier iteration's
label count and epochs (``plain_NN/``), so the two methods are compared as curves, not only
where both may have reached the benchmark's ceiling.

``dagger.json`` holds per iteration: beta, labels collected (and in total), expert share of the
driving, takeovers and takeovers per km, and the evaluation's success %, interventions per km,
lap-time ratio and smoothness ratio per split, plus the plain-cloning row; ``dagger.png`` plots
them. Each stage's folder is reused when complete, so an interrupted run continues.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clonedrive.bench import DEFAULT_SUITE
from clonedrive.config import changed_settings, config_to_dict, read_json, write_json_atomic
from clonedrive.model.train import MAX_LEARNING_RATE
from clonedrive.sim.engine import DEFAULT_RENDERER
from clonedrive.world.vehicle import check_set_speed

DAGGER_JSON = "dagger.json"
DAGGER_PNG = "dagger.png"
#: Settings a rerun into a DAgger folder may change: more iterations extend it (iteration k
#: does not depend on how many follow), workers only share the work, and the plain-cloning
#: folders check their own recording (noise, label count) before they are reused.
RERUN_MAY_CHANGE = ("iterations", "workers", "plain", "plain_each", "plain_noise")
#: Start of the image names of DAgger recordings (reproducible names, like the demo's).
START_TIME = "2026-01-01T12:00:00"


@dataclass(frozen=True)
class DaggerConfig:
    """What ``clonedrive dagger`` runs (see the module doc)."""

    iterations: int = 5
    beta: float = 0.5  #: share of steps the expert drives in iteration 1
    beta_decay: float = 0.5  #: beta_k = beta * beta_decay ** (k - 1)
    tracks: tuple[str, ...] = ("mountain", "lake")  #: where labels are collected
    laps: int = 1  #: laps per track and iteration
    speed_mph: float = 30.0  #: set speed (a cap) while collecting and evaluating
    epochs: int = 2  #: training epochs per iteration, from the previous weights
    learning_rate: float = 5e-4
    eval_tracks: tuple[str, ...] = ("mountain", "lake")
    eval_laps: int = 1
    eval_unseen: int = 3  #: generated tracks evaluate never records on (split ``unseen``)
    bench_suite: str = DEFAULT_SUITE  #: the benchmark suite evaluating each iteration ...
    bench_splits: tuple[str, ...] = ()  #: ... on these splits (none: evaluate's tracks)
    workers: int | None = 1  #: bench worker processes
    takeover_margin_m: float = 0.3  #: the expert takes over this near an edge [m]
    takeover_preview_s: float = 1.0  #: ... judged now and this far ahead on the heading [s]
    takeover_release_cte_m: float = 0.5  #: the network gets the car back within this of centre
    takeover_min_s: float = 1.0  #: a takeover lasts at least this long [s]
    plain: bool = True  #: also train plain cloning with as many extra expert labels
    #: ... and at every earlier iteration's label count too (the comparison as a curve)
    plain_each: bool = False
    plain_noise: float = 0.15  #: the expert's steering noise recording those labels
    seed: int = 0
    max_seconds: float | None = None  #: cap per episode (quick runs)
    scenery: bool = True
    #: recordings of a person's takeovers (``clonedrive web``), aggregated from iteration 1
    human: tuple[str, ...] = ()
    renderer: str = DEFAULT_RENDERER  #: who draws frames (sim/engine.py), collecting and after
    #: evaluate on whole frames, not only the rows the network's crop keeps (collection always
    #: renders whole frames: they are recorded)
    full_frame: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "human", tuple(str(folder) for folder in self.human))
        if self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        for name in ("beta", "beta_decay"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if not self.tracks:
            raise ValueError("give at least one track to collect on")
        if not self.eval_tracks and not self.eval_unseen:
            raise ValueError("give at least one evaluation track (or eval_unseen)")
        check_set_speed(self.speed_mph)
        for name in ("laps", "epochs", "eval_laps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.eval_unseen < 0:
            raise ValueError(f"eval_unseen must be >= 0, got {self.eval_unseen}")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:  # also NaN and infinity
            raise ValueError(f"learning_rate must be in (0, {MAX_LEARNING_RATE:g}], got "
                             f"{self.learning_rate}")
        for name in ("takeover_margin_m", "takeover_preview_s", "takeover_release_cte_m",
                     "takeover_min_s"):
            if not (getattr(self, name) >= 0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number >= 0")
        if not 0.0 <= self.plain_noise <= 1.0:
            raise ValueError(f"plain_noise must be in [0, 1], got {self.plain_noise}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds)
                                                 and self.max_seconds > 0):
            raise ValueError(f"max_seconds must be a positive number of seconds, got "
                             f"{self.max_seconds}")

    def beta_at(self, iteration: int) -> float:
        """The expert's share of the steps in iteration ``iteration`` (1-based)."""
        return self.beta * self.beta_decay ** (iteration - 1)


# --- the mixed driver ----------------------------------------------------------------------


class MixedDriver:
    """A runner :class:`~clonedrive.episode.runner.Driver`: per car and step, the expert's
    controls with probability ``beta`` (or during a safety takeover), else the network's.

    The network's decisions come from one batched prediction for all cars
    (:class:`~clonedrive.episode.drivers.PolicyDriver`); each car has its own expert at the
    wheel, called every step so that its steering filter follows the car whoever drives.
    ``Decision.detail`` says who drove: ``"network"``, ``"expert"`` or ``"takeover"``.
    """

    def __init__(self, policy, experts: Sequence, set_speeds_mph: Sequence[float], *,
                 beta: float, rng: np.random.Generator, margin_m: float = 0.3,
                 preview_s: float = 1.0, release_cte_m: float = 0.5, min_takeover_s: float = 1.0,
                 control_hz: float = 15.0) -> None:
        from clonedrive.episode.drivers import PolicyDriver

        self.network = PolicyDriver(policy, set_speeds_mph)
        self.experts = list(experts)
        self.beta = float(beta)
        self.rng = rng
        self.margin_m = float(margin_m)
        self.preview_s = float(preview_s)
        self.release_cte_m = float(release_cte_m)
        self.min_takeover_steps = int(math.ceil(min_takeover_s * control_hz))
        count = len(self.experts)
        self.takeovers = [0] * count
        self.steps_by = [{"network": 0, "expert": 0, "takeover": 0} for _ in range(count)]
        self._taken = [0] * count  # steps since the takeover began, 0 = none

    def reset(self, car: int) -> None:
        self.network.reset(car)
        self.experts[car].reset()
        self._taken[car] = 0

    def intervened(self, car: int, obs) -> None:
        self.network.intervened(car, obs)
        self._taken[car] = 0

    def about_to_leave(self, car: int, obs) -> bool:
        """The car's outer front tyre is, now or ``preview_s`` ahead on its heading, within
        ``margin_m`` of the road's edge."""
        from clonedrive.world.vehicle import MPH_TO_MPS

        expert = self.experts[car]
        heading = obs.heading_error_rad
        drift = -obs.speed_mph * MPH_TO_MPS * math.sin(heading)  # lateral speed, + = rightward
        ahead = obs.cte_m + drift * self.preview_s
        # The front tyre sits half the car's width to the side, and the axle ahead of the
        # centre reaches further out when the car is yawed.
        corner = expert.config.car_half_width_m * abs(math.cos(heading)) \
            + expert.vehicle.l_f * abs(math.sin(heading))
        half_width = 0.5 * float(expert.track.width_at(float(expert.track.wrap(obs.s_m))))
        outward = max(abs(obs.cte_m), abs(ahead))
        return outward + corner + self.margin_m > half_width

    def act(self, cars: Sequence[int], observations: Sequence) -> list:
        from clonedrive.episode.runner import Decision

        network = self.network.act(cars, observations)
        decisions = []
        for car, obs, mine in zip(cars, observations, network, strict=True):
            expert = self.experts[car].act(obs)
            who = "network"
            if self._taken[car] > 0:
                self._taken[car] += 1
                back = (abs(obs.cte_m) < self.release_cte_m
                        and abs(obs.heading_error_rad) < math.radians(5.0))
                if back and self._taken[car] > self.min_takeover_steps:
                    self._taken[car] = 0
                else:
                    who = "takeover"
            if who == "network" and self.about_to_leave(car, obs):
                self._taken[car] = 1
                self.takeovers[car] += 1
                who = "takeover"
            if who == "network" and self.rng.random() < self.beta:
                who = "expert"
            self.steps_by[car][who] += 1
            controls = mine.controls if who == "network" else expert.controls_applied
            decisions.append(Decision(controls=controls, detail=who))
        return decisions


# --- one iteration's stages ----------------------------------------------------------------


def collect(policy, config: DaggerConfig, beta: float, out: Path, *, seed: int,
            progress: bool = False) -> dict:
    """Drive ``config.tracks`` with the network mixed with the expert (``beta``), the expert
    labelling every step, and write each track's recording under ``out/<track>/``. Returns
    the collection's figures (also written as ``out/collect.json``)."""
    from clonedrive.data.recorder import RowSink, prepare_log_folder
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.episode.drivers import ExpertDriver
    from clonedrive.episode.rules import EpisodeRules
    from clonedrive.episode.runner import Episode, PerCar, Runner
    from clonedrive.paths import safe_stem
    from clonedrive.sim.simulator import SimConfig, Simulator
    from clonedrive.world.catalog import load_track

    tracks = [load_track(name) for name in config.tracks]
    expert_config = ExpertConfig(speed_mph=config.speed_mph)
    rules = EpisodeRules(laps=config.laps, set_speed_mph=config.speed_mph,
                         max_seconds=config.max_seconds)
    folders = [out / safe_stem(name) for name in config.tracks]
    # Whole frames: what collection sees is recorded as training data (a recipe may crop
    # differently, and augmentation shifts rows into the network's view).
    sims, sinks = [], []
    try:
        for track, folder in zip(tracks, folders, strict=True):
            sims.append(Simulator(track, SimConfig(scenery=config.scenery,
                                                   renderer=config.renderer)))
            _, start = prepare_log_folder(folder, START_TIME)
            sinks.append(RowSink(folder, start, relative_paths=True))
        episodes = [Episode(sim, rules, track=name, seed=seed)
                    for sim, name in zip(sims, config.tracks, strict=True)]
        driver = MixedDriver(
            policy, [ExpertPolicy(track, expert_config) for track in tracks],
            [config.speed_mph] * len(tracks), beta=beta,
            rng=np.random.default_rng([config.seed, seed]), margin_m=config.takeover_margin_m,
            preview_s=config.takeover_preview_s, release_cte_m=config.takeover_release_cte_m,
            min_takeover_s=config.takeover_min_s)
        labeller = PerCar([ExpertDriver(ExpertPolicy(track, expert_config)) for track in tracks])

        def on_step(step) -> None:
            label = step.label
            sinks[step.car].submit(step.seen, label.label, step.decision.controls,
                                   target_speed_mph=label.detail.label_speed_mph)

        Runner(episodes, driver, labeller=labeller).run(on_step)
        for sink in sinks:
            sink.close()
        per_track = []
        for car, (name, episode) in enumerate(zip(config.tracks, episodes, strict=True)):
            summary = episode.trace.summary()
            km = summary["distance_m"] / 1000.0
            per_track.append({
                "track": name, "folder": folders[car].name, "labels": sinks[car].rows_written,
                "distance_km": round(km, 3), "takeovers": driver.takeovers[car],
                "off_road_events": summary["interventions"], "steps_by": driver.steps_by[car]})
    finally:
        for sink in sinks:
            sink.close()
        for sim in sims:
            sim.close()
    labels = sum(item["labels"] for item in per_track)
    km = sum(item["distance_km"] for item in per_track)
    takeovers = sum(item["takeovers"] for item in per_track)
    off_road = sum(item["off_road_events"] for item in per_track)
    steps = {key: sum(item["steps_by"][key] for item in per_track)
             for key in ("network", "expert", "takeover")}
    result = {
        "beta": round(beta, 4), "labels": labels, "distance_km": round(km, 3),
        "takeovers": takeovers, "takeovers_per_km": round(takeovers / km, 3) if km else None,
        "off_road_events": off_road, "off_road_per_km": round(off_road / km, 3) if km else None,
        "expert_share": round((steps["expert"] + steps["takeover"]) / max(1, sum(steps.values())),
                              4),
        "tracks": per_track,
    }
    write_json_atomic(out / "collect.json", result)
    return result


def record_plain(config: DaggerConfig, labels: int, out: Path) -> dict:
    """The plain-cloning comparison's data: the expert drives ``config.tracks`` (steering
    noise ``plain_noise``, clean labels) until about ``labels`` rows are recorded, split
    evenly over the tracks."""
    from clonedrive.data.recorder import RecordConfig, record
    from clonedrive.paths import safe_stem
    from clonedrive.udacity_spec import CONTROL_HZ
    from clonedrive.world.catalog import load_track
    from clonedrive.world.vehicle import MPH_TO_MPS

    per_track = max(1, math.ceil(labels / len(config.tracks)))
    seconds = per_track / CONTROL_HZ
    rows = 0
    for index, name in enumerate(config.tracks):
        length = load_track(name).length_m
        # Laps enough for the rows even at the set speed throughout (and a quarter more for a
        # downhill overshoot); ``seconds`` stops it at the rows asked for.
        laps = max(1, math.ceil(seconds * config.speed_mph * MPH_TO_MPS * 1.25 / length))
        summary = record(RecordConfig(track=name, laps=laps, seconds=seconds,
                                      speed_mph=config.speed_mph, noise=config.plain_noise,
                                      seed=config.seed + 100 + index, relative_paths=True,
                                      start_time=START_TIME, scenery=config.scenery),
                         out / safe_stem(name), progress=False)
        rows += summary.rows
    result = {"labels": rows, "asked": labels, "noise": config.plain_noise}
    write_json_atomic(out / "record.json", result)
    return result


def aggregate_recipe(base, folders: Sequence[Path], human: Sequence[str | os.PathLike] = ()):
    """The base recipe plus ``folders`` (DAgger's own) and ``human`` (a person's takeovers,
    ``clonedrive web``): center camera and its mirror image each."""
    from clonedrive.data.recipe import Recipe, RecordingSpec

    extra = tuple(RecordingSpec(path=Path(folder).absolute(), name=f"{folder.parent.parent.name}"
                                f"_{folder.name}", cameras="center", flip=True)
                  for folder in folders)
    extra += tuple(RecordingSpec(path=Path(folder).absolute(), name=f"human_{index}_"
                                 f"{Path(folder).absolute().name}", cameras="center", flip=True)
                   for index, folder in enumerate(human, start=1))
    source = f"{base.source} + DAgger recordings" + (" + human takeovers" if human else "")
    return Recipe(base.recordings + extra, source=source)


def check_human_recordings(folders: Sequence[str | os.PathLike]) -> None:
    """FileNotFoundError naming a folder that holds no driving log."""
    for folder in folders:
        if not (Path(folder) / "driving_log.csv").is_file():
            raise FileNotFoundError(f"{folder}: no driving_log.csv (a takeover recording of "
                                    "clonedrive web expected)")


def retrain(base_config, recipe, init_from: Path, epochs: int, learning_rate: float, out: Path,
            *, seed: int, progress: bool = False) -> Path:
    """Train from ``init_from``'s weights on ``recipe``; returns the model path (reused when
    ``out`` holds a finished run)."""
    from clonedrive.model.train import train

    if (out / "model.keras").is_file() and (out / "state.json").is_file():
        return out / "model.keras"
    config = dataclasses.replace(base_config, epochs=epochs, learning_rate=learning_rate,
                                 init_from=str(init_from), export_h5=False, seed=seed)
    from clonedrive.network.driving_settings import read_notes

    # The new model is driven as the one it starts from (its file's settings and recipe).
    notes = read_notes(init_from) or None
    return train(config, recipe, out, progress=progress, notes=notes).model_path


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
        ref = {id(r): references.get(_reference_key(r["track"], r["speed_mph"])) or {}
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


def _reference_key(track: str, speed_mph: float) -> str:
    return f"{track}@{float(speed_mph):g}"


def expert_references(config: DaggerConfig) -> dict:
    """The expert's figures on every evaluation (track, speed): its lap time and smoothness
    (:func:`clonedrive.evaluate.reference.expert_reference`); the benchmark brings its own."""
    from clonedrive.evaluate.config import UNSEEN_SEED_BASE
    from clonedrive.evaluate.reference import expert_reference

    if config.bench_splits:
        return {}
    names = list(config.eval_tracks) + [f"gen:{UNSEEN_SEED_BASE + index}"
                                        for index in range(config.eval_unseen)]
    return {_reference_key(name, config.speed_mph):
            expert_reference(name, config.speed_mph, laps=config.eval_laps,
                             max_seconds=config.max_seconds)
            for name in names}


# --- the whole run -------------------------------------------------------------------------


def run_dagger(config: DaggerConfig, base_run: str | os.PathLike, out_dir: str | os.PathLike,
               *, progress: bool = True) -> dict:
    """DAgger from the training run folder ``base_run`` into ``out_dir`` (see the module doc).
    Returns what ``dagger.json`` holds."""
    from clonedrive.data.recipe import load_recipe
    from clonedrive.drivers.policy import load_policy
    from clonedrive.model.train import load_run_config
    from clonedrive.paths import check_output_folder

    base = Path(base_run)
    base_model = base / "model.keras"
    if not base_model.is_file() or not (base / "recipe.toml").is_file():
        raise FileNotFoundError(f"{base} is not a finished training run (model.keras and "
                                "recipe.toml expected: clonedrive train --out)")
    check_human_recordings(config.human)
    base_config = load_run_config(base)  # both read before anything is written
    base_recipe = load_recipe(base / "recipe.toml")
    out = check_output_folder(out_dir)
    settings = {**config_to_dict(config), "base": str(base.resolve())}
    check_rerun(out, settings)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "config.json", settings)

    _say(progress, "[dagger] expert reference laps")
    references = expert_references(config)
    rows = []
    _say(progress, "[dagger] iteration 0: the base model")
    rows.append({"iteration": 0, "method": "base", "beta": None, "labels": 0,
                 "labels_total": 0, "model": str(base_model),
                 "eval": evaluate_model(base_model, config, out / "iter_00" / "eval", references,
                                        progress=progress)})
    model = base_model
    folders: list[Path] = []
    labels_total = 0
    for iteration in range(1, config.iterations + 1):
        folder = out / f"iter_{iteration:02d}"
        beta = config.beta_at(iteration)
        _say(progress, f"[dagger] iteration {iteration}: collecting with beta {beta:.3f}")
        collected = _reuse_json(folder / "data" / "collect.json") or collect(
            load_policy(model), config, beta, folder / "data", seed=iteration, progress=progress)
        folders += [folder / "data" / item["folder"] for item in collected["tracks"]]
        labels_total += collected["labels"]
        _say(progress, f"[dagger] iteration {iteration}: {collected['labels']} labels, "
                       f"{collected['takeovers']} takeovers; retraining")
        model = retrain(base_config, aggregate_recipe(base_recipe, folders, config.human), model,
                        config.epochs, config.learning_rate, folder / "train",
                        seed=config.seed + iteration, progress=progress)
        rows.append({"iteration": iteration, "method": "dagger", "beta": round(beta, 4),
                     "labels": collected["labels"], "labels_total": labels_total,
                     "collect": {key: collected[key] for key in
                                 ("distance_km", "takeovers", "takeovers_per_km",
                                  "off_road_events", "off_road_per_km", "expert_share")},
                     "model": str(model),
                     "eval": evaluate_model(model, config, folder / "eval", references,
                                            progress=progress)})
        _write_report(out, config, rows, None, references)

    plain, plain_each = None, []
    if config.plain:
        # Earlier iterations' label counts first (with plain_each), then the last one's.
        counts = [(row["iteration"], row["labels_total"]) for row in rows[1:]]
        for iteration, labels in counts if config.plain_each else counts[-1:]:
            last = iteration == config.iterations
            folder = out / ("plain" if last else f"plain_{iteration:02d}")
            _say(progress, f"[dagger] plain cloning with {labels} extra expert labels "
                           f"({config.epochs * iteration} epochs)")
            entry = train_plain(config, base_config, base_recipe, base_model, labels, iteration,
                                folder, references, progress=progress)
            if last:
                plain = entry
            else:
                plain_each.append(entry)
                _write_report(out, config, rows, None, references, plain_each)
    return _write_report(out, config, rows, plain, references, plain_each)


def check_rerun(out: Path, settings: dict) -> None:
    """``ValueError`` naming each differing setting when ``out`` holds a DAgger run made with
    other ``settings`` (its config.json) than :data:`RERUN_MAY_CHANGE`: a rerun reuses every
    finished iteration, which must not then be labelled with settings it was not made with."""
    path = out / "config.json"
    if not path.is_file():
        return
    changed = changed_settings(read_json(path, what="config file"), settings,
                               may_change=RERUN_MAY_CHANGE)
    if changed:
        raise ValueError(f"{out} holds a DAgger run with other settings ({'; '.join(changed)}), "
                         "whose iterations would be reused as if made with the new ones; rerun "
                         "it with its own settings, or choose another --out")


def train_plain(config: DaggerConfig, base_config, base_recipe, base_model: Path, labels: int,
                iteration: int, folder: Path, references: dict, *, progress: bool) -> dict:
    """Plain cloning with ``labels`` extra expert labels, trained from the base model for as
    many epochs as DAgger had trained by ``iteration``, and evaluated as the iterations are."""
    recorded = _reuse_json(folder / "data" / "record.json")
    if recorded is None:
        recorded = record_plain(config, labels, folder / "data")
    else:  # reused only when recorded as this run asks (older folders hold no "asked")
        if recorded.get("noise") != config.plain_noise:
            raise ValueError(f"{folder / 'data'}: recorded with steering noise "
                             f"{recorded.get('noise')}, not the {config.plain_noise} asked for "
                             "(plain_noise); use another --out, or remove that folder")
        asked = recorded.get("asked", recorded.get("labels"))
        if asked != labels:
            raise ValueError(f"{folder / 'data'}: recorded for {asked} labels, not the "
                             f"{labels} DAgger collected by iteration {iteration}; use another "
                             "--out, or remove that folder")
    folders = [folder / "data" / item.name for item in sorted((folder / "data").iterdir())
               if (item / "driving_log.csv").is_file()]
    # The person's takeovers too: the comparison differs only in where the expert's labels are.
    model = retrain(base_config, aggregate_recipe(base_recipe, folders, config.human), base_model,
                    config.epochs * iteration, config.learning_rate, folder / "train",
                    seed=config.seed, progress=progress)
    return {"method": "plain", "iteration": iteration, "labels_total": recorded["labels"],
            "noise": recorded["noise"], "epochs": config.epochs * iteration, "model": str(model),
            "eval": evaluate_model(model, config, folder / "eval", references,
                                   progress=progress)}


def _reuse_json(path: Path) -> dict | None:
    import json

    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _write_report(out: Path, config: DaggerConfig, rows: list[dict], plain: dict | None,
                  references: dict, plain_each: Sequence[dict] = ()) -> dict:
    report = {"config": dataclasses.asdict(config), "iterations": rows, "plain": plain,
              "plain_each": list(plain_each), "expert": references}
    write_json_atomic(out / DAGGER_JSON, report)
    plot_dagger(report, out / DAGGER_PNG)
    return report


def plot_dagger(report: dict, path: Path) -> Path:
    """Per iteration: interventions per km and success % per split, collection takeovers per
    km, and the plain-cloning comparison as dashed lines."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from clonedrive.config import atomic_path

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


def _say(enabled: bool, text: str) -> None:
    if enabled:
        print(text, flush=True)
