#!/usr/bin/env python3
"""Where a glyph's image lies against its projected cell centre, and where the decoder puts it.

The robustness sweep's clean rows sit at 2.5-4 x their Cramer-Rao bound (docs/robustness.md),
and the bound takes each glyph's rendered image as known.  This asks what that image itself
says: the simulator renders a still pad without noise, once with every glyph, once with
none and nine times with every third row and column of glyphs (``Renderer.render(...,
ink_cells=..., linear=True)``: :func:`~tactile_sl_decoder.tooling.centre_bound.
glyph_shares`, as the bound does), and for each glyph compares with its
projected cell centre (the truth):

* the centroid of its own image share (paper minus print: the ink's darkening), as grey
  levels, and divided by the paper's level there (the reflectance the print removes);
* the decoder's centre (``extract_symbols`` on the 8-bit frame);
* each of them after removing a cubic in image position per symbol and camera (what is
  left is not a smooth function of where the glyph lies).

Figures in pixels, rms over the glyphs, per camera and symbol.  Not a pass/fail test.

    python tools/bench_centres.py                     # the shipped rig, 18 px spacing
    python tools/bench_centres.py --no-distortion --no-convergence
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from scipy.spatial import cKDTree


def _cubic_residual(u: np.ndarray, v: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The values ``y`` less their least-squares cubic in (u, v), normalised to the image."""
    a, b = u / 320.0 - 1.0, v / 240.0 - 1.0
    design = np.column_stack([np.ones_like(a), a, b, a * a, b * b, a * b, a ** 3, b ** 3,
                              a * a * b, a * b * b])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return y - design @ coef


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--spacing", type=float, default=18.0, help="glyph spacing, px")
    parser.add_argument("--supersample", type=int, default=4)
    parser.add_argument("--blur", type=float, default=0.5, help="blur_sigma, px")
    parser.add_argument("--vignetting", type=float, default=0.0)
    parser.add_argument("--no-distortion", action="store_true")
    parser.add_argument("--no-convergence", action="store_true",
                        help="cameras parallel and aligned (no convergence, no misalignment)")
    args = parser.parse_args()

    from tactile_sl_decoder.extract.extraction import extract_symbols
    from tactile_sl_decoder.tooling.centre_bound import glyph_shares
    from tactile_sl_decoder.tooling.training import DEFAULT_PRIMITIVES, artwork_values
    from tactile_sl_sim.artwork import load_artwork
    from tactile_sl_sim.optics import RigParams, SimulatedCameraPair
    from tactile_sl_sim.render import Nuisances, Renderer

    art = load_artwork()
    values = artwork_values(art, DEFAULT_PRIMITIVES)
    rig = RigParams.for_glyph_spacing(args.spacing)
    if args.no_distortion:
        rig = dataclasses.replace(rig, distortion=((0.0,) * 5, (0.0,) * 5))
    if args.no_convergence:
        rig = dataclasses.replace(rig, convergence=0.0, misalignment=((0.0,) * 3, (0.0,) * 3))
    renderer = Renderer(art, SimulatedCameraPair(rig), supersample=args.supersample)
    nz = Nuisances.from_dict({"blur_sigma": args.blur, "noise_sigma": 0.0, "shot_noise": 0.0,
                              "vignetting": args.vignetting})
    frame = renderer.render([], nz, seed=1, frame_index=0)      # the 8-bit images
    full, shares = glyph_shares(renderer, [], nz, seed=1, frame_index=0)
    truth = full.truth
    half = int(0.6 * args.spacing + 3)      # the glyph's blurred footprint, no other glyph
    rows: dict[int, list[tuple[float, ...]]] = {0: [], 1: []}
    for sel, side, share, paper in shares:
        px = truth.px_left if side == 0 else truth.px_right
        ink = np.clip(-share, 0.0, None).astype(np.float64)     # the ink's darkening
        removed = ink / np.maximum(paper, 1e-3)                  # ... as reflectance
        for k in np.flatnonzero(sel & truth.visible):
            u, v = px[k]
            iu, iv = int(round(u)), int(round(v))
            if min(iu, iv) < half or iu + half >= ink.shape[1] or iv + half >= ink.shape[0]:
                continue
            win = (slice(iv - half, iv + half + 1), slice(iu - half, iu + half + 1))
            ys, xs = np.mgrid[win]
            out = [truth.rows[k], truth.cols[k], u, v]
            for w in (ink[win], removed[win]):
                out += [(xs * w).sum() / w.sum() - u, (ys * w).sum() / w.sum() - v]
            rows[side].append(tuple(out))
    print(f"still pad, noise-free, spacing {args.spacing:g} px, supersample "
          f"{args.supersample}, blur {args.blur:g} px, vignetting {args.vignetting:g}"
          f"{', no distortion' if args.no_distortion else ''}"
          f"{', no convergence' if args.no_convergence else ''}")
    print("centre - projected cell centre, rms px u / v (after a cubic in position per "
          "symbol and camera)")
    print(f"{'camera':7s}{'symbol':8s}{'glyphs':>7s}  {'image share, grey':>26s}  "
          f"{'as reflectance':>26s}  {'decoder':>26s}")
    for side in (0, 1):
        r = np.asarray(rows[side])
        gray = frame.left if side == 0 else frame.right
        det = extract_symbols(gray)
        found = np.column_stack([det.u, det.v]).astype(np.float64)
        dist, near = cKDTree(found).query(r[:, 2:4])
        decoded = found[near] - r[:, 2:4]
        ok = dist < 0.25 * args.spacing
        symbol = values[r[:, 0].astype(int), r[:, 1].astype(int)]
        for s in range(int(symbol.max()) + 1):
            m = (symbol == s) & ok
            cols = []
            for du, dv in ((r[m, 4], r[m, 5]), (r[m, 6], r[m, 7]),
                           (decoded[m, 0], decoded[m, 1])):
                smooth = [np.std(_cubic_residual(r[m, 2], r[m, 3], e)) for e in (du, dv)]
                cols.append(f"{np.sqrt(np.mean(du ** 2)):.4f}/{np.sqrt(np.mean(dv ** 2)):.4f}"
                            f" ({smooth[0]:.4f}/{smooth[1]:.4f})")
            print(f"{'left' if side == 0 else 'right':7s}{DEFAULT_PRIMITIVES[s]:8s}"
                  f"{int(m.sum()):7d}  " + "  ".join(f"{c:>26s}" for c in cols))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
