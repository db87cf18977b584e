#!/usr/bin/env python3
"""Digest of every point cloud `tactile-sl replay` makes from the bundled bags.

The refactoring check of the layout (issue 9): the points of every bag must stay
byte-identical.  ``--write FILE`` records the digests of the current tree (run it on the
tree before a change); ``src/tactile_sl_decoder/test/test_points_unchanged.py`` recomputes
them and compares.  Per bag: the number of frames, and per frame the stamp, the point
count and the SHA-256 of the PointCloud2 data bytes.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def cpu_model() -> str:
    """The CPU's model name (float results may differ in the last bit between SIMD paths)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def replay_digests(bag: Path, workdir: Path) -> list[list[Any]]:
    """[stamp_ns, points, sha256] of each /tactile/points message `tactile-sl replay` writes."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from tactile_sl_decoder.cli import main

    out = workdir / (bag.stem + ".points.mcap")
    # points do not depend on the touch stage; without it each bag skips a ~1 s tare
    code = main(["replay", str(bag), "-o", str(out), "--no-progress", "--no-touch"])
    if code:
        raise RuntimeError(f"tactile-sl replay {bag.name} exited {code}")
    frames = []
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, _channel, _message, msg in reader.iter_decoded_messages(
                topics=["/tactile/points"]):
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            data = bytes(msg.data)
            frames.append([stamp, msg.width * msg.height, hashlib.sha256(data).hexdigest()])
    out.unlink()
    return frames


def bag_digests(bags: list[Path]) -> dict[str, Any]:
    """Digests of every bag, with the CPU they were computed on."""
    result: dict[str, Any] = {"cpu": cpu_model(), "bags": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for i, bag in enumerate(bags):
            print(f"[{i + 1}/{len(bags)}] {bag.name}", file=sys.stderr, flush=True)
            result["bags"][bag.name] = replay_digests(bag, Path(tmp))
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bags", type=Path, default=REPO / "bags")
    parser.add_argument("--write", type=Path, help="write the digests as JSON here")
    args = parser.parse_args()
    digests = bag_digests(sorted(args.bags.glob("*.mcap")))
    text = json.dumps(digests, indent=1) + "\n"
    if args.write:
        tmp = args.write.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, args.write)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
