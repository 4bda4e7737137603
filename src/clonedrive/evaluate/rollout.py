"""Closed-loop evaluation: a network drives the simulator, headless and in-process (no socket).

Several runs (track x speed) are driven in lock-step by the episode runner
(:mod:`clonedrive.episode`), the network's predictions for one step beside the rendering of the
next. Each run has its own simulator and its own PI speed controller; steering comes from the
shared network (:class:`~clonedrive.episode.drivers.PolicyDriver`), which predicts each frame
alone (:meth:`~clonedrive.drivers.policy.NetworkPolicy.predict`): a run drives the same path
whichever runs share its group, its worker process or its command.

The runner's rules apply (:mod:`clonedrive.episode.rules`): on an off-road event the frame the
network saw is saved, and the car is put back on the centreline heading along the road at the set
speed (an intervention); a run stops when its laps have been driven or its time limit passes.

Every run renders for the network only the rows the network's crop keeps (``render_rows``, from
the model: :mod:`clonedrive.network.crop`; ``full_frame`` turns it off); the rest of each frame is
a constant, also in its off-road frames. A run with video renders a whole frame for its video
besides (``SimConfig.film``), so a filmed run drives exactly as the same run without video.
eval.json records the rows and the renderer (``renderer``, ``renderer_used``, ``gl_renderer``).

Output file names (maps, videos, off-road frames) are made from the track's own name and the
speed by :func:`clonedrive.base.paths.safe_stem`, never from the path a track was given by.
eval.json is rewritten (atomically) as each run finishes, so an error late in an evaluation
loses none of the runs that finished before it; ``"complete"`` says whether every run is in.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from clonedrive.base.config import save_config, write_json_atomic
from clonedrive.base.paths import safe_stem
from clonedrive.base.udacity_spec import SPEED_KI, SPEED_KP
from clonedrive.episode.rules import EpisodeRules
from clonedrive.episode.runner import Episode, Runner, Step
from clonedrive.evaluate.config import EvalConfig, RunSpec, run_specs
from clonedrive.evaluate.reference import against_expert
from clonedrive.evaluate.results import totals
from clonedrive.network.driving_settings import caution_text, full_speed_text
from clonedrive.world.vehicle import MPH_TO_MPS

if TYPE_CHECKING:
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.sim.camera_pool import CameraPool
    from clonedrive.world.track import Track


@dataclass
class _Run:
    """One evaluation run: its spec, its episode and what it writes."""

    index: int  #: position in run_specs (eval.json keeps that order)
    spec: RunSpec
    episode: Episode
    name: str  #: file-name stem of its outputs
    saliency: object = None  #: a model.saliency.VisualBackProp painting its video frames
    video: object = None
    result: dict | None = None


def run_name(track_name: str, speed_mph: float, taken: set[str] | None = None) -> str:
    """The file-name stem of a run's outputs: the track's own name and the speed, made safe by
    :func:`~clonedrive.base.paths.safe_stem`; ``-2``, ``-3``... when ``taken`` already holds it."""
    stem = safe_stem(f"{track_name}_{speed_mph:g}mph")
    name, number = stem, 1
    while taken is not None and name in taken:
        number += 1
        name = f"{stem}-{number}"
    return name


def hud_frame(image: np.ndarray, *, steering: float, speed_mph: float, cte_m: float, lap: int,
              laps: int, interventions: int, scale: int = 2) -> np.ndarray:
    """The camera frame enlarged with a heads-up display (steering bar, speed, CTE, lap)."""
    import cv2

    frame = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    height, width = frame.shape[:2]
    # A black band (rows 0-58) at 55 % opacity behind the text: only its rows are darkened (a
    # whole-frame blend with a black overlay gives the same pixels at several times the cost).
    frame[:59] = cv2.convertScaleAbs(frame[:59], alpha=0.45)
    text = (f"steer {steering:+.2f}  {speed_mph:4.1f} mph  CTE {cte_m:+.2f} m  "
            f"lap {min(lap + 1, laps)}/{laps}  int. {interventions}")
    cv2.putText(frame, text, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.62, (255, 255, 255), 2,
                cv2.LINE_AA)
    # Steering bar: centre tick, filled to the commanded side.
    bar_y, mid, half = 44, width // 2, width // 3
    cv2.line(frame, (mid - half, bar_y), (mid + half, bar_y), (180, 180, 180), 1)
    cv2.line(frame, (mid, bar_y - 5), (mid, bar_y + 5), (255, 255, 255), 1)
    end = int(mid + half * max(-1.0, min(1.0, steering)))
    cv2.line(frame, (mid, bar_y), (end, bar_y), (255, 200, 0), 4)
    return frame


def _with_curve_rule(policy: NetworkPolicy, parts: list[EvalConfig]) -> NetworkPolicy:
    """``policy``, or a fork of it driving with the parts' ``slow_in_curves`` where that is
    given and differs from the policy's own."""
    if len({part.slow_in_curves for part in parts}) > 1:
        raise ValueError("the parts of one evaluation must agree on slow_in_curves")
    slow_in_curves = parts[0].slow_in_curves
    if slow_in_curves is None or policy.slow_in_curves == slow_in_curves:
        return policy
    car = policy.fork()
    car.slow_in_curves = bool(slow_in_curves)
    return car


