"""``clonedrive video``: a folder of frames -> ``FOLDER.mp4``, like Udacity's video.py."""

from __future__ import annotations

import argparse
import json
import sys

HELP = "turn a folder of frames (e.g. saved by `clonedrive drive`) into an mp4"
DESCRIPTION = (
    "Encode the images of FOLDER, sorted by name, as an H.264 (yuv420p) mp4 named FOLDER.mp4 "
    "beside the folder, as Udacity's video.py does. Frames that do not decode or whose size "
    "differs from the first are skipped and counted."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", help="folder of .jpg/.png frames")
    parser.add_argument("--fps", type=float, default=60.0, help="frames per second of the video")
    parser.add_argument("--out", default=None, help="output file (default: FOLDER.mp4)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    if not args.fps > 0:
        print(f"error: --fps must be positive, got {args.fps}", file=sys.stderr)
        return 2
    from clonedrive.evaluate.video import encode_folder

    try:
        summary = encode_folder(args.folder, args.fps, args.out, progress=not args.json)
    except (FileNotFoundError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if args.json:
        result = {
            "video": str(summary.path),
            "frames": summary.frames,
            "fps": args.fps,
            "skipped": [{"file": name, "reason": reason} for name, reason in summary.skipped],
        }
        print(json.dumps(result))
    else:
        print(f"wrote {summary.path}: {summary.frames} frames at {args.fps:g} fps", end="")
        print(f", {len(summary.skipped)} skipped" if summary.skipped else "")
    return 0
