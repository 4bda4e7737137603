"""Issue 37, part A's probes: inputs small on disk that would fill the memory once read (model
files, driving logs, counts on the command line) and a disk that fills while writing. Each
probe is a real ``clonedrive`` process started from the ``measured()`` launcher of
``faults_round3`` (peak memory of the command itself).

Run alone: python benchmarks/faults_round3_bounds.py (prints its figures, then one line of
JSON). The full-disk probes need ``mount -t tmpfs`` (root in a container); without it they are
reported as skipped.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from faults_round3 import FIXTURES, ROOT, measured  # noqa: E402

sys.path.insert(0, str(ROOT / "tests"))
from support.hostile_files import (  # noqa: E402
    keras_with_huge_dense,
    keras_with_inflating_weights,
    log_of_many_rows,
)

#: Outputs of the huge Dense layer: 8 inputs x 160 million x 4 bytes = 5.1 GB of weights.
HUGE_UNITS = 160_000_000
#: What the inflating model's weights member unpacks to [bytes] (3.9 GiB).
INFLATED_BYTES = 3_900 << 20
#: Rows of the long log: 64 MiB of 36-byte rows, as in the issue.
LOG_ROWS = 1_770_000
#: Size of the tiny disk the full-disk probes write to.
TINY_DISK = "1m"
#: Bytes left free on the tiny disk for ``video`` (less than its mp4 needs).
FREE_FOR_VIDEO = 8 << 10
#: A count far past every stated maximum.
HUGE_COUNT = 1_000_000_000
COUNT_PROBES = (
    ("train", "REC", "--out", "OUT", "--epochs", HUGE_COUNT),
    ("train", "REC", "--out", "OUT", "--batch-size", HUGE_COUNT),
    ("record", "--laps", HUGE_COUNT, "--out", "OUT"),
    ("dagger", "--iterations", HUGE_COUNT, "--out", "OUT"),
    ("demo", "--unseen", HUGE_COUNT),
    ("bench", "--batch", HUGE_COUNT),
    ("saliency", "model.keras", "REC", "--out", "OUT", "--frames-per-log", HUGE_COUNT),
    ("autonomous", "--laps", HUGE_COUNT),
    ("video", "IMG", "--fps", HUGE_COUNT),
    ("sim", "--steps", HUGE_COUNT),
)


def summary(result: dict) -> dict:
    """rc, a traceback or not, peak memory and the last line of the output."""
    output = result.get("output", "").strip()
    return {"rc": result["rc"], "traceback": "Traceback" in output,
            "peak_rss_mb": result["peak_rss_mb"],
            "message": (output.splitlines() or [""])[-1][:200]}


def model_files(sandbox: Path, tiny: Path) -> dict:
    """``export`` (and ``evaluate``) of a model declaring a huge Dense layer, and of one whose
    weights inflate to 3.9 GiB."""
    huge = keras_with_huge_dense(tiny, sandbox / "huge_dense.keras", HUGE_UNITS)
    bomb = keras_with_inflating_weights(tiny, sandbox / "inflating.keras", INFLATED_BYTES)
    figures = {}
    for name, path in (("huge_dense", huge), ("inflating", bomb)):
        export = measured("export", path, "--onnx", "--out", sandbox / f"{name}.onnx")
        figures[name] = {"file_kb": round(path.stat().st_size / 1024, 1), **summary(export)}
    figures["huge_dense_evaluate"] = summary(measured(
        "evaluate", huge, "--laps", 1, "--workers", 1, "--out", sandbox / "eval_huge"))
    return figures


def long_logs(sandbox: Path, tiny: Path) -> dict:
    """``check --no-decode`` and ``train`` of a 64 MiB log of 1.77 million short rows."""
    recording = log_of_many_rows(sandbox / "long_log", LOG_ROWS, FIXTURES / "stationary" / "IMG")
    size_mb = (recording / "driving_log.csv").stat().st_size / 2**20
    check = summary(measured("check", recording, "--no-decode"))
    train = summary(measured("train", recording, "--out", sandbox / "long_run", "--epochs", 1))
    return {"log_mib": round(size_mb, 1), "rows": LOG_ROWS, "check_no_decode": check,
            "train": train}


def counts(sandbox: Path, tiny: Path) -> dict:
    """Each verb's count options at a billion: refused before anything is allocated."""
    places = {"REC": FIXTURES / "stationary", "IMG": FIXTURES / "stationary" / "IMG",
              "OUT": sandbox / "count_out", "model.keras": tiny}
    figures = {}
    for probe in COUNT_PROBES:
        argv = [places.get(str(item), item) for item in probe]
        option = probe[probe.index(HUGE_COUNT) - 1]
        figures[f"{probe[0]} {option}"] = summary(measured(*argv))
    return figures


