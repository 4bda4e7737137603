"""benchmarks/replay.py's comparison of replay with true closed loop, over models: each
model's interventions, distance and time summed over its conditions, then ranked."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("replay_benchmark",
                                                  ROOT / "benchmarks" / "replay.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["replay_benchmark"] = module
    spec.loader.exec_module(module)
    return module


def pair(model: str, replay: tuple[int, float, float], sim: tuple[int, float, float]) -> dict:
    keys = ("interventions", "distance_m", "elapsed_s")
    return {"model": model, **{f"replay_{k}": v for k, v in zip(keys, replay, strict=True)},
            **{f"sim_{k}": v for k, v in zip(keys, sim, strict=True)}}


def test_models_are_totalled_over_their_conditions_and_ranked(bench) -> None:
    pairs = [pair("good", (0, 1000.0, 120.0), (0, 1000.0, 120.0)),
             pair("good", (1, 2000.0, 150.0), (0, 2000.0, 150.0)),
             pair("fair", (2, 1000.0, 120.0), (1, 1000.0, 120.0)),
             pair("fair", (4, 2000.0, 150.0), (5, 2000.0, 150.0)),
             pair("poor", (30, 1000.0, 120.0), (20, 1000.0, 120.0)),
             pair("poor", (60, 2000.0, 150.0), (70, 2000.0, 150.0))]
    rows = {row["model"]: row for row in bench.model_totals(pairs)}
    assert rows["good"]["conditions"] == 2
    assert rows["good"]["replay_interventions_per_km"] == pytest.approx(1 / 3, abs=1e-3)
    assert rows["fair"]["sim_interventions_per_km"] == 2.0
    # 1 - 6 s x 1 / 270 s; a model with more intervention time than driving time floors at 0
    assert rows["good"]["replay_autonomy_pct"] == pytest.approx(97.78, abs=0.01)
    assert rows["poor"]["sim_autonomy_pct"] == 0.0
    ordered = list(rows.values())
    assert bench.rank(ordered, "replay_interventions_per_km", "sim_interventions_per_km") == 1.0
    backwards = [{**row, "sim_interventions_per_km": -row["sim_interventions_per_km"]}
                 for row in ordered]
    assert bench.rank(backwards, "replay_interventions_per_km",
                      "sim_interventions_per_km") == -1.0
