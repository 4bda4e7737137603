import json
from importlib import resources

import numpy as np
import pytest

from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.episode.trace import autonomy_pct, smoothness
from clonedrive.evaluate.results import format_table
from clonedrive.evaluate.rollout import (
    EvalConfig,
    evaluate,
    hud_frame,
    run_specs,
)
from clonedrive.network.tiny_model import build_tiny_model

LAKE_JSON = resources.files("clonedrive.world") / "tracks" / "lake.json"


def test_autonomy_and_smoothness_follow_their_definitions():
    assert autonomy_pct(0, 100.0) == 100.0
    assert autonomy_pct(2, 120.0) == pytest.approx((1 - 2 * 6 / 120) * 100)
    assert autonomy_pct(50, 60.0) == 0.0  # floored
    # Alternating +-0.1 at 15 Hz: each change is 0.2 -> 3.0 per second.
    assert smoothness(np.array([0.1, -0.1] * 10), 15.0) == pytest.approx(3.0)
    assert smoothness(np.full(10, 0.3), 15.0) == 0.0


def test_hud_frame_enlarges_the_camera_and_darkens_a_band_behind_its_text():
    image = np.random.default_rng(3).integers(0, 256, (160, 320, 3), dtype=np.uint8)
    frame = hud_frame(image, steering=-0.3, speed_mph=21.5, cte_m=0.4, lap=0, laps=2,
                      interventions=1)
    enlarged = image.repeat(2, axis=0).repeat(2, axis=1)
    assert frame.shape == (320, 640, 3)
    assert np.array_equal(frame[59:], enlarged[59:])  # below the band: the camera, 2x
    # The band's rows 0-58 at 45 % (OpenCV's rounding: within 1), where no text or bar is
    # drawn (the right edge); the text and the bar differ from that.
    darkened = enlarged[:59].astype(float) * 0.45
    assert np.abs(frame[:59, 600:] - darkened[:, 600:]).max() <= 1.0
    assert np.abs(frame[:59, :560] - darkened[:, :560]).max() > 100


def test_unseen_tracks_use_seeds_disjoint_from_recording():
    specs = run_specs(EvalConfig(tracks=("lake",), speeds_mph=(15.0, 30.0), unseen=3,
                                 unseen_speed_mph=20.0))
    assert [(s.track, s.speed_mph, s.unseen) for s in specs] == [
        ("lake", 15.0, False), ("lake", 30.0, False), ("gen:1000", 20.0, True),
        ("gen:1001", 20.0, True), ("gen:1002", 20.0, True)]


@pytest.fixture(scope="module")
def tiny_policy():
    return NetworkPolicy(build_tiny_model(seed=0), set_speed_mph=15.0)


def test_evaluation_writes_results_maps_frames_and_video(tmp_path, tiny_policy):
    # The tiny network cannot drive: it leaves the road, which exercises interventions.
    config = EvalConfig(tracks=("lake",), speeds_mph=(20.0,), laps=1, video=True, scenery=False,
                        max_seconds=12.0)
    report = evaluate(tiny_policy, config, tmp_path, progress=False, model_path="tiny")
    saved = json.loads((tmp_path / "eval.json").read_text())
    assert saved == json.loads(json.dumps(report))
    (run,) = saved["runs"]
    for key in ("track", "speed_mph", "laps_completed", "interventions", "autonomy_pct",
                "mean_abs_cte_m", "max_abs_cte_m", "smoothness", "distance_m"):
        assert key in run
    assert run["track"] == "lake" and run["speed_mph"] == 20.0
    assert run["timed_out"] and run["laps_completed"] == 0
    assert run["elapsed_s"] == pytest.approx(12.0, abs=0.1)
    assert run["interventions"] == len(run["off_road_events"]) >= 1
    assert run["autonomy_pct"] == pytest.approx(
        autonomy_pct(run["interventions"], run["elapsed_s"]), abs=0.05)
    assert 0 < run["mean_abs_cte_m"] <= run["max_abs_cte_m"]
    assert run["distance_m"] > 30.0
    for event in run["off_road_events"]:
        frame = tmp_path / event["frame_png"]
        assert frame.is_file() and frame.stat().st_size > 1000
        assert abs(event["cte_m"]) > 1.0
    assert (tmp_path / run["map_png"]).is_file()
    import cv2

    capture = cv2.VideoCapture(str(tmp_path / run["video"]))
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert frames == round(12.0 * 15)
    assert "lake" in format_table(saved)
    assert saved["totals"]["builtin"]["laps_target"] == 1


