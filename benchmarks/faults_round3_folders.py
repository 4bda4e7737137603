"""Issue 37, part B's probes: run folders, planted paths, silent accepts and small tracebacks.

Each probe is a real ``clonedrive`` process (or a real WebSocket server answering a real
``clonedrive autonomous``) in a sandbox. Each reports the exit status, whether a traceback was
printed, and for the probes that plant something outside the folders a command names (a link
to a file elsewhere, an input folder), whether that file or folder changed.

Run alone: python benchmarks/faults_round3_folders.py (prints its figures, then one line of
JSON). ``folders(sandbox)`` is what benchmarks/faults.py calls.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from faults_round3 import CLI, ENV, FIXTURES, ROOT, WAIT_S, measured, run_cli

RECORD = ("record", "--track", "lake", "--no-scenery", "--start-time", "2020-01-01T00:00:00")
SUITE = ('id = "tiny"\n[[split]]\nname = "a"\ntracks = ["lake"]\nspeeds_mph = [20.0]\n'
         'conditions = ["clear"]\nseed = 3\n[conditions.clear]\n')
#: Nesting depth of the deep-TOML probes: ~100 KB of brackets.
DEEP = 50_000


def _state(path: Path) -> tuple | None:
    """What says a file was written: its bytes and modification time (None: absent)."""
    return (path.read_bytes(), path.stat().st_mtime_ns) if path.exists() else None


def _listing(folder: Path) -> list[str]:
    return sorted(str(path.relative_to(folder)) for path in folder.rglob("*"))


def planted_links(sandbox: Path) -> dict:
    """record --out DIR where DIR holds driving_log.csv, and then the lock, as a link."""
    results = {}
    for name in ("driving_log.csv", ".clonedrive-recording.lock"):
        target = sandbox / f"elsewhere_{name.strip('.')}.txt"
        target.write_text("someone else's file\n", encoding="utf-8")
        folder = sandbox / f"planted_{name.strip('.')}"
        folder.mkdir()
        (folder / name).symlink_to(target)
        before = _state(target)
        result = run_cli(*RECORD, "--seconds", "0.5", "--out", folder)
        results[name] = {**result, "outside_file_changed": _state(target) != before}
    return results


def interrupted_evaluate(sandbox: Path, model: Path) -> dict:
    """An evaluate, stopped as soon as its config.json is written, in a folder holding another
    model's finished evaluation: does eval.json still claim the old run, complete?"""
    out = sandbox / "eval_again"
    out.mkdir()
    (out / "config.json").write_text('{"tracks": ["mountain"]}\n', encoding="utf-8")
    (out / "eval.json").write_text(json.dumps({"model": "/old/model.keras", "complete": True,
                                               "runs": [{"track": "mountain"}]}))
    before = (out / "config.json").read_text(encoding="utf-8")
    child = subprocess.Popen([*CLI, "evaluate", model, "--track", "lake", "--laps", "1",
                              "--workers", "1", "--no-scenery", "--out", out], env=ENV,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    start = time.monotonic()
    while (out / "config.json").read_text(encoding="utf-8") == before \
            and child.poll() is None and time.monotonic() - start < WAIT_S:
        time.sleep(0.05)
    child.send_signal(signal.SIGTERM)
    _, err = child.communicate()
    report = json.loads((out / "eval.json").read_text(encoding="utf-8"))
    return {"rc": child.returncode, "traceback": "Traceback" in err,
            "old_results_left_complete": report.get("model") == "/old/model.keras"
            and report.get("complete") is True}


def _base_run(sandbox: Path, model: Path, recipe_text: str) -> Path:
    """A training run folder as dagger reads it: model, config and recipe."""
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.base.config import save_config
    from clonedrive.model.train_config import TrainConfig

    base = sandbox / f"base_{len(list(sandbox.glob('base_*')))}"
    base.mkdir()
    shutil.copy(model, base / "model.keras")
    save_config(TrainConfig(), base / "config.json")
    (base / "recipe.toml").write_text(recipe_text, encoding="utf-8")
    return base


def dagger_rerun(sandbox: Path, model: Path) -> dict:
    """dagger into a folder a run with --track lake --beta 0.5 left, with mountain and 0.8."""
    from clonedrive.base.config import config_to_dict
    from clonedrive.pipelines.dagger.config import DaggerConfig

    base = _base_run(sandbox, model, '[[recording]]\npath = "data"\n')
    out = sandbox / "dagger"
    (out / "iter_01" / "data").mkdir(parents=True)
    (out / "iter_01" / "data" / "collect.json").write_text('{"labels": 45}')
    saved = {**config_to_dict(DaggerConfig(tracks=("lake",), beta=0.5)),
             "base": str(base.resolve())}
    (out / "config.json").write_text(json.dumps(saved))
    result = run_cli("dagger", base, "--out", out, "--track", "mountain", "--beta", "0.8",
                     "--iterations", "1", "--no-scenery")
    relabelled = json.loads((out / "config.json").read_text()) != saved
    return {**result, "iterations_relabelled": relabelled}


def newline_names(sandbox: Path) -> dict:
    """A recording named with a newline: train, then --resume; report.md of a run naming it."""
    recording = sandbox / "rec\n# injected | x"
    record = run_cli(*RECORD, "--seconds", "2", "--relative-paths", "--out", recording)
    run = sandbox / "newline_run"
    first = run_cli("train", recording, "--out", run, "--model", "fast", "--epochs", "1",
                    "--no-h5")
    resume = run_cli("train", recording, "--out", run, "--model", "fast", "--epochs", "2",
                     "--no-h5", "--resume")
    report = run_cli("report", run, "--out", sandbox / "newline_report")
    markdown = (sandbox / "newline_report" / "report.md").read_text(encoding="utf-8")
    injected = any(line.startswith("# injected") for line in markdown.splitlines())
    return {"record_rc": record["rc"], "train": first, "resume": resume, "report": report,
            "report_heading_injected": injected}


def suite_text(sandbox: Path, model: Path) -> dict:
    """Suite text with a newline, '#', '|' and a tag, through bench into leaderboard.md."""
    suite = sandbox / "text_suite.toml"
    suite.write_text(SUITE.replace('id = "tiny"', 'id = "tiny | x"\ndescription = """one\n'
                                   '# injected\n| a | b |"""'), encoding="utf-8")
    result = run_cli("bench", model, "--suite", suite, "--max-seconds", "1", "--no-scenery",
                     "--workers", "1", "--out", sandbox / "text_bench")
    lines = (sandbox / "text_bench" / "leaderboard.md").read_text(encoding="utf-8").splitlines()
    return {**result, "heading_injected": any(line.startswith("# injected") for line in lines)}


def float_flags(sandbox: Path, model: Path) -> dict:
    """Values that cannot train: each should exit 2 before any work."""
    recording = FIXTURES / "stationary"
    runs = {f"train {flag} {value}": run_cli("train", recording, "--out", sandbox / "ff",
                                             "--epochs", "1", flag, value)
            for flag, value in (("--lr", "inf"), ("--lr", "1e30"), ("--dropout", "nan"),
                                ("--block-s", "inf"), ("--correction", "nan"))}
    base = _base_run(sandbox, model, '[[recording]]\npath = "data"\n')
    runs["dagger --lr 1e30"] = run_cli("dagger", base, "--out", sandbox / "fd", "--lr", "1e30")
    runs["evaluate --steering-filter nan"] = run_cli("evaluate", model, "--steering-filter",
                                                     "nan", "--out", sandbox / "fe")
    return runs


def _steer_server(reply: str):
    """A real WebSocket server on 127.0.0.1 answering each telemetry with ``reply``."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.server import serve

    frame = '42["steer",' + json.dumps({"steering_angle": reply, "throttle": "0.2"}) + "]"

    def handle(connection) -> None:
        connection.send('0{"sid":"s","upgrades":[],"pingTimeout":60000,"pingInterval":25000}')
        connection.send("40")
        try:
            for message in connection:
                if message.startswith('42["telemetry"'):
                    connection.send(frame)
                elif message == "2":
                    connection.send("3")
        except ConnectionClosed:
            pass

    return serve(handle, "127.0.0.1", 0)


def strict_reply() -> dict:
    """clonedrive autonomous against a server replying "1_0" (Python's float(): 10.0)."""
    server = _steer_server("1_0")
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        result = run_cli("autonomous", "--port", server.socket.getsockname()[1],
                         "--max-seconds", "1", "--no-scenery")
    finally:
        server.shutdown()
        thread.join()
    return result


def tracebacks(sandbox: Path, model: Path) -> dict:
    """Inputs that used to end in a traceback."""
    deep = sandbox / "deep.toml"
    deep.write_text("x = " + "[" * DEEP + "]" * DEEP + "\n", encoding="utf-8")
    table_suite = sandbox / "table_suite.toml"
    table_suite.write_text(SUITE.replace('conditions = ["clear"]', "conditions = [{a = 1}]"))
    huge_suite = sandbox / "huge_suite.toml"
    huge_suite.write_text(SUITE.replace("speeds_mph = [20.0]", f"speeds_mph = [{'9' * 400}]"))
    base = _base_run(sandbox, model, deep.read_text(encoding="utf-8"))
    figures = {
        "record --start-time 9999-12-31T23:59:59": run_cli(
            *RECORD[:-2], "--seconds", "2", "--start-time", "9999-12-31T23:59:59",
            "--out", sandbox / "late"),
        "video --fps 1e30": run_cli("video", FIXTURES / "stationary" / "IMG", "--fps", "1e30",
                                    "--out", sandbox / "fast.mp4"),
        "bench suite with a table": run_cli("bench", model, "--suite", table_suite,
                                            "--out", sandbox / "tb"),
        "bench suite with a 400-digit speed": run_cli("bench", model, "--suite", huge_suite,
                                                    "--out", sandbox / "hb"),
        "dagger BASE with a nested recipe.toml": run_cli("dagger", base, "--out",
                                                         sandbox / "nd"),
    }
    nested = measured("train", "--recipe", deep, "--out", sandbox / "nt")
    output = nested.pop("output")
    figures["train --recipe nested (100 KB)"] = {
        **nested, "traceback": "Traceback" in output,
        "message": (output.strip().splitlines() or [""])[-1][:200]}
    return figures


def _bounded(*argv: object, timeout_s: float = 60.0) -> dict:
    """:func:`run_cli` for a command that may serve until stopped: after ``timeout_s`` it gets
    Ctrl-C, and ``served`` says so."""
    child = subprocess.Popen([*CLI, *map(str, argv)], env=ENV, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        _, err = child.communicate(timeout=timeout_s)
        served = False
    except subprocess.TimeoutExpired:
        child.send_signal(signal.SIGINT)
        _, err = child.communicate()
        served = True
    return {"rc": child.returncode, "traceback": "Traceback" in err, "served": served,
            "message": (err.strip().splitlines() or [""])[-1][:200]}


def claims(sandbox: Path, model: Path) -> dict:
    """replay's --out inside its LOG_DIR, web's --out over its model, a second replay."""
    from clonedrive.data.output_lock import claim_output

    log = sandbox / "replay_log"
    shutil.copytree(FIXTURES / "mountain_windows_paths", log)  # a log replay drives through
    before = _listing(log)
    inside = run_cli("replay", model, log, "--out", log / "replay")
    member = sandbox / "web_model.keras"
    shutil.copy(model, member)
    over = _bounded("web", "--model", member, "--port", "0", "--no-scenery", "--out", member)
    with claim_output("replay", sandbox / "held"):
        second = run_cli("replay", model, log, "--out", sandbox / "held")
    return {"replay_out_inside_log": {**inside, "input_changed": _listing(log) != before},
            "web_out_over_model": {**over, "input_changed":
                                   member.read_bytes() != model.read_bytes()},
            "second_replay": second}


def folders(sandbox: Path) -> dict:
    """Every probe above, in ``sandbox`` (a fresh folder); returns the figures."""
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.network.tiny_model import build_tiny_model

    model = sandbox / "tiny.keras"
    build_tiny_model(seed=3).save(model)
    return {"planted_links": planted_links(sandbox),
            "interrupted_evaluate": interrupted_evaluate(sandbox, model),
            "dagger_rerun": dagger_rerun(sandbox, model),
            "newline_names": newline_names(sandbox),
            "suite_text": suite_text(sandbox, model),
            "float_flags": float_flags(sandbox, model),
            "strict_reply": strict_reply(),
            "tracebacks": tracebacks(sandbox, model),
            "claims": claims(sandbox, model)}


def main() -> None:
    sandbox = Path(tempfile.mkdtemp(prefix="clonedrive-faults3-folders-"))
    try:
        figures = folders(sandbox)
    finally:
        shutil.rmtree(sandbox, ignore_errors=True)
    print("issue 37, part B probes:")
    for name, value in figures.items():
        print(f"  {name}: {json.dumps(value)}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
