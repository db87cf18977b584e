"""``tactile-sl calibrate``: stereo calibration into camera_info YAML files, and its check.

Modes, one per source option (mutually exclusive), dispatched by :func:`run`:

- ``--folder DIR`` / ``--bag BAG``: calibrate from image pairs; with ``--target PATTERN.yaml``
  from views of the printed pattern (:mod:`tactile_sl_decoder.calibrate`), else from a
  checkerboard (``--pattern COLSxROWS --square M``,
  :mod:`tactile_sl_decoder.calibrate.checkerboard`);
- ``--simulate N``: write N simulated view pairs and the true calibration (pattern views with
  ``--target``, else checkerboards);
- ``--check BAG``: judge a calibration from untouched frames of the assembled sensor;
- ``--refine BAG``: re-estimate the extrinsics from such frames, intrinsics fixed;
- ``--bag BAG --loads LOADS.yaml``: force calibration, the elastomer's Young's modulus (and
  with ``--fit-thickness`` its thickness) from frames with known loads
  (:mod:`tactile_sl_decoder.touch.force_calibration`), written as OUT/sensor.yaml.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
from typing import TYPE_CHECKING, Any, Callable

import cv2
import numpy as np

from tactile_sl_common.bag_io import BagError
from tactile_sl_common.camera_info import (
    CameraInfoError,
    calibration_from_msg,
    camera_info_yaml_text,
    load_camera_info_yaml,
)
from tactile_sl_common.images import to_gray
from tactile_sl_common.safe_files import check_outputs, write_files
from tactile_sl_decoder.calibrate import (
    CalibrationOptions,
    PatternTarget,
    ViewDecoder,
    calibrate_pattern_stereo,
)
from tactile_sl_decoder.calibrate.checkerboard import (
    calibrate_stereo,
    iter_bag_pairs,
    iter_folder_pairs,
    unpaired_images,
)
from tactile_sl_decoder.calibrate.health import calibration_health, refine_extrinsics
from tactile_sl_decoder.calibrate.result import CalibrationError
from tactile_sl_decoder.calibrate.simulate import (
    artwork_of,
    random_poses,
    render_pattern_views,
    simulated_board_views,
    write_views,
)
from tactile_sl_decoder.cli.argtypes import number
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.glyphs import PipelineInputError
from tactile_sl_decoder.pattern import PatternFormatError, load_default_pattern, load_pattern
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_decoder.touch.force_calibration import calibrate_forces, load_loads_file
from tactile_sl_decoder.touch.sensor import load_sensor, sensor_yaml_text
from tactile_sl_sim.artwork import Artwork
from tactile_sl_sim.render import Renderer

if TYPE_CHECKING:  # the modes import numpy themselves, so that --help stays fast
    import numpy as np

PROG = "tactile-sl calibrate"
CAMERA_FILES = ["left.yaml", "right.yaml"]
"""What every calibrating mode writes into -o (written all or none, see safe_files)."""


def _pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected COLSxROWS, e.g. 9x6") from exc
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError("a checkerboard needs at least 2x2 inner corners")
    return cols, rows


def _fraction(text: str) -> float:
    value = float(text)
    if not 0.0 <= value < 0.9:
        raise argparse.ArgumentTypeError("expected a fraction in [0, 0.9)")
    return value


def register(subparsers: argparse._SubParsersAction, summary: str | None = None) -> None:
    """Add the ``calibrate`` subcommand."""
    p = subparsers.add_parser(
        "calibrate", help=summary,
        description="Calibrate the stereo pair by Zhang's method (OpenCV) from views of the "
        "printed pattern (--target, partial views fine) or of a checkerboard, and write "
        "OUT/left.yaml and OUT/right.yaml in ROS camera_calibration format (K, D plumb_bob, "
        "R and P from stereoRectify), which the camera nodes load through "
        "left_camera_info_url / right_camera_info_url. --check BAG judges a calibration "
        "from untouched frames of the assembled sensor; --refine BAG re-estimates its "
        "extrinsics from them. See docs/calibration.md.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--folder", help="folder of image pairs named like left_000.png / "
                     "right_000.png")
    src.add_argument("--bag", help="MCAP bag with left/right image topics (paired by stamp)")
    src.add_argument("--simulate", type=int, metavar="N",
                     help="write N simulated view pairs to OUT (left_NNN.png, right_NNN.png) "
                     "plus the true calibration (truth_left.yaml, truth_right.yaml), then stop")
    src.add_argument("--check", metavar="BAG", help="health check: untouched frames of the "
                     "assembled sensor; prints residual, flatness, pitch error, pad pose and "
                     "a verdict (exit 0 pass, 1 fail)")
    src.add_argument("--refine", metavar="BAG", help="refine the stereo extrinsics from "
                     "untouched frames of the assembled sensor (intrinsics fixed); writes OUT")
    t = p.add_argument_group("printed-pattern target")
    t.add_argument("--target", nargs="?", const="", default=None, metavar="PATTERN.yaml",
                   help="calibrate with the printed pattern (default file: the shipped one)")
    t.add_argument("--mirrored", action="store_true",
                   help="the cameras see the artwork mirrored (sensor setting)")
    t.add_argument("--min-cells", type=int, default=30,
                   help="decoded cells a view needs per camera (default 30)")
    t.add_argument("--min-views", type=int, default=4,
                   help="usable views needed per camera (default 4)")
    t.add_argument("--fix-intrinsics", action="store_true",
                   help="stereo step keeps each camera's own intrinsics (default: refine)")
    t.add_argument("--no-coverage", action="store_true", help="do not write coverage.png")
    t.add_argument("--hide", type=_fraction, default=0.3,
                   help="--simulate with --target: share of the cells hidden per view")
    t.add_argument("--seed", type=int, default=0, help="--simulate: random seed")
    c = p.add_argument_group("checkerboard target")
    c.add_argument("--pattern", type=_pattern, default=(9, 6),
                   help="inner corners COLSxROWS (default 9x6)")
    c.add_argument("--square", type=float, default=0.001,
                   help="square size in metres (default 0.001)")
    h = p.add_argument_group("--check / --refine")
    h.add_argument("--calibration", metavar="DIR", help="folder with left.yaml and right.yaml "
                   "to judge (default: the CameraInfo recorded in the bag)")
    h.add_argument("--left-info", help="left camera_info YAML (overrides --calibration)")
    h.add_argument("--right-info", help="right camera_info YAML (overrides --calibration)")
    h.add_argument("--frames", type=int, default=3, help="untouched frames used (default 3)")
    f = p.add_argument_group("force calibration (--bag BAG --loads LOADS.yaml)")
    f.add_argument("--loads", metavar="LOADS.yaml", help="known normal loads, "
                   "'loads: [{frame: I, normal_force: N}, ...]' (frames of --bag from 0, "
                   "pressing force in N); fits the Young's modulus and writes OUT/sensor.yaml")
    f.add_argument("--sensor", metavar="SENSOR.yaml", default=None,
                   help="starting sensor file: Poisson ratio, thickness, pad frame (default: "
                   "the shipped one)")
    f.add_argument("--fit-thickness", action="store_true",
                   help="also choose the layer thickness (0 = half-space ... 8 mm) that best "
                   "explains the displacement fields")
    f.add_argument("--reference-frames", type=number(int, 1, 1000), default=1, metavar="N",
                   help="the first N decoded frames are the untouched reference (default 1)")
    p.add_argument("--left-topic", default="/tactile/left/image_raw")
    p.add_argument("--right-topic", default="/tactile/right/image_raw")
    p.add_argument("--every", type=int, default=1, help="use every Nth pair of a bag")
    p.add_argument("--free-k3", action="store_true",
                   help="also estimate k3 (default: fixed at 0, like ROS camera_calibration)")
    p.add_argument("-o", "--output", default=".", help="output folder (default .)")
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- dispatch


MODES: tuple[tuple[str, Callable[[argparse.Namespace], bool]], ...] = (
    ("simulate", lambda a: a.simulate is not None),
    ("check", lambda a: a.check is not None),
    ("refine", lambda a: a.refine is not None),
    ("force", lambda a: a.loads is not None),        # --bag with --loads
    ("target", lambda a: a.target is not None),      # --folder / --bag with --target
    ("board", lambda a: True),                       # --folder / --bag: checkerboard
)
"""Modes in order of precedence: the first whose test holds runs (add new ones above
"target")."""


def _mode(args: argparse.Namespace) -> str:
    return next(name for name, applies in MODES if applies(args))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``tactile-sl calibrate``: one handler per mode."""
    handlers: dict[str, Callable[[argparse.Namespace], int]] = {
        "board": _run_board, "target": _run_target, "simulate": _run_simulate,
        "check": _run_check, "refine": _run_refine, "force": _run_force}
    try:
        return handlers[_mode(args)](args)
    except (CalibrationError, BagError, CameraInfoError, ValueError, OSError) as exc:
        print(f"\n{PROG}: {exc}", file=sys.stderr)
        return 1


