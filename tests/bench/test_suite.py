"""Suite files: v2 is valid and fixed, v1 is retired with its reason, its families match the
library's, bad files are named."""

import pytest

from clonedrive.bench import DEFAULT_SUITE
from clonedrive.bench.suite import SuiteError, load_suite
from clonedrive.sim.conditions import FAMILIES


def test_v2_is_a_fixed_list_of_episodes_with_the_named_splits():
    assert DEFAULT_SUITE == "v4"  # v3 and v2 stay built in, for comparison with earlier figures
    suite = load_suite("v2")
    assert suite.id == "v2"
    assert suite.split_names() == ["train-tracks", "new-tracks-easy", "new-tracks-medium",
                                   "new-tracks-hard", "new-conditions",
                                   "new-tracks+new-conditions"]
    first, again = suite.episodes(), load_suite("v2").episodes()
    assert first == again
    assert len({spec.key for spec in first}) == len(first)
    held = {spec.family for spec in first if spec.split.startswith("new-tracks+")}
    assert held and all(suite.families[name].held_out for name in held)
    assert {spec.speed_mph for spec in first if spec.split == "new-tracks-hard"} == {20.0, 30.0}
    # A split name the suite lacks is refused by name, even beside one it has.
    with pytest.raises(SuiteError, match="no split named new-trakcs-easy; it has train-tracks"):
        suite.episodes(("train-tracks", "new-trakcs-easy"))
    # the suite's condition families are the library's (one definition, checked)
    for name, family in suite.families.items():
        assert family == FAMILIES[name], name


def test_the_retired_v1_is_refused_with_its_reason_and_a_file_named_v1_still_loads(
        tmp_path, monkeypatch):
    with pytest.raises(SuiteError, match="suite v1: retired: .*under the lake's water.*v2"):
        load_suite("v1")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "v1").write_text(BASE, encoding="utf-8")
    assert load_suite("v1").id == "mine"


def write(tmp_path, text):
    path = tmp_path / "suite.toml"
    path.write_text(text, encoding="utf-8")
    return str(path)


BASE = """
id = "mine"
[[split]]
name = "a"
tracks = ["lake"]
speeds_mph = [20.0]
conditions = ["clear"]
[conditions.clear]
"""


def test_a_copied_suite_can_be_edited(tmp_path):
    suite = load_suite(write(tmp_path, BASE))
    assert [spec.track for spec in suite.episodes()] == ["lake"]


@pytest.mark.parametrize(("change", "message"), [
    (BASE.replace('id = "mine"', ""), "id must be"),
    (BASE + "colour = 1\n", "unknown field 'colour'"),
    (BASE.replace('"lake"', '"gen2:brutal:1"'), "unknown difficulty"),
    (BASE.replace("[20.0]", "[45.0]"), "speeds_mph"),
    (BASE.replace('["clear"]', '["dusk"]'), "'dusk' is not defined"),
    (BASE.replace("name = \"a\"", "name = \"a\"\nlaps = 2"), "unknown key"),
    ("id = [", "not valid TOML"),
    (BASE.replace('conditions = ["clear"]', 'conditions = ["clear"]\ndirections = ["back"]'),
     "directions must be"),
    (BASE.replace('conditions = ["clear"]', 'conditions = ["clear"]\nstarts = [1.0]'),
     r"starts must be .* \[0, 1\)"),
    (BASE.replace('conditions = ["clear"]', 'conditions = ["clear"]\nstarts = [0.5, 0.5]'),
     "distinct"),
])
def test_bad_suites_say_where(tmp_path, change, message):
    with pytest.raises(SuiteError, match=message):
        load_suite(write(tmp_path, change))


def test_suite_text_is_literal_in_the_leaderboard_markdown() -> None:
    """Suite and model names are the user's text: Markdown in them is shown, not obeyed."""
    from clonedrive.bench.leaderboard import _markdown_table, _md

    assert _md("a|b *c* <img>\nnext") == "a\\|b \\*c\\* \\<img\\> next"
    row = _markdown_table(["model"], [["x | y"]])[-1]
    assert row == "| x \\| y |"