def test_lock_step_batching_gives_the_same_runs_as_one_at_a_time(tmp_path):
    from clonedrive.model.architectures import build_model

    # A convolutional network with mirror averaging, as `best` drives: batched, its last bits
    # moved with the batch size, and so did the runs.
    policy = NetworkPolicy(build_model("fast", seed=5, speed_head=True), set_speed_mph=15.0,
                           mirror_average=True)
    base = dict(tracks=("lake", "gen:3", "gen:4", "mountain"), speeds_mph=(15.0,), laps=1,
                scenery=False, max_seconds=6.0)
    together = evaluate(policy, EvalConfig(batch=4, **base), tmp_path / "a", progress=False)
    alone = evaluate(policy, EvalConfig(batch=1, **base), tmp_path / "b", progress=False)
    # The policy predicts each frame alone, so a run drives the same path beside another run
    # as alone: every figure equal, to the last digit written.
    for a, b in zip(together["runs"], alone["runs"], strict=True):
        figures = {key for key, value in a.items() if isinstance(value, int | float)}
        assert {"interventions", "distance_m", "mean_abs_cte_m", "steering_rate_per_s"} <= figures
        assert {key: a[key] for key in figures} == {key: b[key] for key in figures}


def test_a_filmed_run_drives_as_the_same_run_without_video(tmp_path):
    """The network of a filmed run sees the strip its crop keeps, as without video; the video
    gets whole frames rendered besides. (Filmed runs used to render whole frames for the
    network too, whose pixels differ from the strip's, and drove another path.)"""
    from clonedrive.model.architectures import build_model

    policy = NetworkPolicy(build_model("fast", seed=5, speed_head=True), set_speed_mph=15.0,
                           mirror_average=True)
    base = dict(tracks=("lake",), speeds_mph=(15.0,), laps=1, scenery=False, max_seconds=5.0,
                workers=1)
    filmed = evaluate(policy, EvalConfig(video=True, **base), tmp_path / "a", progress=False)
    plain = evaluate(policy, EvalConfig(**base), tmp_path / "b", progress=False)
    (a,), (b,) = filmed["runs"], plain["runs"]
    assert (tmp_path / "a" / a["video"]).stat().st_size > 0 and "video" not in b
    figures = {key for key, value in a.items() if isinstance(value, int | float)}
    assert {"distance_m", "mean_abs_cte_m", "steering_rate_per_s"} <= figures
    assert {key: a[key] for key in figures} == {key: b[key] for key in figures}


def test_a_track_given_by_an_absolute_path_names_its_outputs_by_its_name(tmp_path, tiny_policy):
    """Regression: ``evaluate MODEL --track /some/dir/mytrack.json`` drove the whole run and then
    crashed building the map's file name from the track's path, losing every result."""
    track = json.loads(LAKE_JSON.read_text())
    track["name"] = "my track"
    folder = tmp_path / "some" / "dir"
    folder.mkdir(parents=True)
    path = folder / "mytrack.json"
    path.write_text(json.dumps(track))
    out = tmp_path / "eval"
    config = EvalConfig(tracks=(str(path), "lake"), speeds_mph=(15.0,), laps=1, scenery=False,
                        max_seconds=2.0)
    report = evaluate(tiny_policy, config, out, progress=False)
    first, second = report["runs"]
    assert first["track"] == str(path)  # eval.json keeps what the user asked for
    assert (out / first["map_png"]).is_file() and "/" not in first["map_png"]
    assert first["map_png"].startswith("my_track_15mph")
    assert second["map_png"] == "lake_15mph_map.png"
    assert report["complete"] and sorted(p.name for p in out.iterdir() if p.suffix == ".png") \
        == sorted([first["map_png"], second["map_png"]])


