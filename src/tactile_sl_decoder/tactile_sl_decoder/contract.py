"""The SymbolArray contract's numbers in pure Python: one definition for every module.

``LABEL_UNKNOWN`` and ``CELL_UNKNOWN`` mirror the constants of
``tactile_sl_msgs/msg/SymbolArray.msg`` (the source; a test checks they are equal whenever
tactile_sl_msgs is importable), so the libraries use them without importing messages.
``PATCH_SIZE`` is the side of the glyph patches the extractor samples and the classifier
takes, the value SymbolArray's ``patch_size`` field carries when patches are sent.
"""
from __future__ import annotations

LABEL_UNKNOWN = 255
"""Label of a glyph not (yet) classified, or too uncertain (SymbolArray.LABEL_UNKNOWN)."""

CELL_UNKNOWN = -1
"""Row/col of a glyph not (yet) decoded (SymbolArray.CELL_UNKNOWN)."""

PATCH_SIZE = 18
"""Side of a glyph patch in pixels: the extractor's default and the classifier's input."""
