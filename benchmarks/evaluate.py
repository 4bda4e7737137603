"""Closed-loop throughput (rendering included) and drive-server latency.

- Control steps per second of `clonedrive evaluate` with the `fast` model on the lake track, full
  scenery, one run at a time and 8 runs in lock-step (one network call a step, each frame alone).
  Target: >= 150 steps/s (10x real time at 15 Hz).
- Drive server round trip per telemetry message (decode + predict + reply) with the `seed`
  model over a real socket: median and p99.

Ratios measured in the same run (they travel between machines; absolute figures do not):

The closed-loop figures leave out evaluate's expert reference drive (``expert_reference``), which
is extra work beside the loop, not part of it.

- ``loop_ratio``: closed-loop steps/s (8 runs in lock-step) / render-only steps/s of the center
  camera on the same track (scene built, one frame rendered and read back per step, nothing
  else): everything but rendering is overhead. Target >= 1.2 with the crop.
- ``video_ratio``: closed-loop steps/s of one run with ``--video`` / without. Target >= 0.8.
- ``loop_ratio_onnx``: ``loop_ratio`` with the network run by ONNX Runtime.
- ``loop_ratio_workers``: as users run ``clonedrive evaluate MODEL``: 8 runs of 60 s from a
  model file, their groups driven in worker processes (one per core, each loading the model)
  / the render-only reference in as many processes at once; both include their processes'
  start, imports and scene builds.
- ``loop_ratio_steady``: the same 8 cars stepped by the episode runner once their simulators are
  built (no scene builds, no map plots) / rendering frames once the scene is built.
- ``overlap_speedup``: that steady loop with the overlap / without it (median of 3 alternating
  pairs of 10 s runs, one PyTorch thread in both).
- ``render_beside_network_ratio``: center-camera frames/s while the network predicts frames on
  a second thread / alone (median of 3 pairs): what sharing the machine's two cores costs the
  rendering by itself, with none of our code in between (the loop's network is busy for part of
  each step, so the loop pays part of it).
- ``shared_scene_speedup``: that steady loop with the 8 cars sharing one scene (a
  ``CameraPool``, as evaluate's groups do) / with a scene per car (median of 3 alternating pairs).

``evaluate`` renders for the network only the rows its crop keeps (a run with video renders
whole frames for the video besides), so ``loop_ratio``, ``loop_ratio_onnx`` and
``loop_ratio_workers`` are the cropped loop against full-frame rendering (the reference is
unchanged); the steady-state figures step simulators that draw full frames.
``benchmarks/crop.py`` compares the crop with ``--full-frame``.

``loop_ratio``, ``video_ratio`` and ``loop_ratio_workers`` are each the median of 3 alternating
pairs (the figure, then its reference), as the machine's speed drifts within a run.

In one process, as here, evaluate runs the network for half the cars on a second thread while
the other half renders (``Runner(overlap=True)``, one PyTorch thread): the loop uses two cores,
the render-only reference one (Panda3D's software renderer draws on one thread).

Run: python benchmarks/evaluate.py [MODEL.keras]   (default: an untrained `fast` network; the
weights do not change the cost, only where the car goes)
"""

from __future__ import annotations

import asyncio
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def closed_loop_steps_per_s(policy, batch: int, seconds: float, *,
                            video: bool = False) -> tuple[float, int]:
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    # `batch` runs of the same track at slightly different set speeds, driven in lock-step.
    speeds = tuple(20.0 + 0.5 * i for i in range(batch))
    config = EvalConfig(tracks=("lake",), speeds_mph=speeds, laps=1, batch=batch,
                        max_seconds=seconds, video=video, expert_reference=False)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        report = evaluate(policy, config, out, progress=False)
        wall = time.perf_counter() - start
    steps = sum(round(run["elapsed_s"] * 15) for run in report["runs"])
    return steps / wall, steps


