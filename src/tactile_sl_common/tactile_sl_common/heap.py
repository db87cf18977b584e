"""Short garbage-collector pauses in processes that run at camera rate (no rclpy).

CPython's cyclic collector walks every tracked container of a generation when it collects
it.  A decoder process holds about 143,000 of them after start-up (torch, numpy, rclpy, the
pattern and its codebook): one full (generation-2) collection there took 26-58 ms on the
2-core machine, longer than a 30 Hz frame period.  At camera rate the decoder makes few
containers (``tools/bench_graph.py --rate 6 --seconds 30``: all 3-4 full collections of the
decoder and 2-3 of each camera worker fell in the first 2 s of start-up; afterwards 12 young
collections in 30 s), but with the default thresholds (700, 10, 10) every 100 young
collections with survivors may start a full one: minutes apart, each a late or dropped
frame.  Nearly all of those objects live as long as the process, so after start-up they are
moved out of the collector's reach with :func:`gc.freeze` (Python 3.7+; the Python Library
Reference, ``gc`` module): a full collection then walks only what was made since (0.9 ms
instead of 26-58 ms in the same process).  Garbage made afterwards is collected as before.
"""
from __future__ import annotations

import gc


def freeze_long_lived(collect: bool = True) -> int:
    """Exempt every object alive now from later collections; returns how many are exempt.

    ``collect``: first collect what is garbage already (a full collection: call it at
    start-up, not between frames); without it, garbage that exists now stays (bounded: this
    is called a few times per process).
    """
    if collect:
        gc.collect()
    gc.freeze()
    return gc.get_freeze_count()
