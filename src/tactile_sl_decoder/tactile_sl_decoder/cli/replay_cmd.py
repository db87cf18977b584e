"""`tactile-sl replay IN.mcap -o OUT.mcap [--sensor S.yaml]`: the decoder, offline.

Runs the same :class:`~tactile_sl_decoder.sensor_step.SensorStep` (pipeline, touch stage,
tare policy) as the ``decoder`` node over every stereo frame of a bag and writes
``/tactile/points`` (contract PointCloud2) for each frame that produced at least one point,
and the touch outputs (``field``, ``wrench``, ``contact``, ``depth``, ``slip``) for every
frame after the reference, all stamped exactly like their input frame.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tactile_sl_common.bag_io import BagError, BagReader, BagWriter
from tactile_sl_common.clouds import cloud_fields
from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_common.safe_files import OutputError, check_output, same_file
from tactile_sl_decoder.checks import check_classifier, load_pattern_spec
from tactile_sl_decoder.cli.argtypes import number
from tactile_sl_decoder.decode.codewords import PatternError
from tactile_sl_decoder.frames import bag_frames, bag_topics, count_bag_frames
from tactile_sl_decoder.glyphs import PipelineInputError
from tactile_sl_decoder.pipeline import PipelineParams, StereoPipeline
from tactile_sl_decoder.sensor_step import SensorStep
from tactile_sl_decoder.tooling.progress import progress_bar
from tactile_sl_decoder.touch.messages import pose_fields, touch_messages
from tactile_sl_decoder.touch.reference import residual_warning
from tactile_sl_decoder.touch.sensor import load_sensor
from tactile_sl_decoder.touch.stage import TouchParams

if TYPE_CHECKING:
    from tactile_sl_decoder.touch.driver import TouchFrame


def register(subparsers: Any, summary: str | None = None) -> None:
    """Add the ``replay`` subcommand."""
    p = subparsers.add_parser(
        "replay", help=summary,
        description="Decode every stereo frame of IN.mcap (images + camera_info) and write "
                    "the point clouds to OUT.mcap as /tactile/points.")
    p.add_argument("input", metavar="IN.mcap", help="bag with /tactile/{left,right}/image_raw "
                   "and /tactile/{left,right}/camera_info")
    p.add_argument("-o", "--output", metavar="OUT.mcap", required=True,
                   help="bag to write (/tactile/points)")
    p.add_argument("--pattern", metavar="P.yaml", default=None,
                   help="pattern file (default: the pattern the project ships)")
    p.add_argument("--allow-invalid-pattern", action="store_true",
                   help="use a pattern file that breaks its own min_hamming / window "
                        "uniqueness (experiments only; cells may be wrong)")
    p.add_argument("--classifier", metavar="WEIGHTS", default=None,
                   help="classifier weights (default: the shipped ones); their class count "
                        "must equal the pattern's symbols")
    p.add_argument("--mirrored", action="store_true",
                   help="the cameras see the artwork mirrored (sensor setting)")
    p.add_argument("--sensor", metavar="SENSOR.yaml", default=None,
                   help="sensor file: elastomer and pad frame (default: the shipped one)")
    p.add_argument("--reference-frames", type=number(int, 1, 1000), default=1, metavar="N",
                   help="the first N decoded frames are the untouched reference (default 1)")
    p.add_argument("--artwork-fit", action="store_true",
                   help="fit every decoded glyph's centre with the printed artwork before "
                        "triangulating (the decoder's artwork_fit.enabled; slower, more "
                        "precise: docs/robustness.md)")
    p.add_argument("--no-touch", action="store_true",
                   help="write only /tactile/points (no field, wrench, contact, depth, slip)")
    p.add_argument("--namespace", default="/tactile", help="topic namespace of the bag")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Replay a bag; exit status 0 on success, 1 on bad input files."""
    out_path = Path(args.output)
    try:     # OUT must not be IN: decided by the file system (hard links, bag directories)
        check_output(out_path, [args.input])
    except OutputError as exc:
        print(f"tactile-sl replay: {exc}", file=sys.stderr)
        return 2 if (same_file(args.input, out_path) or Path(args.input).is_dir()) else 1
    pipeline = None
    try:     # the whole input is validated before any output exists
        pattern = load_pattern_spec(args.pattern, args.allow_invalid_pattern)
        params = PipelineParams(classifier_weights=args.classifier)
        params.decode.mirrored = bool(args.mirrored)
        params.artwork_fit.enabled = bool(args.artwork_fit)
        pipeline = StereoPipeline(pattern, None, params)
        check_classifier(pipeline.load_classifier(), pattern.symbols,
                         args.classifier or "(shipped)")
        sensor = None if args.no_touch else load_sensor(args.sensor)
        step = SensorStep(pipeline, sensor, TouchParams(reference_frames=args.reference_frames))
        total = _count_input_frames(args, sensor is not None)
    except (BagError, PatternError, OSError, ValueError) as exc:
        if pipeline is not None:
            pipeline.close()
        print(f"tactile-sl replay: {exc}", file=sys.stderr)
        return 1
    prefix = bag_topics(args.namespace)["left_image"].rsplit("/left/", 1)[0]
    topic = prefix + "/points"
    touch_written = 0
    show = not args.no_progress
    written = skipped = empty = 0
    t0 = time.perf_counter()
    try:
        with BagWriter(out_path) as writer:
            for i, frame in enumerate(bag_frames(args.input, args.namespace,
                                                 ground_truth=False)):
                if show:
                    progress_bar(sys.stderr, i + 1, total, "replay")
                try:
                    if frame.left_info is None or frame.right_info is None:
                        raise PipelineInputError("no camera_info for this frame")
                    out = step.process(to_gray(frame.left_image), to_gray(frame.right_image),
                                       frame.left_info, frame.right_info)
                except (PipelineInputError, ImageFormatError) as exc:
                    skipped += 1
                    if show:
                        sys.stderr.write("\n")
                    print(f"tactile-sl replay: frame {frame.stamp[0]}.{frame.stamp[1]:09d} "
                          f"skipped: {exc}", file=sys.stderr)
                    continue
                result = out.stereo
                if len(result.points) == 0:
                    empty += 1
                    continue
                msg = cloud_fields(result.points, frame.stamp, result.frame_id)
                writer.write(topic, "sensor_msgs/msg/PointCloud2", msg, frame.stamp_ns)
                written += 1
                if step.touch is not None:
                    touch_written += _write_touch(writer, out.touch, frame, prefix,
                                                  step.touch.stage.sensor.pad_frame)
            _check_produced(written, skipped, empty, touch_written,
                            args.reference_frames if sensor is not None else 0)
    except (BagError, OSError, NothingProduced) as exc:
        if show:
            sys.stderr.write("\n")
        print(f"tactile-sl replay: {exc}; {out_path} not written", file=sys.stderr)
        return 1
    finally:
        pipeline.close()
    if show:
        sys.stderr.write("\n")
    dt = time.perf_counter() - t0
    frames = written + skipped + empty
    print(f"replay: {frames} stereo frames in {dt:.1f} s ({frames / max(dt, 1e-9):.1f} fps): "
          f"{written} clouds written to {out_path}, {empty} without points, {skipped} skipped"
          + (f"; touch outputs for {touch_written} frames" if sensor is not None else ""),
          file=sys.stderr)
    return 0