def steady_loop_steps_per_s(policy, batch: int, seconds: float, *,
                            overlap: bool = True, shared: bool = True, rows=None,
                            renderer: str = "auto") -> float:
    """Closed-loop steps/s of ``batch`` cars in lock-step once built: the runner's stepping
    alone (render, predict, control, physics, rules), without scene builds or map plots.
    ``shared``: the cars share one scene, as in evaluate (a CameraPool); else one each.
    ``rows``: render only these rows (the crop), as ``SimConfig.render_rows``."""
    from clonedrive.base.keras_backend import compute_threads
    from clonedrive.episode.drivers import PolicyDriver
    from clonedrive.episode.rules import EpisodeRules
    from clonedrive.episode.runner import Episode, Runner
    from clonedrive.sim.camera_pool import CameraPool
    from clonedrive.sim.simulator import SimConfig, Simulator

    speeds = [20.0 + 0.5 * i for i in range(batch)]
    pool = CameraPool() if shared else None
    config = SimConfig(cameras=("center",), render_rows=rows, renderer=renderer)
    sims = [Simulator("lake", config, pool=pool) for _ in speeds]
    try:
        episodes = [Episode(sim, EpisodeRules(laps=1, set_speed_mph=speed, max_seconds=seconds),
                            track="lake", seed=0) for sim, speed in zip(sims, speeds,
                                                                         strict=True)]
        # As evaluate drives a group in its own process: the network on a second thread.
        runner = Runner(episodes, PolicyDriver(policy, speeds), overlap=overlap)
        runner.reset()
        steps = 0

        def count(_step) -> None:
            nonlocal steps
            steps += 1

        with compute_threads(1):
            start = time.perf_counter()
            runner.run(count)
            return steps / (time.perf_counter() - start)
    finally:
        for sim in sims:
            sim.close()
        if pool is not None:
            pool.close()


def workers_loop_steps_per_s(model_path: str, batch: int, seconds: float,
                             workers: int) -> tuple[float, int]:
    """``clonedrive evaluate MODEL`` as a user runs it: the runs cut into groups driven in
    ``workers`` worker processes that load the model themselves (process start, imports and
    scene builds included, as in every evaluation)."""
    from clonedrive.drivers.policy import load_policy
    from clonedrive.evaluate.rollout import EvalConfig, evaluate

    speeds = tuple(20.0 + 0.5 * i for i in range(batch))
    config = EvalConfig(tracks=("lake",), speeds_mph=speeds, laps=1, batch=batch,
                        max_seconds=seconds, video=False, expert_reference=False,
                        workers=workers)
    policy = load_policy(model_path)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        report = evaluate(policy, config, out, progress=False, model_path=model_path)
        wall = time.perf_counter() - start
    steps = sum(round(run["elapsed_s"] * 15) for run in report["runs"])
    return steps / wall, steps


def _render_only_task(steps: int) -> int:
    render_only_steps_per_s(steps)
    return steps


