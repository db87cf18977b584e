"""The `tactile-sl` command-line tool: one entry point, one module per subcommand.

Each subcommand module exposes ``register(subparsers, summary)``, which adds its parser
(with ``summary``, its line in the list of commands) and sets ``func`` (called with the
parsed arguments, returning the exit status).  Only the module of
the command being run is imported: ``tactile-sl --help`` lists the commands from
:data:`COMMANDS` without loading numpy, OpenCV, the numba kernels or torch, so the command
modules import their libraries at the top like any other module.  Commands are listed here
rather than discovered so that their order is stable.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import signal
import sys
from typing import Sequence

from tactile_sl_common import signals
from tactile_sl_common.signals import Terminated

COMMANDS: dict[str, tuple[str, str]] = {
    # name: (module, one line for `tactile-sl --help`), in help order
    "pattern": ("tactile_sl_decoder.cli.pattern_cmd",
                "M-array pattern: generate, verify, render, bound, benchmark"),
    "synth": ("tactile_sl_sim.cli.synth_cmd",
              "render simulated stereo bags (images, camera_info, ground truth)"),
    "calibrate": ("tactile_sl_decoder.cli.calibrate_cmd",
                  "stereo calibration (printed pattern or checkerboard) -> left/right "
                  "camera_info YAML; --check judges one in place"),
    "train": ("tactile_sl_decoder.cli.train_cmd",
              "train the glyph classifier on simulated images (CPU, minutes)"),
    "evaluate": ("tactile_sl_decoder.cli.evaluate_cmd",
                 "per scene and frame: extraction recall/spurious rate, classification "
                 "accuracy and confusion matrix, end-to-end and touch figures against a bag's "
                 "ground truth"),
    "replay": ("tactile_sl_decoder.cli.replay_cmd",
               "decode a bag offline into /tactile/points (same pipeline as the node)"),
    "view": ("tactile_sl_viewer.view_cmd",      # the viewer package's (left out when absent)
             "a recorded bag in the browser viewer, with a frame slider (a bag of images "
             "only is decoded first)"),
}
"""Every subcommand; one whose package is not installed is left out."""

__all__ = ["COMMANDS", "Terminated", "build_parser", "command_of", "main"]


def _installed(module: str) -> bool:
    return importlib.util.find_spec(module.split(".")[0]) is not None


def command_of(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` runs (its first word that names one), or None."""
    return next((word for word in argv if word in COMMANDS), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser: every installed command listed, ``command`` with all its arguments."""
    parser = argparse.ArgumentParser(
        prog="tactile-sl",
        description="tactile-sl: structured-light tactile sensor tools "
        "(patterns, simulation, calibration, training, offline replay and evaluation).",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, text) in COMMANDS.items():
        if not _installed(module):
            continue                         # subcommand not built yet / package not installed
        if name == command:
            importlib.import_module(module).register(subparsers, text)
        else:
            subparsers.add_parser(name, help=text)
    return parser


def _interrupt_behind(exc: SystemError) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM a SystemError reports, if that is what it is.

    A frame's work holds the signals (:func:`tactile_sl_common.signals.held`); elsewhere (a
    second Ctrl-C, a command's own compiled calls) a signal that comes while numba calls back
    into Python (loading a cached kernel: ``_numba_unpickle``) is raised by its handler there,
    and CPython reports it as the cause of a SystemError ("returned a result with an
    exception set"); the kernel's caller may wrap that SystemError in another one.
    """
    cause: BaseException | None = exc
    for _ in range(8):                      # a chain of SystemErrors, each the next's cause
        if isinstance(cause, KeyboardInterrupt):
            return cause
        if not isinstance(cause, SystemError):
            return None
        cause = cause.__cause__
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand; its exit status (130 after Ctrl-C, 143 after SIGTERM)."""
    words = sys.argv[1:] if argv is None else list(argv)
    command = command_of(words)
    try:
        # from the start (the command's imports take a while); a frame's work holds them
        with signals.as_exceptions():
            parser = build_parser(command)
            args = parser.parse_args(words)
            if not getattr(args, "func", None):
                parser.print_help()
                return 0 if args.command is None else 2
            try:
                return int(args.func(args) or 0)
            except SystemError as exc:
                interrupt = _interrupt_behind(exc)
                if interrupt is not None:
                    raise interrupt from None
                raise
    except Terminated:
        print("terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1
    except (OSError, MemoryError) as exc:     # last resort: one line, never a traceback
        text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        filename = getattr(exc, "filename", None)   # MemoryError has none
        where = f" {filename}:" if filename else ""
        print(f"tactile-sl {command}:{where} {text}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
