"""M-array pattern encoder: constraints, file format, verifier, generators, artwork.

Library only (no ROS imports): the CLI (`tactile-sl pattern ...`) and the nodes use it.
"""
from __future__ import annotations

from pathlib import Path

from .constraints import Constraints, parse_shape
from .fileio import Pattern, PatternFormatError, load_pattern, save_pattern
from .verify import Certificate, verify_array, verify_pattern

__all__ = [
    "Certificate", "Constraints", "Pattern", "PatternFormatError", "default_pattern_path",
    "load_default_pattern", "load_pattern", "parse_shape", "save_pattern", "verify_array",
    "verify_pattern",
]


def default_pattern_path() -> Path:
    """Path of the pattern the package ships as the sensor default."""
    return Path(__file__).resolve().parent.parent / "data" / "pattern.yaml"


def load_default_pattern() -> Pattern:
    """Load the shipped default pattern."""
    return load_pattern(default_pattern_path())
