"""argparse types shared by the subcommands: numbers checked against their range.

argparse prefixes the message with the option's name, so a bad value reads
``argument --seed: must be in [0, 4294967295], got -1`` and exits with status 2.
"""
from __future__ import annotations

import argparse
import math
from typing import Callable


def number(kind: type, low: float, high: float) -> Callable[[str], float | int]:
    """An argparse type: a finite ``kind`` (int or float) in [low, high]."""
    def parse(text: str) -> float | int:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {kind.__name__}") from None
        if not math.isfinite(value) or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be in [{low}, {high}], got {text}")
        return value
    return parse
