"""``clonedrive bench merge``: bench runs of one suite made a split at a time become one run
whose figures equal those of all the episodes scored together, with the dev tier's agreement
with the rest; runs that cannot be merged are refused, naming the run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clonedrive.bench.merge import COMPACT_RUN_FIELDS, MergeError, merge_reports
from clonedrive.bench.run import summarize
from clonedrive.bench.scores import dev_agreement
from clonedrive.cli import main

SPLITS = ("easy", "hard", "dev")


def _run(split: str, index: int, score: float) -> dict:
    clean = score > 0.99
    return {"key": f"{split}/{index:03d}", "split": split, "index": index, "track": "lake",
            "distance_m": 400.0 + 10 * index, "interventions": 0 if clean else 1,
            "clean": clean, "conditions": {"light": 0.5}, "steering_trace": [0.0] * 50,
            "scores": {"clean": clean, "interventions_per_km": 0.0 if clean else 2.5,
                       "autonomy_pct": 100.0 if clean else 95.0, "mean_abs_cte_m": 0.3,
                       "lap_time_ratio": 1.02 if clean else None, "smoothness_ratio": 1.5,
                       "driving_score": score}}


def _model_runs(quality: float, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    runs = []
    for split in SPLITS:
        for index in range(8):
            score = 1.0 if rng.random() < quality else round(float(rng.uniform(0.2, 0.9)), 4)
            runs.append(_run(split, index, score))
    return runs


def _report(models: dict[str, list[dict]], splits: tuple[str, ...], *, suite: str = "s",
            renderer: str = "software") -> dict:
    chosen = {path: {"label": Path(path).stem, "path": path,
                     "runs": [r for r in runs if r["split"] in splits]}
              for path, runs in models.items()}
    splits_table = [{"name": s, "description": f"the {s} split", "tracks": ["lake"],
                     "speeds_mph": [20.0], "conditions": ["clear"]} for s in SPLITS]
    return {"suite": {"id": suite, "description": "a suite for the test", "laps": 1,
                      "splits": splits_table},
            "rendering": {"renderer_used": renderer}, "complete": True,
            "reference": {f"lake@{len(splits)}": {"lap_time_s": 60.0}},
            "driving": {Path(p).stem: {} for p in models}, "models": chosen}


@pytest.fixture
def models() -> dict[str, list[dict]]:
    return {f"/m/q{int(q * 100)}.keras": _model_runs(q, seed)
            for seed, q in enumerate((0.2, 0.5, 0.8, 0.95))}


def test_split_by_split_runs_merge_to_the_figures_of_all_episodes(models) -> None:
    parts = [(split, _report(models, (split,))) for split in reversed(SPLITS)]
    merged = merge_reports(parts)
    whole = {path: {"label": Path(path).stem, "path": path, "runs": runs}
             for path, runs in models.items()}
    methods = summarize(whole, list(SPLITS))
    assert merged["split_names"] == list(SPLITS)  # the suite's order, not the inputs'
    for path, model in whole.items():
        got = merged["models"][path]
        assert len(got["runs"]) == 24
        assert got["splits"] == model["splits"] and got["overall"] == model["overall"]
    assert merged["methods"] == methods and merged["complete"]
    assert merged["settings"]["merged_from"] == ["dev", "hard", "easy"]
    assert len(merged["reference"]) == 1  # the three runs' references, one name
    # The dev tier ranks the four models as the other splits do here.
    agreement = merged["dev_agreement"]
    assert agreement == dev_agreement(whole) and agreement["models"] == 4
    dev = [np.mean([r["scores"]["driving_score"] for r in runs if r["split"] == "dev"])
           for runs in models.values()]
    rest = [np.mean([r["scores"]["driving_score"] for r in runs if r["split"] != "dev"])
            for runs in models.values()]
    assert agreement["driving_score"]["pearson"] == pytest.approx(
        np.corrcoef(dev, rest)[0, 1], abs=1e-4)


def test_compact_keeps_each_runs_figures_and_drops_its_traces(models) -> None:
    parts = [(split, _report(models, (split,))) for split in SPLITS]
    merged = merge_reports(parts, compact=True)
    full = merge_reports(parts)
    run = merged["models"]["/m/q20.keras"]["runs"][0]
    assert "steering_trace" not in run and "conditions" not in run
    assert set(run) <= set(COMPACT_RUN_FIELDS) and run["scores"]["driving_score"] > 0
    assert merged["methods"] == full["methods"] and merged["reference"] == {}


def test_runs_that_cannot_be_merged_are_refused_naming_the_run(models) -> None:
    easy = ("easy.json", _report(models, ("easy",)))
    with pytest.raises(MergeError, match=r"other\.json is of suite t"):
        merge_reports([easy, ("other.json", _report(models, ("hard",), suite="t"))])
    with pytest.raises(MergeError, match=r"gl\.json was drawn by the egl renderer"):
        merge_reports([easy, ("gl.json", _report(models, ("hard",), renderer="egl"))])
    with pytest.raises(MergeError, match=r"again\.json: model /m/q20\.keras drove episode "
                                         r"easy/000 in another run too"):
        merge_reports([easy, ("again.json", _report(models, ("easy",)))])
    relabelled = _report(models, ("hard",))
    relabelled["models"]["/m/q20.keras"]["label"] = "other"
    with pytest.raises(MergeError, match=r"labelled 'other' there and 'q20'"):
        merge_reports([easy, ("r.json", relabelled)])
    steadier = _report(models, ("hard",))
    steadier["driving"]["q20"] = {"steering_hold": 0.05}
    with pytest.raises(MergeError, match=r"h\.json: method 'q20' drives with other settings"):
        merge_reports([easy, ("h.json", steadier)])
    # A run made before a setting existed drove with its default: it merges with a run that
    # names the default, not with one that names another value.
    named = _report(models, ("hard",))
    named["driving"]["q20"] = {"speed_scale": 1.0}
    assert merge_reports([easy, ("n.json", named)])["driving"]["q20"]["speed_scale"] == 1.0
    named["driving"]["q20"] = {"speed_scale": 1.05}
    with pytest.raises(MergeError, match=r"n\.json: method 'q20' drives with other settings"):
        merge_reports([easy, ("n.json", named)])
    with pytest.raises(MergeError, match="nothing to merge"):
        merge_reports([])


def test_a_merge_says_how_its_inputs_predicted(models) -> None:
    """Runs made before bench.json recorded ``prediction`` batched the lock-step cars' frames;
    merged with runs that predicted each frame alone, the merged run names both ways."""
    from clonedrive.drivers.policy import PREDICTION, PREDICTION_BEFORE

    new = [(split, {**_report(models, (split,)), "prediction": PREDICTION})
           for split in ("easy", "hard")]
    assert merge_reports(new)["prediction"] == PREDICTION
    merged = merge_reports([*new, ("dev", _report(models, ("dev",)))])
    assert merged["prediction"] == f"mixed: {PREDICTION}; {PREDICTION_BEFORE}"
    # The leaderboard says so; a board whose runs were all driven alike does not.
    from clonedrive.bench.leaderboard import markdown

    page = markdown(merged, [])
    assert "Not every run was driven alike" in page and "lock-step" in page
    assert "driven alike" not in markdown(merge_reports(new), [])


def test_the_merge_command_relabels_writes_a_leaderboard_and_compare_reads_it(
        tmp_path: Path, models, capsys: pytest.CaptureFixture) -> None:
    for split in SPLITS:
        folder = tmp_path / split
        folder.mkdir()
        (folder / "bench.json").write_text(json.dumps(_report(models, (split,))),
                                           encoding="utf-8")
    weak = {p: r for p, r in models.items() if p.endswith(("q20.keras", "q50.keras"))}
    strong = {p: r for p, r in models.items() if p not in weak}
    for name, chosen in (("weak", weak), ("strong", strong)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "bench.json").write_text(json.dumps(_report(chosen, SPLITS)),
                                                   encoding="utf-8")
    out = tmp_path / "merged"
    assert main(["bench", "merge", *(str(tmp_path / s) for s in SPLITS), "--out",
                 str(out)]) == 0
    assert "merged 3 bench run(s)" in capsys.readouterr().out
    assert set(json.loads((out / "bench.json").read_text())["methods"]) == {
        "q20", "q50", "q80", "q95"}
    page = (out / "leaderboard.md").read_text(encoding="utf-8")
    assert "## The dev tier against the rest" in page and "Over 4 models" in page
    assert "Merged from 3 bench runs" in page and (out / "bench_success.png").is_file()
    # LABEL=RUN makes every model of a run one method (training seeds of one recipe).
    assert main(["bench", "merge", f"weak={tmp_path / 'weak'}",
                 f"strong={tmp_path / 'strong'}", "--out", str(out), "--compact"]) == 0
    report = json.loads((out / "bench.json").read_text())
    assert {m: len(v["models"]) for m, v in report["methods"].items()} == {"weak": 2,
                                                                            "strong": 2}
    capsys.readouterr()
    assert main(["bench", "compare", f"{out}:strong", f"{out}:weak", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)["comparisons"][0]
    assert result["episodes"] == 24 and result["difference"] > 0
    # Refusals: models driven alike only can be one method; an unfinished run, a folder
    # without bench.json, nothing to merge.
    mixed = _report(models, ("easy",))
    mixed["driving"]["q50"] = {"mirror_average": True}
    (tmp_path / "mixed").mkdir()
    (tmp_path / "mixed" / "bench.json").write_text(json.dumps(mixed), encoding="utf-8")
    assert main(["bench", "merge", f"one={tmp_path / 'mixed'}", "--out", str(out)]) == 2
    assert "cannot be one method 'one'" in capsys.readouterr().err
    unfinished = _report(models, ("easy",))
    unfinished["complete"] = False
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "bench.json").write_text(json.dumps(unfinished), encoding="utf-8")
    assert main(["bench", "merge", str(tmp_path / "half"), "--out", str(out)]) == 2
    assert "an unfinished bench run" in capsys.readouterr().err
    assert main(["bench", "merge", str(tmp_path / "nothing"), "--out", str(out)]) == 2
    assert "no bench.json there" in capsys.readouterr().err
    assert main(["bench", "merge", "--out", str(out)]) == 2


def test_the_repositorys_leaderboard_page_is_made_from_its_data() -> None:
    from clonedrive.bench.leaderboard import markdown
    from clonedrive.bench.merge import load_bench_run

    board = Path(__file__).resolve().parents[2] / "docs" / "leaderboard"
    report = load_bench_run(str(board))
    again = merge_reports([(str(board), report)], compact=True)
    assert again["settings"] == report["settings"]  # a merged run names what it came from
    assert again["methods"] == report["methods"] and again["models"] == report["models"]
    page = markdown(again, ["bench_success.png", "bench_lap_time.png"])
    assert page == (board / "leaderboard.md").read_text(encoding="utf-8")


def _newer(suite: dict, **dev_changes) -> dict:
    """``suite`` as a newer version: id s2, its dev split redefined by ``dev_changes``."""
    splits = [dict(s, **dev_changes) if s["name"] == "dev" else dict(s)
              for s in suite["splits"]]
    splits[0]["description"] = "reworded, the same episodes"
    return {**suite, "id": "s2", "splits": splits}


def test_runs_of_an_earlier_suite_carry_into_a_newer_one_split_by_split(models) -> None:
    old = _report(models, SPLITS)
    old["suite"]["conditions"] = {"clear": {"description": "as recorded", "light": 1.0}}
    newer = _newer(old["suite"], tracks=["mountain"])
    dev = _report(models, ("dev",), suite="s2")
    dev["suite"] = newer
    merged = merge_reports([("old.json", old), ("dev.json", dev)], suite=newer)
    assert merged["suite"]["id"] == "s2"
    assert merged["settings"]["left_out"] == {"old.json": ["dev"]}
    for path, runs in models.items():  # easy and hard from the old run, dev from the new one
        assert merged["models"][path]["runs"] == runs
    # A model that drove only what is left out is left out with it.
    only_dev = _report({"/m/dev-only.keras": models["/m/q20.keras"]}, ("dev",))
    only_dev["suite"] = old["suite"]
    merged = merge_reports([("old.json", old), ("only.json", only_dev)], suite=newer)
    assert "/m/dev-only.keras" not in merged["models"] and len(merged["models"]) == 4
    assert merged["settings"]["left_out"]["only.json"] == ["dev"]
    # A split whose conditions draw other values has other episodes: left out too.
    changed = {**newer, "conditions": {"clear": {"description": "as recorded", "light": 0.5}}}
    with pytest.raises(MergeError, match="suite s2 defines every split of the runs otherwise"):
        merge_reports([("old.json", old)], suite=changed)
    # Without a suite, runs of two suite ids are still refused.
    with pytest.raises(MergeError, match=r"dev\.json is of suite s2, old\.json of s"):
        merge_reports([("old.json", old), ("dev.json", dev)])


def test_merge_carries_a_v3_run_into_v4_keeping_all_but_the_dev_tier(
        tmp_path: Path, models, capsys: pytest.CaptureFixture) -> None:
    from clonedrive.bench.suite import load_suite

    v3 = load_suite("v3", check_tracks=False)
    runs = {path: [dict(run, key=run["key"].replace(run["split"], split), split=split)
                   for split in ("hard-30", "dev")
                   for run in runs if run["split"] == "easy"] for path, runs in models.items()}
    report = _report(runs, ("hard-30", "dev"), suite="v3")
    report["suite"] = v3.to_dict()
    (tmp_path / "v3run").mkdir()
    (tmp_path / "v3run" / "bench.json").write_text(json.dumps(report), encoding="utf-8")
    out = tmp_path / "v4"
    assert main(["bench", "merge", str(tmp_path / "v3run"), "--suite", "v4", "--out",
                 str(out)]) == 0
    assert "left out split(s) dev (suite v4 defines them otherwise)" in capsys.readouterr().out
    merged = json.loads((out / "bench.json").read_text())
    assert merged["suite"]["id"] == "v4" and merged["split_names"] == ["hard-30"]
    page = (out / "leaderboard.md").read_text(encoding="utf-8")
    assert "Carried into suite v4 from `" in page
    assert "v3run`, without its split(s) dev, which this suite defines otherwise" in page
    # Merged again (the board gaining a row), the carried run's note stays.
    again = merge_reports([("v4", json.loads((out / "bench.json").read_text()))])
    assert again["settings"]["left_out"] == merged["settings"]["left_out"]
    assert main(["bench", "merge", str(tmp_path / "v3run"), "--suite", "v9", "--out",
                 str(out)]) == 2
    assert "v9: no such suite" in capsys.readouterr().err
