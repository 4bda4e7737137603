"""clonedrive bench: figures per run, split and method; the same results with 1 worker, 2
workers and Ray; bench.json and the leaderboard written."""

import json
import shutil
from dataclasses import replace

import pytest

from clonedrive.base.workers import run_tasks
from clonedrive.bench.driving import drive_batch
from clonedrive.bench.run import BenchConfig, bench, plan_tasks
from clonedrive.bench.scores import correlation, method_scores, run_scores, split_scores
from clonedrive.bench.suite import load_suite

SUITE = """
id = "tiny"
[[split]]
name = "a"
tracks = ["lake"]
speeds_mph = [20.0]
conditions = ["clear", "late"]
seed = 3
[conditions.clear]
[conditions.late]
held_out = true
latency_steps = 2
jpeg_quality = [30, 40]
"""


def run(clean, interventions=0, distance_m=500.0, lap_time_s=60.0, smoothness=0.2):
    return {"clean": clean, "interventions": interventions, "distance_m": distance_m,
            "autonomy_pct": 100.0 - 10 * interventions, "mean_abs_cte_m": 0.5,
            "lap_time_s": lap_time_s if clean else None, "smoothness": smoothness}


def test_scores_per_run_split_and_method():
    reference = {"lap_time_s": 50.0, "smoothness": 0.1}
    a = {**run(True), "scores": run_scores(run(True), reference)}
    b = {**run(False, 2), "scores": run_scores(run(False, 2), reference)}
    assert a["scores"]["lap_time_ratio"] == pytest.approx(1.2)
    assert a["scores"]["smoothness_ratio"] == pytest.approx(2.0)
    assert b["scores"]["interventions_per_km"] == pytest.approx(4.0)
    split = split_scores([a, b])
    assert split["success_pct"] == 50.0 and split["interventions_per_km"] == pytest.approx(2.0)
    assert split["lap_time_ratio"] == pytest.approx(1.2)  # clean runs only
    models = [{"splits": {"s": split}, "overall": split},
              {"splits": {"s": split_scores([a])}, "overall": split_scores([a])}]
    method = method_scores(models, ["s"])
    assert method["s"]["success_pct"]["mean"] == 75.0
    assert method["s"]["success_pct"]["std"] == pytest.approx(35.3553, abs=1e-3)
    assert correlation([1, 2, 3, 4], [8, 6, 4, 2]) == {"n": 4, "pearson": -1.0,
                                                        "spearman": -1.0}
    assert correlation([1, 2], [3, 4])["pearson"] is None


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory):
    from clonedrive.network.tiny_model import build_tiny_model

    folder = tmp_path_factory.mktemp("models")
    paths = []
    for seed in (0, 1):
        path = folder / f"tiny{seed}.keras"
        build_tiny_model(seed).save(path)
        paths.append(str(path))
    return paths


@pytest.mark.slow
def test_bench_writes_its_files_and_the_same_results_with_1_and_2_workers(tmp_path,
                                                                          tiny_models):
    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    reports = []
    for workers in (1, 2):
        config = BenchConfig(models=(f"tiny={tiny_models[0]}",),
                             suite=str(suite_path), workers=workers, batch=1,
                             max_seconds=3.0, scenery=False)
        reports.append(bench(config, tmp_path / f"w{workers}", progress=False))
    one, two = reports
    assert json.dumps(one["models"], sort_keys=True) == json.dumps(two["models"], sort_keys=True)
    assert one["complete"] and set(one["methods"]) == {"tiny"}
    assert one["rendering"]["renderer"] == "auto" and one["rendering"]["gl_renderer"]
    assert one["rendering"]["full_frame"] is False
    runs = one["models"][f"tiny={tiny_models[0]}"]["runs"]
    assert [r["family"] for r in runs] == ["clear", "late"]
    assert runs[1]["conditions"]["latency_steps"] == 2
    assert runs[0]["elapsed_s"] == pytest.approx(3.0)
    assert one["methods"]["tiny"]["scores"]["a"]["success_pct"]["n"] == 1
    # Every run has a driving score in [0, 1]; split figures and methods carry 95 % intervals.
    assert all(0.0 <= r["scores"]["driving_score"] <= 1.0 and r["route_m"] > 0 for r in runs)
    split = one["models"][f"tiny={tiny_models[0]}"]["splits"]["a"]
    for figure in ("success_pct", "interventions_per_km", "driving_score"):
        interval = split["ci"][figure]
        assert interval["n"] == 2 and interval["low"] <= interval["value"] <= interval["high"]
    method_ci = one["methods"]["tiny"]["ci"]["a"]["driving_score"]
    assert method_ci["low"] <= method_ci["value"] <= method_ci["high"]
    for name in ("bench.json", "leaderboard.md", "leaderboard.html", "bench_success.png",
                 "bench_lap_time.png"):
        assert (tmp_path / "w1" / name).is_file()
    assert "| tiny |" in (tmp_path / "w1" / "leaderboard.md").read_text(encoding="utf-8")
    # clonedrive report shows a run folder's bench runs (here bench/parity/) as a section.
    from clonedrive.report.writeup import write_report

    shutil.copytree(tmp_path / "w1", tmp_path / "run" / "bench" / "parity")
    result = write_report(tmp_path / "run", tmp_path / "report")
    markdown = result.markdown_path.read_text(encoding="utf-8")
    section = markdown[markdown.index(". Benchmark\n"):]
    assert "### `bench/parity`" in section and "| tiny |" in section
    assert "Suite `tiny`" in section
    assert (tmp_path / "report" / "report" / "bench_parity_bench_success.png").is_file()


