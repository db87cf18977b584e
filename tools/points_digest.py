#!/usr/bin/env python3
"""Digests of every point cloud and touch output `tactile-sl replay` makes of the bundled bags.

The refactoring check (issues 9, 26, 29): the points and touch outputs of every bag must
stay byte-identical unless a change is meant to alter them.  ``--write FILE`` records the
current tree's digests into FILE (``src/tactile_sl_decoder/test/data/points_digests.json``),
``src/tactile_sl_decoder/test/test_points_unchanged.py`` recomputes and compares them.

Per bag and output topic (points, field, wrench, contact, depth, slip): per message the stamp, its
size (points / cells for the clouds, 1 otherwise) and the SHA-256 of its serialised data.
Stamps and sizes hold on every machine (``frames``); the bytes only on the CPU model they
were computed on (numpy and OpenCV pick SIMD code paths per CPU, which can move a float's
last bit), so they are kept per CPU model and vector extension (``digests``): writing adds
or replaces this CPU's entry and keeps the others' for the outputs it did not change here.
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
TOPICS = ("points", "field", "wrench", "contact", "depth", "slip")


def cpu_model() -> str:
    """The CPU's model name and widest vector extension: the key of its digests.

    Float results may differ in the last bit between SIMD code paths, which numpy, OpenCV
    and OpenBLAS choose by the CPU's extensions; a virtual machine's model name alone
    ("AMD EPYC") covers CPUs with and without AVX-512.
    """
    name, flags = "", set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name") and not name:
                name = line.split(":", 1)[1].strip()
            elif line.startswith("flags") and not flags:
                flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    name = name or platform.processor() or "unknown"
    widest = next((f for f in ("avx512f", "avx2", "avx", "sse4_2") if f in flags), "")
    return f"{name} [{widest}]" if widest else name


def replay_digests(bag: Path, workdir: Path) -> dict[str, list[list[Any]]]:
    """Per topic, [stamp_ns, size, sha256] of each message `tactile-sl replay` writes."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from tactile_sl_decoder.cli import main

    out = workdir / (bag.stem + ".out.mcap")
    code = main(["replay", str(bag), "-o", str(out), "--no-progress"])
    if code:
        raise RuntimeError(f"tactile-sl replay {bag.name} exited {code}")
    found: dict[str, list[list[Any]]] = {t: [] for t in TOPICS}
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, msg in reader.iter_decoded_messages(
                topics=[f"/tactile/{t}" for t in TOPICS]):
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            size = msg.width * msg.height if hasattr(msg, "point_step") else 1
            found[channel.topic.rsplit("/", 1)[1]].append(
                [stamp, size, hashlib.sha256(bytes(message.data)).hexdigest()])
    out.unlink()
    return found


def bag_digests(bags: list[Path]) -> dict[str, dict[str, list[list[Any]]]]:
    """Digests of every bag on this machine."""
    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, bag in enumerate(bags):
            print(f"[{i + 1}/{len(bags)}] {bag.name}", file=sys.stderr, flush=True)
            result[bag.name] = replay_digests(bag, Path(tmp))
    return result


def record(digests: dict[str, Any], old: dict[str, Any] | None) -> dict[str, Any]:
    """The file's content: frames and sizes, this CPU's bytes, other CPUs' still valid ones.

    Another CPU's digests of a bag's topic are kept only where this CPU's are as recorded
    before (the change being recorded did not alter that output here); where it did, the
    other CPU's bytes have most likely changed too, and are dropped until recorded there.
    On a CPU recorded for the first time nothing tells whether the change altered an
    output, so another CPU's digests are kept only where they equal this CPU's (equal
    sizes did not do: a first recording on an AVX-512 EPYC, 2026-12-04, kept the AVX2 and
    Xeon digests of outputs the change had moved, and the test failed there).
    """
    old = old or {"frames": {}, "digests": {}}
    frames = {bag: {t: [m[:2] for m in msgs] for t, msgs in topics.items()}
              for bag, topics in digests.items()}
    cpu = cpu_model()
    mine = {bag: {t: [m[2] for m in msgs] for t, msgs in topics.items()}
            for bag, topics in digests.items()}
    before = old["digests"].get(cpu)
    by_cpu: dict[str, Any] = {cpu: mine}

    def unchanged(bag: str, topic: str, theirs: list[str]) -> bool:
        if before is None:           # not recorded here before: only bytes equal to these
            return theirs == mine[bag].get(topic)
        return before.get(bag, {}).get(topic) == mine[bag].get(topic)

    for other, bags in old["digests"].items():
        if other != cpu:
            by_cpu[other] = {bag: {t: h for t, h in topics.items() if unchanged(bag, t, h)}
                             for bag, topics in bags.items() if bag in frames}
    return {"frames": frames, "digests": by_cpu}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bags", type=Path, default=REPO / "bags")
    parser.add_argument("--write", type=Path, help="record the digests in this JSON file")
    args = parser.parse_args()
    digests = bag_digests(sorted(args.bags.glob("*.mcap")))
    if not args.write:
        json.dump(digests, sys.stdout, indent=1)
        return 0
    old = json.loads(args.write.read_text()) if args.write.exists() else None
    text = json.dumps(record(digests, old), indent=1) + "\n"
    tmp = args.write.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, args.write)
    print(f"recorded {len(digests)} bags for CPU {cpu_model()!r} in {args.write}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
