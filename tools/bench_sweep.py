#!/usr/bin/env python3
"""Robustness sweep: every simulator nuisance at three levels, and all of them at once.

    python tools/bench_sweep.py                  # full sweep, table into docs/robustness.md
    python tools/bench_sweep.py --only jpeg dust --no-write
    python tools/bench_sweep.py --json out.json

Each row renders the same few stereo frames (contacts of several shapes, so the touching
object is seen through the pad) with one nuisance at its mild, realistic or severe level
(``LEVELS``, ranges in docs/camera.md), runs them through the shared
:class:`~tactile_sl_decoder.pipeline.StereoPipeline` in process (the node's and the
replay's code) and compares the points with the renderer's ground truth:

* coverage: visible *undamaged* glyphs (not worn, scratched, under a bubble or a dust
  speck) decoded to their cell and triangulated within half a pitch of the truth;
* wrong: output points at a wrong cell, or farther than half a pitch from their cell's
  true centre (e2e_metrics' definition), among all output points, damaged glyphs included;
* RMSE: 3-D error of the correct points of undamaged glyphs;
* labels: the classifier's output on the detections of undamaged glyphs (each matched to
  the nearest true glyph within a quarter spacing, both images): share read right and share
  read *confidently wrong* (a misread the decoder must correct; below the confidence
  threshold a label is unknown, neither).

Figures, not pass/fail; the acceptance limits of issue 11 are printed next to them.
Pictures (``--pictures DIR``, default out/sweep; rows of ``--picture-rows``, default the
combined ones): the first frame of a row, both images side by side, each true glyph
marked as measured (green: from a glyph the extraction found; magenta: found by
the rescue, where the extraction found none), lost (red) or damaged (grey); with
``--bound`` also ``<row>_bound.png``, every glyph coloured by its point's bound.
"""
from __future__ import annotations

import argparse
import copy
import json
import pathlib
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "robustness.md"
BEGIN, END = "<!-- sweep:begin -->", "<!-- sweep:end -->"
OBJECTS = ("dark", "stripes", "noise", "text")

