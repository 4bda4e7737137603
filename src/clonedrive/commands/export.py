"""``clonedrive export``: a trained model as ONNX, for ONNX Runtime and other runtimes."""

from __future__ import annotations

import argparse
import sys

HELP = "export a model as ONNX (checked against Keras)"
DESCRIPTION = (
    "Write MODEL (.keras or .h5) as an ONNX file for ONNX Runtime (clonedrive drive/evaluate "
    "--runtime onnx, or any ONNX runtime). The input is the centre camera as RGB uint8 "
    "(N, 160, 320, 3), named as in the Keras model (image_rgb); the outputs keep the Keras "
    "names (steering, and target_speed for a speed head). The export is checked: both runtimes "
    "predict the same test frames and the largest difference is printed. Needs the onnx extra "
    '(pip install -e ".[onnx]").'
)
#: Example command lines, shown at the end of ``clonedrive export --help``.
EXAMPLES = (
    "clonedrive export runs/x/model.keras --onnx      # writes runs/x/model.onnx",
)
#: The export is refused if ONNX Runtime and Keras differ by more than this on the test frames.
PARITY_LIMIT = 1e-4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", help="Keras model file (.keras or .h5)")
    parser.add_argument("--onnx", action="store_true", required=True,
                        help="write ONNX (the only export format)")
    parser.add_argument("--out", default=None,
                        help="the .onnx file to write (default: MODEL with the suffix .onnx)")
    parser.add_argument("--trust-model", action="store_true",
                        help="allow Lambda layers (Python code in the file); see drive --help")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from clonedrive.base.udacity_spec import IMAGE_SHAPE
    from clonedrive.network.model_file import load_model

    model_path = Path(args.model)
    out = Path(args.out) if args.out else model_path.with_suffix(".onnx")
    if out.suffix.lower() != ".onnx":
        print(f"clonedrive export: --out {out}: the file name must end in .onnx", file=sys.stderr)
        return 2
    if model_path.suffix.lower() == ".onnx":
        print(f"clonedrive export: {model_path} is already ONNX", file=sys.stderr)
        return 2
    from clonedrive.commands.output_claim import claim

    lock = claim("export", out, inputs=[model_path], is_file=True)
    if lock is None:
        return 1
    try:
        with lock:
            model = load_model(model_path, trust=args.trust_model, runtime="keras")
            from clonedrive.network.onnx_runtime import OnnxModel, export_onnx

            export_onnx(model, out)
            from clonedrive.network.driving_settings import copy_notes

            copy_notes(model_path, out)  # driven as the model it came from
        onnx_model = OnnxModel.from_file(out)
    except (FileNotFoundError, ValueError) as error:
        print(f"clonedrive export: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        from clonedrive.base.paths import describe_os_error, with_filename

        print(f"clonedrive export: cannot write {out}: "
              f"{describe_os_error(with_filename(error, out))}", file=sys.stderr)
        return 1
    frames = np.random.default_rng(0).integers(0, 256, (8, *IMAGE_SHAPE), dtype=np.uint8)
    keras_out = model.predict_on_batch(frames.astype(np.float32))
    onnx_out = onnx_model.predict_on_batch(frames)
    pairs = zip(keras_out, onnx_out, strict=True) if isinstance(keras_out, list) else [
        (keras_out, onnx_out)]
    difference = max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in pairs)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB); outputs "
          f"{', '.join(onnx_model.output_names)}; max |ONNX Runtime - Keras| on 8 test frames: "
          f"{difference:.2e}")
    if difference > PARITY_LIMIT:
        print(f"clonedrive export: the ONNX model differs from Keras by {difference:.2e} "
              f"(> {PARITY_LIMIT})",
              file=sys.stderr)
        return 1
    return 0
