"""`tactile-sl evaluate BAG.mcap ...`: symbol and end-to-end figures against ground truth.

The report is a list of sections, each a function of (args, bags) returning text; the
symbol sections live here, later stages append theirs to ``SECTIONS``.
"""
from __future__ import annotations

import argparse
import io
import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactile_sl_common.bag_io import BagError
from tactile_sl_common.safe_files import OutputError, check_output, write_text
from tactile_sl_decoder.classify.classifier import Classifier
from tactile_sl_decoder.cli.argtypes import number
from tactile_sl_decoder.pattern import load_default_pattern, load_pattern
from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
from tactile_sl_decoder.tooling.bag_runs import evaluate_bag, evaluate_touch_bag
from tactile_sl_decoder.tooling.e2e_metrics import BagMetrics, FrameMetrics
from tactile_sl_decoder.tooling.e2e_metrics import format_table as format_bag_table
from tactile_sl_decoder.tooling.evaluation import (
    aggregate,
    classification_section,
    confusion_section,
    evaluate_symbols_bag,
    extraction_section,
    format_confusion,
    format_table,
    to_json,
)
from tactile_sl_decoder.tooling.slip_metrics import format_slip_report, slip_frames
from tactile_sl_decoder.tooling.touch_metrics import (
    LIMITS,
    format_report,
    has_touch_truth,
    resolve_sensor,
    sensor_text,
)
from tactile_sl_decoder.tooling.training import DEFAULT_PRIMITIVES, artwork_values
from tactile_sl_decoder.touch.sensor import SensorFileError
from tactile_sl_sim.artwork import load_artwork


def register(subparsers: Any, summary: str | None = None) -> None:
    """Add the ``evaluate`` subcommand."""
    p = subparsers.add_parser(
        "evaluate", help=summary,
        description="Runs glyph extraction and classification on every frame of bags that "
        "carry /tactile/ground_truth/points and compares with the ground truth projected "
        "into both images (see docs/extraction.md for the definitions); then the end-to-end "
        "figures, and for bags with /tactile/ground_truth/wrench the touch figures "
        "(docs/touch_evaluation.md).")
    p.add_argument("bags", nargs="+", type=Path, help="MCAP bags with ground truth")
    p.add_argument("--pattern", type=Path, default=None,
                   help="pattern YAML giving the true symbol of each cell (default: shipped)")
    p.add_argument("--weights", type=Path, default=None,
                   help="classifier weights (default: shipped)")
    p.add_argument("--namespace", default="/tactile", help="topic namespace in the bags")
    p.add_argument("--max-frames", type=number(int, 0, 10**9), default=0,
                   help="frames per bag (0 = all)")
    p.add_argument("--totals-only", action="store_true",
                   help="print one row per scene instead of one per image")
    p.add_argument("--json", type=Path, default=None, help="also write every figure as JSON")
    p.add_argument("--sensor", type=Path, default=None, metavar="SENSOR.yaml",
                   help="sensor file for the touch figures (default: the elastomer of the "
                   "bag's scene in a *scenes.yaml beside it, else the shipped sensor file)")
    p.add_argument("--reference-frames", type=number(int, 1, 1000), default=1, metavar="N",
                   help="touch figures: the first N decoded frames are the untouched "
                   "reference, as in `tactile-sl replay` (default 1)")
    p.set_defaults(func=run)