@pytest.mark.slow
def test_ray_gives_the_same_results_as_local_workers(tmp_path, tiny_models):
    ray = pytest.importorskip("ray")
    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    config = BenchConfig(models=(tiny_models[0],), suite=str(suite_path), batch=1,
                         max_seconds=3.0, scenery=False)
    tasks, _ = plan_tasks(load_suite(config.suite), config)
    local = run_tasks(drive_batch, tasks, workers=2)
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        distributed = run_tasks(drive_batch, tasks, ray="local")
    finally:
        ray.shutdown()
    assert json.dumps(local, sort_keys=True) == json.dumps(distributed, sort_keys=True)


def test_every_model_task_carries_the_policy_options_and_the_workers_drive_with_them(
        tmp_path, tiny_models):
    from clonedrive.drivers.policy import load_policy

    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    config = BenchConfig(models=(tiny_models[0],), suite=str(suite_path), batch=2,
                         max_seconds=4.0, scenery=False, steering_hold=0.3,
                         steering_filter_s=0.1, slow_in_curves=True, mirror_average=True,
                         steering_scale_from_mph=10.0)
    tasks, _ = plan_tasks(load_suite(config.suite), config)
    models = [task for task in tasks if task.kind == "model"]
    policy = load_policy(tiny_models[0], **config.policy_options())
    assert policy.mirror_average and policy.steering_hold == 0.3
    assert policy.steering_scale_from_mph == 10.0
    for task in models:  # named as NetworkPolicy names them, so it drives the same way
        options = task.policy_options
        assert set(options) <= set(policy.options())
        assert all(policy.options()[key] == value for key, value in options.items())
    held = drive_batch(models[0])
    loose = drive_batch(replace(models[0], policy_options={}))
    assert [r["smoothness"] for r in held] != [r["smoothness"] for r in loose]
    assert all(h["smoothness"] < lo["smoothness"] for h, lo in zip(held, loose, strict=True))


def test_the_bench_command_drives_with_the_steering_options(tmp_path, tiny_models, capsys):
    from clonedrive.cli import main

    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    out = tmp_path / "bench"
    assert main(["bench", tiny_models[0], "--suite", str(suite_path), "--split", "a",
                 "--max-seconds", "2", "--no-scenery", "--workers", "1", "--out", str(out),
                 "--steering-hold", "0.3", "--steering-filter", "0.1",
                 "--mirror-average", "--steering-scale-from", "12"]) == 0
    settings = json.loads((out / "bench.json").read_text(encoding="utf-8"))["settings"]
    assert (settings["steering_hold"], settings["steering_filter_s"],
            settings["mirror_average"], settings["steering_scale_from_mph"]) == (0.3, 0.1, True,
                                                                                  12.0)
    # --resume with other options: one line naming the file and the field, nothing changed.
    before = (out / "bench.json").read_bytes()
    assert main(["bench", tiny_models[0], "--suite", str(suite_path), "--split", "a",
                 "--max-seconds", "2", "--no-scenery", "--out", str(out), "--resume"]) == 2
    error = capsys.readouterr().err
    assert "bench.json: its 'settings' differs" in error and "Traceback" not in error
    assert (out / "bench.json").read_bytes() == before


