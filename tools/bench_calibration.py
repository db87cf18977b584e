"""Benchmark: stereo calibration with the printed pattern vs a checkerboard, and --check.

Simulated views (the simulator's rig is the truth): N view pairs of the flat artwork at
tilts up to 35 deg and 12-20 mm, with a share of the pattern hidden in each, calibrate the
pair through the pattern-target path; checkerboard views at the same poses (fully visible)
go through the checkerboard path.  Both are scored on reprojection RMS, focal lengths,
principal points and baseline against the truth, and on triangulation error of separate flat
test views of the pattern (decoded by the pipeline, triangulated with each calibration).
Then the health check judges the truth and three bad calibrations from an untouched frame.
Then views of the whole artwork tilted 20/30/35/40 deg about either axis (16 mm, the
pattern's centre on the rig's axis): per camera, the cells visible (glyph wholly inside the
image) and the share of them decoded to the right cell, and wrong cells.
Figures, not pass/fail (the acceptance limits are printed beside them).

    python tools/bench_calibration.py [--views 12] [--hide 0.3] [--test-views 6]
                                      [--tilts 20,30,35,40] [--tilt-distance 0.016] [--plain]

``--plain``: the decoder as the sensor's pipeline runs it (no perspective extraction, no
local lattice gates), the figures before tilted views were handled.
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from tactile_sl_common.camera_info import CameraCalibration
from tactile_sl_decoder.calibrate import (
    CalibrationOptions,
    PatternTarget,
    ViewDecoder,
    calibrate_pattern_stereo,
)
from tactile_sl_decoder.calibrate.checkerboard import calibrate_stereo
from tactile_sl_decoder.calibrate.health import calibration_health, matched_cells
from tactile_sl_decoder.calibrate.result import CalibrationError
from tactile_sl_decoder.calibrate.simulate import (
    artwork_of,
    random_poses,
    render_board_views,
    render_pattern_views,
    score_decoded_cells,
    tilted_pose,
    true_cells_left,
)
from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_sim.render import Renderer


def _errors(left: CameraCalibration, right: CameraCalibration, baseline: float,
            rig: object) -> dict[str, float]:
    """Relative focal / baseline errors (%) and principal point errors (px) vs the truth."""
    true_l, true_r = rig.left, rig.right  # type: ignore[attr-defined]
    f = max(abs(est.K[i, i] / true.K[i, i] - 1) for est, true in ((left, true_l),
                                                                  (right, true_r))
            for i in (0, 1))
    pp = max(float(np.abs(est.K[:2, 2] - true.K[:2, 2]).max())
             for est, true in ((left, true_l), (right, true_r)))
    b = abs(baseline / np.linalg.norm(rig.T) - 1)  # type: ignore[attr-defined]
    return {"focal_pct": 100 * f, "pp_px": pp, "baseline_pct": 100 * b}


def _test_cells(decoder: ViewDecoder, views: list, poses: list, renderer: Renderer,
                target: PatternTarget) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cells decoded in both images of the test views: left uv, right uv, true xyz (m)."""
    uvl, uvr, truth = [], [], []
    for (img_l, img_r), pose in zip(views, poses):
        v = decoder.decode(img_l, img_r)
        row, col, a, b = matched_cells(v.left, v.right, target)
        uvl.append(a)
        uvr.append(b)
        truth.append(true_cells_left(renderer, pose, row, col, target.pitch_m))
    return np.concatenate(uvl), np.concatenate(uvr), np.concatenate(truth)


def _triangulation_errors(cells: tuple[np.ndarray, np.ndarray, np.ndarray],
                          left: CameraCalibration, right: CameraCalibration) -> np.ndarray:
    """3-D error (m) of every test cell triangulated with a calibration (pipeline's stereo)."""
    uvl, uvr, truth = cells
    xyz, _err = StereoRig(left, right).triangulate(uvl, uvr)
    return np.linalg.norm(xyz - truth, axis=1)


def _bad(rig: object, rotate_deg: tuple[float, float, float] = (0, 0, 0),
         focal: float = 1.0) -> StereoRig:
    K1 = rig.left.K.copy()  # type: ignore[attr-defined]
    K1[0, 0] *= focal
    K1[1, 1] *= focal
    dR = cv2.Rodrigues(np.radians(np.asarray(rotate_deg, float)))[0]
    R, T = dR @ rig.R, dR @ rig.T  # type: ignore[attr-defined]
    Dl, Dr, Kr = rig.left.D, rig.right.D, rig.right.K  # type: ignore[attr-defined]
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, Dl, Kr, Dr, (640, 480), R, T.reshape(3, 1),
                                           flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    return StereoRig(CameraCalibration(640, 480, K1, Dl, R1, P1),
                     CameraCalibration(640, 480, Kr, Dr, R2, P2))


