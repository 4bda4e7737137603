"""The evaluate, record, autonomous and sim verbs take their defaults from their config
dataclasses, and bad values are refused with one clear line before anything runs."""

from __future__ import annotations

import pytest

from clonedrive.cli import build_parser, main
from clonedrive.data.recorder import RecordConfig
from clonedrive.evaluate.config import EvalConfig
from clonedrive.manual.config import DEFAULT_OUT_DIR, ManualConfig
from clonedrive.udacity.client import AutonomousConfig


def parse(*argv: str):
    return build_parser().parse_args(list(argv))


def test_option_defaults_are_the_configs_defaults():
    evaluate = parse("evaluate", "model.keras")
    d = EvalConfig()
    assert (evaluate.laps, evaluate.unseen, evaluate.unseen_speed, evaluate.unseen_laps,
            evaluate.batch, evaluate.max_seconds) == (d.laps, d.unseen, d.unseen_speed_mph,
                                                      d.unseen_laps, d.batch, d.max_seconds)
    assert evaluate.no_scenery is (not d.scenery)

    record = parse("record", "--out", "x")
    r = RecordConfig()
    assert (record.track, record.style, record.laps, record.seconds, record.speed, record.noise,
            record.seed, record.offset_fraction, record.max_off_road, record.jpeg_quality,
            record.start_time) == (r.track, r.style, r.laps, r.seconds, r.speed_mph, r.noise,
                                   r.seed, r.offset_fraction, r.max_off_road_events,
                                   r.jpeg_quality, r.start_time)

    autonomous = parse("autonomous")
    a = AutonomousConfig()
    assert (autonomous.track, autonomous.laps, autonomous.speed, autonomous.host,
            autonomous.port, autonomous.connect_timeout, autonomous.max_seconds,
            autonomous.seed) == (a.track, a.laps, a.speed_mph, a.client.host, a.client.port,
                                 a.client.connect_timeout_s, a.max_seconds, a.seed)

    sim = parse("sim")
    m = ManualConfig()
    assert (sim.out, sim.server, sim.seed, sim.generated_seed, sim.jpeg_quality) == (
        DEFAULT_OUT_DIR, f"{m.server_host}:{m.server_port}", m.seed, m.generated_seed,
        m.jpeg_quality)


@pytest.mark.parametrize("speed", ["nan", "-5", "inf", "0"])
def test_a_bad_set_speed_is_refused_by_every_driving_verb(speed, tmp_path, capsys):
    assert main(["record", "--out", str(tmp_path / "rec"), "--speed", speed]) == 2
    assert "record: --speed must be a speed in (0, 30] mph" in capsys.readouterr().err
    assert not (tmp_path / "rec").exists()

    out = tmp_path / "eval"
    assert main(["evaluate", str(tmp_path / "none.keras"), "--speed", speed, "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err
    assert "evaluate: --speed must be a speed in (0, 30] mph" in err and err.count("\n") == 1
    assert not out.exists()

    assert main(["autonomous", "--speed", speed, "--json"]) == 2
    assert "autonomous: --speed must be a speed in (0, 30] mph" in capsys.readouterr().err

    if speed != "0":  # drive.py parks the car at 0
        assert main(["drive", str(tmp_path / "none.keras"), "--speed", speed]) == 2
        assert "--speed must be a speed in (0, 30] mph" in capsys.readouterr().err


def test_bad_evaluate_options_are_named(tmp_path, capsys):
    model = str(tmp_path / "none.keras")
    for argv, words in ((["--laps", "0"], "laps must be at least 1"),
                        (["--batch", "0"], "batch must be at least 1"),
                        (["--unseen-speed", "nan"], "--unseen-speed must be"),
                        (["--max-seconds", "-1"], "max_seconds"),
                        (["--unseen", "-2"], "unseen must be >= 0")):
        assert main(["evaluate", model, *argv]) == 2, argv
        assert words in capsys.readouterr().err, argv


def test_configs_validate_themselves():
    with pytest.raises(ValueError, match="nothing to evaluate"):
        EvalConfig(tracks=(), unseen=0)
    with pytest.raises(ValueError, match="tracks must be a tuple"):
        EvalConfig(tracks="lake")
    with pytest.raises(ValueError, match="seconds must be a positive number"):
        RecordConfig(seconds=float("inf"))
    with pytest.raises(ValueError, match="offset_fraction"):
        RecordConfig(offset_fraction=2.0)
    with pytest.raises(ValueError, match="connect_timeout_s"):
        AutonomousConfig().client.__class__(connect_timeout_s=float("inf"))
    with pytest.raises(ValueError, match="reply_timeout_s"):
        ManualConfig(reply_timeout_s=float("nan"))