# nuisance -> (mild, realistic, severe) scene nuisances; "rig_spacing" scales the focal
# lengths to that glyph spacing in pixels (RigParams default 18 px).
LEVELS: dict[str, tuple[dict[str, Any], dict[str, Any], dict[str, Any]]] = {
    "object_dark": tuple({"see_through": "dark", "object_albedo": a} for a in (0.35, 0.2, 0.1)),
    "object_stripes": tuple({"see_through": "stripes", "object_albedo": 0.6,
                             "object_contrast": c, "object_scale": s}
                            for c, s in ((0.2, 5e-4), (0.4, 4e-4), (0.55, 3e-4))),
    "object_noise": tuple({"see_through": "noise", "object_albedo": 0.7, "object_contrast": c,
                           "object_scale": 2.5e-4} for c in (0.2, 0.4, 0.65)),
    "object_text": tuple({"see_through": "text", "object_albedo": 0.7, "object_contrast": c,
                          "object_scale": s}
                         for c, s in ((0.2, 4e-4), (0.4, 3.5e-4), (0.65, 3e-4))),
    "jpeg": tuple({"jpeg_quality": q} for q in (90, 70, 50)),
    "defocus": tuple({"defocus_px": r} for r in (1.0, 1.5, 2.5)),
    "motion_blur": tuple({"motion_blur_px": n, "motion_blur_angle_deg": 30.0}
                         for n in (2.0, 4.0, 8.0)),
    "exposure": tuple({"exposure_right": r, "exposure_jitter_camera": j}
                      for r, j in ((0.9, 0.05), (0.75, 0.1), (0.55, 0.2))),
    "dropout": tuple({"dropout": p} for p in (0.01, 0.03, 0.08)),
    "wear": tuple({"wear": p} for p in (0.02, 0.05, 0.15)),
    "scratches": tuple({"scratches": n} for n in (2, 5, 12)),
    "bubbles": tuple({"bubbles": n} for n in (1, 3, 8)),
    "dust": tuple({"dust": n, "dust_radius_px": r, "dust_strength": k}
                  for n, r, k in ((10, 1.5, 0.4), (25, 2.5, 0.6), (60, 3.5, 0.8))),
    "spacing_small": tuple({"rig_spacing": s} for s in (16.0, 14.0, 12.0)),
    "spacing_large": tuple({"rig_spacing": s} for s in (20.0, 22.0, 24.0)),
    "lighting": (
        {"blur_sigma": 0.8, "noise_sigma": 2.0, "shot_noise": 0.05, "vignetting": 0.3,
         "illumination_gradient": (0.03, -0.02), "ambient": 0.3, "gamma": 1.3,
         "exposure_jitter": 0.05,
         "shadows": [{"x": -0.004, "y": 0.003, "radius": 0.0025, "strength": 0.3,
                      "softness": 0.0015}]},
        {"blur_sigma": 1.3, "noise_sigma": 4.0, "shot_noise": 0.15, "vignetting": 0.45,
         "illumination_gradient": (0.06, -0.04), "light": (0.004, -0.007, -0.011),
         "ambient": 0.25, "gamma": 1.8, "exposure": 0.8, "exposure_jitter": 0.12,
         "shadows": [{"x": -0.004, "y": 0.003, "radius": 0.0025, "strength": 0.45,
                      "softness": 0.0015}],
         "occluders": [{"u": 520, "v": 90, "radius": 22, "strength": 0.5, "softness": 8,
                        "camera": "left"}]},
        {"blur_sigma": 1.6, "noise_sigma": 6.0, "shot_noise": 0.25, "vignetting": 0.6,
         "illumination_gradient": (0.1, -0.07), "light": (0.005, -0.006, -0.009),
         "ambient": 0.15, "gamma": 2.2, "exposure": 0.7, "exposure_jitter": 0.2,
         "shadows": [{"x": -0.004, "y": 0.003, "radius": 0.0025, "strength": 0.6,
                      "softness": 0.001}],
         "occluders": [{"u": 520, "v": 90, "radius": 22, "strength": 0.6, "softness": 8,
                        "camera": "left"}]}),
}
LEVEL_NAMES = ("mild", "realistic", "severe")
COMBINED_SKIP = ("spacing_large",)    # combined: the smaller (harder) spacing only
ACCEPT = {"realistic": (0.97, 0.0005, 1.0e-5), "severe": (None, 0.001, None)}
BOUND_SHARE = ACCEPT["realistic"][0]   # the bound over the best 97 %: the coverage bar
EFFICIENCY_TARGET = 1.25   # issue 25: a realistic row's RMSE at most 1.25x its bound
SUPERSAMPLE = 4
"""Samples per pixel and axis the renderer averages (``--supersample``).  A camera's pixel
integrates the light over its area; with 2 x 2 point samples the rendered glyph's position
depends on its sub-pixel phase by itself, an error no estimator of the camera's image can
remove: on a still pad without noise the centroids' 3-D error is 1.97 um at 2, 1.38 um at 8,
the artwork fit's 0.96 / 0.50 um, and the fit's centre errors at 4 are within 0.0003 px per
axis of those at 8 (docs/robustness.md, "Where the artwork fit's error is left")."""


def frame_contacts(index: int) -> list[Any]:
    """Contacts of sweep frame ``index`` (each frame its own shape and contact area).

    Sphere; small, deep, sheared sphere; flat punch + cylinder; rounded edge.
    """
    from tactile_sl_sim.contact import Contact

    shapes = [
        [Contact(kind="sphere", radius=0.004, x=0.0003, y=-0.0002, depth=0.0005)],
        [Contact(kind="sphere", radius=0.002, x=0.0012, y=-0.0008, depth=0.0008,
                 shear=(0.0001, 0.0))],
        [Contact(kind="flat", radius=0.0015, x=-0.002, y=0.001, depth=0.0003),
         Contact(kind="cylinder", radius=0.003, length=0.004, x=0.0025, y=-0.0015,
                 depth=0.0004, angle=float(np.radians(20.0)))],
        [Contact(kind="edge", radius=0.0008, x=0.0, y=0.0, depth=0.0004,
                 angle=float(np.radians(30.0)))],
    ]
    return shapes[index % len(shapes)]


def level_nuisances(names: list[str], level: int, frame: int) -> tuple[dict[str, Any], float]:
    """Merged nuisance mapping of some sweep rows at a level, and the glyph spacing (px)."""
    nz: dict[str, Any] = {}
    spacing = 18.0
    for name in names:
        doc = copy.deepcopy(LEVELS[name][level])
        spacing = float(doc.pop("rig_spacing", spacing))
        if doc.get("see_through") and len(names) > 1:   # combined: one object per frame
            kind = OBJECTS[frame % len(OBJECTS)]
            if name != f"object_{kind}":
                continue
        nz.update(doc)
    return nz, spacing