def test_two_tracks_with_one_name_get_distinct_files(tmp_path, tiny_policy):
    copy = tmp_path / "lake.json"
    copy.write_text(LAKE_JSON.read_text())  # also named "lake"
    config = EvalConfig(tracks=("lake", str(copy)), speeds_mph=(15.0,), laps=1, scenery=False,
                        max_seconds=1.0)
    report = evaluate(tiny_policy, config, tmp_path / "eval", progress=False)
    assert [run["map_png"] for run in report["runs"]] == ["lake_15mph_map.png",
                                                           "lake_15mph-2_map.png"]


class FailsLater(NetworkPolicy):
    """A network whose inference breaks after ``calls`` batches (a late error)."""

    def __init__(self, model, calls: int) -> None:
        super().__init__(model, set_speed_mph=15.0)
        self.calls = calls

    def predict(self, images):
        self.calls -= 1
        if self.calls < 0:
            raise RuntimeError("the model broke")
        return super().predict(images)


def test_eval_json_keeps_the_runs_finished_before_a_late_error(tmp_path):
    policy = FailsLater(build_tiny_model(seed=0), calls=30 + 5)  # 2 s of run 1, then 5 steps
    config = EvalConfig(tracks=("lake", "gen:3"), speeds_mph=(15.0,), laps=1, scenery=False,
                        max_seconds=2.0, batch=1)
    with pytest.raises(RuntimeError, match="the model broke"):
        evaluate(policy, config, tmp_path, progress=False)
    saved = json.loads((tmp_path / "eval.json").read_text())
    assert not saved["complete"]
    (run,) = saved["runs"]
    assert run["track"] == "lake" and run["elapsed_s"] == pytest.approx(2.0)
    assert saved["totals"]["all"]["runs"] == 1
    assert (tmp_path / run["map_png"]).is_file()


def test_runs_spread_over_worker_processes_give_the_same_results(tmp_path):
    import keras

    model_file = tmp_path / "tiny.keras"
    build_tiny_model(seed=3).save(model_file)
    policy = NetworkPolicy(keras.saving.load_model(model_file), set_speed_mph=15.0)
    config = EvalConfig(tracks=("lake", "mountain"), speeds_mph=(15.0,), laps=1, scenery=False,
                        max_seconds=6.0, workers=1)
    alone = evaluate(policy, config, tmp_path / "one", progress=False,
                     model_path=str(model_file))
    spread = evaluate(policy, EvalConfig(**{**config.__dict__, "workers": 2}),
                      tmp_path / "two", progress=False, model_path=str(model_file))
    assert [run["track"] for run in spread["runs"]] == ["lake", "mountain"]
    assert spread["complete"] and (tmp_path / "two" / spread["runs"][1]["map_png"]).is_file()
    for one, two in zip(alone["runs"], spread["runs"], strict=True):
        assert (one["laps_completed"], one["interventions"]) == \
            (two["laps_completed"], two["interventions"])
        # Panda3D's software renderer may differ in a few edge pixels between the first and a
        # later simulator of a process, and the network's steering may follow them.
        assert two["mean_abs_cte_m"] == pytest.approx(one["mean_abs_cte_m"], abs=0.05)


