"""The rendering options every command that renders shares, declared once.

``--renderer auto|software|egl`` chooses who draws the frames (:mod:`clonedrive.sim.engine`);
``--full-frame`` (commands whose network crops its input) renders whole frames instead of only
the rows the network looks at. :func:`renderer_error` checks that the chosen renderer opens on
this machine before anything drives.
"""

from __future__ import annotations

import argparse


def add_render_arguments(parser: argparse.ArgumentParser, *, crop: bool = True) -> None:
    """``--renderer``, and with ``crop`` also ``--full-frame``."""
    from clonedrive.sim.engine import DEFAULT_RENDERER, RENDERERS

    parser.add_argument(
        "--renderer", choices=RENDERERS, default=DEFAULT_RENDERER,
        help="who draws the camera frames: software (p3tinydisplay, on the CPU), egl (OpenGL "
             "through EGL, on the GPU where there is one), or auto (egl when EGL runs on a GPU, "
             "else software). Frames differ slightly between the two, so results are compared "
             "on one renderer")
    if crop:
        parser.add_argument(
            "--full-frame", action="store_true",
            help="render all 160 rows of each frame; by default only the rows the network's "
                 "crop keeps are rendered and the rest are filled with a constant (the network "
                 "never sees them); runs that write a video always get whole frames")


def renderer_error(args: argparse.Namespace, verb: str) -> str | None:
    """A one-line error (``clonedrive VERB: ...``) when ``--renderer egl`` was asked for and
    EGL does not open here; None when the renderer can be used."""
    from clonedrive.sim.engine import probe_egl

    if getattr(args, "renderer", None) == "egl" and probe_egl() is None:
        return (f"clonedrive {verb}: --renderer egl: Panda3D's EGL pipe (p3headlessgl) does not "
                "open on this machine; use --renderer software")
    return None