def tilted_view_rows(decoder: ViewDecoder, renderer: Renderer, artwork: object,
                     target: PatternTarget, tilts: list[float], distance_m: float,
                     seed: int = 0) -> list[dict[str, object]]:
    """Per tilt and axis, per camera: visible cells, decoded share, wrong cells.

    Scored by :func:`~tactile_sl_decoder.calibrate.simulate.score_decoded_cells`.
    """
    out = []
    for axis in ("x", "y"):
        for tilt in tilts:
            pose = tilted_pose(artwork, axis, tilt, distance_m)  # type: ignore[arg-type]
            (left, right), = render_pattern_views(renderer, artwork,  # type: ignore[arg-type]
                                                  [pose], seed=seed)
            row: dict[str, object] = {"axis": axis, "tilt": tilt}
            for cam, glyphs in enumerate(decoder.decode_glyphs(left, right)):
                visible, right_cells, wrong = score_decoded_cells(
                    renderer, pose, glyphs, target.shape, target.pitch_m, cam)
                side = "LR"[cam]
                row[f"visible_{side}"] = visible
                row[f"share_{side}"] = 100.0 * right_cells / max(visible, 1)
                row[f"wrong_{side}"] = wrong
            out.append(row)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument("--hide", type=float, default=0.3)
    ap.add_argument("--test-views", type=int, default=6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--board", default="9x6", help="checkerboard inner corners COLSxROWS")
    ap.add_argument("--square", type=float, default=0.0008, help="checkerboard square, m")
    ap.add_argument("--tilts", default="20,30,35,40", help="tilted views, deg ('' = none)")
    ap.add_argument("--tilt-distance", type=float, default=0.016,
                    help="distance of the tilted pattern's centre from the cameras, m")
    ap.add_argument("--plain", action="store_true",
                    help="the sensor pipeline's settings: no perspective extraction, no "
                         "local lattice gates (the figures before tilted views decoded)")
    args = ap.parse_args()
    board = tuple(int(v) for v in args.board.split("x"))

    artwork = artwork_of()
    renderer = Renderer(artwork)
    rig = renderer.rig
    target = PatternTarget.load()
    poses = random_poses(args.views, artwork, seed=args.seed, hide_fraction=args.hide)
    t0 = time.perf_counter()
    pattern_views = render_pattern_views(renderer, artwork, poses, seed=args.seed)
    board_views = render_board_views(renderer, artwork, poses, board, args.square,
                                     seed=args.seed)
    test_poses = random_poses(args.test_views, artwork, seed=args.seed + 1000)
    test_views = render_pattern_views(renderer, artwork, test_poses, seed=args.seed + 1000)
    print(f"rendered {args.views} calibration pairs ({100 * args.hide:.0f} % of the pattern "
          f"hidden in each), {args.views} checkerboard pairs at the same poses and "
          f"{args.test_views} test pairs in {time.perf_counter() - t0:.1f} s")

    decoder = ViewDecoder(target, tilted=not args.plain)
    t0 = time.perf_counter()
    views = [decoder.decode(left, right, f"{i:03d}")
             for i, (left, right) in enumerate(pattern_views)]
    t_decode = time.perf_counter() - t0
    rows = {}
    for name, fix in (("pattern", False), ("pattern, fixed K", True)):
        t0 = time.perf_counter()
        cal = calibrate_pattern_stereo(views, target, CalibrationOptions(fix_intrinsics=fix))
        if name == "pattern":
            print(cal.report())
            print(cal.summary())
        rows[name] = {"pairs": f"{cal.result.pairs_used}/{len(views)}",
                      "rms_px": cal.result.rms_stereo,
                      "points": len(cal.points_left),
                      **_errors(cal.left, cal.right, cal.result.baseline, rig),
                      "calib": (cal.left, cal.right),
                      "seconds": t_decode + time.perf_counter() - t0}
    try:
        t0 = time.perf_counter()
        res = calibrate_stereo(board_views, board, args.square, min_pairs=3)
        rows["checkerboard"] = {"pairs": f"{res.pairs_used}/{res.pairs_total}",
                                "rms_px": res.rms_stereo,
                                "points": res.pairs_used * board[0] * board[1],
                                **_errors(res.left, res.right, res.baseline, rig),
                                "calib": (res.left, res.right),
                                "seconds": time.perf_counter() - t0}
    except CalibrationError as exc:
        print(f"checkerboard path: {exc}")
    rows["truth"] = {"pairs": "-", "rms_px": float("nan"), "points": 0, "focal_pct": 0.0,
                     "pp_px": 0.0, "baseline_pct": 0.0,
                     "calib": (rig.left_info, rig.right_info), "seconds": 0.0}
    cells = _test_cells(decoder, test_views, test_poses, renderer, target)
    # Glyphs whose centroid the extractor misplaced (they triangulate badly with the true
    # calibration too) say nothing about a calibration: score every calibration on the
    # same cells, those within 25 um with the truth.
    good = _triangulation_errors(cells, rig.left_info, rig.right_info) < 25e-6
    for row in rows.values():
        e = _triangulation_errors(cells, *row["calib"])[good]
        row["tri_um"] = 1e6 * float(np.sqrt(np.mean(e ** 2)))
    print(f"\n{'calibration':18s} {'pairs':>6s} {'corners':>7s} {'RMS px':>7s} "
          f"{'focal %':>8s} {'pp px':>6s} {'baseline %':>10s} {'triang. um':>10s} {'s':>5s}")
    for name, r in rows.items():
        print(f"{name:18s} {r['pairs']:>6s} {r['points']:7d} {r['rms_px']:7.3f} "
              f"{r['focal_pct']:8.4f} {r['pp_px']:6.3f} {r['baseline_pct']:10.4f} "
              f"{r['tri_um']:10.2f} {r['seconds']:5.1f}")
    print(f"{'acceptance':18s} {'12':>6s} {'':7s} {'<=0.1':>7s} {'<=0.2':>8s} {'<=0.5':>6s} "
          f"{'<=0.2':>10s} {'<=5':>10s}")
    print(f"(triangulation: RMS 3-D error, left optical frame, of {int(good.sum())} cells "
          f"decoded in both images of {args.test_views} flat test views; {int((~good).sum())} "
          "cells with misplaced centroids (> 25 um even with the true calibration) left out; "
          "'truth' = the centroid-noise floor)")

    frame = renderer.render([], seed=args.seed)
    gl, gr = decoder.decode_glyphs(frame.left, frame.right)
    print("\nhealth check on one untouched frame:")
    print(f"{'calibration':34s} {'resid px':>8s} {'flat um':>8s} {'pitch %':>8s} "
          f"{'tilt deg':>8s} verdict")
    cases = {"truth": StereoRig(rig.left_info, rig.right_info),
             "right turned 0.2 deg about x": _bad(rig, (0.2, 0, 0)),
             "right turned 0.2 deg about y": _bad(rig, (0, 0.2, 0)),
             "right turned 0.2 deg about z": _bad(rig, (0, 0, 0.2)),
             "left focal (fx, fy) off 1 %": _bad(rig, focal=1.01),
             "swapped left/right files": StereoRig(rig.right_info, rig.left_info)}
    for name, r in cases.items():
        rep = calibration_health(gl, gr, r, target)
        print(f"{name:34s} {rep.reprojection_rms_px:8.3f} {rep.flatness_rms_m * 1e6:8.2f} "
              f"{100 * rep.pitch_error:8.3f} {rep.tilt_deg:8.2f} {rep.verdict}")
    tilts = [float(t) for t in args.tilts.split(",") if t.strip()]
    if tilts:
        print(f"\ntilted views ({1e3 * args.tilt_distance:.0f} mm): visible cells, decoded "
              "share, wrong cells, left | right")
        for r in tilted_view_rows(decoder, renderer, artwork, target, tilts,
                                  args.tilt_distance, seed=args.seed):
            print(f"  {r['tilt']:4.0f} deg about {r['axis']}: "
                  + " | ".join(f"{r[f'visible_{s}']:4d} visible, {r[f'share_{s}']:5.1f} % "
                               f"decoded, {r[f'wrong_{s}']} wrong" for s in "LR"))
        print("  acceptance: >= 80 % decoded at 40 deg about either axis")
    decoder.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
