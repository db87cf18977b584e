"""One-line progress bar on a terminal stream: the bag drivers and `tactile-sl replay`."""
from __future__ import annotations

from typing import TextIO


def progress_bar(stream: TextIO, done: int, total: int, label: str = "") -> None:
    """One-line progress bar on a terminal stream (carriage return, no newline)."""
    width = 30
    if total > 0:
        fill = int(width * min(done, total) / total)
        text = f"\r{label} [{'#' * fill}{'.' * (width - fill)}] {done}/{total}"
    else:
        text = f"\r{label} {done} frames"
    stream.write(text)
    stream.flush()
