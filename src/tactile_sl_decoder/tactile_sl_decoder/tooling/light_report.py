"""The lighting scenes' tables of ``tools/bench_touch.py`` (no rclpy).

Per lighting scene (bags/light_scenes.yaml, rendered in one or more noise draws): the pooled
figures against the limits of issue 25 (:func:`light_table`), each draw's signed force and
centroid error per load (:func:`light_draws_table`: bias or scatter) and the touch stage's
scatter over the draws beside the Cramer-Rao bound of the load's estimates
(:func:`light_bound_table`, :mod:`~tactile_sl_decoder.tooling.touch_bound`).
"""
from __future__ import annotations

import pathlib
import sys

import cv2
import numpy as np

from tactile_sl_common.safe_files import atomic_path
from tactile_sl_decoder.tooling.pictures import render_cells
from tactile_sl_decoder.tooling.touch_bound import (
    FrameBound,
    centre_within_share,
    scene_bounds,
    within_share,
)
from tactile_sl_sim.scenes import load_scenes
from tactile_sl_sim.synth import RendererCache

CLEAN_LIGHT = "light_clean"
"""The scene whose displacement RMSE the others are compared with."""


def _light_figures(frames: list) -> dict[str, float]:
    """Pooled displacement RMSE (m) and the worst centroid (m), normal and vector errors (%)."""
    cells = sum(f.cells for f in frames)
    sq = sum(f.disp_rmse ** 2 * f.cells for f in frames if f.cells)
    loaded = [f for f in frames if f.force_true is not None and np.any(f.force_true)]
    return {
        "rmse": float(np.sqrt(sq / cells)) if cells else float("nan"),
        "centroid": max((f.centroid_err for f in frames if f.contact_true), default=np.nan),
        "normal": max((abs(f.normal_err_pct) for f in loaded), default=np.nan),
        "vector": max((100.0 * float(np.linalg.norm(f.force_est - f.force_true)
                                     / np.linalg.norm(f.force_true)) for f in loaded),
                      default=np.nan),
        "area": max((abs(f.area_err_pct) for f in frames if f.contact_true), default=np.nan)}


def light_draws_table(draws: list[tuple[str, str, list]]) -> str:
    """Per lighting scene and load, each draw's signed normal force error and centroid error.

    What the pooled table's worst frame hides: whether a load's error is a bias (one sign in
    every draw) or scatter.  ``draws``: (scene, bag name, evaluated frames) per rendered bag.
    """
    seeds = [bag.rsplit("_seed", 1)[1] for _, bag, _ in draws if "_seed" in bag]
    columns = "seeds " + ", ".join(dict.fromkeys(seeds)) if seeds else "the file's draw"
    lines = [f"per draw: signed normal force error %, centroid error mm; columns: {columns}"]
    for scene in dict.fromkeys(name for name, _, _ in draws):
        runs = [frames for name, _, frames in draws if name == scene]
        lines.append(f"{scene}:")
        for k, frame in enumerate(runs[0]):
            if frame.force_true is None or not np.any(frame.force_true):
                continue
            same = [frames[k] for frames in runs if len(frames) > k]
            fn = " ".join(f"{f.normal_err_pct:+6.2f}" for f in same)
            cen = " ".join(f"{1e3 * f.centroid_err:5.3f}" if f.contact_true else "    -"
                           for f in same)
            errors = np.array([f.normal_err_pct for f in same])
            sd = float(errors.std(ddof=1)) if len(errors) > 1 else 0.0
            lines.append(f"  Fn {-float(frame.force_true[2]):5.2f} N  dFn % {fn}   (mean "
                         f"{errors.mean():+.2f}, sd {sd:.2f})   dCen mm {cen}")
    return "\n".join(lines)


def light_bound_table(scenes_file: pathlib.Path, noise: dict[str, list[dict]],
                      draws: list[tuple[str, str, list]],
                      pictures: pathlib.Path | None = None) -> str:
    """Per lighting scene and load: the touch stage's scatter over the draws beside its bound.

    The bound (:mod:`tactile_sl_decoder.tooling.touch_bound`) of an unbiased estimator that
    knows the load's profile but not its force, centre or radius: from the draws' measured
    displacement noise ("points") and from the images' point bounds ("images").  The last
    columns: the chance that an estimator at the images' bound meets the harsh rows' limits
    (force within 2 %, centroid within 0.1 mm) in one draw and in every draw.  ``pictures``:
    a folder for each scene's picture of its lightest load (:func:`write_bound_picture`).
    """
    scenes = {s.name: s for s in load_scenes(scenes_file)}
    cache = RendererCache()
    n_draws = max(len(v) for v in noise.values())
    lines = [f"bound ({n_draws} draws; Cramer-Rao, docs/touch.md 'What the images allow'): "
             f"sd of the normal force and rms of the centroid error, the touch stage's over "
             f"the draws beside the bound from the points' noise and from the images (and "
             f"the touch stage's mean normal force error: its bias); P: an estimator at the "
             f"images' bound within 2 % and 0.1 mm, 1 draw / all",
             f"{'scene':<20} {'Fn N':>5} {'mean dFn mN':>12} {'sd Fn mN: touch':>16} {'points':>7} "
             f"{'images':>7} {'dCen rms mm: touch':>19} {'points':>7} {'images':>7} "
             f"{'P(Fn) 1 / all':>15} {'P(cen) 1 / all':>15}"]
    for name, scene_draws in noise.items():
        sys.stderr.write(f"bound: {name}\n")
        scene = scenes[name]
        runs = [frames for scene_name, _, frames in draws if scene_name == name]
        bounds = scene_bounds(scene, scene_draws, cache.get(scene))
        if pictures is not None and bounds:
            lightest = min(bounds, key=lambda b: -float(b.force[2]))
            path = write_bound_picture(pictures / f"touch_bound_{name}.png", name, lightest)
            sys.stderr.write(f"bound: wrote {path}\n")
        for b in bounds:
            stamp = scene.stamp_ns(b.frame)
            same = [f for frames in runs for f in frames if f.stamp_ns == stamp]
            fn = -float(b.force[2])
            if len(same) < 2 or fn <= 0:
                continue
            err = np.array([f.normal_err for f in same])
            cen = np.array([f.centroid_err for f in same if f.contact_true])
            cen_rms = float(np.sqrt(np.mean(cen ** 2))) if len(cen) else float("nan")
            img = b.images if b.images is not None else b.points
            p_fn = within_share(0.02 * fn, img.normal_force_sd)
            p_cen = centre_within_share(1e-4, img.centre_rms)
            lines.append(
                f"{name:<20} {fn:5.2f} {1e3 * err.mean():+12.2f} {1e3 * err.std(ddof=1):16.2f} "
                f"{1e3 * b.points.normal_force_sd:7.2f} {1e3 * img.normal_force_sd:7.2f} "
                f"{1e3 * cen_rms:19.3f} {1e3 * b.points.centre_rms:7.3f} "
                f"{1e3 * img.centre_rms:7.3f} "
                f"{p_fn:7.2f} / {p_fn ** len(same):5.2f} {p_cen:7.2f} / {p_cen ** len(same):5.2f}")
    return "\n".join(lines)


