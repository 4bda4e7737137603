"""Smoothness as numbers: closed-form checks of the figures, interventions break the series, and
the expert's reference run as the yardstick of eval.json's ratios."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clonedrive.episode.smoothness import (
    FIGURES,
    round_figure,
    smoothness_figures,
    smoothness_ratios,
)
from clonedrive.evaluate.reference import against_expert, expert_reference

HZ = 15.0


def circle(steps: int, radius_m: float, speed_mps: float):
    t = np.arange(steps) / HZ
    angle = speed_mps / radius_m * t
    return radius_m * np.cos(angle), radius_m * np.sin(angle)


def test_figures_match_closed_forms() -> None:
    x, y = circle(600, 25.0, 10.0)
    t = np.arange(600) / HZ
    steering = 0.3 * np.sin(2.0 * t)  # rate 0.6 cos(2t): mean |.| = 0.6 * 2 / pi
    figures = smoothness_figures(steering, x, y, np.full(600, 10.0), HZ)
    assert list(figures) == list(FIGURES)
    assert figures["steering_rate_per_s"] == pytest.approx(0.6 * 2 / math.pi, rel=0.02)
    assert figures["steering_jerk_per_s2"] == pytest.approx(1.2 * 2 / math.pi, rel=0.03)
    assert figures["lateral_accel_rms_mps2"] == pytest.approx(10.0**2 / 25.0, rel=1e-3)
    assert figures["lateral_accel_max_mps2"] == pytest.approx(4.0, rel=1e-3)
    assert figures["lateral_jerk_mps3"] == pytest.approx(0.0, abs=1e-6)


def test_an_intervention_is_not_a_jerk() -> None:
    x, y = circle(300, 30.0, 12.0)
    steering = np.full(300, 0.2)
    steering[150:] = -0.2  # the car put back on the road after step 149, steering anew
    x[150:] += 5.0  # ... somewhere else
    broken = smoothness_figures(steering, x, y, np.full(300, 12.0), HZ, breaks=[149])
    assert broken["steering_rate_per_s"] == 0.0 and broken["lateral_jerk_mps3"] < 1e-6
    assert smoothness_figures(steering, x, y, np.full(300, 12.0), HZ)["steering_rate_per_s"] > 0


def test_standing_still_has_no_lateral_figures() -> None:
    figures = smoothness_figures(np.zeros(50), np.zeros(50), np.zeros(50), np.zeros(50), HZ)
    assert all(value == 0.0 for value in figures.values())
    with pytest.raises(ValueError, match="one value per step"):
        smoothness_figures([0.0], [0.0, 1.0], [0.0], [0.0], HZ)


def test_ratios_against_the_expert() -> None:
    expert = {name: 2.0 for name in FIGURES}
    run = {name: 3.0 for name in FIGURES}
    ratios = smoothness_ratios(run, expert)
    assert ratios == {f"{name}_ratio": 1.5 for name in FIGURES}
    assert smoothness_ratios(run, {})["steering_rate_per_s_ratio"] is None


def test_a_gentle_runs_figures_keep_their_digits_and_so_do_their_ratios() -> None:
    # A wheel turning 0.0052585 per second, as the expert's on a large gentle loop: four
    # decimals would keep 0.0053, and a run at twice that would read 1.98x instead of 2.
    steps = 15 * 60
    steering = np.arange(steps) * (0.0052585 / HZ)
    still = np.zeros(steps)
    expert = smoothness_figures(steering, still, still, still, HZ)
    assert expert["steering_rate_per_s"] == pytest.approx(0.0052585, rel=1e-5)
    run = smoothness_figures(2.0 * steering, still, still, still, HZ)
    assert smoothness_ratios(run, expert)["steering_rate_per_s_ratio"] == 2.0
    assert round_figure(0.010554466517) == 0.0105545
    assert round_figure(1234.56789) == 1234.57 and round_figure(0.0) == 0.0


def test_the_expert_against_itself_is_one() -> None:
    reference = expert_reference("lake", 20.0, laps=1, max_seconds=40.0)
    assert reference["interventions"] == 0 and reference["steering_rate_per_s"] > 0
    assert reference["lateral_accel_max_mps2"] < 0.5 * 9.81 + 0.5  # its planned grip, about
    compared = against_expert(reference, max_seconds=40.0)
    assert compared["steering_rate_per_s_ratio"] == 1.0
    assert compared["expert"]["lateral_accel_rms_mps2"] == reference["lateral_accel_rms_mps2"]
