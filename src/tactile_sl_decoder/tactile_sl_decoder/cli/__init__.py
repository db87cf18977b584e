"""The `tactile-sl` command-line tool: one entry point, one module per subcommand.

Each subcommand module exposes ``register(subparsers)``, which adds its parser and sets
``func`` (called with the parsed arguments, returning the exit status). Modules are listed
here rather than discovered so that ``tactile-sl --help`` is fast and its order is stable.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import threading
from typing import Iterator, Sequence

# Subcommand modules in help order; one whose package is not installed is omitted.
SUBCOMMAND_MODULES: tuple[str, ...] = (
    "tactile_sl_decoder.cli.pattern_cmd",
    "tactile_sl_sim.cli.synth_cmd",
    "tactile_sl_decoder.cli.calibrate_cmd",
    "tactile_sl_decoder.cli.train_cmd",
    "tactile_sl_decoder.cli.evaluate_cmd",
    "tactile_sl_decoder.cli.replay_cmd",
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


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C's KeyboardInterrupt.

    So every ``finally`` runs and every temporary output (``BagWriter``, ``atomic_path``)
    is removed, instead of the process dying where it stands.
    """


def _terminate(signum: int, _frame: object) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def _sigterm_as_exception() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` for the block (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand; its exit status (130 after Ctrl-C, 143 after SIGTERM)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        with _sigterm_as_exception():
            return int(args.func(args) or 0)
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
        print(f"tactile-sl {args.command}:{where} {text}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
