"""The one console entry, ``clonedrive``: a table of verbs in data-flow order.

Each verb lives in ``clonedrive.commands.<module>`` and provides ``HELP`` (one line),
``EXAMPLES`` (command lines shown at the end of its ``--help``), ``add_arguments(parser)`` and
``run(args) -> int``. Command modules import heavy libraries
(Keras, Panda3D) inside ``run`` so that ``clonedrive --help`` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

from clonedrive.base.allocator import keep_freed_memory
from clonedrive.base.interrupts import Terminated, interruptible

# (verb, module under clonedrive.commands) in data-flow order.
VERBS: list[tuple[str, str]] = [
    ("demo", "demo"),
    ("tracks", "tracks"),
    ("sim", "sim"),
    ("web", "web"),
    ("record", "record"),
    ("check", "check"),
    ("train", "train"),
    ("ensemble", "ensemble"),
    ("drive", "drive"),
    ("autonomous", "autonomous"),
    ("evaluate", "evaluate"),
    ("crosscheck", "crosscheck"),
    ("replay", "replay"),
    ("saliency", "saliency"),
    ("bench", "bench"),
    ("dagger", "dagger"),
    ("export", "export"),
    ("video", "video"),
    ("report", "report"),
]


def _available_verbs() -> list[tuple[str, object]]:
    return [(verb, importlib.import_module(f"clonedrive.commands.{module_name}"))
            for verb, module_name in VERBS]


#: The top-level help's closing text: the order a user runs the verbs in, and the docs.
TOP_EPILOG = """\
in the order you would run them:
  clonedrive demo                                  # all of it, on built-in defaults
  clonedrive record ... -> check -> train -> evaluate -> report
  then: saliency, crosscheck + replay (real logs), bench, dagger, ensemble, export, drive (Udacity)

'clonedrive VERB --help' explains a verb and ends with examples.
Documentation: the docs/ folder of the repository (mkdocs serve), starting at
docs/getting-started.md."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="clonedrive",
        description=(
            "Behavioural cloning of driving: record an expert in a headless 3D simulator, "
            "train a Keras network to steer from one camera image, and prove in closed loop "
            "that it drives. Compatible with the Udacity simulator's data and drive protocol."
        ),
        epilog=TOP_EPILOG,
        formatter_class=_HelpFormatter,
    )
    from clonedrive import __version__

    parser.add_argument("--version", action="version", version=f"clonedrive {__version__}")
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB")
    for verb, module in _available_verbs():
        sub = subparsers.add_parser(
            verb,
            help=module.HELP,
            description=getattr(module, "DESCRIPTION", module.HELP),
            epilog=_examples(module.EXAMPLES),
            formatter_class=_HelpFormatter,
        )
        module.add_arguments(sub)
        sub.set_defaults(_run=module.run)
    return parser


def _examples(lines: tuple[str, ...]) -> str:
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """A count's maximum, and argparse's "(default: ...)" after each option's help, except on
    on/off flags (whose
    default is only the opposite of the flag: "--no-video (default: True)" misleads), on
    options whose default is None (their help says what happens without them) and on help
    that already names its default. Examples and the verb order are shown as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith(("examples:", "in the order")):
            return "\n".join(indent + line for line in text.splitlines())
        return super()._fill_text(text, width, indent)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        most = getattr(action.type, "most", None)  # a count's maximum (commands/counts.py)
        if most is not None and "at most" not in text:
            shown = f"{most:,}" if isinstance(most, int) else f"{most:g}"
            text = f"{text} (at most {shown})" if text else f"at most {shown}"
        if action.nargs == 0 or action.default is None or "default" in text:
            return text
        return text + super()._get_help_string(action)[len(action.help or ""):]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.verb is None:
        parser.print_help()
        return 2
    keep_freed_memory()  # base/allocator.py: freed batches stay in the process for the next
    with interruptible():
        return _run_verb(args)


def _run_verb(args: argparse.Namespace) -> int:
    try:
        return int(args._run(args) or 0)
    except Terminated:
        print("terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the output went to a pipe that closed (| head): nothing to say
        sys.stdout = open(os.devnull, "w")  # Python flushes stdout at exit
        return 1
    except OSError as error:
        # A full disk, a read-only folder, a missing permission: one line naming the path.
        from clonedrive.base.paths import FILE_SYSTEM_ERRNOS, describe_os_error

        if error.errno not in FILE_SYSTEM_ERRNOS:
            raise
        print(f"clonedrive {args.verb}: {describe_os_error(error)}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
