"""A model drives the same way whoever renders, and whether or not only its crop is rendered.

The model is :func:`~clonedrive.network.tiny_model.build_road_follower` (hand-weighted, no
training; it crops rows 75-130 after a per-pixel Rescaling, which :mod:`clonedrive.network.crop`
reads as its crop), on lake and mountain without scenery, for the first ``SECONDS`` of a lap
each: laps and interventions must be equal with the software renderer full-frame, the software
renderer cropped, and EGL (llvmpipe here and in CI) cropped; the cross-track error may move by
what the renderers' texture sampling does to the network's input. Whole laps of the demo's
trained model are compared by ``benchmarks/crop.py`` (crop against full frame).
"""

from __future__ import annotations

import pytest

from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.evaluate.config import EvalConfig
from clonedrive.evaluate.rollout import evaluate
from clonedrive.network.tiny_model import build_road_follower
from clonedrive.sim.engine import probe_egl

#: Simulated seconds per run, and the set speed [mph].
SECONDS, SPEED_MPH = 40.0, 12.0
#: Allowed difference in mean |CTE| between the ways of rendering [m].
MEAN_CTE_TOLERANCE_M = 0.1
KEYS = ("track", "laps_completed", "interventions", "stopped")


def drive(tmp_path, name: str, *, renderer: str, full_frame: bool) -> list[dict]:
    policy = NetworkPolicy(build_road_follower(), set_speed_mph=SPEED_MPH)
    assert policy.visible_rows == (75, 130)
    config = EvalConfig(tracks=("lake", "mountain"), speeds_mph=(SPEED_MPH,), laps=1,
                        scenery=False, max_seconds=SECONDS, expert_reference=False,
                        renderer=renderer, full_frame=full_frame, workers=1)
    report = evaluate(policy, config, tmp_path / name, progress=False)
    assert report["renderer_used"] == renderer
    assert report["render_rows"] == (None if full_frame else [75, 130])
    return report["runs"]


def test_laps_and_interventions_do_not_depend_on_the_crop_or_the_renderer(tmp_path):
    reference = drive(tmp_path, "software-full", renderer="software", full_frame=True)
    assert all(run["distance_m"] > 100.0 for run in reference)  # it drove, not stood
    others = [drive(tmp_path, "software-crop", renderer="software", full_frame=False)]
    if probe_egl() is not None:
        others.append(drive(tmp_path, "egl-crop", renderer="egl", full_frame=False))
    else:  # pragma: no cover - CI has EGL (llvmpipe)
        pytest.skip("EGL does not open here: only the crop was compared")
    for runs in others:
        for run, expected in zip(runs, reference, strict=True):
            assert [run[key] for key in KEYS] == [expected[key] for key in KEYS]
            assert run["mean_abs_cte_m"] == pytest.approx(expected["mean_abs_cte_m"],
                                                          abs=MEAN_CTE_TOLERANCE_M)
