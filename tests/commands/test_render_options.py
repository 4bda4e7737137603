"""``--renderer`` and ``--full-frame`` on the commands that render."""

from __future__ import annotations

import pytest

from clonedrive.cli import main
from clonedrive.sim import engine


@pytest.mark.parametrize("verb", ["evaluate", "bench", "dagger", "record", "autonomous"])
def test_every_command_that_renders_takes_a_renderer(verb, capsys):
    with pytest.raises(SystemExit):
        main([verb, "--help"])
    text = capsys.readouterr().out
    assert "--renderer {auto,software,egl}" in text
    assert ("--full-frame" in text) == (verb in ("evaluate", "bench", "dagger"))


def test_egl_that_does_not_open_is_one_line_naming_the_verb(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(engine, "probe_egl", lambda: None)
    code = main(["evaluate", str(tmp_path / "model.keras"), "--renderer", "egl",
                 "--out", str(tmp_path / "eval")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("clonedrive evaluate: --renderer egl:")
    assert len(err.strip().splitlines()) == 1


def test_an_unknown_renderer_is_refused_by_the_parser(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", str(tmp_path / "model.keras"), "--renderer", "vulkan"])
    assert "invalid choice: 'vulkan'" in capsys.readouterr().err