def _count_input_frames(args: argparse.Namespace, touch: bool) -> int:
    """Check the input bag before any output exists; its number of stereo frames.

    Raises BagError (unreadable, topics missing, no frames) or ValueError (the touch
    reference would take every frame: no touch output could follow).
    """
    reader = BagReader(args.input)
    topics = bag_topics(args.namespace)
    reader.require_topics([topics[k] for k in ("left_image", "right_image", "left_info",
                                              "right_info")])
    reader.verify()
    total = count_bag_frames(args.input, args.namespace)
    if total == 0:
        raise BagError(f"{reader.path}: no stereo frames (0 messages on "
                       f"{topics['left_image']}); nothing to replay")
    if touch and args.reference_frames >= total:
        raise ValueError(f"--reference-frames {args.reference_frames}: {reader.path} has "
                         f"{total} stereo frame(s), so no frame would follow the reference "
                         f"and no touch output would be written (take fewer reference "
                         f"frames, or --no-touch for the points alone)")
    return total


class NothingProduced(Exception):
    """The run produced none of what it was asked for: it fails, and no bag is written."""


def _check_produced(written: int, skipped: int, empty: int, touch_written: int,
                    reference_frames: int) -> None:
    """Raise NothingProduced when no cloud, or no touch output when they were asked for.

    ``reference_frames`` is 0 without touch outputs (``--no-touch``).
    """
    frames = written + skipped + empty
    if written == 0:
        raise NothingProduced(f"no point cloud from any of the {frames} stereo frame(s) "
                              f"({skipped} skipped for bad input, {empty} without points)")
    if reference_frames and touch_written == 0:
        raise NothingProduced(f"no touch output: no frame followed a usable reference "
                              f"({written} frame(s) with points, the reference takes "
                              f"{reference_frames}); take fewer --reference-frames, or "
                              f"--no-touch for the points alone")


def _write_touch(writer: Any, touch: "TouchFrame", frame: Any, prefix: str,
                 pad_frame: str) -> int:
    """Touch outputs of one frame into the bag (1 if written, 0 while building the reference).

    Offline the reference is prepared in line: it is ready at the frame that completes it,
    and every later frame has outputs (none waits, so there is no backlog).
    """
    if touch.reference_failed is not None:
        print(f"tactile-sl replay: frame {frame.stamp[0]}.{frame.stamp[1]:09d}: reference not "
              f"usable ({touch.reference_failed}); trying again with the next frames",
              file=sys.stderr)
        return 0
    if touch.result is None:
        ready = touch.reference_ready
        if ready is not None:                        # the reference was just taken
            pose = pose_fields(ready.reference.pose, frame.stamp, ready.frame_id)
            writer.write(f"{prefix}/pad_pose", "geometry_msgs/msg/PoseStamped", pose,
                         frame.stamp_ns)
            warning = residual_warning(ready.reference.pose.residual_rms)
            if warning is not None:
                print(f"tactile-sl replay: WARNING: reference at frame {frame.stamp[0]}."
                      f"{frame.stamp[1]:09d}: {warning}", file=sys.stderr)
        return 0
    for name, schema, fields in touch_messages(touch.result, frame.stamp, pad_frame):
        writer.write(f"{prefix}/{name}", schema, fields, frame.stamp_ns)
    return 1
