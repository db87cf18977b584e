#!/usr/bin/env python3
"""Median time per 640x480 image of glyph extraction and classification on ONE core.

Usage: python tools/bench_extraction.py [--repeat 200] [--bag bags/sphere_deep_small.mcap]
                                       [--stages]

Images: synthetic glyph grids (~1,000-1,150 glyphs, tactile_sl_decoder.tooling.synth_glyphs) and,
if given, the left images of a bag. Threads of OpenBLAS/OpenMP/OpenCV are limited to
one and the process is pinned to one CPU. Prints the median and 90th percentile of the wall
time and of the thread CPU time (the latter is what a core actually spent; on a shared, busy
machine the wall time also counts time the scheduler gave to other processes).
--stages adds the thread-CPU median of each extraction stage, timed alone on the first
image of each set (so with warmer caches than inside the full call).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tactile_sl_decoder.classify.classifier import Classifier  # noqa: E402
from tactile_sl_decoder.cpu_threads import set_cpu_threads  # noqa: E402
from tactile_sl_decoder.extract import extraction as ex  # noqa: E402
from tactile_sl_decoder.extract.centroid import patch_centroid_offset  # noqa: E402
from tactile_sl_decoder.extract.extraction import extract_symbols  # noqa: E402
from tactile_sl_decoder.extract.patches import sample_patches  # noqa: E402
from tactile_sl_decoder.tooling.synth_glyphs import synth_image  # noqa: E402


def timed(fn, repeat: int) -> tuple[np.ndarray, np.ndarray]:
    """Wall and thread-CPU seconds of ``repeat`` calls (after two warm-up calls)."""
    fn()
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.thread_time()
        fn()
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
    return np.array(wall) * 1e3, np.array(cpu) * 1e3


def line(name: str, wall: np.ndarray, cpu: np.ndarray, extra: str = "") -> str:
    """One result row."""
    return (f"{name:34s} wall median {np.median(wall):6.2f} ms  p90 {np.percentile(wall, 90):6.2f}"
            f"   cpu median {np.median(cpu):6.2f} ms  p90 {np.percentile(cpu, 90):6.2f}  {extra}")


def _cycle(fn, items: list) -> callable:
    """A no-argument call of ``fn`` on the next item, round robin."""
    state = {"i": 0}

    def call() -> None:
        fn(items[state["i"] % len(items)])
        state["i"] += 1
    return call


def stage_rows(gray: np.ndarray, repeat: int) -> list[str]:
    """Thread-CPU median of each extraction stage on one image, timed alone."""
    params = ex.ExtractionParams()
    det = extract_symbols(gray, params)
    mask = ex.threshold_ink(gray, params)
    ox, oy, roi = ex._ink_box(mask)
    step = det.local_spacing * np.float32(params.patch_span / params.patch_size)
    patches = sample_patches(gray, det.u, det.v, step, params.patch_size)
    area = float(np.median(det.area))
    stages = {
        "threshold + opening": lambda: ex.threshold_ink(gray, params),
        "connected regions": lambda: cv2.connectedComponentsWithStatsWithAlgorithm(
            roi, 8, cv2.CV_32S, cv2.CCL_BBDT),
        "spacing": lambda: ex.estimate_spacing(det.u, det.v, params.default_spacing_px,
                                               search_px=2.4 * np.sqrt(area)),
        "patch resampling": lambda: sample_patches(gray, det.u, det.v, step,
                                                      params.patch_size),
        "centre refinement": lambda: patch_centroid_offset(patches, params.dark_glyphs),
    }
    return [f"    {name:22s} cpu median {np.median(timed(fn, repeat)[1]):6.3f} ms"
            for name, fn in stages.items()]


def bag_images(path: str, count: int) -> list[np.ndarray]:
    """The first ``count`` left images of a bag, grey."""
    from tactile_sl_common.bag_io import BagReader
    from tactile_sl_common.images import to_gray

    out = []
    for _, msg in BagReader(path).messages(["/tactile/left/image_raw"]):
        out.append(np.array(to_gray(msg)))
        if len(out) >= count:
            break
    return out


def main() -> int:
    """Run the benchmark and print one row per image set and stage."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200, help="timed calls per image set")
    parser.add_argument("--bag", default=None, help="also time the left images of this bag")
    parser.add_argument("--stages", action="store_true",
                        help="also time each extraction stage alone")
    args = parser.parse_args()
    set_cpu_threads(1)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    clf = Classifier.load()
    sets = {"synthetic 16.5 px": [synth_image(np.random.default_rng(s), spacing=16.5).gray
                                  for s in range(4)]}
    if args.bag:
        sets[os.path.basename(args.bag)] = bag_images(args.bag, 4)
    print(f"one core: BLAS and cv2 threads {cv2.getNumThreads()}, affinity "
          f"{sorted(os.sched_getaffinity(0))}; machine load average {os.getloadavg()[0]:.2f} "
          f"on {os.cpu_count()} CPUs")
    for name, images in sets.items():
        dets = [extract_symbols(g) for g in images]
        glyphs = int(np.mean([len(d) for d in dets]))
        wall, cpu = timed(_cycle(extract_symbols, images), args.repeat)
        print(line(f"extraction  [{name}]", wall, cpu, f"{glyphs} glyphs/image"))
        if args.stages:
            print("\n".join(stage_rows(images[0], args.repeat)))
        wall, cpu = timed(_cycle(clf.predict, [d.patches for d in dets]), args.repeat)
        print(line(f"classification [{name}]", wall, cpu, f"{glyphs} patches/image"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
