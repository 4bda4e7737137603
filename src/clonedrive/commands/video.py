"""``clonedrive video``: a folder of frames -> ``FOLDER.mp4``, like Udacity's video.py."""

from __future__ import annotations

import argparse
import json
import sys

from clonedrive.commands.counts import MAX_FPS, rate

HELP = "turn a folder of frames (e.g. saved by `clonedrive drive`) into an mp4"
DESCRIPTION = (
    "Encode the images of FOLDER, sorted by name, as an H.264 (yuv420p) mp4 named FOLDER.mp4 "
    "beside the folder, as Udacity's video.py does. Frames that do not decode or whose size "
    "differs from the first are skipped and counted."
)
#: Example command lines, shown at the end of ``clonedrive video --help``.
EXAMPLES = (
    "clonedrive video frames/                          # frames/ -> frames.mp4",
    "clonedrive video frames/ --fps 30 --out drive.mp4",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.evaluate.video import VideoConfig

    defaults = VideoConfig()
    parser.add_argument("folder", help="folder of .jpg/.png frames")
    parser.add_argument("--fps", type=rate(MAX_FPS), default=defaults.fps,
                        help="frames per second of the video")
    parser.add_argument("--out", default=defaults.out, help="output file (default: FOLDER.mp4)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    from clonedrive.evaluate.video import VideoConfig, encode_folder

    try:
        config = VideoConfig(fps=args.fps, out=args.out)
    except ValueError as error:
        print(f"clonedrive video: {error}", file=sys.stderr)
        return 2
    try:
        summary = encode_folder(args.folder, config.fps, config.out, progress=not args.json)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive video: {error}", file=sys.stderr)
        return 1
    if args.json:
        result = {
            "video": str(summary.path),
            "frames": summary.frames,
            "fps": config.fps,
            "skipped": [{"file": name, "reason": reason} for name, reason in summary.skipped],
        }
        print(json.dumps(result))
    else:
        print(f"wrote {summary.path}: {summary.frames} frames at {config.fps:g} fps", end="")
        print(f", {len(summary.skipped)} skipped" if summary.skipped else "")
    return 0
