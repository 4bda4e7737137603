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


def test_the_hierarchical_interval_of_one_model_is_its_episode_bootstrap() -> None:
    """With one model there is no seed spread: the interval is the episodes' own, up to the
    resampling noise of two different draws."""
    episodes = np.random.default_rng(5).normal(0.7, 0.2, 200)
    nested, plain = stats.hierarchical_ci([episodes]), stats.bootstrap_ci(episodes)
    assert nested["value"] == plain["value"] and nested["n"] == plain["n"] == 200
    assert nested["low"] == pytest.approx(plain["low"], abs=0.01)
    assert nested["high"] == pytest.approx(plain["high"], abs=0.01)
    assert stats.hierarchical_ci([[None], []])["value"] is None


def test_the_hierarchical_interval_draws_in_bounded_pieces(monkeypatch) -> None:
    """Drawn a few resamples at a time (bounded memory), the interval is the one-piece draw's."""
    rng = np.random.default_rng(6)
    seeds = [rng.normal(0.8, 0.1, 40), rng.normal(0.6, 0.1, 40), rng.normal(0.7, 0.1, 40)]
    whole = stats.hierarchical_ci(seeds)
    monkeypatch.setattr(stats, "MAX_DRAWN_VALUES", 100)  # two resamples of 40 at a time
    pieces = stats.hierarchical_ci(seeds)
    assert pieces == whole
    assert whole["low"] < whole["value"] < whole["high"]


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


def test_compare_says_when_the_two_runs_predicted_another_way(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A bench run made before bench.json recorded ``prediction`` batched its lock-step cars'
    frames; compared with one that predicted each frame alone, the comparison says so."""
    from clonedrive.drivers.policy import PREDICTION, PREDICTION_BEFORE

    scores = [[1.0, 0.8, 0.9, 1.0]]
    paths = [_bench_json(tmp_path / name, name, scores) for name in ("old", "new", "newer")]
    for path in paths[1:]:
        report = json.loads((path / "bench.json").read_text(encoding="utf-8"))
        (path / "bench.json").write_text(json.dumps({**report, "prediction": PREDICTION}),
                                         encoding="utf-8")
    assert main(["bench", "compare", str(paths[1]), str(paths[2]), "--json"]) == 0
    assert "caveat" not in json.loads(capsys.readouterr().out)
    assert main(["bench", "compare", str(paths[0]), str(paths[1])]) == 0
    printed = capsys.readouterr().out
    assert f"note: A and B did not predict alike (A: {PREDICTION_BEFORE}; B: {PREDICTION})" \
        in printed


def test_the_label_permutation_p_value_is_exact_for_few_models() -> None:
    # Three against three, wholly apart: 2 of the 20 splits are as extreme (this one and its
    # mirror), the least p-value three against three can give.
    p_value, smallest = stats.label_permutation_p(np.array([1.0, 2.0, 3.0]),
                                                  np.array([4.0, 5.0, 6.0]))
    assert (p_value, smallest) == (0.1, 0.1)
    mixed, _ = stats.label_permutation_p(np.array([1.0, 5.0, 3.0]), np.array([2.0, 4.0, 6.0]))
    assert mixed > 0.5
    apart, floor = stats.label_permutation_p(np.arange(5.0), np.arange(5.0) + 10.0)
    assert apart == floor == round(2 / 252, 4)


def test_the_drawn_label_permutation_p_value_counts_the_observed_assignment() -> None:
    # 12 against 12 has 2.7 million assignments: drawn, not enumerated. Wholly apart, no draw
    # is more extreme, yet the p-value is the floor 1 / (draws + 1), never 0.
    p_value, smallest = stats.label_permutation_p(np.arange(12.0), np.arange(12.0) + 50.0,
                                                  draws=999)
    assert (p_value, smallest) == (0.001, 0.001)
    mixed, _ = stats.label_permutation_p(np.arange(12.0), np.arange(12.0) + 0.5, draws=999)
    assert 0.5 < mixed <= 1.0
    # Five against five drawn (99 draws) instead of enumerated: a multiple of 1/100 near the
    # exact 2/252, not the exact value itself.
    drawn, floor = stats.label_permutation_p(np.arange(5.0), np.arange(5.0) + 10.0,
                                             exact_limit=1, draws=99)
    assert floor == 0.01 and drawn in (0.01, 0.02, 0.03, 0.04)


def test_a_difference_over_seeds_needs_enough_seeds_to_be_detected() -> None:
    """Seeds of A all a little better than seeds of B, each seed's episodes noisy: three
    against three cannot reach p < 0.05 (and says so); six against six can."""
    rng = np.random.default_rng(8)
    episodes = [f"s/{i:03d}" for i in range(40)]

    def models(mean: float, count: int) -> list[dict[str, float]]:
        return [dict(zip(episodes, rng.normal(mean + rng.normal(0, 0.02), 0.1, 40),
                         strict=True)) for _ in range(count)]

    few = stats.seed_comparison(models(0.8, 3), models(0.7, 3), figure="driving score",
                                names=("a", "b"))
    assert few["models"] == [3, 3] and few["episodes"] == 40
    assert few["low"] < few["difference"] < few["high"] and few["difference"] > 0
    assert few["p_value"] == few["smallest_p"] == 0.1 and few["a_beats_b_share"] == 1.0
    assert "cannot give a p-value below 0.1000" in few["sentence"]
    assert few["sentence"].startswith("Over training seeds, no difference detected")
    many = stats.seed_comparison(models(0.8, 6), models(0.7, 6), figure="driving score",
                                 names=("a", "b"))
    assert many["p_value"] < 0.05 and many["low"] > 0
    assert many["sentence"].startswith("Over training seeds too, a is better in driving score")
    lower = stats.seed_comparison(models(0.8, 6), models(0.7, 6), figure="interventions",
                                  higher_is_better=False, names=("a", "b"))
    assert "b is better" in lower["sentence"] and lower["a_beats_b_share"] == 0.0


def test_compare_adds_the_comparison_over_seeds_for_methods_of_several_models(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rng = np.random.default_rng(9)
    good = _bench_json(tmp_path / "good", "best",
                       [np.clip(rng.normal(0.9, 0.05, 20), 0, 1).tolist() for _ in range(3)])
    bad = _bench_json(tmp_path / "bad", "plain",
                      [np.clip(rng.normal(0.6, 0.05, 20), 0, 1).tolist() for _ in range(3)])
    assert main(["bench", "compare", str(good), str(bad), "--json"]) == 0
    seeds = json.loads(capsys.readouterr().out)["over_seeds"][0]
    assert seeds["figure"] == "driving score" and seeds["models"] == [3, 3]
    assert seeds["p_value"] == 0.1 and len(seeds["a_model_means"]) == 3
    assert main(["bench", "compare", f"{good}:best=0", f"{bad}:plain=0", "--json"]) == 0
    assert "over_seeds" not in json.loads(capsys.readouterr().out)  # one model each
    assert main(["bench", "compare", str(good), str(bad)]) == 0
    assert "driving score over seeds (3 against 3 models)" in capsys.readouterr().out