@dataclass
class RowFigures:
    """Pooled counts of one sweep row."""

    visible: int = 0
    correct: int = 0
    points: int = 0
    wrong: int = 0
    errors: list[np.ndarray] = field(default_factory=list)
    ms: list[float] = field(default_factory=list)
    labelled: int = 0        # detections of undamaged glyphs matched to their true glyph
    labels_right: int = 0
    labels_misread: int = 0  # confident and wrong
    bounds: list[np.ndarray] = field(default_factory=list)   # CRLB (m^2) per undamaged glyph

    def summary(self) -> dict[str, float]:
        err = np.concatenate(self.errors) if self.errors else np.zeros(0)
        rmse = float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")
        return {"visible": self.visible, "points": self.points, "correct": self.correct,
                "wrong": self.wrong,
                "coverage": self.correct / self.visible if self.visible else float("nan"),
                "wrong_rate": self.wrong / self.points if self.points else 0.0,
                "rmse_m": rmse,
                "labels_right": self.labels_right / self.labelled if self.labelled else 0.0,
                "labels_misread": (self.labels_misread / self.labelled if self.labelled
                                   else 0.0),
                "ms": float(np.median(self.ms)) if self.ms else float("nan"),
                **self._bound_summary(rmse)}

    def _bound_summary(self, rmse: float) -> dict[str, float]:
        """Cramer-Rao bound of the row's 3-D RMSE (``--bound``; empty without it).

        Over all glyphs, over the best share a decoder meeting the coverage bar may keep,
        and over the share this decoder kept, with the row's efficiency: its RMSE over that
        bound (1 = as close as any unbiased per-point measurement can get).
        """
        if not self.bounds:
            return {}
        from tactile_sl_decoder.tooling.centre_bound import best_share_rmse

        b = np.concatenate(self.bounds)
        # the decoder's own share: its RMSE is over the points it kept, so the fair bound
        # is that of the same share of the best glyphs (never more than all of them)
        share = min(1.0, self.correct / self.visible) if self.visible else 1.0
        bound_kept = best_share_rmse(b, share)
        return {"bound_all_m": best_share_rmse(b, 1.0),
                "bound_best_m": best_share_rmse(b, BOUND_SHARE),
                "bound_kept_m": bound_kept,
                "efficiency": rmse / bound_kept if bound_kept > 0 else float("nan")}


