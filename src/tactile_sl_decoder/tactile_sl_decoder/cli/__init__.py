"""The `tactile-sl` command-line tool: one entry point, one module per subcommand.

Each subcommand module exposes ``register(subparsers)``, which adds its parser and sets
``func`` (called with the parsed arguments, returning the exit status). Modules are listed
here rather than discovered so that ``tactile-sl --help`` is fast and its order is stable.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

# Subcommand modules in help order; one whose package is not installed is omitted.
SUBCOMMAND_MODULES: tuple[str, ...] = (
    "tactile_sl_decoder.cli.pattern_cmd",
    "tactile_sl_camera.cli.synth_cmd",
    "tactile_sl_decoder.cli.calibrate_cmd",
    "tactile_sl_decoder.cli.train_cmd",
    "tactile_sl_decoder.cli.evaluate_cmd",
    "tactile_sl_decoder.cli.replay_cmd",
    "tactile_sl_viewer.view_cmd",        # the viewer package's (omitted when not installed)
)


def build_parser() -> argparse.ArgumentParser:
    """Assemble the parser from every subcommand module that is present."""
    parser = argparse.ArgumentParser(
        prog="tactile-sl",
        description="tactile-sl: structured-light tactile sensor tools "
        "(patterns, simulation, calibration, training, offline replay and evaluation).",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and name.startswith(exc.name):
                continue  # subcommand not built yet / package not installed
            raise
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1
    except (OSError, MemoryError) as exc:     # last resort: one line, never a traceback
        text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        filename = getattr(exc, "filename", None)   # MemoryError has none
        where = f" {filename}:" if filename else ""
        print(f"tactile-sl {args.command}:{where} {text}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
