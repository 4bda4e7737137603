"""The model-loading options that ``drive``, ``evaluate`` and ``bench`` share, declared once.

``--trust-model`` allows Lambda layers (Python code stored in a model file: students' Keras 2
models) with a loud warning; ``--runtime`` runs the model with Keras or ONNX Runtime;
``--allow-nan-model`` drives a model whose steering is NaN on a probe frame (refused
otherwise: such a model would be driven straight, frame after frame, and score as if it
drove). Loading goes through :func:`clonedrive.drivers.policy.load_policy`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

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
    parser.add_argument(
        "--allow-nan-model", action="store_true",
        help="drive a model whose steering is NaN or infinite on a probe frame (refused by "
             "default; each such prediction steers straight and is counted)")


def add_steering_arguments(parser: argparse.ArgumentParser, *, speed: bool = True) -> None:
    """``--steering-filter``, ``--steering-hold``, ``--steering-scale-from``,
    ``--mirror-average`` and (with ``speed``) ``--slow-in-curves``, ``--speed-scale`` and
    ``--full-speed-at``: what stands between the
    network and the controls (:class:`clonedrive.network.driving_settings.DrivingSettings`).
    Each left out takes the setting stored in the model file (drive.py's, all off, for a file
    without them)."""
    parser.add_argument("--steering-filter", type=_setting("check_steering_filter_s"),
                        default=None, metavar="S",
                        help="low-pass the predicted steering with this time constant [s] "
                             "(0.1 = the expert's hand; 0 = off, as drive.py; default: the "
                             "model's own setting)")
    parser.add_argument("--steering-hold", type=_setting("check_steering_hold"),
                        default=None, metavar="H",
                        help="hold the wheel while the predicted steering stays within H of it "
                             "(steering units, -1..1; removes jitter smaller than H without a "
                             "delay; 0 = off, as drive.py; default: the model's own setting)")
    parser.add_argument("--steering-scale-from", type=_setting("check_steering_scale_from"),
                        default=None, metavar="MPH",
                        help="above MPH, multiply the predicted steering by MPH / the car's "
                             "speed, so that a prediction turns the car no faster than at MPH "
                             "(a calmer wheel, a wider line through fast bends; 0 = off, as "
                             "drive.py; default: the model's own setting)")
    parser.add_argument("--mirror-average", action=argparse.BooleanOptionalAction, default=None,
                        help="predict on each frame and on its mirror image and average the "
                             "two (mirrored steering negated): cancels the part of the "
                             "network's frame-to-frame noise the two views do not share, for "
                             "twice the inference (default: the model's own setting)")
    if speed:
        from clonedrive.network.driving_settings import STRETCH_FROM

        parser.add_argument("--slow-in-curves", action=argparse.BooleanOptionalAction,
                            default=None,
                            help="the hand-made curve rule: lower the target speed as "
                                 "|steering| grows, down to 40%% of the set speed (default: "
                                 "the model's own setting; off for a model without one, as "
                                 "drive.py)")
        parser.add_argument("--speed-scale", type=_setting("check_speed_scale"),
                            default=None, metavar="K",
                            help="multiply a speed head's target speed by K before the set "
                                 "speed caps it (1 = as learned; no effect without a speed "
                                 "head; default: the model's own setting)")
        parser.add_argument("--full-speed-at", type=_setting("check_full_speed_at"),
                            default=None, metavar="F",
                            help="drive a speed head's target at or above F times the set "
                                 f"speed at the set speed, and stretch its targets from "
                                 f"{STRETCH_FROM:g} times the set speed up to match (1 = as "
                                 "learned; default: the model's own setting)")
        parser.add_argument("--caution", type=_setting("check_caution"), default=None, metavar="C",
                            help="slow where the network is unsure: divide the target speed "
                                 "by 1 + C x the disagreement between a frame's steering and "
                                 "its mirror image's (needs mirror averaging; 0 = off; "
                                 "default: the model's own setting)")
        parser.add_argument("--caution-from", type=_setting("check_caution_from"),
                            default=None, metavar="D",
                            help="the disagreement (steering units) below which --caution "
                                 "does not slow: what the two views differ by where the "
                                 "network knows the road (default: the model's own setting)")


def _setting(check_name: str):
    """An argparse ``type`` for a driving setting's flag: the text as a float, refused by
    argparse (exit 2) with the message of ``network.driving_settings.<check_name>``, the one
    check that the setting's value passes everywhere (imported when a flag is given, so that
    ``--help`` stays fast)."""

    def checked(text: str) -> float:
        from clonedrive.network import driving_settings

        return _checked_float(text, getattr(driving_settings, check_name))

    return checked


def _checked_float(text: str, check) -> float:
    try:
        value = float(text)
        check(value)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return value


def load_policy_from_args(args: argparse.Namespace, model_path: str, **policy_options):
    """``load_policy(model_path, trust=args.trust_model, runtime=args.runtime, ...)``, with the
    steering filter, hold and mirror averaging when the command has
    :func:`add_steering_arguments`."""
    from clonedrive.drivers.policy import load_policy

    check_model_path(model_path)
    policy = load_policy(model_path, trust=getattr(args, "trust_model", False),
                         runtime=getattr(args, "runtime", "auto"), **steering_options(args),
                         **policy_options)
    if not getattr(args, "allow_nan_model", True):
        check_finite_on_probe(policy, model_path)
    return policy


def check_model_path(model_path: str) -> None:
    """``FileNotFoundError`` with a hint when ``model_path`` is not a file: a run folder names
    the model inside it, anything else the kinds of model file there are."""
    path = Path(model_path)
    if path.is_file():
        return
    if path.is_dir():
        inside = [str(candidate) for candidate in (path / "model.keras",
                                                   path / "train" / "model.keras")
                  if candidate.is_file()]
        hint = f"did you mean {inside[0]}?" if inside else "give a model file, not a folder"
        raise FileNotFoundError(f"{model_path}: a folder, not a model file; {hint}")
    raise FileNotFoundError(f"{model_path}: no such model file (a .keras, .h5 or .onnx file, "
                            "such as runs/demo/train/model.keras)")


#: The probe frame's grey level: a picture with nothing in it, which any model can take.
PROBE_GREY = 128


def check_finite_on_probe(policy, model_path: str) -> None:
    """``ValueError`` naming ``model_path`` if the policy's steering is NaN or infinite on a
    uniform grey frame; the probe is not counted among the policy's NaN predictions."""
    import numpy as np

    from clonedrive.base.udacity_spec import IMAGE_SHAPE

    frame = np.full((1, *IMAGE_SHAPE), PROBE_GREY, dtype=np.uint8)
    counted = policy.nan_predictions
    policy.predict(frame)
    nonfinite = bool(policy.last_nonfinite.any())
    policy.nan_predictions = counted
    if nonfinite:
        raise ValueError(f"{model_path}: the model's steering is NaN or infinite on a probe "
                         "frame (its weights hold NaN?); --allow-nan-model drives it anyway")


def steering_options(args: argparse.Namespace) -> dict:
    """The :func:`add_steering_arguments` options given on the command line, as NetworkPolicy
    (and BenchConfig) name them; the ones left out are not in the dict (the model's own)."""
    given = {"steering_filter_s": getattr(args, "steering_filter", None),
             "steering_hold": getattr(args, "steering_hold", None),
             "steering_scale_from_mph": getattr(args, "steering_scale_from", None),
             "mirror_average": getattr(args, "mirror_average", None),
             "slow_in_curves": getattr(args, "slow_in_curves", None),
             "speed_scale": getattr(args, "speed_scale", None),
             "full_speed_at": getattr(args, "full_speed_at", None),
             "caution": getattr(args, "caution", None),
             "caution_from": getattr(args, "caution_from", None)}
    return {name: value for name, value in given.items() if value is not None}
