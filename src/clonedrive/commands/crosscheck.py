"""``clonedrive crosscheck``: a model's steering against the human's on a recorded Udacity log."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from clonedrive.commands.counts import MAX_ROWS, MAX_SHOWN, count
from clonedrive.commands.model_options import add_model_arguments, load_policy_from_args

HELP = "open-loop check of a model on any Udacity log: RMSE, correlation, baselines, a plot"
DESCRIPTION = (
    "Predict the steering for every centre image of LOG_DIR (a driving_log.csv and IMG/ as the "
    "Udacity simulator or clonedrive record writes them; centre-only logs work) and compare it "
    "with the recorded steering: RMSE beside the always-0 and always-the-mean baselines, and "
    "the correlation with the human's steering lightly smoothed (a centred moving average; "
    "keyboard steering is spiky). Writes crosscheck.json, crosscheck.csv (per row) and "
    "crosscheck.png (traces and a scatter) into --out."
)
#: Example command lines, shown at the end of ``clonedrive crosscheck --help``.
EXAMPLES = (
    "clonedrive crosscheck runs/x/model.keras ~/udacity/my_recording --out runs/x/crosscheck",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from clonedrive.evaluate.crosscheck import CrosscheckConfig

    defaults = CrosscheckConfig()
    parser.add_argument("model", help="model file (.keras, .h5 or .onnx)")
    parser.add_argument("log_dir", metavar="LOG_DIR", help="folder holding driving_log.csv + IMG/")
    parser.add_argument("--out", default=None,
                        help="output folder (default: crosscheck/<log folder name>/ beside the "
                             "model)")
    parser.add_argument("--smooth", type=count(MAX_SHOWN),
                        default=defaults.smoothing_frames, metavar="N",
                        help="moving-average window on the human's steering, frames (odd)")
    parser.add_argument("--max-rows", type=count(MAX_ROWS), default=defaults.max_rows,
                        help="at most this many rows (evenly spaced) are predicted")
    parser.add_argument("--json", action="store_true", help="print crosscheck.json's content")
    add_model_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from clonedrive.base.paths import check_output_folder, safe_stem
    from clonedrive.data.driving_log import DrivingLogError
    from clonedrive.evaluate.crosscheck import CrosscheckConfig, crosscheck, format_summary

    try:
        config = CrosscheckConfig(smoothing_frames=args.smooth, max_rows=args.max_rows)
    except ValueError as error:
        print(f"clonedrive crosscheck: {error}", file=sys.stderr)
        return 2
    log_dir = Path(args.log_dir)
    out = Path(args.out) if args.out else (
        Path(args.model).resolve().parent / "crosscheck" / safe_stem(log_dir.resolve().name))
    try:
        check_output_folder(out)
        policy = load_policy_from_args(args, args.model)
        report = crosscheck(policy, log_dir, out, config, model_path=str(args.model),
                            progress=not args.json)
    except (FileNotFoundError, ValueError, DrivingLogError) as error:
        print(f"clonedrive crosscheck: {error}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_summary(report))
        print(f"wrote {out / report['files']['json']}, {report['files']['csv']}, "
              f"{report['files']['plot']}")
    return 0