def render_only_workers_steps_per_s(steps: int, workers: int) -> float:
    """The reference on as many cores: ``workers`` processes rendering the center camera at
    once, ``steps`` in all (process start, imports and scene builds included)."""
    from clonedrive.base.workers import run_tasks

    share = [steps // workers + (1 if i < steps % workers else 0) for i in range(workers)]
    start = time.perf_counter()
    run_tasks(_render_only_task, share, workers=workers)
    return steps / (time.perf_counter() - start)


def render_only_steps_per_s(steps: int, track_name: str = "lake", *,
                            steady: bool = False) -> float:
    """The reference: the center camera alone, built and rendered along the centreline."""
    from clonedrive.base.udacity_spec import CONTROL_HZ
    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene
    from clonedrive.world.catalog import load_track
    from clonedrive.world.vehicle import MPH_TO_MPS

    track = load_track(track_name)
    step_m = 20.0 * MPH_TO_MPS / CONTROL_HZ
    start = time.perf_counter()
    with Scene(track) as scene, CameraRig(scene, cameras=("center",)) as rig:
        if steady:  # time the frames only, not the scene build
            start = time.perf_counter()
        for i in range(steps):
            s = i * step_m
            x, y, z = track.point(s)
            rig.render(float(x), float(y), float(z), float(track.heading_at(s)),
                       pitch_rad=float(track.grade(s)))
    return steps / (time.perf_counter() - start)


def render_beside_network(policy, frames: int = 400) -> tuple[float, float]:
    """Center-camera frames/s on the lake, (alone, while the network predicts 4 frames a call on a
    second thread): what the two cores' sharing costs the rendering, apart from any of our code
    (the render call releases Python's lock; one PyTorch thread)."""
    import threading

    import numpy as np

    from clonedrive.base.keras_backend import compute_threads
    from clonedrive.base.udacity_spec import IMAGE_SHAPE
    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene
    from clonedrive.world.catalog import load_track

    track = load_track("lake")
    batch = np.zeros((4, *IMAGE_SHAPE), np.uint8)
    stop = threading.Event()

    def predict() -> None:
        with compute_threads(1):
            while not stop.is_set():
                policy.predict(batch)

    with Scene(track) as scene, CameraRig(scene, cameras=("center",)) as rig:
        x, y, z = (float(v) for v in track.point(100.0))
        heading = float(track.heading_at(100.0))
        rig.render(x, y, z, heading)

        def rate() -> float:
            start = time.perf_counter()
            for _ in range(frames):
                rig.render(x, y, z, heading)
            return frames / (time.perf_counter() - start)

        alone = rate()
        helper = threading.Thread(target=predict)
        helper.start()
        try:
            beside = rate()
        finally:
            stop.set()
            helper.join()
    return alone, beside


#: Alternating (figure, reference) pairs per ratio.
PAIRS = 3


def _median_pair(pairs: list[tuple[float, float]]) -> tuple[float, float]:
    """The pair whose ratio is the median one (an odd count of pairs)."""
    ranked = sorted(pairs, key=lambda pair: pair[0] / pair[1])
    return ranked[len(ranked) // 2]


def _listed(pairs: list[tuple[float, float]]) -> str:
    return ", ".join(f"{a:.0f} / {b:.0f}" for a, b in pairs)


def workers_pairs_steps_per_s(model, workers: int) -> list[tuple[float, float]]:
    """PAIRS alternating pairs: 8 runs of 60 s from a model file on ``workers`` processes, and
    rendering on as many processes (the model given on the command line, else ``model`` saved)."""
    with tempfile.TemporaryDirectory() as folder:
        if len(sys.argv) > 1:
            model_file = sys.argv[1]
        else:
            model_file = str(Path(folder) / "fast.keras")
            model.save(model_file)
        pairs = []
        for _ in range(PAIRS):
            on_workers, workers_steps = workers_loop_steps_per_s(model_file, 8, 60.0, workers)
            pairs.append((on_workers, render_only_workers_steps_per_s(workers_steps, workers)))
    return pairs


def server_round_trip_ms() -> tuple[float, float]:
    """The drive server's round trip with the ``seed`` model: (median, p99) [ms], printed."""
    from server_latency import round_trips, sample_jpeg

    from clonedrive.base.udacity_spec import SET_SPEED_MPH
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.model.architectures import build_model
    from clonedrive.udacity import protocol
    from clonedrive.udacity.server import DriveServer

    seed_policy = NetworkPolicy(build_model("seed"), set_speed_mph=SET_SPEED_MPH)
    server = DriveServer(seed_policy, port=0, status_interval_s=0)
    port = server.start()
    try:
        frame = protocol.telemetry_frame(0.0, 0.0, 5.0, sample_jpeg())
        (trips,) = asyncio.run(round_trips([port], frame, 20, 300))
    finally:
        server.stop()
    trips_ms = sorted(t * 1e3 for t in trips)
    median = statistics.median(trips_ms)
    p99 = trips_ms[min(len(trips_ms) - 1, int(round(0.99 * (len(trips_ms) - 1))))]
    print(f"drive server, seed model, {len(trips)} messages: median {median:.2f} ms, "
          f"p99 {p99:.2f} ms")
    return median, p99


def main() -> None:
    import numpy as np

    from clonedrive.base.udacity_spec import IMAGE_SHAPE
    from clonedrive.base.workers import default_workers
    from clonedrive.drivers.policy import NetworkPolicy
    from clonedrive.model.architectures import build_model
    from clonedrive.network.model_file import load_model

    model = load_model(sys.argv[1]) if len(sys.argv) > 1 else build_model("fast")
    policy = NetworkPolicy(model, set_speed_mph=20.0)
    policy.predict_steering(np.zeros((8, *IMAGE_SHAPE), np.uint8))  # warm up
    # Each ratio from PAIRS alternating pairs (the figure and its reference one after the
    # other), the median pair's: this machine's speed drifts by 30 % within minutes, and a
    # reference measured once can land on a fast or a slow spell.
    loop_pairs, video_pairs = [], []
    for _ in range(PAIRS):
        batched, batched_steps = closed_loop_steps_per_s(policy, 8, 20.0)
        loop_pairs.append((batched, render_only_steps_per_s(batched_steps)))
        single, single_steps = closed_loop_steps_per_s(policy, 1, 40.0)
        video_pairs.append((closed_loop_steps_per_s(policy, 1, 40.0, video=True)[0], single))
    batched, render_only = _median_pair(loop_pairs)
    with_video, single = _median_pair(video_pairs)
    # As users run it: a model file, its groups on every core in worker processes, against the
    # reference on as many cores.
    workers = default_workers()
    workers_pairs = workers_pairs_steps_per_s(model, workers)
    on_workers, render_workers = _median_pair(workers_pairs)
    # The same loop with the network run by ONNX Runtime (evaluate --runtime onnx).
    from clonedrive.network.onnx_runtime import OnnxModel, onnx_bytes

    onnx_policy = NetworkPolicy(OnnxModel(onnx_bytes(model)), set_speed_mph=20.0)
    onnx_policy.predict_steering(np.zeros((8, *IMAGE_SHAPE), np.uint8))
    batched_onnx, _ = closed_loop_steps_per_s(onnx_policy, 8, 20.0)
    # Steady state: the loop once its 8 simulators are built, against rendering once built.
    steady = steady_loop_steps_per_s(policy, 8, 20.0)
    render_steady = render_only_steps_per_s(batched_steps, steady=True)
    # What the overlap gains: the same steady loop without and with it, alternately.
    pairs = [(steady_loop_steps_per_s(policy, 8, 10.0, overlap=False),
              steady_loop_steps_per_s(policy, 8, 10.0, overlap=True)) for _ in range(3)]
    overlap_speedup = statistics.median(with_ / without for without, with_ in pairs)
    # What sharing one scene among the 8 cars gains (a CameraPool, as evaluate does): the same
    # steady loop with a scene per car / with the shared one, alternately.
    shared_pairs = [(steady_loop_steps_per_s(policy, 8, 10.0, shared=False),
                     steady_loop_steps_per_s(policy, 8, 10.0, shared=True)) for _ in range(3)]
    shared_scene_speedup = statistics.median(shared / own for own, shared in shared_pairs)
    # What sharing the two cores costs the rendering while the network runs on the other one.
    beside_pairs = [render_beside_network(policy) for _ in range(3)]
    beside_ratio = statistics.median(beside / alone for alone, beside in beside_pairs)
    loop_ratio = batched / render_only
    video_ratio = with_video / single
    print("closed loop, lake, fast model, full scenery (includes scene build and map plots):")
    print(f"  1 run:            {single:7.1f} steps/s ({single_steps} steps)")
    print(f"  1 run, --video:   {with_video:7.1f} steps/s -> video_ratio {video_ratio:.2f} "
          "(target >= 0.8)")
    print(f"  8 runs lock-step: {batched:7.1f} steps/s ({batched_steps} steps)")
    print(f"  pairs (8 runs / render only): {_listed(loop_pairs)}; (--video / without): "
          f"{_listed(video_pairs)} steps/s; the median pair's ratio of {PAIRS} is reported")
    print(f"  render only:      {render_only:7.1f} steps/s (center camera, same track) -> "
          f"loop_ratio {loop_ratio:.2f} (target >= 1.2, with the crop)")
    print(f"  8 runs of 60 s on {workers} worker processes (a model file, as `clonedrive "
          f"evaluate` runs it): {on_workers:7.1f} steps/s against {render_workers:7.1f} "
          f"rendering on as many processes -> loop_ratio_workers "
          f"{on_workers / render_workers:.2f} (pairs: {_listed(workers_pairs)})")
    print(f"  8 runs, ONNX Runtime: {batched_onnx:7.1f} steps/s -> loop_ratio_onnx "
          f"{batched_onnx / render_only:.2f}")
    print(f"  steady state (built simulators, no maps): {steady:7.1f} steps/s against "
          f"{render_steady:7.1f} frames/s rendering -> loop_ratio_steady "
          f"{steady / render_steady:.2f}")
    print("  the same without / with the network on a second thread, alternately: "
          + ", ".join(f"{without:.0f} / {with_:.0f}" for without, with_ in pairs)
          + f" steps/s -> overlap_speedup {overlap_speedup:.2f} (median)")
    print("  the same with a scene per car / one scene shared by the 8 cars, alternately: "
          + ", ".join(f"{own:.0f} / {shared:.0f}" for own, shared in shared_pairs)
          + f" steps/s -> shared_scene_speedup {shared_scene_speedup:.2f} (median)")
    print("  rendering alone / while the network predicts on the other core: "
          + ", ".join(f"{alone:.0f} / {beside:.0f}" for alone, beside in beside_pairs)
          + f" frames/s -> render_beside_network_ratio {beside_ratio:.2f} (median)")

    median, p99 = server_round_trip_ms()
    steps = max(single, batched)
    print(f"target >= 150 steps/s: {'met' if steps >= 150 else 'NOT met'} ({steps:.0f})")
    print(json.dumps({"loop_ratio": round(loop_ratio, 3),
                      "loop_ratio_onnx": round(batched_onnx / render_only, 3),
                      "loop_ratio_steady": round(steady / render_steady, 3),
                      "loop_ratio_workers": round(on_workers / render_workers, 3),
                      "steps_per_s_workers": round(on_workers, 1),
                      "overlap_speedup": round(overlap_speedup, 3),
                      "shared_scene_speedup": round(shared_scene_speedup, 3),
                      "render_beside_network_ratio": round(beside_ratio, 3),
                      "video_ratio": round(video_ratio, 3),
                      "render_only_steps_per_s": round(render_only, 1),
                      "steps_per_s_video": round(with_video, 1),
                      "steps_per_s": round(steps, 1),
                      "steps_per_s_single": round(single, 1),
                      "steps_per_s_batched8": round(batched, 1),
                      "server_latency_ms_median": round(median, 2),
                      "server_latency_ms_p99": round(p99, 2)}))


if __name__ == "__main__":
    main()