def _pairs(args: argparse.Namespace) -> Any:
    if args.folder:
        alone = unpaired_images(args.folder)
        if alone:       # "pairs used 4/4" alone would hide them
            print(f"{PROG}: {len(alone)} image(s) without a partner, not used: "
                  f"{', '.join(p.name for p in alone)}", file=sys.stderr)
        return iter_folder_pairs(args.folder)
    return iter_bag_pairs(args.bag, args.left_topic, args.right_topic, args.every)


def _target(args: argparse.Namespace) -> Any:
    try:
        return PatternTarget.load(args.target or None, mirrored=args.mirrored)
    except (PatternFormatError, OSError) as exc:
        raise ValueError(f"--target: {exc}") from None


# --------------------------------------------------------------------------- modes


def _run_board(args: argparse.Namespace) -> int:
    """Checkerboard calibration (the original path)."""
    check_outputs(args.output, CAMERA_FILES)       # before any work

    def on_pair(i: int, ok: bool) -> None:
        print(f"\rpair {i + 1}: {'board found' if ok else 'no board'}   ", end="",
              file=sys.stderr, flush=True)

    result = calibrate_stereo(_pairs(args), args.pattern, args.square,
                              fix_k3=not args.free_k3, on_pair=on_pair)
    print(file=sys.stderr)
    left, right = result.save(pathlib.Path(args.output))
    print(result.summary())
    print(f"wrote {left} and {right}")
    return 0


