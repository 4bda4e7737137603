"""One DAgger iteration's stages: collect labels where the network drives, record the
plain-cloning comparison's labels, aggregate the recordings, retrain."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from clonedrive.base.config import write_json_atomic
from clonedrive.pipelines.dagger.config import START_TIME, DaggerConfig
from clonedrive.pipelines.dagger.mixed_driver import MixedDriver


def collect(policy, config: DaggerConfig, beta: float, out: Path, *, seed: int,
            progress: bool = False) -> dict:
    """Drive ``config.tracks`` with the network mixed with the expert (``beta``), the expert
    labelling every step, and write each track's recording under ``out/<track>/``. Returns
    the collection's figures (also written as ``out/collect.json``)."""
    from clonedrive.base.paths import safe_stem
    from clonedrive.data.log_folder import prepare_log_folder
    from clonedrive.data.row_sink import RowSink
    from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
    from clonedrive.episode.drivers import ExpertDriver
    from clonedrive.episode.rules import EpisodeRules
    from clonedrive.episode.runner import Episode, PerCar, Runner
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
    from clonedrive.base.paths import safe_stem
    from clonedrive.base.udacity_spec import CONTROL_HZ
    from clonedrive.data.recorder import RecordConfig, record
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
