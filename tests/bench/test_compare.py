"""Confidence for benchmark figures: bootstrap intervals, the hierarchical bootstrap over a
method's seeds, and ``clonedrive bench compare`` on bench.json files written for the test."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clonedrive.bench import stats
from clonedrive.bench.scores import INTERVENTION_PENALTY, driving_score
from clonedrive.cli import main


def test_a_bootstrap_interval_holds_the_mean_and_narrows_with_more_episodes() -> None:
    rng = np.random.default_rng(3)
    few = stats.bootstrap_ci(rng.normal(0.7, 0.2, 12))
    many = stats.bootstrap_ci(rng.normal(0.7, 0.2, 400))
    for interval in (few, many):
        assert interval["low"] < interval["value"] < interval["high"]
    assert many["high"] - many["low"] < 0.5 * (few["high"] - few["low"])
    assert stats.bootstrap_ci([1.0, 0.0, 1.0]) == stats.bootstrap_ci([1.0, 0.0, 1.0])  # seeded
    assert stats.bootstrap_ci([None])["value"] is None


def test_the_hierarchical_interval_holds_the_spread_between_seeds() -> None:
    """Two seeds that disagree: the method's interval is wider than pooling their episodes."""
    rng = np.random.default_rng(4)
    seeds = [rng.normal(0.9, 0.05, 30), rng.normal(0.5, 0.05, 30)]
    nested = stats.hierarchical_ci(seeds)
    pooled = stats.bootstrap_ci(np.concatenate(seeds))
    assert nested["value"] == pytest.approx(pooled["value"], abs=1e-3)
    assert nested["high"] - nested["low"] > 3 * (pooled["high"] - pooled["low"])


def test_the_pooled_ratio_interval_is_interventions_over_kilometres() -> None:
    interval = stats.ratio_ci([0, 2, 1, 0], [1.0, 1.0, 0.5, 0.5])
    assert interval["value"] == pytest.approx(1.0)
    assert interval["low"] <= 1.0 <= interval["high"]


def test_the_driving_score_is_completion_times_a_penalty_per_intervention() -> None:
    clean = {"distance_m": 1200.0, "route_m": 1000.0, "interventions": 0, "clean": True}
    assert driving_score(clean) == 1.0
    two = {**clean, "interventions": 2, "clean": False}
    assert driving_score(two) == pytest.approx(INTERVENTION_PENALTY ** 2)
    half = {**clean, "distance_m": 500.0}
    assert driving_score(half) == pytest.approx(0.5)


def _bench_json(path: Path, label: str, scores_by_seed: list[list[float]],
                suite: str = "v2") -> Path:
    models = {}
    for seed, scores in enumerate(scores_by_seed):
        runs = [{"key": f"s/{i:03d}", "split": "s",
                 "scores": {"driving_score": score, "clean": score > 0.99,
                            "interventions_per_km": 0.0 if score > 0.99 else 1.0,
                            "lap_time_ratio": 1.0 if score > 0.99 else None}}
                for i, score in enumerate(scores)]
        models[f"{label}={seed}"] = {"label": label, "runs": runs}
    report = {"suite": {"id": suite}, "models": models,
              "methods": {label: {"models": list(models)}}}
    path.mkdir(parents=True)
    (path / "bench.json").write_text(json.dumps(report), encoding="utf-8")
    return path


def test_compare_finds_a_real_difference_and_none_between_seeds_of_one_recipe(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rng = np.random.default_rng(5)
    seeds = [np.clip(rng.normal(0.95, 0.08, 30), 0, 1) for _ in range(3)]
    good = _bench_json(tmp_path / "good", "best", [s.tolist() for s in seeds])
    bad = _bench_json(tmp_path / "bad", "writeup",
                      [np.clip(rng.normal(0.6, 0.2, 30), 0, 1).tolist() for _ in range(3)])
    # The same recipe's episodes in another order (another draw of the same scores), one of
    # them a hair better: no difference to find.
    twin_seeds = [np.roll(s, 7) for s in seeds]
    twin_seeds[0][0] = min(1.0, twin_seeds[0][0] + 0.003)
    twin = _bench_json(tmp_path / "twin", "best", [s.tolist() for s in twin_seeds])
    assert main(["bench", "compare", str(good), str(bad), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    score = result["comparisons"][0]
    assert score["figure"] == "driving score" and score["episodes"] == 30
    assert score["p_value"] < 0.01 and score["low"] > 0
    assert score["sentence"].startswith("best (good) is better than writeup (bad)")
    assert main(["bench", "compare", str(good), str(twin), "--json"]) == 0
    same = json.loads(capsys.readouterr().out)["comparisons"][0]
    assert same["p_value"] > 0.05 and same["low"] < 0 < same["high"]
    assert same["sentence"].startswith("No difference detected in driving score")
    assert "paired episodes" in same["sentence"]
    # Plain text, and the refusals.
    assert main(["bench", "compare", str(good), str(bad)]) == 0
    assert "is better than" in capsys.readouterr().out
    other = _bench_json(tmp_path / "other", "x", [[1.0, 1.0]], suite="v1")
    assert main(["bench", "compare", str(good), str(other)]) == 2
    assert "different suites" in capsys.readouterr().err
    assert main(["bench", "compare", str(good)]) == 2
    # One model of a method (one training seed) against another.
    assert main(["bench", "compare", f"{good}:best=0", f"{good}:best=1", "--json"]) == 0
    seeds_result = json.loads(capsys.readouterr().out)
    assert seeds_result["comparisons"][0]["episodes"] == 30
    assert seeds_result["a"].startswith("best=0")
    assert main(["bench", "compare", str(good), f"{bad}:nosuch"]) == 2
    assert "no method 'nosuch'" in capsys.readouterr().err
    listed = tmp_path / "list.json"
    listed.write_text("[1, 2]", encoding="utf-8")
    assert main(["bench", "compare", str(good), str(listed)]) == 2
    assert "not a bench.json (its top level is not an object)" in capsys.readouterr().err
