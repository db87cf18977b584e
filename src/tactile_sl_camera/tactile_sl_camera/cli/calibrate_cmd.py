"""``tactile-sl calibrate``: stereo checkerboard calibration into camera_info YAML files."""
from __future__ import annotations

import argparse
import pathlib
import sys


def _pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected COLSxROWS, e.g. 9x6") from exc
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError("a checkerboard needs at least 2x2 inner corners")
    return cols, rows


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` subcommand."""
    p = subparsers.add_parser(
        "calibrate", help="stereo checkerboard calibration -> left/right camera_info YAML",
        description="Calibrate the stereo pair from checkerboard image pairs (Zhang's method "
        "through OpenCV) and write OUT/left.yaml and OUT/right.yaml in ROS camera_calibration "
        "format (K, D plumb_bob, R and P from stereoRectify), which the camera nodes load "
        "through left_camera_info_url / right_camera_info_url.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--folder", help="folder of image pairs named like left_000.png / "
                     "right_000.png")
    src.add_argument("--bag", help="MCAP bag with left/right image topics (paired by stamp)")
    src.add_argument("--simulate", type=int, metavar="N",
                     help="write N simulated checkerboard pairs to OUT (left_NNN.png, "
                     "right_NNN.png) plus the true calibration (truth_left.yaml, "
                     "truth_right.yaml), then stop")
    p.add_argument("--pattern", type=_pattern, default=(9, 6),
                   help="inner corners COLSxROWS (default 9x6)")
    p.add_argument("--square", type=float, default=0.001,
                   help="square size in metres (default 0.001)")
    p.add_argument("--left-topic", default="/tactile/left/image_raw")
    p.add_argument("--right-topic", default="/tactile/right/image_raw")
    p.add_argument("--every", type=int, default=1, help="use every Nth pair of a bag")
    p.add_argument("--free-k3", action="store_true",
                   help="also estimate k3 (default: fixed at 0, like ROS camera_calibration)")
    p.add_argument("-o", "--output", default=".", help="output folder (default .)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``tactile-sl calibrate``."""
    from ..bag_io import BagError
    from ..calibration import CalibrationError, calibrate_stereo, iter_bag_pairs, iter_folder_pairs

    out = pathlib.Path(args.output)
    if args.simulate is not None:
        return _simulate(args, out)
    pairs = (iter_folder_pairs(args.folder) if args.folder else
             iter_bag_pairs(args.bag, args.left_topic, args.right_topic, args.every))

    def on_pair(i: int, ok: bool) -> None:
        print(f"\rpair {i + 1}: {'board found' if ok else 'no board'}   ", end="",
              file=sys.stderr, flush=True)

    try:
        result = calibrate_stereo(pairs, args.pattern, args.square,
                                  fix_k3=not args.free_k3, on_pair=on_pair)
    except (CalibrationError, BagError) as exc:
        print(f"\ntactile-sl calibrate: {exc}", file=sys.stderr)
        return 1
    print(file=sys.stderr)
    left, right = result.save(out)
    print(result.summary())
    print(f"wrote {left} and {right}")
    return 0


def _simulate(args: argparse.Namespace, out: pathlib.Path) -> int:
    import cv2
    import numpy as np

    from ..calibration import simulated_board_views
    from ..camera_info import save_camera_info_yaml
    from ..sim.artwork import Artwork
    from ..sim.render import Renderer

    # the pad artwork is irrelevant for boards: a blank one keeps this independent of it
    blank = Artwork(np.ones((8, 8), np.float32), (3.5, 3.5), 4.0, 0.0005, 1, 1)
    renderer = Renderer(blank)
    views = simulated_board_views(renderer, args.pattern, args.square, args.simulate)
    out.mkdir(parents=True, exist_ok=True)
    for i, (left, right) in enumerate(views):
        cv2.imwrite(str(out / f"left_{i:03d}.png"), left)
        cv2.imwrite(str(out / f"right_{i:03d}.png"), right)
    save_camera_info_yaml(out / "truth_left.yaml", renderer.rig.left_info)
    save_camera_info_yaml(out / "truth_right.yaml", renderer.rig.right_info)
    print(f"wrote {len(views)} simulated pairs and the true calibration to {out}")
    return 0