@contextmanager
def tiny_disk(folder: Path) -> Iterator[Path | None]:
    """A tmpfs of :data:`TINY_DISK` mounted on ``folder``; None when mounting is refused."""
    folder.mkdir(parents=True, exist_ok=True)
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={TINY_DISK}", "tmpfs",
                              str(folder)], capture_output=True).returncode == 0
    try:
        yield folder if mounted else None
    finally:
        if mounted:
            subprocess.run(["umount", str(folder)], check=False)


def full_disk(sandbox: Path, tiny: Path) -> dict:
    """``train --cache memmap``, ``evaluate --video`` and ``video`` onto a 1 MB disk."""
    with tiny_disk(sandbox / "disk") as disk:
        if disk is None:
            return {"skipped": "mount -t tmpfs refused (not root?)"}
        figures = {}
        # --json: no progress bar, whose unended line would swallow the launcher's figure
        train = measured("train", FIXTURES / "stationary", "--out", disk / "run", "--epochs", 1,
                         "--cache", "memmap", "--json")
        figures["train_memmap"] = summary(train)
        shutil.rmtree(disk / "run", ignore_errors=True)
        evaluate = measured("evaluate", tiny, "--laps", 1, "--max-seconds", 20, "--video",
                            "--workers", 1, "--no-scenery", "--json", "--out", disk / "eval")
        figures["evaluate_video"] = {**summary(evaluate), "mp4_left": sorted(
            path.name for path in (disk / "eval").rglob("*.mp4"))}
        shutil.rmtree(disk / "eval", ignore_errors=True)
        frames = FIXTURES / "stationary" / "IMG"
        filler = disk / "filler"
        filler.write_bytes(bytes(max(0, shutil.disk_usage(disk).free - FREE_FOR_VIDEO)))
        video = measured("video", frames, "--out", disk / "frames.mp4", "--json")
        figures["video"] = {**summary(video), "left_under_final_name":
                            (disk / "frames.mp4").exists(), "files_left": sorted(
                                path.name for path in disk.iterdir() if path != filler)}
        return figures


def bounds(sandbox: Path) -> dict:
    """Every probe above; returns the figures."""
    sys.path.insert(0, str(ROOT / "src"))
    from clonedrive.base.keras_backend import choose_backend

    choose_backend()
    from clonedrive.network.tiny_model import build_tiny_model

    tiny = sandbox / "tiny.keras"
    build_tiny_model(seed=3).save(tiny)
    return {"model_files": model_files(sandbox, tiny), "long_logs": long_logs(sandbox, tiny),
            "counts": counts(sandbox, tiny), "full_disk": full_disk(sandbox, tiny)}


if __name__ == "__main__":
    print("issue 37 part A probes (bounded memory, full disk, counts):")
    work = Path(tempfile.mkdtemp(prefix="clonedrive-bounds-"))
    try:
        results = bounds(work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    for group, values in results.items():
        print(f"  {group}: {json.dumps(values)}")
    print(json.dumps(results))
