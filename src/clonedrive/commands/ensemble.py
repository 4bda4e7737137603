"""``clonedrive ensemble``: several trained models as one model file, the mean of their outputs."""

from __future__ import annotations

import argparse
import sys

HELP = "combine trained models into one that predicts their mean (steadier steering)"
DESCRIPTION = (
    "Write one model file whose outputs are the means of MODEL... outputs (steering, and the "
    "target speed when every model has the speed head). Networks trained alike from other "
    "seeds (clonedrive train --seed N) err differently from frame to frame, so their mean "
    "steers more steadily than any one of them; it costs their inference together. The file "
    "is an ordinary .keras model: drive, evaluate, bench and export take it. The ensemble is "
    "checked against the members' mean on test frames and the largest difference is printed."
)
#: Example command lines, shown at the end of ``clonedrive ensemble --help``.
EXAMPLES = (
    "clonedrive ensemble runs/a/model.keras runs/b/model.keras --out runs/ens.keras",
)
#: The ensemble is refused if it differs from the members' mean by more than this.
PARITY_LIMIT = 1e-5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("models", nargs="+", metavar="MODEL",
                        help="trained model files (.keras or .h5), at least 2")
    parser.add_argument("--out", required=True, help="the .keras file to write")
    parser.add_argument("--trust-model", action="store_true",
                        help="allow Lambda layers (Python code in the files); see drive --help")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from clonedrive.commands.output_claim import claim

    out = Path(args.out)
    if out.suffix.lower() != ".keras":
        print(f"clonedrive ensemble: --out {out}: the file name must end in .keras",
              file=sys.stderr)
        return 2
    if any(Path(path).suffix.lower() == ".onnx" for path in args.models):
        print("clonedrive ensemble: ONNX files cannot be combined; give the .keras or .h5 files",
              file=sys.stderr)
        return 2
    lock = claim("ensemble", out, inputs=args.models, is_file=True)
    if lock is None:
        return 1
    with lock:
        return _combine(args, out)


def _combine(args: argparse.Namespace, out) -> int:
    import numpy as np

    from clonedrive.base.config import atomic_path
    from clonedrive.base.udacity_spec import IMAGE_SHAPE
    from clonedrive.network.contract import has_speed_head
    from clonedrive.network.driving_settings import copy_notes
    from clonedrive.network.model_file import load_model

    try:
        members = [load_model(path, trust=args.trust_model, runtime="keras")
                   for path in args.models]
        from clonedrive.model.ensemble import build_ensemble

        ensemble = build_ensemble(members)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive ensemble: {error}", file=sys.stderr)
        return 2
    frames = np.random.default_rng(0).integers(0, 256, (8, *IMAGE_SHAPE), dtype=np.uint8)
    frames = frames.astype(np.float32)
    outputs = [_as_list(member.predict_on_batch(frames)) for member in members]
    expected = [np.mean([member[k] for member in outputs], axis=0)
                for k in range(len(outputs[0]))]
    got = _as_list(ensemble.predict_on_batch(frames))
    difference = max(float(np.max(np.abs(np.asarray(g) - e))) for g, e in zip(got, expected,
                                                                               strict=True))
    if difference > PARITY_LIMIT:
        print("clonedrive ensemble: the ensemble differs from its members' mean by "
              f"{difference:.2e}",
              file=sys.stderr)
        return 1
    try:
        with atomic_path(out) as temporary:  # creates the folder
            ensemble.save(temporary)
            copy_notes(args.models[0], temporary)  # driven as its first member says
    except OSError as error:
        from clonedrive.base.paths import describe_os_error, with_filename

        print(f"clonedrive ensemble: cannot write {out}: "
              f"{describe_os_error(with_filename(error, out))}", file=sys.stderr)
        return 1
    kind = "steering and target speed" if has_speed_head(ensemble) else "steering"
    print(f"wrote {out}: the mean {kind} of {len(members)} models "
          f"(largest difference from the members' mean on test frames: {difference:.1e})")
    return 0


def _as_list(output) -> list:
    return list(output) if isinstance(output, list | tuple) else [output]
