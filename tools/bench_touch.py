#!/usr/bin/env python3
"""Benchmark of the touch stage: accuracy against known loads and its time per frame.

    python tools/bench_touch.py                  # the three touch bags + an untouched control
    python tools/bench_touch.py --repeat 5       # more frames for the timing figures
    python tools/bench_touch.py --no-slip        # without the slip scenes
    python tools/bench_touch.py --no-shapes      # without the indenter shape scenes
    python tools/bench_touch.py --compare        # lighting table without and with weights
    python tools/bench_touch.py --no-slip --no-shapes --light-seeds 11 12 13 14 15 16 --bound

Runs the evaluation of ``tactile-sl evaluate`` (pipeline + touch stage, each frame decoded
once, reference = the first frame) over bags/touch_halfspace.mcap and
bags/touch_calibration.mcap (elastic half-space) and bags/touch_layer.mcap (2 mm layer),
with E and nu of bags/touch_scenes.yaml, and over bags/no_contact.mcap as an untouched
control (truth: no force, no contact, no displacement).  Prints the per-frame and per-bag
table with the acceptance limits of issue 10 (figures, not pass/fail: the exit status is 0).

Then the indenter shape scenes (bags/shape_scenes.yaml: a sphere, a small sphere, flat
punches, a cylinder lying on the pad, a long rounded edge, two contacts and a 2 mm layer,
each untouched then pressed lightly and firmly; rendered into a temporary folder first, a
few seconds): per frame the true and estimated contact area and largest indentation, with
the limits of issue 25 (area within 15 %, indentation within 10 um).

Then the slip scenes (bags/slip_scenes.yaml: tangential loads ramped to gross slip at several
friction coefficients, sizes, directions and normal loads, with and without image
nuisances; rendered into a temporary folder first, about a minute): per scene and frame the
true and estimated slip state, stick ratio, margin and friction coefficient, and the
acceptance figures of issue 24 (docs/slip.md).

Then the lighting scenes (bags/light_scenes.yaml: the same known loads under clean light,
harsh light and harsh light with MJPEG; rendered first, a few seconds): per scene the pooled
displacement RMSE and its ratio to the clean scene's, and the worst centroid, normal force,
force vector and contact area errors, with the limits of issue 25 (harsh rows: RMSE <= 2x clean,
centroid <= 0.1 mm, force within 2 %).  ``--light-seeds 11 12 13`` renders them once per
noise seed (the file's own seed is 11) and pools the figures of every draw: the RMSE over all
of them, the worst frame of any draw (one draw's worst can be luck: docs/touch.md, "the 0.1 N
frame's figures depend on the noise draw").  ``--compare`` evaluates every touch bag and scene
twice, without the per-cell weights (``WeightParams.enabled = False``, the touch stage before
issue 25) and with them, and prints both side by side, with both touch stage times.
``--bound`` (with five or more ``--light-seeds``) adds, per scene and load, the touch stage's
scatter over the draws beside the Cramer-Rao bound of the load's normal force and centroid,
from the draws' own displacement noise and from the images' point bounds
(tactile_sl_decoder/tooling/touch_bound.py; docs/touch.md, "What the images allow").

Last the touch stage's time per frame (``TouchResult.timings_ms['touch']``) and its slip
estimate's part (``['slip']``) beside the pipeline's own time per stereo pair
(``timings_ms['total']``), measured in the same run, and the machine's load.
Definitions: docs/touch_evaluation.md, docs/slip.md.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time
from typing import Any

import numpy as np

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
from tactile_sl_decoder.tooling.bag_runs import displacement_errors, evaluate_touch_bag
from tactile_sl_decoder.tooling.light_report import (
    light_bound_table,
    light_draws_table,
    light_table,
)
from tactile_sl_decoder.tooling.slip_metrics import format_slip_report, slip_frames
from tactile_sl_decoder.tooling.touch_metrics import (
    format_report,
    format_shape_report,
    sensor_text,
)
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams
from tactile_sl_decoder.touch.weights import WeightParams

REPO = pathlib.Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"
# (bag, layer thickness m): E and nu as in bags/touch_scenes.yaml
TOUCH_BAGS = (("touch_halfspace", 0.0), ("touch_layer", 0.002), ("touch_calibration", 0.0))
CONTROL_BAG = "no_contact"
SLIP_SCENES = BAGS / "slip_scenes.yaml"
SHAPE_SCENES = BAGS / "shape_scenes.yaml"
LIGHT_SCENES = BAGS / "light_scenes.yaml"


def render_scenes(scenes_file: pathlib.Path, out: pathlib.Path, only: list[str],
                  seeds: list[int] | None = None
                  ) -> list[tuple[str, pathlib.Path, SensorConfig]]:
    """The scenes of ``scenes_file`` as bags in ``out``: (name, bag, its sensor).

    ``only``: these scene names (all when empty).  ``seeds``: each scene once per noise seed
    (same name; the file's own seed when None or empty).
    """
    import dataclasses

    from tactile_sl_sim.scenes import load_scenes
    from tactile_sl_sim.synth import RendererCache, write_scene_bag

    cache = RendererCache()
    out.mkdir(parents=True, exist_ok=True)
    bags = []
    scenes = load_scenes(scenes_file)
    unknown = sorted(set(only) - {s.name for s in scenes})
    if unknown:
        raise SystemExit(f"bench_touch: no scene {', '.join(unknown)} in {scenes_file}")
    draws = [(s, None) for s in scenes] if not seeds else [
        (dataclasses.replace(s, seed=seed), seed) for s in scenes for seed in seeds]
    for scene, seed in (d for d in draws if not only or d[0].name in only):
        label = scene.name if seed is None else f"{scene.name}_seed{seed}"
        sys.stderr.write(f"rendering {label} ({scene.frames} frames)\n")
        path = write_scene_bag(scene, cache.get(scene), out / f"{label}.mcap")
        bags.append((scene.name, path, SensorConfig(scene.elastomer, source=str(scenes_file))))
    return bags


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3,
                        help="evaluate the bags this many times (timing samples; the table "
                        "is from the first pass)")
    parser.add_argument("--youngs-modulus", type=float, default=3.0e5, help="Pa")
    parser.add_argument("--poisson-ratio", type=float, default=0.49)
    parser.add_argument("--slip-scenes", type=pathlib.Path, default=SLIP_SCENES,
                        help="scenes with friction to render and evaluate (default: %(default)s)")
    parser.add_argument("--no-slip", action="store_true", help="leave the slip scenes out")
    parser.add_argument("--only", action="append", default=[], metavar="SCENE",
                        help="render only this slip scene (repeatable; default: all)")
    parser.add_argument("--shape-scenes", type=pathlib.Path, default=SHAPE_SCENES,
                        help="indenter shapes to render and evaluate (default: %(default)s)")
    parser.add_argument("--no-shapes", action="store_true",
                        help="leave the indenter shape scenes out")
    parser.add_argument("--light-scenes", type=pathlib.Path, default=LIGHT_SCENES,
                        help="known loads under clean and harsh light (default: %(default)s)")
    parser.add_argument("--no-light", action="store_true", help="leave the lighting scenes out")
    parser.add_argument("--light-seeds", type=int, nargs="+", default=[], metavar="SEED",
                        help="render the lighting scenes once per noise seed and pool the "
                        "draws (default: the file's own seed)")
    parser.add_argument("--per-draw", action="store_true",
                        help="also each lighting draw's signed normal force and centroid error "
                        "per load (with --light-seeds: bias or scatter)")
    parser.add_argument("--bound", action="store_true",
                        help="with --light-seeds (5 or more): the Cramer-Rao bound of each "
                        "lighting scene's normal force and centroid per load, from the draws' "
                        "displacement noise and from the images' point bounds, beside the "
                        "touch stage's scatter over the draws (about 20 s per scene)")
    parser.add_argument("--bound-pictures", type=pathlib.Path, metavar="DIR",
                        help="with --bound: each lighting scene's lightest load as a picture "
                        "in DIR (the displacement noise as measured and as the images allow "
                        "it, and where the best normal force's noise comes from)")
    parser.add_argument("--artwork-fit", action="store_true",
                        help="the decoder's artwork fit on (artwork_fit.enabled: glyph centres "
                        "fitted with the printed artwork)")
    parser.add_argument("--compare", action="store_true",
                        help="the touch bags and lighting scenes without the per-cell weights "
                        "too (the touch stage before issue 25), side by side")
    args = parser.parse_args()
    if args.bound and (args.no_light or len(set(args.light_seeds)) < 5):
        parser.error("--bound needs the lighting scenes with --light-seeds of 5 or more seeds "
                     "(each cell's noise is its variance over the draws)")
    if args.bound_pictures is not None and not args.bound:
        parser.error("--bound-pictures needs --bound")
    with tempfile.TemporaryDirectory(prefix="bench_touch_") as tmp:
        shape_bags = ([] if args.no_shapes else
                      render_scenes(args.shape_scenes, pathlib.Path(tmp) / "shapes", []))
        slip_bags = [] if args.no_slip else render_scenes(args.slip_scenes,
                                                          pathlib.Path(tmp) / "slip", args.only)
        light_bags = ([] if args.no_light else
                      render_scenes(args.light_scenes, pathlib.Path(tmp) / "light", [],
                                    args.light_seeds))
        return _run(args, slip_bags, shape_bags, light_bags)


def _run(args: argparse.Namespace, slip_bags: list[tuple[str, pathlib.Path, SensorConfig]],
         shape_bags: list[tuple[str, pathlib.Path, SensorConfig]],
         light_bags: list[tuple[str, pathlib.Path, SensorConfig]]) -> int:
    load0 = os.getloadavg()
    pipe = StereoPipeline(PatternSpec.load(None))
    pipe.params.artwork_fit.enabled = bool(args.artwork_fit)
    times: dict[str, list[float]] = {"touch": [], "slip": [], "pipeline": []}
    unweighted_times: list[float] = []
    weighted = TouchParams()
    unweighted = TouchParams(weights=WeightParams(enabled=False))
    report = slip_report = shape_report = light_report = None
    t0 = time.perf_counter()
    try:
        for rep in range(max(1, args.repeat)):
            progress = sys.stderr if rep == 0 else None
            per_bag = []
            compared: list[tuple[str, list, list]] = []   # (name, unweighted, weighted)
            for name, thickness in TOUCH_BAGS + ((CONTROL_BAG, 0.0),):
                sensor = SensorConfig(Elastomer(args.youngs_modulus, args.poisson_ratio,
                                                thickness), source="bench_touch")
                control = name == CONTROL_BAG
                frames = evaluate_touch_bag(BAGS / f"{name}.mcap", pipe, sensor,
                                            untouched=control, progress=progress,
                                            touch_params=weighted)
                what = sensor_text(sensor) + (" (untouched control: zero truth)"
                                              if control else "")
                per_bag.append((name, what, frames))
                _collect(times, frames)
                if args.compare:
                    old = evaluate_touch_bag(BAGS / f"{name}.mcap", pipe, sensor,
                                             untouched=control, touch_params=unweighted)
                    unweighted_times.extend(f.timings_ms["touch"] for f in old
                                            if "touch" in f.timings_ms)
                    compared.append((name, old, frames))
            draws, noise = _light_pass(args, light_bags, pipe, progress, times,
                                       unweighted_times, compared, rep == 0)
            per_shape = []
            for name, path, sensor in shape_bags:
                frames = evaluate_touch_bag(path, pipe, sensor, progress=progress)
                per_shape.append((name, frames))
                _collect(times, frames)
            per_scene = []
            for name, path, sensor in slip_bags:
                frames = evaluate_touch_bag(path, pipe, sensor, progress=progress)
                per_scene.append((name, slip_frames(frames)))
                _collect(times, frames)
            if report is None:
                report = format_report(per_bag)[0]
                light_report = (light_table(compared, args.compare)
                                if light_bags or args.compare else None)
                if light_report and args.per_draw:
                    light_report += "\n\n" + light_draws_table(draws)
                if light_report and args.bound:
                    light_report += "\n\n" + light_bound_table(args.light_scenes, noise, draws,
                                                                     args.bound_pictures)
                slip_report = format_slip_report(per_scene) if per_scene else None
                shape_report = format_shape_report(per_shape) if per_shape else None
    finally:
        pipe.close()
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    print(report)
    print()
    if shape_report:
        print(f"indenter shapes ({args.shape_scenes}):")
        print(shape_report)
        print()
    if light_report:
        draws = (f"; {len(args.light_seeds)} draws, seeds "
                 f"{' '.join(map(str, args.light_seeds))}, pooled" if args.light_seeds else "")
        print(f"lighting and touch bags ({args.light_scenes}{draws}; per-cell weights, "
              f"docs/touch.md; before -> with weights):" if args.compare else
              f"lighting ({args.light_scenes}{draws}):")
        print(light_report)
        print()
    if slip_report:
        print(f"slip ({args.slip_scenes}; truth t / estimate e; docs/slip.md):")
        print(slip_report)
        print()
    t, s, p = (np.asarray(times[k]) for k in ("touch", "slip", "pipeline"))
    print(f"time per stereo frame, same run ({len(t)} frames with touch outputs over "
          f"{max(1, args.repeat)} pass(es), {wall:.1f} s; load average "
          f"{load0[0]:.2f} before, {load1[0]:.2f} after, on {os.cpu_count()} CPUs):")
    print(f"{'':<22} {'median ms':>10} {'p90 ms':>8} {'max ms':>8}")
    for label, v in (("touch stage", t), ("  of which slip", s), ("pipeline (total)", p)):
        print(f"{label:<22} {np.median(v):>10.2f} {np.percentile(v, 90):>8.2f} "
              f"{v.max():>8.2f}")
    if unweighted_times:
        u = np.asarray(unweighted_times)
        print(f"{'touch, no weights':<22} {np.median(u):>10.2f} {np.percentile(u, 90):>8.2f} "
              f"{u.max():>8.2f}   (--compare: the same bags, weights off)")
    print(f"touch stage / pipeline (medians): {100 * np.median(t) / np.median(p):.1f} %; "
          f"limits: touch stage <= 3 ms, slip estimate <= 1 ms per frame")
    return 0


def _light_pass(args: argparse.Namespace,
                light_bags: list[tuple[str, pathlib.Path, SensorConfig]], pipe: StereoPipeline,
                progress: Any, times: dict[str, list[float]], unweighted_times: list[float],
                compared: list[tuple[str, list, list]], first: bool
                ) -> tuple[list[tuple[str, str, list]], dict[str, list[dict]]]:
    """One pass over the lighting bags: their draws' frames and raw errors.

    The frames are also appended to ``compared``, pooled per scene; the raw errors (the touch
    bound's noise) are taken with ``--bound`` on the ``first`` pass only.
    """
    pooled: dict[str, tuple[list, list]] = {}     # a scene's draws (--light-seeds)
    draws: list[tuple[str, str, list]] = []       # (scene, bag name, frames)
    noise: dict[str, list[dict]] = {}             # --bound: the draws' raw errors
    for name, path, sensor in light_bags:
        frames = evaluate_touch_bag(path, pipe, sensor, progress=progress,
                                    touch_params=TouchParams())
        _collect(times, frames)
        draws.append((name, pathlib.Path(path).stem, frames))
        old = []
        if args.compare:
            old = evaluate_touch_bag(path, pipe, sensor,
                                     touch_params=TouchParams(weights=WeightParams(enabled=False)))
            unweighted_times.extend(f.timings_ms["touch"] for f in old
                                    if "touch" in f.timings_ms)
        if args.bound and first:
            noise.setdefault(name, []).append(displacement_errors(path, pipe, sensor))
        before, after = pooled.setdefault(name, ([], []))
        before.extend(old)
        after.extend(frames)
    compared.extend((name, old, new) for name, (old, new) in pooled.items())
    return draws, noise


def _collect(times: dict[str, list[float]], frames: list) -> None:
    for f in frames:
        times["pipeline"].append(f.timings_ms["pipeline"])
        for key in ("touch", "slip"):
            if key in f.timings_ms:
                times[key].append(f.timings_ms[key])


if __name__ == "__main__":
    sys.exit(main())
