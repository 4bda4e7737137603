"""DAgger: the mixed driver with its safety takeover, and one whole (tiny) iteration with the
plain-cloning comparison, end to end on real rendering and real training."""

from __future__ import annotations

import json
from pathlib import Path

import keras
import numpy as np
import pytest

from clonedrive.cli import main
from clonedrive.data.driving_log import read_driving_log
from clonedrive.data.recorder import RecordConfig, record
from clonedrive.drivers.expert import ExpertConfig, ExpertPolicy
from clonedrive.drivers.policy import NetworkPolicy
from clonedrive.episode.rules import EpisodeRules
from clonedrive.episode.runner import Episode, Runner
from clonedrive.model.train import train
from clonedrive.model.train_config import TrainConfig
from clonedrive.pipelines.dagger.config import DaggerConfig
from clonedrive.pipelines.dagger.figures import format_table
from clonedrive.pipelines.dagger.mixed_driver import MixedDriver
from clonedrive.pipelines.dagger.stages import record_plain
from clonedrive.sim.simulator import SimConfig, Simulator


def steer_right_model():
    """Steers right whatever it sees: off the road within seconds."""
    inputs = keras.Input(shape=(160, 320, 3))
    x = keras.layers.GlobalAveragePooling2D()(inputs)
    dense = keras.layers.Dense(1, name="steering")
    model = keras.Model(inputs, dense(x))
    dense.set_weights([np.zeros((3, 1), np.float32), np.array([0.3], np.float32)])
    return model


def drive_mixed(beta: float, seconds: float = 12.0):
    with Simulator("lake", SimConfig(cameras=("center",), scenery=False)) as sim:
        episode = Episode(sim, EpisodeRules(laps=1, set_speed_mph=15.0, max_seconds=seconds))
        driver = MixedDriver(NetworkPolicy(steer_right_model()),
                             [ExpertPolicy(sim.track, ExpertConfig(speed_mph=15.0))], [15.0],
                             beta=beta, rng=np.random.default_rng(0))
        who = []
        Runner([episode], driver).run(lambda step: who.append(step.decision.detail))
        return driver, episode, who


def test_the_safety_takeover_keeps_a_bad_network_on_the_road_and_is_counted() -> None:
    driver, episode, who = drive_mixed(beta=0.0)
    assert episode.trace.summary()["interventions"] == 0  # never left the road
    assert driver.takeovers[0] >= 2  # it tried to, again and again: each one counted
    assert set(who) == {"network", "takeover"}
    assert driver.steps_by[0]["takeover"] == who.count("takeover")


def test_beta_one_is_the_expert_driving() -> None:
    driver, episode, who = drive_mixed(beta=1.0, seconds=4.0)
    assert set(who) == {"expert"} and driver.takeovers == [0]


def test_config_is_validated() -> None:
    with pytest.raises(ValueError, match="beta"):
        DaggerConfig(beta=1.5)
    with pytest.raises(ValueError, match="iterations"):
        DaggerConfig(iterations=0)
    assert DaggerConfig(beta=0.5, beta_decay=0.5).beta_at(3) == pytest.approx(0.125)


@pytest.mark.slow
def test_two_dagger_iterations_end_to_end_with_plain_cloning_at_each(tmp_path: Path,
                                                                      capsys) -> None:
    data = tmp_path / "expert"
    record(RecordConfig(track="lake", seconds=3.0, speed_mph=15.0, scenery=False,
                        start_time="2026-11-21T10:11:12.345"), data, progress=False)
    base = tmp_path / "base"
    train(TrainConfig(model="fast", batch_size=32, epochs=1, learning_rate=1e-3,
                      speed_head=True, export_h5=False), [data], base, progress=False)
    out = tmp_path / "dagger"
    arguments = ["dagger", str(base), "--out", str(out), "--iterations", "2", "--plain-each",
                 "--track", "lake", "--eval-track", "lake", "--unseen", "0", "--epochs", "1",
                 "--speed", "15", "--max-seconds", "3", "--no-scenery"]
    code = main([*arguments, "--plain-noise", "0"])
    assert code == 0
    report = json.loads((out / "dagger.json").read_text())
    base_row, first, second = report["iterations"]
    assert base_row["iteration"] == 0 and first["iteration"] == 1 and first["beta"] == 0.5
    # The expert labelled every visited frame: a Udacity log plus its target speeds.
    log = read_driving_log(out / "iter_01" / "data" / "lake")
    assert len(log.rows) == first["labels"] == 45  # 3 s at 15 Hz
    assert all(row.target_speed_mph is not None for row in log.rows)
    assert first["collect"]["takeovers_per_km"] is not None
    assert (out / "iter_01" / "train" / "model.keras").is_file()
    assert first["eval"]["builtin"]["runs"] == 1
    assert second["beta"] == 0.25 and second["labels_total"] == 90
    # Plain cloning got as many extra expert labels, and as many epochs, at each iteration.
    (early,) = report["plain_each"]
    plain = report["plain"]
    assert (early["iteration"], early["labels_total"], early["epochs"]) == (1, 45, 1)
    assert (plain["iteration"], plain["labels_total"], plain["epochs"]) == (2, 90, 2)
    # --plain-noise 0: the expert recorded them without steering noise (textbook cloning).
    assert report["config"]["plain_noise"] == 0.0 and early["noise"] == plain["noise"] == 0.0
    assert json.loads((out / "plain" / "data" / "record.json").read_text())["noise"] == 0.0
    assert early["eval"]["builtin"]["runs"] == plain["eval"]["builtin"]["runs"] == 1
    assert (out / "plain_01" / "train" / "model.keras").is_file()
    assert (out / "plain" / "train" / "model.keras").is_file()
    assert (out / "dagger.png").is_file()
    printed = capsys.readouterr().out
    assert "plain cloning with 45 extra expert labels (1 epochs)" in printed
    # The table lists both plain rows at their iterations.
    table = [line.split()[:2] for line in format_table(report).splitlines()[2:]]
    assert table == [["0", "base"], ["1", "dagger"], ["2", "dagger"], ["1", "plain"],
                     ["2", "plain"]]
    # Re-run on the same folder with another noise: the saved plain data is not reused silently.
    assert main([*arguments, "--plain-noise", "0.15"]) == 1  # a folder refused: exit 1
    assert "recorded with steering noise 0.0, not the 0.15" in capsys.readouterr().err
    # ... nor data recorded for another label count (a run re-used with more iterations).
    saved = out / "plain" / "data" / "record.json"
    saved.write_text(json.dumps({**json.loads(saved.read_text()), "asked": 60}))
    assert main([*arguments, "--plain-noise", "0"]) == 1
    assert "recorded for 60 labels, not the 90 DAgger collected by iteration 2" \
        in capsys.readouterr().err
    # A stage record that cannot be read is an error naming it, not a stage to run again.
    collected = out / "iter_01" / "data" / "collect.json"
    collected.write_text("{ cut short", encoding="utf-8")
    assert main([*arguments, "--plain-noise", "0"]) == 1
    assert str(collected) in capsys.readouterr().err
    assert collected.read_text(encoding="utf-8") == "{ cut short"