def _run_target(args: argparse.Namespace) -> int:
    """Printed-pattern calibration: decode every view, calibrate, report, write."""
    check_outputs(args.output, CAMERA_FILES + ([] if args.no_coverage else ["coverage.png"]))
    target = _target(args)
    decoder = ViewDecoder(target)
    views, first = [], None
    try:
        for i, (left, right) in enumerate(_pairs(args)):
            view = decoder.decode(_gray(left), _gray(right), f"{i:03d}")
            print(f"\rview {view.name}: {len(view.left)} / {len(view.right)} cells decoded   ",
                  end="", file=sys.stderr, flush=True)
            views.append(view)
            first = first or (left, right)
    finally:
        decoder.close()
    print(file=sys.stderr)
    opts = CalibrationOptions(min_cells=args.min_cells, min_views=args.min_views,
                              fix_k3=not args.free_k3, fix_intrinsics=args.fix_intrinsics)
    try:
        cal = calibrate_pattern_stereo(views, target, opts)
    except CalibrationError as exc:
        for v in views:
            print(f"view {v.name}: cells L {len(v.left)} R {len(v.right)}", file=sys.stderr)
        raise CalibrationError(f"{exc}{_mirror_hint(target, views, first, opts)}") from None
    print(cal.report())
    print(cal.summary())
    written = cal.save(args.output, coverage=not args.no_coverage)
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _gray(image: Any) -> Any:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def _mirror_hint(target: Any, views: list[Any], first: Any, opts: Any) -> str:
    """Advice when the first pair decodes far better with the other ``mirrored`` setting."""
    if first is None or not views:
        return ""
    now = max(len(views[0].left), len(views[0].right))
    other = ViewDecoder(PatternTarget(target.pattern, not target.mirrored))
    try:
        alt = other.decode(_gray(first[0]), _gray(first[1]))
    finally:
        other.close()
    then = max(len(alt.left), len(alt.right))
    if then >= opts.min_cells and then > 3 * now:
        flag = "pass --mirrored" if not target.mirrored else "drop --mirrored"
        return (f". The first view decodes {then} cells with mirrored="
                f"{'false' if target.mirrored else 'true'} ({now} now): the cameras see the "
                f"artwork {'as printed' if target.mirrored else 'mirrored'}; {flag}")
    return ""


