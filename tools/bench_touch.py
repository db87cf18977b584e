#!/usr/bin/env python3
"""Benchmark of the touch stage: accuracy against known loads and its time per frame.

    python tools/bench_touch.py                  # the three touch bags + an untouched control
    python tools/bench_touch.py --repeat 5       # more frames for the timing figures

Runs the evaluation of ``tactile-sl evaluate`` (pipeline + touch stage, each frame decoded
once, reference = the first frame) over bags/touch_halfspace.mcap and
bags/touch_calibration.mcap (elastic half-space) and bags/touch_layer.mcap (2 mm layer),
with E and nu of bags/touch_scenes.yaml, and over bags/no_contact.mcap as an untouched
control (truth: no force, no contact, no displacement).  Prints the per-frame and per-bag
table with the acceptance limits of issue 10 (figures, not pass/fail: the exit status is 0),
then the touch stage's time per frame (``TouchResult.timings_ms['touch']``) beside the
pipeline's own time per stereo pair (``timings_ms['total']``), measured in the same run,
and the machine's load.  Definitions: docs/touch_evaluation.md.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

import numpy as np

from tactile_sl_camera.elasticity import Elastomer
from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
from tactile_sl_decoder.tooling.bag_runs import evaluate_touch_bag
from tactile_sl_decoder.tooling.touch_metrics import format_report, sensor_text
from tactile_sl_decoder.touch.sensor import SensorConfig

REPO = pathlib.Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"
# (bag, layer thickness m): E and nu as in bags/touch_scenes.yaml
TOUCH_BAGS = (("touch_halfspace", 0.0), ("touch_layer", 0.002), ("touch_calibration", 0.0))
CONTROL_BAG = "no_contact"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3,
                        help="evaluate the bags this many times (timing samples; the table "
                        "is from the first pass)")
    parser.add_argument("--youngs-modulus", type=float, default=3.0e5, help="Pa")
    parser.add_argument("--poisson-ratio", type=float, default=0.49)
    args = parser.parse_args()
    load0 = os.getloadavg()
    pipe = StereoPipeline(PatternSpec.load(None))
    touch_ms: list[float] = []
    pipeline_ms: list[float] = []
    report = None
    t0 = time.perf_counter()
    try:
        for rep in range(max(1, args.repeat)):
            per_bag = []
            for name, thickness in TOUCH_BAGS + ((CONTROL_BAG, 0.0),):
                sensor = SensorConfig(Elastomer(args.youngs_modulus, args.poisson_ratio,
                                                thickness), source="bench_touch")
                control = name == CONTROL_BAG
                frames = evaluate_touch_bag(BAGS / f"{name}.mcap", pipe, sensor,
                                            untouched=control,
                                            progress=sys.stderr if rep == 0 else None)
                what = sensor_text(sensor) + (" (untouched control: zero truth)"
                                              if control else "")
                per_bag.append((name, what, frames))
                touch_ms += [f.timings_ms["touch"] for f in frames if "touch" in f.timings_ms]
                pipeline_ms += [f.timings_ms["pipeline"] for f in frames]
            if report is None:
                report = format_report(per_bag)[0]
    finally:
        pipe.close()
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    print(report)
    print()
    t, p = np.asarray(touch_ms), np.asarray(pipeline_ms)
    print(f"time per stereo frame, same run ({len(t)} frames with touch outputs over "
          f"{max(1, args.repeat)} pass(es), {wall:.1f} s; load average "
          f"{load0[0]:.2f} before, {load1[0]:.2f} after, on {os.cpu_count()} CPUs):")
    print(f"{'':<22} {'median ms':>10} {'p90 ms':>8} {'max ms':>8}")
    for label, v in (("touch stage", t), ("pipeline (total)", p)):
        print(f"{label:<22} {np.median(v):>10.2f} {np.percentile(v, 90):>8.2f} "
              f"{v.max():>8.2f}")
    print(f"touch stage / pipeline (medians): {100 * np.median(t) / np.median(p):.1f} %; "
          f"limit: touch stage <= 3 ms per frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
