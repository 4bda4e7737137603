"""Generator v2: tracks from segments, graded by difficulty, reachable by name; v1 unchanged."""

import math

import numpy as np
import pytest

from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
from clonedrive.sim.simulator import SimConfig, Simulator
from clonedrive.world.catalog import load_track
from clonedrive.world.generate import GENERATOR_VERSION, generate
from clonedrive.world.segments import DIFFICULTIES, Difficulty, curved_fraction, generate_v2
from clonedrive.world.track import TrackError


def test_same_seed_same_track_and_names_agree():
    a, b = generate_v2(7, "hard"), load_track("gen2:hard:7")
    assert np.array_equal(a.xyz, b.xyz) and np.array_equal(a.width, b.width)
    assert b.name == "gen2:hard:7" and b.version == GENERATOR_VERSION == 2
    assert not np.array_equal(generate_v2(8, "hard").xyz[:50], a.xyz[:50])
    # the difficulty is part of the seed; gen2:<seed> is medium
    assert not np.array_equal(generate_v2(7, "easy").xyz[:50], generate_v2(7, "medium").xyz[:50])
    assert np.array_equal(load_track("gen2:7").xyz, load_track("gen2:medium:7").xyz)
    assert np.array_equal(generate(7).xyz, generate_v2(7).xyz)


def test_v1_stays_reachable_by_both_names():
    old, versioned = load_track("gen:17"), load_track("gen1:17")
    assert np.array_equal(old.xyz, versioned.xyz)
    assert old.version == versioned.version == 1
    assert old.name == "gen:17" and versioned.name == "gen1:17"


@pytest.mark.parametrize("name", ["gen2:x", "gen2:brutal:3", "gen2:hard:3:4", "gen1:-1",
                                  "gen2:hard:"])
def test_bad_generated_names_say_how_to_name_one(name):
    with pytest.raises(TrackError, match="gen2|difficulty|seed"):
        load_track(name)


@pytest.mark.parametrize("difficulty", list(DIFFICULTIES))
def test_each_difficulty_stays_within_its_bounds(difficulty):
    d = DIFFICULTIES[difficulty]
    themes = set()
    for seed in range(6):
        track = generate_v2(seed, difficulty)
        themes.add(track.theme)
        assert 0.9 * d.min_radius_m <= track.min_radius_m <= d.max_radius_m
        assert d.width_m[0] - 1e-6 <= float(track.width.mean()) <= d.width_m[1] + 1e-6
        assert track.max_grade <= d.max_grade * 1.02
        assert 500.0 <= track.length_m <= 3200.0
        # the start line is on a straight
        assert abs(float(track.curvature_table[0])) < 1e-3
    assert themes == {"lake", "mountain"}


def test_hard_tracks_have_hairpins_steep_grades_and_narrow_roads():
    tracks = [generate_v2(seed, "hard") for seed in range(6)]
    assert min(t.min_radius_m for t in tracks) < 11.0
    assert max(t.max_grade for t in tracks) > 0.11  # a mountain one climbs at ~12 %
    assert all(float(t.width.max()) <= 7.0 for t in tracks)
    for track in tracks:
        # a 180 deg turn (hairpin or switchback): heading changes by ~pi within ~60 m
        window = int(60.0 / track.ds_m)
        turned = np.abs(np.convolve(track.curvature_table, np.ones(window), "valid")) * track.ds_m
        assert turned.max() > 0.9 * math.pi
    easy = [generate_v2(seed, "easy") for seed in range(6)]
    assert np.mean([curved_fraction(t) for t in tracks]) > np.mean(
        [curved_fraction(t) for t in easy])


@pytest.mark.parametrize("name", ["gen2:hard:0", "gen2:hard:3"])
def test_the_expert_drives_a_hard_track_cleanly_at_30_mph(name):
    track = load_track(name)
    expert = ExpertPolicy(track, ExpertConfig(speed_mph=30.0))
    with Simulator(track, SimConfig(cameras=())) as sim:
        obs, _ = sim.reset(seed=0)
        while sim.laps_started < 1 and obs.time_s < 400:
            obs, _ = sim.step(expert.act(obs).controls_applied)
    assert obs.laps == 1 and obs.off_road_events == 0


def test_difficulty_rejects_impossible_settings():
    with pytest.raises(ValueError, match="narrower"):
        Difficulty("x", min_radius_m=6.0, max_radius_m=20.0, width_m=(10.0, 11.0),
                   max_grade=0.05, curve_density=0.5, features=("hairpin",),
                   length_m=(800.0, 900.0))
    with pytest.raises(ValueError, match="unknown feature"):
        Difficulty("x", min_radius_m=10.0, max_radius_m=20.0, width_m=(6.0, 7.0),
                   max_grade=0.05, curve_density=0.5, features=("loop",),
                   length_m=(800.0, 900.0))