def test_directions_and_starts_multiply_a_split_and_name_their_references(tmp_path):
    text = BASE.replace('conditions = ["clear"]', 'conditions = ["clear"]\n'
                        'directions = ["forward", "reverse"]\nstarts = [0.0, 0.25, 0.5]\n'
                        "seed = 40")
    episodes = load_suite(write(tmp_path, text)).episodes()
    assert [(e.reverse, e.start_fraction) for e in episodes] == [
        (False, 0.0), (False, 0.25), (False, 0.5), (True, 0.0), (True, 0.25), (True, 0.5)]
    assert [e.seed for e in episodes] == list(range(40, 46))
    assert [e.reference_key for e in episodes[2:4]] == ["lake@20/start=0.5", "lake@20/reverse"]
    assert episodes[0].reference_key == "lake@20"  # v2's names where nothing is new
    assert episodes[4].reset_options(1000.0) == {"reverse": True, "s_m": 250.0}


def test_a_split_without_directions_or_starts_drives_as_before():
    suite = load_suite("v2")
    assert all(not e.reverse and e.start_fraction == 0.0 for e in suite.episodes())
    assert sum(split.size for split in suite.splits) == len(suite.episodes()) == 44


def test_the_expert_drives_a_whole_lap_from_any_start_in_either_direction(tmp_path):
    """A lap is a whole track's length from wherever the car starts; the expert's reference
    laps (physics only) are clean in both directions and from a later start."""
    from clonedrive.bench.driving import BatchTask, drive_batch

    text = BASE.replace('conditions = ["clear"]', 'conditions = ["clear"]\n'
                        'directions = ["forward", "reverse"]\nstarts = [0.0, 0.5]')
    specs = load_suite(write(tmp_path, text)).episodes()
    results = drive_batch(BatchTask(kind="expert", episodes=tuple(specs)))
    assert [(r["reverse"], r["start_fraction"]) for r in results] == [
        (False, 0.0), (False, 0.5), (True, 0.0), (True, 0.5)]
    assert all(r["clean"] and r["lap_time_s"] for r in results)
    lake_m = results[0]["route_m"]
    assert all(r["distance_m"] >= lake_m for r in results)
    assert len({spec.reference_key for spec in specs}) == 4  # four references, not one


def test_v3_has_at_least_24_episodes_a_split_a_harder_tier_and_a_dev_tier():
    suite = load_suite("v3")
    sizes = {split.name: split.size for split in suite.splits}
    assert sizes.pop("dev") == 12
    assert sizes and all(size >= 24 for size in sizes.values())
    assert {"hard-30", "hard-late"} <= set(sizes)
    episodes = suite.episodes()
    assert {e.reverse for e in episodes} == {False, True}
    assert len({e.start_fraction for e in episodes}) >= 3
    late = [e for e in episodes if e.split == "hard-late"]
    assert all(e.speed_mph == 30.0 and e.conditions.latency_steps >= 1 for e in late)
    for name, family in suite.families.items():  # one definition of every family
        assert family == FAMILIES[name], name
    # v2 stays built in, unchanged, for comparison
    assert len(load_suite("v2").episodes()) == 44


def test_v4_is_v3_episode_for_episode_but_for_a_dev_tier_on_hard_tracks_of_its_own():
    v3, v4 = load_suite("v3"), load_suite("v4")
    assert v4.split_names() == v3.split_names()
    for name in v3.split_names():
        if name != "dev":
            assert v4.episodes((name,)) == v3.episodes((name,)), name
    dev = v4.episodes(("dev",))
    assert len(dev) == 12
    assert all(e.track.startswith("gen2:hard:") and e.speed_mph == 30.0 for e in dev)
    assert {e.reverse for e in dev} == {False, True}
    assert {e.family for e in dev} == {"clear", "dusk-late"}
    elsewhere = {t for s in v4.splits if s.name != "dev" for t in s.tracks}
    assert not {e.track for e in dev} & (elsewhere | {"gen2:hard:3000", "gen2:hard:3001"})
    for name, family in v4.families.items():
        assert family == FAMILIES[name], name