class Sweep:
    """Renderers per glyph spacing, one pipeline, the ground-truth comparison."""

    def __init__(self, frames: int, seed: int, weights: str | None = None,
                 bound: bool = False, artwork_fit: bool = False,
                 supersample: int = SUPERSAMPLE) -> None:
        from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
        from tactile_sl_sim.artwork import load_artwork

        self.frames, self.seed, self.bound = frames, seed, bound
        self.supersample = supersample
        self.artwork = load_artwork()
        self.pattern = PatternSpec.load()
        params = PipelineParams(threads=1, classifier_weights=weights)
        params.artwork_fit.enabled = artwork_fit
        self.pipeline = StereoPipeline(self.pattern, params=params)
        from tactile_sl_decoder.tooling.training import DEFAULT_PRIMITIVES, artwork_values

        # every cell's symbol read from the rendered artwork (the pattern's, by construction)
        self.values = artwork_values(self.artwork, DEFAULT_PRIMITIVES)
        self._renderers: dict[float, Any] = {}

    def renderer(self, spacing: float) -> Any:
        from tactile_sl_sim.optics import RigParams, SimulatedCameraPair
        from tactile_sl_sim.render import Renderer

        if spacing not in self._renderers:
            rig = RigParams.for_glyph_spacing(spacing)
            self._renderers[spacing] = Renderer(self.artwork, SimulatedCameraPair(rig),
                                                supersample=self.supersample)
        return self._renderers[spacing]

    def run_row(self, names: list[str], level: int,
                picture: pathlib.Path | None = None) -> RowFigures:
        from tactile_sl_common.clouds import pack_points
        from tactile_sl_decoder.stereo.stereo import StereoRig
        from tactile_sl_decoder.tooling.centre_bound import frame_point_bounds
        from tactile_sl_decoder.tooling.e2e_metrics import frame_metrics
        from tactile_sl_sim.render import Nuisances

        out = RowFigures()
        for frame in range(self.frames):
            doc, spacing = level_nuisances(names, level, frame)
            nz = Nuisances.from_dict({"blur_sigma": 0.5, "noise_sigma": 0.8, "shot_noise": 0.02,
                                      "vignetting": 0.2, **doc})
            renderer = self.renderer(spacing)
            seed = self.seed + 101 * level + frame
            contacts = frame_contacts(frame)
            f = renderer.render(contacts, nz, seed=seed, frame_index=frame)
            rig = StereoRig(renderer.rig.left_info, renderer.rig.right_info)
            if self.bound:
                out.bounds.append(frame_point_bounds(renderer, rig, contacts, nz, seed, frame,
                                                     spacing))
            self.pipeline.forget_frames()    # each frame is a scene of its own, not a stream
            t0 = time.perf_counter()
            res = self.pipeline.process(f.left, f.right, rig, rig)
            out.ms.append(1e3 * (time.perf_counter() - t0))
            t = f.truth
            vis = t.visible
            undamaged = vis & ~t.damaged if t.damaged is not None else vis
            tol = 0.5 * self.pattern.pitch_m
            all_gt = pack_points(t.xyz[vis], t.rows[vis], t.cols[vis])
            fm_all = frame_metrics(res.points, all_gt, tol)
            out.points += fm_all.points
            out.wrong += fm_all.wrong
            und_gt = pack_points(t.xyz[undamaged], t.rows[undamaged], t.cols[undamaged])
            cells = t.rows * self.artwork.cols + t.cols
            bad_cells = cells[vis & ~undamaged]
            pts = res.points
            keep = ~np.isin(pts["row"].astype(np.int64) * self.artwork.cols + pts["col"],
                            bad_cells)
            fm = frame_metrics(pts[keep], und_gt, tol)
            out.visible += fm.visible
            out.correct += fm.correct
            out.errors.append(fm.errors_m)
            self._count_labels(out, res, t, undamaged)
            if picture is not None and frame == 0:
                write_picture(picture, f, res, self.artwork.cols)
                if self.bound:
                    write_bound_picture(picture.with_name(picture.stem + "_bound.png"), f,
                                        undamaged, out.bounds[-1])
        return out

    def _count_labels(self, out: RowFigures, res: Any, truth: Any, undamaged: np.ndarray
                      ) -> None:
        """Add the classifier's right and confidently wrong labels of one frame to ``out``."""
        from tactile_sl_decoder.glyphs import LABEL_UNKNOWN
        from tactile_sl_decoder.tooling.training import label_detections

        values = self.values[truth.rows[undamaged], truth.cols[undamaged]]
        for glyphs, px in ((res.left, truth.px_left), (res.right, truth.px_right)):
            chosen, true_label = label_detections(glyphs, px[undamaged], values)
            label = glyphs.label[chosen]
            out.labelled += len(chosen)
            out.labels_right += int((label == true_label).sum())
            out.labels_misread += int(((label != true_label) & (label != LABEL_UNKNOWN)).sum())


def write_picture(path: pathlib.Path, frame: Any, res: Any, cols: int) -> None:
    """Both images side by side, every true glyph marked by what became of it.

    Green: its cell is a point, measured at a glyph the extraction found in this image;
    magenta: a point, but the extraction found no glyph there (the rescue measured it);
    red: visible, undamaged and no point; grey: damaged print or dust (not counted).
    """
    import cv2
    from scipy.spatial import cKDTree

    t = frame.truth
    spacing = max(res.left.spacing_px, res.right.spacing_px, 1.0)
    have = set((res.points["row"].astype(np.int64) * cols + res.points["col"]).tolist())
    damaged = t.damaged if t.damaged is not None else np.zeros(len(t.rows), bool)
    panels = []
    for gray, glyphs, px in ((frame.left, res.left, t.px_left),
                             (frame.right, res.right, t.px_right)):
        img = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
        found = (cKDTree(np.column_stack([glyphs.u, glyphs.v])).query(px)[0] < 0.3 * spacing
                 if len(glyphs) else np.zeros(len(px), bool))
        for k in np.flatnonzero(t.visible):
            centre = (int(round(px[k, 0])), int(round(px[k, 1])))
            if damaged[k]:
                colour = (128, 128, 128)
            elif int(t.rows[k]) * cols + int(t.cols[k]) in have:
                colour = (0, 200, 0) if found[k] else (255, 0, 255)
            else:
                colour = (0, 0, 255)
            cv2.circle(img, centre, 2 if colour == (0, 200, 0) else 4, colour, -1)
        panels.append(img)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.png")
    cv2.imwrite(str(tmp), np.hstack(panels))
    tmp.replace(path)