def _run_simulate(args: argparse.Namespace) -> int:
    """Simulated views (pattern with --target, else checkerboards) and the truth."""
    out = pathlib.Path(args.output)
    if args.simulate < 1:
        raise ValueError("--simulate needs at least 1 view")
    if args.target is None:
        # the pad artwork is irrelevant for boards: a blank one keeps this independent of it
        blank = Artwork(np.ones((8, 8), np.float32), (3.5, 3.5), 4.0, 0.0005, 1, 1)
        renderer = Renderer(blank)
        views = simulated_board_views(renderer, args.pattern, args.square, args.simulate,
                                      seed=args.seed)
        write_views(out, views, renderer)
        print(f"wrote {len(views)} simulated checkerboard pairs and the true calibration "
              f"to {out}")
        return 0

    pattern = load_pattern(args.target) if args.target else load_default_pattern()
    artwork = artwork_of(pattern if args.target else None)
    renderer = Renderer(artwork)
    poses = random_poses(args.simulate, artwork, seed=args.seed, hide_fraction=args.hide)
    views = render_pattern_views(renderer, artwork, poses, mirrored=args.mirrored,
                                 seed=args.seed)
    write_views(out, views, renderer, poses)
    print(f"wrote {len(views)} simulated views of the pattern ({100 * args.hide:.0f} % hidden "
          f"each) and the true calibration to {out}")
    return 0


def _untouched(args: argparse.Namespace, bag: str) -> tuple[list[Any], Any, Any]:
    """Decoded untouched frames of a bag, and the calibration to judge (left, right)."""
    if args.frames < 1:
        raise ValueError("--frames must be at least 1")
    folder = pathlib.Path(args.calibration) if args.calibration else None
    left_path = args.left_info or (folder / "left.yaml" if folder else None)
    right_path = args.right_info or (folder / "right.yaml" if folder else None)
    if (left_path is None) != (right_path is None):
        raise ValueError("give both --left-info and --right-info (or --calibration DIR)")
    files = left_path is not None and right_path is not None
    decoder = ViewDecoder(_target(args))
    views, infos = [], None
    try:
        # the bag's camera_info topics are needed only without calibration files
        for frame in bag_frames(bag, ground_truth=False, camera_info=not files):
            views.append(decoder.decode(to_gray(frame.left_image), to_gray(frame.right_image),
                                        f"{frame.stamp[0]}.{frame.stamp[1]:09d}"))
            if infos is None and frame.left_info is not None and frame.right_info is not None:
                infos = (frame.left_info, frame.right_info)
            if len(views) >= args.frames:
                break
    finally:
        decoder.close()
    if not views:
        raise ValueError(f"{bag}: no stereo frames")
    if left_path is not None and right_path is not None:
        return views, load_camera_info_yaml(left_path), load_camera_info_yaml(right_path)
    if infos is None:
        raise ValueError(f"{bag}: no CameraInfo recorded; pass --calibration DIR")
    return (views, calibration_from_msg(infos[0], "left CameraInfo"),
            calibration_from_msg(infos[1], "right CameraInfo"))


