"""`tactile-sl view BAG.mcap`: a recorded bag in the browser, with a frame slider.

Registered in ``tactile_sl_decoder.cli``; the implementation lives here with the viewer.
The page is the live viewer's (read-only); a bag without the decoder's outputs is decoded
first with the decoder's own pipeline (:mod:`tactile_sl_viewer.bag_source`).
"""
from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Any

from tactile_sl_common.bag_io import BagError
from tactile_sl_decoder.checks import load_pattern_spec
from tactile_sl_decoder.decode.codewords import PatternError
from tactile_sl_decoder.tooling.progress import progress_bar
from tactile_sl_decoder.touch.sensor import SensorFileError
from tactile_sl_viewer.bag_source import BagSource
from tactile_sl_viewer.packets import PacketBuilder
from tactile_sl_viewer.view_model import PadGeometry
from tactile_sl_viewer.web import ViewerServer


def register(subparsers: Any, summary: str | None = None) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view", help=summary,
        description="Serve the viewer's page for a recorded bag: the left image with the "
                    "decoded glyphs, the pressure or depth map, force, moment, contact and "
                    "slip of each frame, with a frame slider. A bag without the decoder's "
                    "outputs is decoded first (the same pipeline as the decoder node).")
    p.add_argument("bag", metavar="BAG.mcap", help="MCAP bag (or rosbag2 directory)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this computer only)")
    p.add_argument("--port", type=int, default=8080, help="TCP port (default 8080; 0 = any)")
    p.add_argument("--max-rate", type=float, default=0.0, metavar="FPS",
                   help="frames a second sent to each page at most (default 0: as many as "
                        "the page asks for)")
    p.add_argument("--namespace", default="/tactile", help="topic namespace of the bag")
    p.add_argument("--decode", choices=("auto", "always", "never"), default="auto",
                   help="decode the images here: auto (when the bag has no recorded "
                        "outputs), always, never")
    p.add_argument("--pattern", metavar="P.yaml", default=None,
                   help="pattern file (default: the shipped one)")
    p.add_argument("--classifier", metavar="WEIGHTS", default=None,
                   help="classifier weights for decoding (default: the shipped ones)")
    p.add_argument("--sensor", metavar="SENSOR.yaml", default=None,
                   help="sensor file for the touch outputs (default: the shipped one)")
    p.add_argument("--mirrored", action="store_true",
                   help="the cameras see the artwork mirrored (sensor setting)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C or SIGTERM (status 0); 1 on a bad bag, file or address."""
    if args.max_rate < 0:
        print("tactile-sl view: --max-rate must be 0 (no cap) or more", file=sys.stderr)
        return 1

    def progress(done: int, total: int) -> None:
        if not args.no_progress:
            progress_bar(sys.stderr, done, total, "decode")

    try:

        pattern = load_pattern_spec(args.pattern)
        source = BagSource(args.bag, args.namespace, args.decode,
                           {"pattern": args.pattern, "classifier": args.classifier,
                            "sensor": args.sensor, "mirrored": args.mirrored}, progress)
    except (BagError, PatternError, SensorFileError, OSError, ValueError) as exc:
        print(f"\ntactile-sl view: {exc}", file=sys.stderr)
        return 1
    if source.decoded_here and not args.no_progress:
        sys.stderr.write("\n")
    rows, cols = pattern.array.shape
    builder = PacketBuilder(PadGeometry(int(rows), int(cols), float(pattern.pitch_m)),
                            source.namespace.strip("/"))
    server = ViewerServer(source, builder, args.host, args.port, max_rate=args.max_rate)
    try:
        url = server.start()
    except OSError as exc:
        print(f"tactile-sl view: {exc}", file=sys.stderr)
        return 1
    how = "decoded here" if source.decoded_here else "outputs as recorded"
    print(f"tactile-sl view: {source.path.name}, {len(source.stamps)} frames ({how}); open "
          f"{url}  (Ctrl-C to stop)", flush=True)
    stopping = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stopping.set())
    try:
        while not stopping.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        server.stop()
    return 0
