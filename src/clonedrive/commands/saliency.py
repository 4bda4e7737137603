"""``clonedrive saliency``: where a model looks (VisualBackProp overlays)."""

from __future__ import annotations

import json
import sys

from clonedrive.commands.counts import count

HELP = "VisualBackProp saliency overlays: which pixels the network's features respond to"
DESCRIPTION = (
    "For each image (or evenly spaced center frames of each driving log) write an overlay of "
    "the VisualBackProp mask (Bojarski et al. 2016) of a convolutional steering model: the "
    "averaged feature maps of the convolutions, scaled back up layer by layer and multiplied, "
    "painted in green on the frame. Writes <name>_saliency.png per frame and saliency.json "
    "(predicted steering and, for a speed-head model, target speed) into --out."
)
#: Example command lines, shown at the end of ``clonedrive saliency --help``.
EXAMPLES = (
    "clonedrive saliency runs/x/model.keras data/middle --out runs/x/saliency",
)


def add_arguments(parser) -> None:
    from clonedrive.model.saliency import DEFAULT_FRAMES_PER_LOG, MAX_FRAMES

    parser.add_argument("model", help="trained model (.keras or .h5)")
    parser.add_argument("inputs", nargs="+", metavar="IMAGE_OR_LOG",
                        help="320x160 image files, or driving-log folders (driving_log.csv)")
    parser.add_argument("--out", required=True, help="folder for the overlays")
    parser.add_argument("--frames-per-log", type=count(MAX_FRAMES), default=DEFAULT_FRAMES_PER_LOG,
                        metavar="N", help="center frames taken from each log, evenly spaced")
    parser.add_argument("--json", action="store_true", help="print saliency.json's content")


def run(args) -> int:
    from clonedrive.model.saliency import write_saliency

    try:
        report = write_saliency(args.model, args.inputs, args.out,
                                frames_per_log=args.frames_per_log)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive saliency: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"wrote {len(report['frames'])} overlay(s) and saliency.json to {args.out}")
    return 0