def _report_header(policy: NetworkPolicy, first: EvalConfig, model_path: str | None) -> dict:
    """eval.json before any run: the model, how it is driven and rendered, no runs yet."""
    speed_head, slow_in_curves = policy.speed_head, policy.slow_in_curves
    return {
        "model": model_path,
        "recipe": dict(policy.notes.get("recipe") or {}) or None,
        "slow_in_curves": slow_in_curves,
        "speed_head": speed_head,
        "steering_filter_s": policy.steering_filter_s,
        "steering_hold": policy.steering_hold,
        "steering_scale_from_mph": policy.steering_scale_from_mph,
        "mirror_average": policy.mirror_average,
        "speed_scale": policy.speed_scale,
        "full_speed_at": policy.full_speed_at,
        "caution": policy.caution,
        "caution_from": policy.caution_from,
        "speed_control": f"PI (kp {SPEED_KP}, ki {SPEED_KI})"
                         + (_learned_speed_text(policy) if speed_head else "")
                         + (", target speed reduced with |steering|" if slow_in_curves
                            else ""),
        **_rendering(policy, first),
        "complete": False,
        "runs": [],
        "totals": totals([]),
    }


def _learned_speed_text(policy: NetworkPolicy) -> str:
    scaled = f" times {policy.speed_scale:g}" if policy.speed_scale != 1.0 else ""
    if policy.full_speed_at != 1.0:
        scaled += f", {full_speed_text(policy.full_speed_at)}"
    if policy.caution:
        scaled += f", {caution_text(policy.caution, policy.caution_from)}"
    return f", target speed learned (speed head){scaled}, capped by the set speed"


def _groups(parts: list[EvalConfig], part_specs: list[list[RunSpec]], workers: int
            ) -> list[tuple[EvalConfig, list[tuple[int, RunSpec]]]]:
    """Each part's runs cut into lock-step groups (at most ``batch`` runs, and no more groups
    than ``workers`` need), each run with its index in the whole evaluation."""
    groups = []
    offset = 0
    for part, specs_of_part in zip(parts, part_specs, strict=True):
        size = max(1, min(part.batch, math.ceil(len(specs_of_part) / workers)))
        for start in range(0, len(specs_of_part), size):
            chunk = specs_of_part[start:start + size]
            groups.append((part, list(enumerate(chunk, start=offset + start))))
        offset += len(specs_of_part)
    return groups


