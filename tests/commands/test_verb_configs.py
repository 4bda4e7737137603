"""Configs of the tracks, check, video, report and demo verbs: frozen, validated when built,
and the source of their command-line defaults; a bad value is one line and exit status 2."""

from __future__ import annotations

import dataclasses
import math

import pytest

from clonedrive.cli import build_parser, main
from clonedrive.commands.check import CheckConfig
from clonedrive.evaluate.video import VideoConfig
from clonedrive.pipelines.demo import DEMO_MODELS, DemoConfig
from clonedrive.report.writeup import ReportConfig


def test_defaults_come_from_the_configs():
    parser = build_parser()
    video = parser.parse_args(["video", "frames"])
    assert (video.fps, video.out) == (VideoConfig().fps, VideoConfig().out)
    assert parser.parse_args(["report", "run"]).max_failures == ReportConfig().max_failures
    assert parser.parse_args(["check", "data"]).decode == CheckConfig().decode
    demo = parser.parse_args(["demo"])
    assert DemoConfig(quick=demo.quick, epochs=demo.epochs, unseen=demo.unseen,
                      model=demo.model, video=demo.video, seed=demo.seed) == DemoConfig()


def test_configs_are_frozen():
    for config in (VideoConfig(), ReportConfig(), CheckConfig(), DemoConfig()):
        field = dataclasses.fields(config)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(config, field, None)


@pytest.mark.parametrize(("build", "message"), [
    (lambda: VideoConfig(fps=0), "fps"), (lambda: VideoConfig(fps=math.nan), "fps"),
    (lambda: ReportConfig(max_failures=-1), "max_failures"),
    (lambda: ReportConfig(stills_per_video=0), "stills_per_video"),
    (lambda: CheckConfig(decode="yes"), "decode"),
    (lambda: DemoConfig(epochs=0), "epochs"), (lambda: DemoConfig(unseen=-1), "unseen"),
    (lambda: DemoConfig(model="resnet"), "model"),
])
def test_bad_values_are_refused_naming_the_field(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_the_demo_trains_the_architectures_the_models_module_builds():
    from clonedrive.model.architectures import MODEL_NAMES

    assert sorted(DEMO_MODELS) == sorted(MODEL_NAMES)


@pytest.mark.parametrize("argv", [["demo", "--epochs", "0"], ["demo", "--unseen", "-2"],
                                  ["video", "FOLDER", "--fps", "-1"],
                                  ["report", "RUN", "--max-failures", "-1"],
                                  ["train", "FOLDER", "--out", "RUN/t", "--lr", "inf"],
                                  ["train", "FOLDER", "--out", "RUN/t", "--lr", "1e30"],
                                  ["train", "FOLDER", "--out", "RUN/t", "--lr", "nan"],
                                  ["train", "FOLDER", "--out", "RUN/t", "--dropout", "nan"]])
def test_a_bad_option_is_one_line_and_status_2(argv, tmp_path, capsys):
    argv = [str(tmp_path) if arg in ("FOLDER", "RUN") else arg.replace("RUN/", f"{tmp_path}/")
            for arg in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"clonedrive {argv[0]}: ") and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []  # nothing written
