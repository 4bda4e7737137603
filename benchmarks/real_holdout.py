"""A real-frames training set that shares no frame with the replayed lake slice (issue 32).

The only real lake recording here is one student's log: ``lake_rikki_3cam`` is its first 1200
rows with all three cameras, ``lake_rikki_center`` the whole log (4594 rows) with the centre
images only. A model "trained only on real frames of another log" is trained on the rows after
the slice, with a gap of ``--gap`` rows so that no training frame is a near-copy of the slice's
last frames. This writes that folder (``driving_log.csv`` with the original lines, byte for
byte, and their centre images); then::

    clonedrive train OUT --out runs/real_lake
    python benchmarks/replay.py --model real=runs/real_lake/model.keras \\
        --replay-log ../shared/realdata/lake_rikki_3cam

Run: python benchmarks/real_holdout.py OUT [--first-row 1300]
Ends with one JSON line: {"rows", "images", "first_row", "source"}.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

REALDATA = Path(__file__).resolve().parents[2] / "shared" / "realdata"
SOURCE = REALDATA / "lake_rikki_center"
SLICE_ROWS = 1200  #: the rows ``lake_rikki_3cam`` holds (the log's first ones)
GAP_ROWS = 100  #: rows left out after the slice (about 9 s of driving)


def write_holdout(source: Path, out: Path, first_row: int) -> dict:
    """Copy the log's lines from ``first_row`` (0-based) on, and their centre images."""
    lines = (source / "driving_log.csv").read_bytes().splitlines(keepends=True)
    kept = lines[first_row:]
    (out / "IMG").mkdir(parents=True, exist_ok=True)
    (out / "driving_log.csv").write_bytes(b"".join(kept))
    copied = 0
    for line in kept:
        field = line.split(b",", 1)[0].strip().decode("utf-8")
        name = field.replace("\\", "/").rsplit("/", 1)[-1]
        image = source / "IMG" / name
        if image.is_file():
            shutil.copyfile(image, out / "IMG" / name)
            copied += 1
    return {"rows": len(kept), "images": copied, "first_row": first_row, "source": str(source)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--source", type=Path, default=SOURCE)
    parser.add_argument("--first-row", type=int, default=SLICE_ROWS + GAP_ROWS)
    args = parser.parse_args()
    if args.first_row < SLICE_ROWS:
        parser.error(f"--first-row must be at least {SLICE_ROWS}: the replayed slice's rows")
    figures = write_holdout(args.source, args.out, args.first_row)
    print(f"{figures['rows']} rows, {figures['images']} centre images from row "
          f"{figures['first_row']} of {figures['source']} -> {args.out}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
