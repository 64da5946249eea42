"""Entry point of the ``fusion-vo`` command.

Each sub-command lives in its own module of this package and exposes ``register(subparsers)``, which
adds an ``argparse`` parser and sets ``func`` to a callable ``run(args) -> int``. User mistakes raise
:class:`fusion_vo.errors.InputError`; they are printed as one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from fusion_vo.errors import InputError
from fusion_vo.outputs import Terminated, handle_signals

#: sub-command modules, in the order ``--help`` lists them
COMMANDS = [
    "demo",
    "run",
    "replay",
    "simulate",
    "evaluate",
    "compare",
    "batch",
    "sweep",
    "export",
    "show_matches",
    "import_bag",
    "ros2",
    "calibrate",
    "bench",
]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other error of the command."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def version_text() -> str:
    """``fusion-vo VERSION`` and the versions of the libraries its results depend on (read from the
    installed distributions' metadata, nothing imported), for bug reports."""
    from importlib.metadata import PackageNotFoundError, version

    from fusion_vo import __version__

    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "not installed"

    libraries = ", ".join(f"{name} {installed(name)}" for name in
                          ("numpy", "scipy", "opencv-python-headless", "gtsam", "filterpy", "evo"))
    return f"fusion-vo {__version__} (Python {sys.version.split()[0]}; {libraries})"


class _Version(argparse.Action):
    """``--version``: the text of :func:`version_text` on one line (argparse's own action wraps it)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(version_text())
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fusion-vo",
        description="Ground-camera visual odometry fused with wheel encoders and an IMU.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv for debug output)")
    parser.add_argument("-q", "--quiet", action="store_true", help="only errors")
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="print the version of fusion-vo and of the libraries it uses, and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"fusion_vo.cli.{name}")
        except ModuleNotFoundError as exc:  # a command not present in this build
            if exc.name == f"fusion_vo.cli.{name}":
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.ERROR if args.quiet else [logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        with handle_signals():
            return int(args.func(args) or 0)
    except InputError as exc:  # one line, even when a library's message (a YAML parser's) spans several
        print(f"fusion-vo: error: {' '.join(part.strip() for part in str(exc).splitlines() if part.strip())}",
              file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of our output went away (| head): nothing to report (before OSError,
        try:                 # of which it is one); what is still buffered goes nowhere, not into a second error
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
    except OSError as exc:  # permissions, a full disk, a path that cannot be created
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"fusion-vo: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fusion-vo: interrupted; nothing was left half-written", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"fusion-vo: {exc}; nothing was left half-written", file=sys.stderr)
        return 128 + exc.signum
    except MemoryError:
        print("fusion-vo: error: out of memory", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: one line, the traceback only with -vv
        logging.getLogger("fusion_vo").debug("traceback of the internal error", exc_info=True)
        print(f"fusion-vo: internal error: {type(exc).__name__}: {_one_line(exc)} "
              "(please report it; -vv shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:300] + ("..." if len(text) > 300 else "")


if __name__ == "__main__":
    sys.exit(main())