def write_bound_picture(path: pathlib.Path, frame: Any, undamaged: np.ndarray,
                        bounds_m2: np.ndarray) -> None:
    """Both images side by side, each visible undamaged glyph coloured by its point's bound.

    ``undamaged``: the truth's visible undamaged glyphs, the order of ``bounds_m2``.

    Colour: the Cramer-Rao bound of the 3-D error (square root, log scale 0.5-50 um, the
    inferno map: dark = small); a grey cross where the images hold no information at all.
    The scale bar underneath marks 0.5, 5 and 50 um and the 10 um bar of issue 11.
    """
    import cv2

    t = frame.truth
    err_um = 1e6 * np.sqrt(bounds_m2)
    finite = np.isfinite(err_um)
    level = np.zeros(len(err_um), np.uint8)
    level[finite] = np.clip(255 * (np.log10(err_um[finite]) + 0.30103) / 2.0, 0, 255)
    colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_INFERNO).reshape(-1, 3)
    panels = []
    for gray, px in ((frame.left, t.px_left[undamaged]), (frame.right, t.px_right[undamaged])):
        img = cv2.cvtColor((gray // 2 + 64).astype(np.uint8), cv2.COLOR_GRAY2BGR)
        for k, (u, v) in enumerate(np.rint(px).astype(int)):
            if finite[k]:
                cv2.circle(img, (int(u), int(v)), 4, tuple(int(c) for c in colours[k]), -1)
            else:
                cv2.drawMarker(img, (int(u), int(v)), (128, 128, 128), cv2.MARKER_TILTED_CROSS, 6)
        panels.append(img)
    picture = np.hstack(panels)
    bar = np.zeros((40, picture.shape[1], 3), np.uint8)
    ramp = np.linspace(0, 255, picture.shape[1]).astype(np.uint8).reshape(1, -1)
    bar[:16] = cv2.applyColorMap(np.repeat(ramp, 16, axis=0), cv2.COLORMAP_INFERNO)
    for um in (0.5, 5.0, 10.0, 50.0):
        x = int((np.log10(um) + 0.30103) / 2.0 * (picture.shape[1] - 1))
        cv2.line(bar, (x, 0), (x, 20), (255, 255, 255), 1)
        cv2.putText(bar, f"{um:g} um", (min(x + 3, picture.shape[1] - 60), 34),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.png")
    cv2.imwrite(str(tmp), np.vstack([picture, bar]))
    tmp.replace(path)


def table(results: list[tuple[str, str, dict[str, float]]]) -> str:
    """Markdown table of the sweep rows."""
    bound = bool(results) and "bound_best_m" in results[0][2]
    lines = ["| nuisance | level | visible | coverage | wrong | wrong % | 3-D RMSE "
             + ("| CRLB, best 97 % | RMSE / CRLB (kept share) " if bound else "")
             + "| labels right | misread | ms/pair |",
             "|---|---|---|---|---|---|---|---|---|---|" + ("---|---|" if bound else "")]
    for name, level, s in results:
        limits = ACCEPT.get(level)
        flag = ""
        if limits:
            cov, wrong, rmse = limits
            fails = ((cov is not None and not s["coverage"] >= cov)
                     or (wrong is not None and s["wrong_rate"] > wrong)
                     or (rmse is not None and not s["rmse_m"] <= rmse))
            flag = " **(fails)**" if fails else ""
        eff = s.get("efficiency", float("nan"))
        eff_flag = (" **(> %.2f)**" % EFFICIENCY_TARGET
                    if level == "realistic" and not eff <= EFFICIENCY_TARGET else "")
        lines.append(f"| {name} | {level}{flag} | {s['visible']} | {100 * s['coverage']:.2f} % "
                     f"| {s['wrong']} | {100 * s['wrong_rate']:.3f} % "
                     f"| {1e3 * s['rmse_m']:.4f} mm "
                     + (f"| {1e3 * s['bound_best_m']:.4f} mm | {eff:.2f}{eff_flag} "
                        if bound else "")
                     + f"| {100 * s['labels_right']:.2f} % "
                     f"| {100 * s['labels_misread']:.2f} % | {s['ms']:.1f} |")
    return "\n".join(lines) + "\n"


def write_doc(text: str, path: pathlib.Path = DOC) -> None:
    """Replace the generated section of docs/robustness.md (markers kept)."""
    doc = path.read_text() if path.exists() else f"# Robustness\n\n{BEGIN}\n{END}\n"
    if BEGIN not in doc or END not in doc:
        doc = doc.rstrip() + f"\n\n{BEGIN}\n{END}\n"
    head, rest = doc.split(BEGIN, 1)
    _old, tail = rest.split(END, 1)
    path.write_text(f"{head}{BEGIN}\n{text}{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=None, help="nuisances (and/or 'combined')")
    ap.add_argument("--levels", nargs="*", default=list(LEVEL_NAMES), choices=LEVEL_NAMES)
    ap.add_argument("--frames", type=int, default=4, help="stereo frames per row")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--weights", default=None,
                    help="classifier weights (default: the shipped ones), e.g. to compare")
    ap.add_argument("--no-write", action="store_true", help="do not update docs/robustness.md")
    ap.add_argument("--bound", action="store_true",
                    help="also the Cramer-Rao bound of each row's 3-D RMSE over the best 97 %% "
                         "of its glyphs (renders every frame 11 more times: its signal before "
                         "noise, without glyphs and with every third row and column of them)")
    ap.add_argument("--json", default=None, help="also write the figures as JSON")
    ap.add_argument("--artwork-fit", action="store_true",
                    help="the decoder's artwork fit on (artwork_fit.enabled; implies --no-write: "
                         "the table in docs/robustness.md is the default decoder's)")
    ap.add_argument("--supersample", type=int, default=SUPERSAMPLE,
                    help="samples per pixel and axis the renderer averages (default "
                         f"{SUPERSAMPLE}; the tables before 2026-12-07 were rendered with 2)")
    ap.add_argument("--pictures", type=pathlib.Path, default=REPO / "out" / "sweep",
                    help="folder of the rows' pictures (default out/sweep)")
    ap.add_argument("--picture-rows", nargs="*", default=["combined"],
                    help="rows drawn (first frame, both images): nuisance names")
    args = ap.parse_args(argv)
    rows = list(LEVELS) + ["combined"]
    if args.only:
        unknown = sorted(set(args.only) - set(rows))
        if unknown:
            ap.error(f"unknown nuisance(s) {', '.join(unknown)}; known: {', '.join(rows)}")
        rows = [r for r in rows if r in args.only]
    if args.artwork_fit:
        args.no_write = True
    if args.supersample < 1:
        ap.error("--supersample must be at least 1")
    sweep = Sweep(args.frames, args.seed, args.weights, args.bound, args.artwork_fit,
                  args.supersample)
    results: list[tuple[str, str, dict[str, float]]] = []
    t0 = time.time()
    for name in rows:
        names = [n for n in LEVELS if n not in COMBINED_SKIP] if name == "combined" else [name]
        for level_name in args.levels:
            picture = (args.pictures / f"{name}_{level_name}.png"
                       if name in args.picture_rows else None)
            s = sweep.run_row(names, LEVEL_NAMES.index(level_name), picture).summary()
            results.append((name, level_name, s))
            print(f"{name:15s} {level_name:9s} coverage {100 * s['coverage']:6.2f} %  "
                  f"wrong {s['wrong']:3d} ({100 * s['wrong_rate']:.3f} %)  "
                  f"rmse {1e3 * s['rmse_m']:.4f} mm  labels right "
                  f"{100 * s['labels_right']:.2f} % misread {100 * s['labels_misread']:.2f} %"
                  + (f"  CRLB {1e3 * s['bound_all_m']:.4f} mm, best 97 % "
                     f"{1e3 * s['bound_best_m']:.4f} mm, RMSE / bound of the kept share "
                     f"{s['efficiency']:.2f}" if "bound_best_m" in s else ""),
                  file=sys.stderr, flush=True)
    text = table(results)
    print(text)
    print(f"({len(results)} rows, {args.frames} stereo frames each, supersample "
          f"{args.supersample}, {time.time() - t0:.0f} s)",
          file=sys.stderr)
    if not args.no_write:
        write_doc(text)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(
            [{"nuisance": n, "level": lv, **s} for n, lv, s in results], indent=1))
    sweep.pipeline.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
