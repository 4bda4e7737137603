"""``clonedrive report``: the generated write-up of a run folder."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from clonedrive.commands.counts import MAX_SHOWN, count

HELP = "write report.md and a self-contained report.html describing a run folder"
DESCRIPTION = (
    "Write the run's write-up, in the manner of the Udacity Behavioral Cloning write-up but "
    "generated from the run: the recordings (table, sample camera frames, augmentation "
    "examples), steering balancing, the network's layers, training loss per epoch and the "
    "split used, and the closed-loop results (per track and speed, track maps, video stills, "
    "and each off-road event with the frame the car saw). RUN_DIR may hold data/ (recordings), "
    "train/ (or model.keras itself), eval/ (eval.json) and demo.json; a missing piece leaves a "
    "one-line note in its section. Writes OUT/report.md with its figures in OUT/report/, and "
    "OUT/report.html with the figures embedded (one file to send). With --real-log, a section "
    "checks the model on recorded Udacity logs, open loop (clonedrive crosscheck) and closed "
    "loop (clonedrive replay)."
)
#: Example command lines, shown at the end of ``clonedrive report --help``.
EXAMPLES = (
    "clonedrive report runs/x                          # runs/x/report.md and report.html",
    "clonedrive report runs/demo --real-log ~/udacity/my_recording",
)


def add_arguments(parser) -> None:
    from clonedrive.report.context import ReportConfig

    defaults = ReportConfig()
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="the run folder")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for report.md, report.html and report/ (default: RUN_DIR)")
    parser.add_argument("--max-failures", type=count(MAX_SHOWN),
                        default=defaults.max_failures, metavar="N",
                        help="off-road events shown with their frames")
    parser.add_argument("--real-log", action="append", default=[], metavar="LOG_DIR",
                        help="also check the model on this recorded Udacity log, open and closed "
                             "loop (repeatable; see clonedrive crosscheck and replay)")
    parser.add_argument("--json", action="store_true",
                        help="no progress bar; print one JSON object with the written paths")


def run(args) -> int:
    from clonedrive.report.writeup import ReportConfig, write_report

    if not args.run_dir.is_dir():
        print(f"clonedrive report: run folder {args.run_dir} does not exist", file=sys.stderr)
        return 2
    try:
        config = ReportConfig(max_failures=args.max_failures,
                              real_logs=tuple(str(log) for log in args.real_log))
    except ValueError as error:
        print(f"clonedrive report: {error}", file=sys.stderr)
        return 2
    result = write_report(args.run_dir, args.out, config, progress=not args.json)
    if args.json:
        print(json.dumps({
            "markdown": str(result.markdown_path),
            "html": str(result.html_path),
            "figures": [str(path) for path in result.figures],
            "sections": result.sections,
            "notes": result.notes,
        }))
        return 0
    print(f"wrote {result.markdown_path} ({len(result.figures)} figures in "
          f"{result.markdown_path.parent / 'report'})")
    print(f"wrote {result.html_path} (self-contained)")
    for note in result.notes:
        print(f"note: {note}")
    return 0
