"""Every verb's ``--help`` teaches: it ends with example command lines of that verb, and the
top-level help lists the verbs in the order a user runs them and names the docs."""

from __future__ import annotations

import pytest

from clonedrive.cli import VERBS, main


@pytest.mark.parametrize("verb", [verb for verb, _ in VERBS])
def test_every_verb_help_ends_with_its_examples(verb: str, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as stop:
        main([verb, "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    tail = out[out.rindex("examples:"):].splitlines()[1:]
    assert tail and all(line.strip().startswith("clonedrive ") for line in tail)
    assert any(line.strip().startswith(f"clonedrive {verb}") for line in tail)


def test_top_level_help_gives_the_order_and_the_docs(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    listed = [line.split()[0] for line in out.splitlines()
              if line[:4] == "    " and line[4:5].isalpha() and line.split()[0] in dict(VERBS)]
    assert listed == [verb for verb, _ in VERBS]
    assert "record ... -> check -> train -> evaluate -> report" in out
    assert "docs/" in out


def test_track_help_names_every_generated_form(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["record", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "gen2:<easy|medium|hard>:<seed>" in out and "gen1:<seed>" in out