def _run_check(args: argparse.Namespace) -> int:
    """Health check in place: figures and a verdict (exit status 0 pass, 1 fail)."""
    views, left, right = _untouched(args, args.check)
    report = calibration_health([v.left for v in views], [v.right for v in views],
                                StereoRig(left, right), _target(args))
    print(f"{len(views)} untouched frame(s) of {args.check}")
    print(report.summary())
    return 0 if report.ok else 1


def _run_refine(args: argparse.Namespace) -> int:
    """Refine the extrinsics in place; write the refined calibration atomically."""
    check_outputs(args.output, CAMERA_FILES)       # before any work
    views, left, right = _untouched(args, args.refine)
    target = _target(args)
    before = calibration_health([v.left for v in views], [v.right for v in views],
                                StereoRig(left, right), target)
    result = refine_extrinsics(views, left, right, target)
    after = calibration_health([v.left for v in views], [v.right for v in views],
                               StereoRig(result.left, result.right), target)
    print(f"before:\n{before.summary()}\nafter refining the extrinsics (RMS "
          f"{result.rms_stereo:.3f} px, baseline {result.baseline * 1e3:.4f} mm):\n"
          f"{after.summary()}")
    written = write_files(args.output, {
        "left.yaml": camera_info_yaml_text(result.left).encode(),
        "right.yaml": camera_info_yaml_text(result.right).encode()})
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _run_force(args: argparse.Namespace) -> int:
    """Fit the elastomer to a recording with known loads; write OUT/sensor.yaml."""
    if not args.bag:
        raise ValueError("--loads needs the recording: --bag BAG")
    check_outputs(args.output, ["sensor.yaml"])      # before any work
    loads = load_loads_file(args.loads)
    start = load_sensor(args.sensor)
    pattern = PatternSpec.load(args.target or None)
    params = PipelineParams()
    params.decode.mirrored = bool(args.mirrored)
    pipeline = StereoPipeline(pattern, None, params)
    frames: list[np.ndarray] = []
    try:
        for frame in bag_frames(args.bag, "/tactile", ground_truth=False):
            if frame.left_info is None or frame.right_info is None:
                continue
            try:
                result = pipeline.process(to_gray(frame.left_image), to_gray(frame.right_image),
                                          frame.left_info, frame.right_info)
            except PipelineInputError as exc:
                print(f"{PROG}: frame {len(frames)} skipped: {exc}", file=sys.stderr)
                continue
            if len(result.points):
                frames.append(result.points)
    finally:
        pipeline.close()
    print(f"{PROG}: {len(frames)} decoded frames in {args.bag}; fitting "
          f"{len(loads)} known loads", file=sys.stderr)

    def progress(h: float, residual: float) -> None:
        if args.fit_thickness:
            print(f"  thickness {h * 1e3:.3g} mm: displacement residual {residual:.4f}",
                  file=sys.stderr)

    fit = calibrate_forces(frames, loads, start, pattern.array.shape, pattern.pitch_m,
                           bool(args.mirrored), args.reference_frames, args.fit_thickness,
                           progress)
    print(fit.report())
    comment = (f"written by tactile-sl calibrate --loads {args.loads} --bag {args.bag}\n"
               f"RMS force error {fit.rms_error * 100:.2f} % over {len(fit.loads)} loads")
    written = write_files(args.output, {
        "sensor.yaml": sensor_yaml_text(fit.sensor, comment).encode()})
    print(f"wrote {written[0]}")
    return 0