@pytest.mark.slow
def test_worker_processes_drive_with_the_policys_steering_filter_and_hold(tmp_path):
    """The workers build their own policy from the model file: it must steer through the same
    filter, hold and mirror averaging as the policy evaluate was given."""
    model_file = tmp_path / "tiny.keras"
    build_tiny_model(seed=3).save(model_file)
    config = EvalConfig(tracks=("lake", "mountain"), speeds_mph=(15.0,), laps=1, scenery=False,
                        max_seconds=6.0, workers=2)
    figures = {}
    for name, options in (("raw", {}), ("held", {"steering_filter_s": 0.5,
                                                 "steering_hold": 0.05,
                                                 "mirror_average": True})):
        policy = NetworkPolicy(build_tiny_model(seed=3), set_speed_mph=15.0, **options)
        for workers in (1, 2):
            report = evaluate(policy, EvalConfig(**{**config.__dict__, "workers": workers}),
                              tmp_path / f"{name}{workers}", progress=False,
                              model_path=str(model_file))
            figures[name, workers] = [run["steering_rate_per_s"] for run in report["runs"]]
    assert report["steering_hold"] == 0.05 and report["steering_filter_s"] == 0.5
    assert report["mirror_average"] is True
    for raw, held in zip(figures["raw", 1], figures["held", 1], strict=True):
        assert held < 0.5 * raw  # the filter and hold matter on these runs
    for alone, spread in zip(figures["held", 1], figures["held", 2], strict=True):
        assert spread == pytest.approx(alone, rel=0.2)


@pytest.mark.slow
def test_parts_are_one_evaluation_scheduled_on_one_pool(tmp_path):
    """The demo's shape: a part with two laps on a built-in track, a part on an unseen track
    with one lap; one eval.json holds both parts' runs in order, as each part alone gives them."""
    model_file = tmp_path / "tiny.keras"
    build_tiny_model(seed=3).save(model_file)
    policy = NetworkPolicy(build_tiny_model(seed=3), set_speed_mph=15.0)
    common = {"scenery": False, "max_seconds": 3.0, "workers": 2}
    parts = [EvalConfig(tracks=("lake",), speeds_mph=(15.0, 20.0), laps=2, **common),
             EvalConfig(tracks=(), speeds_mph=(15.0,), laps=1, unseen=1, **common)]
    both = evaluate(policy, parts, tmp_path / "both", progress=False, model_path=str(model_file))
    alone = [evaluate(policy, part, tmp_path / f"part{i}", progress=False,
                      model_path=str(model_file))["runs"] for i, part in enumerate(parts)]
    assert [(r["track"], r["speed_mph"], r["laps_target"]) for r in both["runs"]] == \
        [("lake", 15.0, 2), ("lake", 20.0, 2), ("gen:1000", 15.0, 1)]
    assert both["complete"] and both["totals"]["unseen"]["runs"] == 1
    keys = ("laps_completed", "interventions", "distance_m", "mean_abs_cte_m")
    assert [[r[k] for k in keys] for r in both["runs"]] == \
        [[r[k] for k in keys] for r in alone[0] + alone[1]]
    saved = json.loads((tmp_path / "both" / "config.json").read_text(encoding="utf-8"))
    assert [part["laps"] for part in saved["parts"]] == [2, 1]


@pytest.mark.parametrize("workers", [1, 2])
def test_a_track_is_resolved_once_and_the_loaded_track_drives(tmp_path, tiny_model_path,
                                                              workers):
    """The Track the caller loaded goes down to the simulators, the workers and the expert's
    reference: the file it came from is gone before anything drives."""
    from clonedrive.drivers.policy import load_policy
    from clonedrive.world.catalog import load_track

    path = tmp_path / "mine.json"
    path.write_text(LAKE_JSON.read_text(encoding="utf-8").replace('"lake"', '"mine"', 1),
                    encoding="utf-8")
    tracks = {str(path): load_track(path)}
    path.unlink()
    config = EvalConfig(tracks=(str(path),), speeds_mph=(15.0, 20.0), laps=1, scenery=False,
                        max_seconds=3.0, batch=1, workers=workers)
    report = evaluate(load_policy(tiny_model_path), config, tmp_path / "eval", progress=False,
                      model_path=str(tiny_model_path), tracks=tracks)
    assert report["complete"]
    assert [run["track"] for run in report["runs"]] == [str(path)] * 2
    assert all(run["expert"]["lap_time_s"] is None for run in report["runs"])  # 3 s: no lap
    assert all(run["distance_m"] > 0 and run["expert"]["mean_speed_mph"] > 0
               for run in report["runs"])
    with pytest.raises(Exception, match="mine.json"):
        load_track(path)  # the name alone no longer resolves
