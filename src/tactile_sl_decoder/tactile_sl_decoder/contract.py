"""The contract's message numbers in pure Python: one definition for every module.

``LABEL_UNKNOWN`` and ``CELL_UNKNOWN`` mirror the constants of
``tactile_sl_msgs/msg/SymbolArray.msg`` and the ``SLIP_*`` states those of
``tactile_sl_msgs/msg/Slip.msg`` (the sources; a test checks they are equal whenever
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

SLIP_NO_CONTACT = 0
"""Slip state: nothing presses on the pad (Slip.STATE_NO_CONTACT)."""

SLIP_STICK = 1
"""Slip state: the contact sticks; no slip annulus is seen (Slip.STATE_STICK)."""

SLIP_PARTIAL = 2
"""Slip state: its rim slides while its centre sticks (Slip.STATE_PARTIAL_SLIP)."""

SLIP_GROSS = 3
"""Slip state: the whole contact slides (Slip.STATE_GROSS_SLIP)."""