def _was(old: dict[str, float] | None, key: str) -> float | None:
    return None if old is None else old[key]


def light_table(compared: list[tuple[str, list, list]], both: bool) -> str:
    """The lighting table: per bag or scene its figures (``both``: unweighted -> weighted).

    The ratio is to the clean scene's RMSE (``light_clean``) of the same variant.
    """
    figures = {name: (_light_figures(old) if old else None, _light_figures(new))
               for name, old, new in compared}
    clean = figures.get(CLEAN_LIGHT)
    lines = [f"{'scene':<20} {'dRMSE um':>16} {'x clean':>12} {'dCen worst mm':>16} "
             f"{'dFn worst %':>14} {'|dF| worst %':>14} {'|dArea| worst %':>16}"]

    def cell(old: float | None, new: float, scale: float, fmt: str, width: int) -> str:
        text = f"{new * scale:{fmt}}"
        if both and old is not None:
            text = f"{old * scale:{fmt}} -> {text}"
        return f"{text:>{width}}"

    for name, (old, new) in figures.items():
        ratio_new = new["rmse"] / clean[1]["rmse"] if clean else np.nan   # nan: no clean scene
        ratio_old = (old["rmse"] / clean[0]["rmse"] if old is not None and clean
                     and clean[0] is not None else None)
        lines.append(f"{name:<20} {cell(_was(old, 'rmse'), new['rmse'], 1e6, '.2f', 16)} "
                     f"{cell(ratio_old, ratio_new, 1.0, '.2f', 12)} "
                     f"{cell(_was(old, 'centroid'), new['centroid'], 1e3, '.3f', 16)} "
                     f"{cell(_was(old, 'normal'), new['normal'], 1.0, '.2f', 14)} "
                     f"{cell(_was(old, 'vector'), new['vector'], 1.0, '.2f', 14)} "
                     f"{cell(_was(old, 'area'), new['area'], 1.0, '.1f', 16)}")
    lines.append("limits (issue 25, harsh rows): dRMSE <= 2 x clean, dCen <= 0.1 mm, "
                 "force within 2 %; clean rows and bags: no worse")
    return "\n".join(lines)


def write_bound_picture(path: pathlib.Path, scene: str, bound: FrameBound) -> pathlib.Path:
    """Three maps of one loaded frame's cells side by side, as a PNG at ``path``.

    The normal displacement's noise as the draws measured it and as the images allow it
    (standard deviation, um, one colour scale), and each cell's share of the efficient
    normal force estimate's variance (%): where the force's noise comes from.  The white
    circle is the load's disc.
    """
    xy = 1e3 * bound.rest_xy
    pitch = float(np.median(np.abs(np.diff(np.unique(np.round(xy[:, 0], 4))))))
    circle = (1e3 * bound.load.x, 1e3 * bound.load.y, 1e3 * bound.load.reach)
    fn = -float(bound.force[2])
    measured = 1e6 * np.sqrt(bound.noise[:, 2])
    allowed = (None if bound.image_noise is None else 1e6 * np.sqrt(bound.image_noise[:, 2]))
    top = float(np.percentile(measured, 99))
    panels = [render_cells(xy, measured, pitch, f"{scene} {fn:.2f} N: u_z noise, draws", "um",
                           vmax=top, circle=circle)]
    if allowed is not None:
        panels.append(render_cells(xy, allowed, pitch, "u_z noise the images allow", "um",
                                   vmax=top, circle=circle))
    panels.append(render_cells(xy, 100.0 * bound.force_share, pitch,
                               "share of the best Fn's variance", "%", circle=circle,
                               colormap=cv2.COLORMAP_VIRIDIS))
    height = max(p.shape[0] for p in panels)
    image = np.hstack([np.pad(p, ((0, height - p.shape[0]), (0, 0), (0, 0)),
                              constant_values=255) for p in panels])
    ok, png = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"cannot encode the picture for {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_bytes(png.tobytes())
    return path
