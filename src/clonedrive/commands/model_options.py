"""The model-loading options that ``drive``, ``evaluate`` and ``bench`` share, declared once.

``--trust-model`` allows Lambda layers (Python code stored in a model file: students' Keras 2
models) with a loud warning; ``--runtime`` runs the model with Keras or ONNX Runtime. Loading
goes through :func:`clonedrive.drivers.network.load_policy`.
"""

from __future__ import annotations

import argparse

RUNTIME_CHOICES = ("auto", "keras", "onnx")


def add_model_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--trust-model", action="store_true",
        help="load a model with Lambda layers (Python code in the file, e.g. a student's Keras 2 "
             ".h5); Keras safe mode is off for it: only for files you trust")
    parser.add_argument(
        "--runtime", choices=RUNTIME_CHOICES, default="auto",
        help="run the model with Keras or ONNX Runtime (auto: ONNX Runtime for a .onnx file; "
             "onnx with a Keras file converts it in memory; needs the onnx extra)")


def load_policy_from_args(args: argparse.Namespace, model_path: str, **policy_options):
    """``load_policy(model_path, trust=args.trust_model, runtime=args.runtime, ...)``."""
    from clonedrive.drivers.network import load_policy

    return load_policy(model_path, trust=getattr(args, "trust_model", False),
                       runtime=getattr(args, "runtime", "auto"), **policy_options)
