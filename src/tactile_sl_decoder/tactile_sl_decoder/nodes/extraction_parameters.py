"""The glyph-extraction parameters, one per ExtractionParams field, shared by two nodes.

``symbol_extractor`` declares them bare (``block_size``), the ``decoder`` as
``extraction.block_size``; both through the one parameter mechanism
(:class:`tactile_sl_common.nodes.parameters.LiveParameters`), with the field docstrings of
:class:`~tactile_sl_decoder.extract.extraction.ExtractionParams` as descriptions, the ranges below,
and live changes (except ``patch_size``, the classifier's input size, read-only).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

from tactile_sl_common.nodes.parameters import LiveParameters, dataclass_fields, field_docs
from tactile_sl_decoder.extract.extraction import ExtractionParams

# Ranges of the extraction parameters (rclpy refuses values outside; more checks below).
EXTRACTION_RANGES: dict[str, tuple[float, float]] = {
    "block_size": (3, 1001), "offset": (-255.0, 255.0), "open_size": (0, 51),
    "min_area_px": (0.0, 1e6), "min_area_ratio": (0.0, 100.0), "split_ratio": (1.0, 100.0),
    "triple_ratio": (1.0, 100.0), "max_area_ratio": (1.0, 1000.0),
    "split_iterations": (0, 100), "min_split_distance": (0.0, 10.0),
    "core_radius": (0.0, 10.0), "min_core_fill": (0.0, 1.0), "patch_size": (4, 256),
    "patch_span": (0.1, 10.0), "default_spacing_px": (1.0, 10000.0),
    "large_offset": (-255.0, 255.0), "refine_split": (0, 5),
    "split_centroid_radius": (0.05, 0.5), "centroid_level": (0.0, 1.0),
    "centroid_plane_misfit": (0.0, 10.0), "centroid_background_step": (0.0, 10.0),
}
READ_ONLY = frozenset({"patch_size"})     # the classifier's input size


def extraction_check(name: str, value: Any) -> str | None:
    """Checks beyond the ranges: the reason a value is refused, or None."""
    if name == "block_size" and int(value) % 2 == 0:
        return "must be odd (adaptive threshold window)"
    return None


def declare_extraction(params: LiveParameters, prefix: str,
                       apply: Callable[[str, Any], None], what: str = "") -> ExtractionParams:
    """Declare ``<prefix><field>`` for every ExtractionParams field; return the values.

    ``apply(field, value)`` is called for a live change that passed the checks.
    """
    defaults = ExtractionParams()
    docs = field_docs(ExtractionParams)
    values = {}
    for name, default in dataclass_fields(defaults):
        extra: dict[str, Any] = {}
        if name in READ_ONLY:
            extra["read_only"] = True
        else:
            extra["apply"] = (lambda v, n=name: apply(n, type(getattr(defaults, n))(v)))
            extra["check"] = (lambda v, n=name: extraction_check(n, v))
        values[name] = type(default)(params.declare(
            prefix + name, default, what + docs.get(name, name), EXTRACTION_RANGES.get(name),
            **extra))
    return dataclasses.replace(defaults, **values)