def test_a_model_with_many_batches_is_traced_once_and_its_workers_drive_the_same(
        tmp_path, tiny_models, monkeypatch):
    """With enough batches per worker, bench makes the model's checked traces in its own
    process and hands them to every batch (no Keras import in the workers); a batch drives
    with them exactly as from the model file. Below the threshold, the workers load the file."""
    from clonedrive.bench import run as bench_run

    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    config = BenchConfig(models=(tiny_models[0],), suite=str(suite_path), batch=2,
                         max_seconds=3.0, scenery=False, mirror_average=True)
    tasks, _ = plan_tasks(load_suite(config.suite), config)
    bench_run._add_portable_models(tasks, config, workers=1)  # 1 batch: below the threshold
    assert all(task.portable is None for task in tasks)
    monkeypatch.setattr(bench_run, "PORTABLE_FROM_BATCHES_PER_WORKER", 1)
    bench_run._add_portable_models(tasks, config, workers=1)
    (task,) = [task for task in tasks if task.kind == "model"]
    assert sorted(task.portable.traces) == [2]  # each frame alone, mirrored
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        traced = drive_batch(task)
        from_file = drive_batch(replace(task, portable=None))
        assert torch.get_num_threads() == 2  # a batch drives on one thread, then gives it back
    finally:
        torch.set_num_threads(before)
    assert json.dumps(traced, sort_keys=True) == json.dumps(from_file, sort_keys=True)


@pytest.mark.slow
def test_a_resumed_bench_keeps_the_finished_batches_and_ends_as_an_uninterrupted_run(
        tmp_path, tiny_models):
    from clonedrive.bench.resume import ResumeError

    suite_path = tmp_path / "tiny.toml"
    suite_path.write_text(SUITE, encoding="utf-8")
    config = BenchConfig(models=(f"a={tiny_models[0]}", f"b={tiny_models[1]}"),
                         suite=str(suite_path), workers=2, batch=1, max_seconds=3.0,
                         scenery=False)
    # Nothing to resume in an empty folder: the run starts from the first batch.
    whole = bench(config, tmp_path / "whole", progress=False, resume=True)
    assert whole["complete"] and len(whole["models"][f"b={tiny_models[1]}"]["runs"]) == 2
    # An interrupted run: model b's last batch and the completion are missing, and one of the
    # kept runs is marked, so the resumed file shows whether it was kept or driven again.
    cut = json.loads((tmp_path / "whole" / "bench.json").read_text(encoding="utf-8"))
    cut["complete"] = False
    cut["models"][f"b={tiny_models[1]}"]["runs"].pop()
    cut["models"][f"a={tiny_models[0]}"]["runs"][0]["marked"] = True
    # ... and made before the speed scale was a setting: it drove at its default.
    del cut["settings"]["speed_scale"]
    for settings in cut["driving"].values():
        del settings["speed_scale"]
    (tmp_path / "cut").mkdir()
    (tmp_path / "cut" / "bench.json").write_text(json.dumps(cut), encoding="utf-8")
    resumed = bench(replace(config, workers=1), tmp_path / "cut", progress=False, resume=True)
    assert resumed["complete"]
    kept = resumed["models"][f"a={tiny_models[0]}"]["runs"]
    assert kept[0].pop("marked") is True  # kept, not driven again
    assert json.dumps(resumed["models"], sort_keys=True) == json.dumps(
        json.loads(json.dumps(whole["models"])), sort_keys=True)
    assert (tmp_path / "cut" / "leaderboard.html").is_file()
    # A bench.json made with other settings is refused, and left as it was.
    before = (tmp_path / "cut" / "bench.json").read_bytes()
    with pytest.raises(ResumeError, match="'settings' differs"):
        bench(replace(config, max_seconds=2.0), tmp_path / "cut", progress=False, resume=True)
    assert (tmp_path / "cut" / "bench.json").read_bytes() == before
    # So is one made before bench.json recorded how the policy predicted (it batched the
    # lock-step cars' frames, so its runs differ from this code's by their last bits).
    old = json.loads(before)
    assert old.pop("prediction") == "each frame alone"
    (tmp_path / "cut" / "bench.json").write_text(json.dumps(old), encoding="utf-8")
    with pytest.raises(ResumeError, match="'prediction' differs"):
        bench(config, tmp_path / "cut", progress=False, resume=True)