def evaluate(policy: NetworkPolicy, config: EvalConfig | Sequence[EvalConfig],
             out_dir: str | Path, *, progress: bool = True, model_path: str | None = None,
             model_options: dict | None = None,
             tracks: Mapping[str, Track] | None = None) -> dict:
    """Drive every run of ``config`` with ``policy`` (a NetworkPolicy) and write the results.

    Writes ``config.json``, ``eval.json`` (again after each finished run), a map PNG per run,
    off-road frames and (with ``video``) an mp4 per built-in-track run, under ``out_dir``.
    Returns the final eval.json content.

    ``config`` may also be several configs (parts: say, two laps with video on the built-in
    tracks and one lap without on unseen ones); their runs go into one eval.json, in order,
    and are all scheduled on one pool, so no worker waits for a part to finish.

    With several workers (``config.workers``, default one per CPU core) and the model's file
    (``model_path``; ``model_options`` are :func:`~clonedrive.drivers.policy.load_policy`'s
    ``trust`` and ``runtime``), each part's runs are cut into groups before anything drives
    (at most ``batch`` runs, and no more groups than workers need), and each group is driven in
    lock-step in a fresh worker process that loads the model itself; the groups start longest
    first. The results do not depend on that order. Driven in this process instead (one worker,
    or an in-memory model) and without video, a group's network runs on a second thread beside
    the rendering (``Runner(overlap=True)``), for half of the cars at a time.

    Each track is resolved once (``tracks``: those the caller already loaded, by the name the
    config gives) and the :class:`Track` itself goes to the simulators, the workers and the
    expert's reference: a track file edited while an evaluation runs changes nothing in it.
    """
    from clonedrive.base.config import config_to_dict
    from clonedrive.base.keras_backend import compute_threads
    from clonedrive.base.progress import progress_bar
    from clonedrive.base.workers import default_workers

    parts = [config] if isinstance(config, EvalConfig) else list(config)
    if not parts:
        raise ValueError("nothing to evaluate: no config given")
    first = parts[0]
    policy = _with_curve_rule(policy, parts)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    part_specs = [run_specs(part) for part in parts]
    specs = [spec for specs in part_specs for spec in specs]
    part_of = [number for number, specs in enumerate(part_specs) for _ in specs]
    resolved = resolve_tracks([spec.track for spec in specs], tracks)
    report = _report_header(policy, first, model_path)
    # A previous evaluation's eval.json goes first: an interrupted run must never leave this
    # run's config.json beside another run's results marked complete.
    write_json_atomic(out / "eval.json", report)
    if len(parts) == 1:
        save_config(first, out / "config.json")
    else:
        write_json_atomic(out / "config.json",
                          {"parts": [config_to_dict(part) for part in parts]})
    finished: dict[int, dict] = {}

    def publish(index: int, result: dict) -> None:
        part = parts[part_of[index]]
        if part.expert_reference:
            result.update(against_expert(result, max_seconds=part.max_seconds,
                                         track=resolved[specs[index].track]))
        finished[index] = result
        report["runs"] = [finished[i] for i in sorted(finished)]
        report["totals"] = totals(report["runs"])
        report["complete"] = len(finished) == len(specs)
        write_json_atomic(out / "eval.json", report)

    names = _run_names(specs, resolved)
    workers = first.workers or default_workers()
    if model_path is None:
        workers = 1  # an in-memory model cannot be loaded by another process
    groups = _groups(parts, part_specs, workers)
    expected = [sum(_expected_steps(spec, part, resolved[spec.track]) for _, spec in group)
                for part, group in groups]
    # Only built-in tracks get video; a step with a video frame costs about half a step more.
    filmed = [part.video and any(not spec.unseen for _, spec in group) for part, group in groups]
    cost = [steps * (1.5 if video else 1.0) for steps, video in zip(expected, filmed, strict=True)]
    bar = progress_bar(total=sum(expected), unit="step", desc="evaluate", enabled=progress)
    try:
        if workers == 1 or len(groups) == 1:
            # With video, half the cores go to the encoder (ffmpeg) and the HUD, not PyTorch.
            # Without video, a group of two or more cars overlaps its network with rendering
            # (Runner's overlap): the network decides for one half of the cars on a second
            # thread, with one PyTorch thread, while the other half renders on this one.
            overlap = default_workers() > 1 and not any(filmed)
            threads = 1 if overlap else (max(1, default_workers() // 2) if any(filmed) else None)
            with compute_threads(threads):
                for part, group in groups:
                    _drive_group(policy, group, names, part, out, bar, publish, resolved,
                                 overlap=overlap and not part.video_saliency)
        else:
            _drive_in_workers(policy, parts, groups, names, out, resolved, workers,
                              cost=cost, model_path=model_path, model_options=model_options,
                              on_results=publish,
                              on_group=lambda group: bar.update(expected[group]))
    finally:
        bar.close()
    return report


def _drive_in_workers(policy: NetworkPolicy, parts: list[EvalConfig], groups: list,
                      names: list[str], out: Path, tracks: Mapping[str, Track], workers: int, *,
                      cost: list[float], model_path: str, model_options: dict | None,
                      on_results, on_group) -> None:
    """Drive each group in a worker process, longest first (so that the last group to start
    is a short one); ``on_results(index, result)`` for each run, ``on_group(group)`` after
    each group."""
    from clonedrive.base.workers import run_tasks

    order = sorted(range(len(groups)), key=lambda i: -cost[i])
    # Each worker builds a policy that drives as ``policy`` does: from the model's checked
    # traces where it runs traced (no Keras to import: ~3 s less per worker), else from the
    # model file (also for saliency videos: they need the Keras model).
    portable = None
    if not any(part.video_saliency for part in parts):
        portable = policy.portable()
    tasks = [GroupTask(model_path=str(model_path), model_options=dict(model_options or {}),
                       policy_options=policy.options(), portable=portable,
                       group=tuple(groups[i][1]), names=tuple(names), config=groups[i][0],
                       tracks={spec.track: tracks[spec.track] for _, spec in groups[i][1]},
                       out=str(out)) for i in order]

    def on_done(task: int, results: list[tuple[int, dict]]) -> None:
        for index, result in results:
            on_results(index, result)
        on_group(order[task])

    run_tasks(_drive_group_task, tasks, workers=workers, on_done=on_done)


@dataclass(frozen=True)
class GroupTask:
    """What a worker process needs to drive one group of an evaluation."""

    model_path: str
    model_options: dict  #: load_policy's trust and runtime
    policy_options: dict  #: how the policy drives (NetworkPolicy.options)
    portable: object  #: the model's checked traces (NetworkPolicy.portable), or None
    group: tuple  #: (index, RunSpec) of each run
    names: tuple[str, ...]  #: every run's file-name stem
    config: EvalConfig
    tracks: dict  #: track name -> Track, as the caller resolved them
    out: str


def _drive_group_task(task: GroupTask) -> list[tuple[int, dict]]:
    """A worker's share of an evaluation: load the model, drive the group, return results."""
    from clonedrive.drivers.policy import load_policy

    options = dict(task.policy_options)
    if task.config.slow_in_curves is not None:
        options["slow_in_curves"] = task.config.slow_in_curves
    policy = load_policy(task.model_path, **task.model_options, portable=task.portable,
                         **options)
    results: list[tuple[int, dict]] = []
    _drive_group(policy, list(task.group), list(task.names), task.config, Path(task.out), None,
                 lambda index, result: results.append((index, result)), task.tracks)
    return results


def resolve_tracks(names: Sequence[str], known: Mapping[str, Track] | None = None
                   ) -> dict[str, Track]:
    """Each distinct track name's :class:`Track`, loaded once (``known``: already loaded)."""
    from clonedrive.world.catalog import load_track

    resolved = dict(known or {})
    for name in names:
        if name not in resolved:
            resolved[name] = load_track(name)
    return resolved


def _run_names(specs: list[RunSpec], tracks: Mapping[str, Track]) -> list[str]:
    """Each run's file-name stem, fixed before any run drives (so workers cannot clash)."""
    taken: set[str] = set()
    names = []
    for spec in specs:
        name = run_name(tracks[spec.track].name, spec.speed_mph, taken)
        taken.add(name)
        names.append(name)
    return names


def _expected_steps(spec: RunSpec, config: EvalConfig, track: Track) -> int:
    length = track.length_m
    seconds = spec.laps * length / max(spec.speed_mph * MPH_TO_MPS * 0.85, 1.0)
    if config.max_seconds is not None:
        seconds = min(seconds, config.max_seconds)
    return int(seconds * 15)


def _rendering(policy: NetworkPolicy, config: EvalConfig) -> dict:
    """What eval.json records about how frames were drawn: the renderer (sim/engine.py) and the
    rows rendered for the network (None: whole frames)."""
    from clonedrive.sim.engine import renderer_info

    rows = None if config.full_frame else policy.visible_rows
    return {**renderer_info(config.renderer), "render_rows": None if rows is None else
            list(rows)}


def _open_run(index: int, spec: RunSpec, name: str, config: EvalConfig, out: Path,
              pool: CameraPool, rows: tuple[int, int] | None, track: Track) -> _Run:
    from clonedrive.sim.simulator import SimConfig, Simulator

    filmed = config.video and not spec.unseen
    sim = Simulator(track, SimConfig(cameras=("center",), scenery=config.scenery,
                                     renderer=config.renderer, render_rows=rows, film=filmed),
                    pool=pool)
    try:
        rules = EpisodeRules(laps=spec.laps, set_speed_mph=spec.speed_mph,
                             max_seconds=config.max_seconds,
                             time_limit_factor=config.time_limit_factor)
        episode = Episode(sim, rules, track=spec.track, seed=0)
        run = _Run(index=index, spec=spec, episode=episode, name=name)
        if filmed:
            from clonedrive.evaluate.video import VideoWriter

            run.video = VideoWriter(out / f"{name}.mp4", fps=sim.config.control_hz)
    except BaseException:
        sim.close()
        raise
    return run


def _drive_group(policy: NetworkPolicy, group: list[tuple[int, RunSpec]], names: list[str],
                 config: EvalConfig, out: Path, bar, publish, tracks: Mapping[str, Track], *,
                 overlap: bool = False) -> None:
    """Drive ``group``'s runs in lock-step; ``overlap``: the network decides for half the
    cars on a second thread while the other half renders (:class:`Runner`). The group's cars on
    one track share one scene (:class:`CameraPool`)."""
    from clonedrive.episode.drivers import PolicyDriver
    from clonedrive.sim.camera_pool import CameraPool

    runs: list[_Run] = []
    pool = CameraPool()
    rows = None if config.full_frame else policy.visible_rows
    try:
        for index, spec in group:
            runs.append(_open_run(index, spec, names[index], config, out, pool, rows,
                                  tracks[spec.track]))
        if config.video_saliency and any(run.video is not None for run in runs):
            from clonedrive.model.saliency import VisualBackProp

            saliency = VisualBackProp(policy.model)
            for run in runs:
                run.saliency = saliency
        driver = PolicyDriver(policy, [run.spec.speed_mph for run in runs])
        runner = Runner([run.episode for run in runs], driver, overlap=overlap)
        runner.reset()
        for run in runs:
            run.episode.trace.unseen = run.spec.unseen

        def on_step(step: Step) -> None:
            run = runs[step.car]
            _record_step(run, step, out)
            if bar is not None:
                bar.update(1)
            if step.stopped is not None:
                run.result = _finish(run, out)
                run.result["nan_predictions"] = driver.nan_predictions[step.car]
                publish(run.index, run.result)

        runner.run(on_step)
    finally:
        for run in runs:
            if run.video is not None:
                run.video.close()
            run.episode.sim.close()
        pool.close()


def _record_step(run: _Run, step: Step, out: Path) -> None:
    """A run's outputs for one step: the video frame, the frames of off-road events."""
    trace = run.episode.trace
    earlier = len(trace.off_road) - len(step.events)  # interventions before this step
    if run.video is not None:
        observed = step.observed
        frame = _whole(step.seen)
        if run.saliency is not None:  # where the network looked, in what it saw
            from clonedrive.model.saliency import overlay

            frame = overlay(frame, run.saliency.masks(step.seen.images["center"])[0])
        # A callable: the HUD is drawn on the video's feeder thread, off the driving loop.
        run.video.append(functools.partial(
            hud_frame, frame, steering=step.decision.controls.steering,
            speed_mph=observed.speed_mph, cte_m=observed.cte_m,
            lap=run.episode.laps_started, laps=run.spec.laps, interventions=earlier))
    for number, record in enumerate(trace.off_road[earlier:], start=earlier + 1):
        frame_png = _save_frame(_whole(step.observed),
                                out / "off_road" / f"{run.name}_{number:03d}.png")
        record.frame_png = str(frame_png.relative_to(out))


def _whole(observation) -> np.ndarray:
    """The center camera's frame as a person should see it: the whole frame of a filmed run
    (its network sees a strip), else the frame the network saw."""
    if observation.film_frame is not None:
        return observation.film_frame
    return observation.images["center"]


def _save_frame(image: np.ndarray, path: Path) -> Path:
    import cv2

    from clonedrive.base.config import write_bytes_atomic

    ok, encoded = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError(f"OpenCV could not encode the frame for {path}")
    return write_bytes_atomic(path, encoded.tobytes())  # never through a link at the name


def _finish(run: _Run, out: Path) -> dict:
    from clonedrive.evaluate.maps import plot_track_map

    if run.video is not None:
        run.video.close()  # the mp4 is whole before eval.json names it
    trace = run.episode.trace
    summary = trace.summary()
    off_xy = np.array([(e.x_m, e.y_m) for e in trace.off_road]).reshape(-1, 2)
    map_path = plot_track_map(
        run.episode.sim.track, out / f"{run.name}_map.png",
        title=(f"{trace.track} at {trace.speed_mph:g} mph: {trace.laps_completed}/"
               f"{trace.laps_target} laps, {len(trace.off_road)} interventions"),
        driven_xy=np.column_stack([trace.x_m, trace.y_m]), abs_cte_m=np.abs(trace.cte_m),
        off_road_xy=off_xy)
    summary["map_png"] = str(map_path.relative_to(out))
    if run.video is not None:
        summary["video"] = f"{run.name}.mp4"
    return summary