def test_plain_cloning_records_as_many_labels_as_asked_past_one_lap(tmp_path: Path) -> None:
    # 1,400 rows on the 1,090 m lake at 30 mph is more than a lap: an estimate of laps from a
    # slow average speed (8 m/s) once stopped at the lap's end, short of the rows asked for.
    config = DaggerConfig(tracks=("lake",), speed_mph=30.0, plain_noise=0.0, scenery=False)
    result = record_plain(config, 1400, tmp_path / "data")
    assert result == {"labels": 1400, "asked": 1400, "noise": 0.0}
    assert len(read_driving_log(tmp_path / "data" / "lake").rows) == 1400


def test_a_takeover_recording_from_the_web_page_is_aggregated(tmp_path: Path) -> None:
    """HG-DAgger: a model drives (here the expert stands in for it), a person takes over; the
    recording keeps only the person's rows, counts the takeover, and ``dagger`` aggregates it."""
    from clonedrive.data.recipe import Recipe, expand
    from clonedrive.manual.config import ManualConfig
    from clonedrive.manual.session import DrivingSession
    from clonedrive.pipelines.dagger.stages import aggregate_recipe, check_human_recordings
    from clonedrive.web.pilots import ExpertPilot

    out = tmp_path / "takeovers"
    with DrivingSession(ManualConfig(scenery=False), out,
                        sim_config=SimConfig(scenery=False)) as session:
        session.choose("lake")
        session.step()
        assert session.start_autonomous(ExpertPilot(session.sim.track), takeover=True,
                                        takeover_labels=True)
        assert session.start_recording()
        for _ in range(4):
            session.step()  # the pilot drives: not recorded
        session.key_down("d")
        for _ in range(5):
            session.step()  # the person drives: the labels
        session.key_up("d")
        for _ in range(4):
            session.step()
        assert session.stop_recording() == 5
        assert session.takeovers == 1
    rows = read_driving_log(out / "driving_log.csv", verify_images="exists").rows
    assert len(rows) == 5 and all(row.steering > 0 for row in rows)
    entry = json.loads((out / "config.json").read_text())["sessions"][-1]
    assert entry["rows"] == 5 and entry["takeovers"] == 1

    check_human_recordings([out])
    with pytest.raises(FileNotFoundError, match="no driving_log.csv"):
        check_human_recordings([tmp_path])
    recipe = aggregate_recipe(Recipe((), source="base"), [], [out])
    assert [spec.name for spec in recipe.recordings] == ["human_1_takeovers"]
    samples = expand(recipe)
    assert len(samples.steering) == 10  # the center camera and its mirror image
    assert DaggerConfig(human=[out]).human == (str(out),)


def test_collection_records_whole_frames_whatever_the_network_crops(tmp_path: Path) -> None:
    """Collected frames are training data: they are rendered whole even for a policy that
    looks at a strip (a recipe may crop differently, and augmentation shifts rows)."""
    from clonedrive.network.tiny_model import build_road_follower
    from clonedrive.pipelines.dagger.stages import collect

    policy = NetworkPolicy(build_road_follower(), set_speed_mph=15.0)
    assert policy.visible_rows is not None  # it looks at a strip only
    config = DaggerConfig(tracks=("lake",), speed_mph=15.0, max_seconds=1.0, scenery=False)
    collect(policy, config, beta=0.0, out=tmp_path, seed=0)
    rows = read_driving_log(tmp_path / "lake").rows
    assert rows
    from clonedrive.base.images import read_rgb

    for camera in ("center", "left", "right"):
        frame = read_rgb(getattr(rows[-1], camera))
        assert frame[:40].std() > 5 and frame[150:].std() > 1  # sky and bonnet drawn