class SkippedFrames:
    """Frames left out because their input is unusable: said once each on stderr, counted.

    Every section evaluates the same frames, so a frame is reported by the first section
    that meets it; ``evaluated`` counts the frames the symbol section could use.
    """

    def __init__(self, stream: Any = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.frames: dict[tuple[str, int], str] = {}
        self.evaluated = 0

    def callback(self, bag: Path) -> Callable[[int, str], None]:
        """``on_skip`` for the evaluations of one bag."""
        def skip(stamp_ns: int, why: str) -> None:
            key = (str(bag), int(stamp_ns))
            if key not in self.frames:
                self.frames[key] = why
                self.stream.write(f"\nevaluate: {Path(bag).name}: frame "
                                  f"{stamp_ns // 10**9}.{stamp_ns % 10**9:09d} skipped: {why}\n")
        return skip


def _skips(args: argparse.Namespace, bag: Path) -> Callable[[int, str], None] | None:
    skipped = getattr(args, "skipped", None)
    return skipped.callback(bag) if skipped is not None else None


def pattern_values(path: Path | None) -> tuple[np.ndarray, list[str], str]:
    """(values array, primitive names, where they came from) for labelling the truth."""
    try:
        pat = load_pattern(path) if path is not None else load_default_pattern()
        return pat.array, list(pat.primitives), str(path or "shipped pattern")
    except (ValueError, OSError) as exc:
        if path is not None:
            raise
        # the shipped pattern must match the shipped artwork; read the values from it
        print(f"evaluate: warning: shipped pattern unreadable ({exc}); reading cell values "
              "from the simulator artwork instead", file=sys.stderr)
        return (artwork_values(load_artwork(), DEFAULT_PRIMITIVES), list(DEFAULT_PRIMITIVES),
                "simulator artwork")


def symbol_sections(args: argparse.Namespace, bags: list[Path]) -> str:
    """Extraction, classification and confusion tables of every bag, plus JSON."""
    try:
        values, names, source = pattern_values(args.pattern)
        clf = Classifier.load(args.weights)
    except (ValueError, OSError) as exc:  # pattern, artwork and weights errors say which file
        raise SystemExit(f"evaluate: {exc}") from None
    all_rows, totals, out = [], [], []
    for bag in bags:
        def bar(done: int, total: int, name: str = bag.name) -> None:
            sys.stderr.write(f"\r{name}: frame {done}/{total}   ")
            sys.stderr.flush()
        try:
            rows = evaluate_symbols_bag(bag, values, clf, namespace=args.namespace,
                                        progress=bar, max_frames=args.max_frames,
                                        on_skip=_skips(args, bag))
        except BagError as exc:
            sys.stderr.write("\n")
            raise SystemExit(f"evaluate: {exc}") from None
        sys.stderr.write("\n")
        if getattr(args, "skipped", None) is not None:
            args.skipped.evaluated += len({r.frame for r in rows})
        if not rows:
            out.append(f"{bag.name}: no frame with ground truth could be evaluated\n")
            continue
        all_rows += rows
        totals.append(aggregate(rows))
    shown = totals if args.totals_only else [r for bag_rows in _by_scene(all_rows, totals)
                                             for r in bag_rows]
    out.append(f"true labels from {source}; classifier threshold {clf.threshold:.2f}\n")
    out.append(format_table(extraction_section(shown), "== extraction =="))
    out.append(format_table(classification_section(shown), "== classification =="))
    if totals:
        overall = aggregate(all_rows, "all scenes")
        if overall.matched > 100 and overall.accuracy < 0.6:
            out.append(f"WARNING: accuracy {100 * overall.accuracy:.1f} % is near chance: the "
                       f"pattern ({source}) is probably not the one these bags were "
                       "rendered from; pass the right one with --pattern\n")
        out.append(format_table(extraction_section(totals + [overall]),
                                "== extraction, per scene =="))
        out.append(format_table(classification_section(totals + [overall]),
                                "== classification, per scene =="))
        for t in totals + [overall]:
            out.append(format_confusion(confusion_section(t, names)))
    if args.json:
        write_text(args.json, json.dumps({"images": to_json(all_rows),
                                          "scenes": to_json(totals)}, indent=1))
    return "\n".join(out)


def _by_scene(rows: list[Any], totals: list[Any]) -> list[list[Any]]:
    out = []
    for t in totals:
        out.append([r for r in rows if r.scene == t.scene] + [t])
    return out


def e2e_section(args: argparse.Namespace, bags: list[Path]) -> str:
    """End-to-end figures per frame and per bag: coverage, wrong cells, 3-D error.

    Reads ``args.pattern``, ``args.weights``, ``args.namespace``, ``args.max_frames``,
    ``args.totals_only`` and ``args.json`` (figures also written to
    ``<json stem>.e2e.json``) when present.
    """
    classifier = None
    weights = getattr(args, "weights", None)
    if weights:
        classifier = Classifier.load(weights)
    pattern = getattr(args, "pattern", None)
    pipe = StereoPipeline(PatternSpec.load(pattern), classifier)
    namespace = getattr(args, "namespace", "/tactile")
    per_bag: list[BagMetrics] = []
    per_frame: list[tuple[str, FrameMetrics]] = []
    try:
        for bag in bags:
            frames, summary = evaluate_bag(bag, pipe, namespace, progress=sys.stderr,
                                           max_frames=int(getattr(args, "max_frames", 0) or 0),
                                           on_skip=_skips(args, bag))
            per_bag.append(summary)
            per_frame += [(summary.name, f) for f in frames]
    finally:
        pipe.close()
    out = io.StringIO()
    print("End to end (decoded cells and 3-D points vs ground truth; coverage = visible "
          "glyphs decoded to the right cell and triangulated)", file=out)
    if not getattr(args, "totals_only", False):
        print(f"{'bag':<24} {'stamp':>20} {'visible':>8} {'points':>7} {'coverage':>9} "
              f"{'wrong':>6} {'rmse mm':>8} {'med mm':>7} {'p95 mm':>7} {'ms':>6}", file=out)
        for name, f in per_frame:
            s = f.summary()
            print(f"{name:<24} {f.stamp_ns:>20} {f.visible:>8} {f.points:>7} "
                  f"{100 * f.coverage:>8.2f}% {f.wrong:>6} {1e3 * s['rmse_m']:>8.4f} "
                  f"{1e3 * s['median_m']:>7.4f} {1e3 * s['p95_m']:>7.4f} "
                  f"{f.timings_ms.get('total', float('nan')):>6.1f}", file=out)
        print(file=out)
    format_bag_table(per_bag, file=out)
    json_path = getattr(args, "json", None)
    if json_path:
        target = Path(json_path).with_suffix(".e2e.json")
        write_text(target, json.dumps({
            "bags": [b.summary() for b in per_bag],
            "frames": [dict(bag=name, **f.summary()) for name, f in per_frame]}, indent=1))
        print(f"(end-to-end figures also in {target})", file=out)
    return out.getvalue().rstrip("\n")


def touch_section(args: argparse.Namespace, bags: list[Path]) -> str:
    """Touch figures (displacement, force, moment, contact) of bags with touch ground truth.

    Bags with ``ground_truth/slip`` add the slip table and its acceptance figures.

    Reads ``args.sensor``, ``args.reference_frames``, ``args.pattern``, ``args.weights``,
    ``args.namespace``, ``args.max_frames``, ``args.totals_only`` and ``args.json`` (figures
    also written to ``<json stem>.touch.json``) when present.
    """
    try:
        namespace = getattr(args, "namespace", "/tactile")
        touch_bags = [b for b in bags if has_touch_truth(b, namespace)]
        if not touch_bags:
            return ("Touch: no bag carries ground_truth/wrench (render touch scenes with "
                    "`tactile-sl synth`, e.g. bags/touch_scenes.yaml)")
        sensor_path = getattr(args, "sensor", None)
        sensors = [resolve_sensor(b, sensor_path) for b in touch_bags]
        classifier = None
        weights = getattr(args, "weights", None)
        if weights:
            classifier = Classifier.load(weights)
        pipe = StereoPipeline(PatternSpec.load(getattr(args, "pattern", None)), classifier)
        per_bag = []
        try:
            for bag, (sensor, where) in zip(touch_bags, sensors):
                frames = evaluate_touch_bag(
                    bag, pipe, sensor, int(getattr(args, "reference_frames", 1) or 1), namespace,
                    progress=sys.stderr, max_frames=int(getattr(args, "max_frames", 0) or 0),
                    on_skip=_skips(args, bag))
                per_bag.append((Path(bag).stem, f"{sensor_text(sensor)} ({where})", frames))
        finally:
            pipe.close()
        text, totals = format_report(per_bag, bool(getattr(args, "totals_only", False)))
        slips = [(name, slip_frames(frames)) for name, _, frames in per_bag]
        slips = [(name, frames) for name, frames in slips if frames]
        if slips:           # bags with ground_truth/slip (scenes with friction)
            text += ("\n\nSlip (truth t / estimate e, contact pressing hardest; "
                     "docs/slip.md):\n" + format_slip_report(slips))
        skipped = [Path(b).stem for b in bags if b not in touch_bags]
        if skipped:
            text += f"\n(no touch ground truth, not in the touch figures: {', '.join(skipped)})"
        json_path = getattr(args, "json", None)
        if json_path:
            target = Path(json_path).with_suffix(".touch.json")
            write_text(target, json.dumps({
                "limits": asdict(LIMITS),
                "sensors": {name: sensor for name, sensor, _ in per_bag},
                "bags": totals,
                "frames": [f.summary() for _, _, frames in per_bag for f in frames]}, indent=1))
            text += f"\n(touch figures also in {target})"
        return text
    except (SensorFileError, BagError) as exc:
        raise SystemExit(f"evaluate: {exc}") from None


SECTIONS: list[Callable[[argparse.Namespace, list[Path]], str]] = [symbol_sections,
                                                                  e2e_section,
                                                                  touch_section]
"""Report sections, printed in order."""


def run(args: argparse.Namespace) -> int:
    """Print every section; returns the exit status."""
    missing = [str(b) for b in args.bags if not b.is_file()]
    if missing:
        print(f"evaluate: no such bag: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.json:     # before any work: an output that cannot be written is said at once

        try:
            check_output(args.json, args.bags)
        except OutputError as exc:
            print(f"evaluate: {exc}", file=sys.stderr)
            return 2
    args.skipped = SkippedFrames()
    for section in SECTIONS:
        print(section(args, list(args.bags)))
    skipped = len(args.skipped.frames)
    if skipped and not args.skipped.evaluated:
        print(f"evaluate: all {skipped} frame(s) with ground truth were skipped (unusable "
              "input, see above): nothing was evaluated", file=sys.stderr)
        return 1
    if skipped:
        print(f"evaluate: {skipped} frame(s) skipped (unusable input, see above); the figures "
              "are of the other frames", file=sys.stderr)
    return 0
