"""Checks at load: a pattern that breaks its own constraints, a classifier for another alphabet.

Used by the decoder node and ``tactile-sl replay`` so that a file that cannot decode
correctly is refused at start with one line saying why, instead of giving empty or wrong
clouds later (rclpy-free, like every stage library).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from tactile_sl_decoder.pattern import default_pattern_path, load_pattern
from tactile_sl_decoder.pipeline import PatternSpec


class ConfigurationError(ValueError):
    """Files or settings that do not fit together; the message names them."""


def load_pattern_spec(path: str | Path | None, allow_invalid: bool = False) -> Any:
    """The decoder's :class:`~tactile_sl_decoder.pipeline.PatternSpec` of a pattern file.

    The file is verified against its own ``min_hamming`` and window uniqueness
    (:class:`~tactile_sl_decoder.pattern.fileio.PatternInvalidError` when it breaks them)
    unless ``allow_invalid`` (experiments only).
    """
    pattern = load_pattern(path or default_pattern_path(), verify=not allow_invalid)
    return PatternSpec.from_pattern(pattern)


def check_classifier(classifier: Any, symbols: int, source: str | None = None) -> None:
    """Refuse a classifier whose class count differs from the pattern's symbol count."""
    classes = int(classifier.classes)
    if classes != int(symbols):
        where = f"classifier weights {source}" if source else "the classifier"
        raise ConfigurationError(
            f"{where} label {classes} classes but the pattern has {symbols} symbols: "
            "use weights trained for this pattern's alphabet (`tactile-sl train`)")


def check_threshold(value: float) -> float | None:
    """A confidence threshold in [0, 1], or None (< 0: the value stored with the weights)."""
    value = float(value)
    if value < 0:
        return None
    if value > 1:
        raise ConfigurationError(f"classifier_threshold {value} is not a probability: "
                                 "give a value in [0, 1], or < 0 for the weights' own")
    return value
