"""Touch figures against the simulator's ground truth: displacement, force, moment, contact.

Tooling for ``tactile-sl evaluate``, ``tools/bench_touch.py`` and the demo; the touch stage
never imports it.  Definitions of every figure and of the acceptance limits (issue 10):
``docs/touch_evaluation.md``.  One frame's estimate is a
:class:`~tactile_sl_decoder.touch.stage.TouchResult`, its truth a
:class:`~tactile_sl_camera.sim.loads.TouchTruth` rebuilt from the bag's
``ground_truth/{wrench,field,contact}`` (or an untouched pad, for control bags without them).
"""
from __future__ import annotations

import io
import json
import math
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable, TextIO

import numpy as np

NAN = float("nan")


@dataclass(frozen=True)
class AcceptanceLimits:
    """Issue 10's acceptance limits (SI); ``x_rel * |truth| + x_abs`` where both are given."""

    disp_rmse: float = 5e-6           # m, 3-D over the cells in both fields
    normal_rel: float = 0.05
    normal_abs: float = 5e-3          # N
    tangential_rel: float = 0.10      # of the true tangential magnitude
    tangential_abs: float = 5e-3      # N
    moment_rel: float = 0.10
    moment_abs: float = 5e-5          # N m (0.05 mN m floor)
    centroid: float = 1e-4            # m
    area_rel: float = 0.15
    contact_on: float = 0.020         # N: in_contact must be true above this normal force


LIMITS = AcceptanceLimits()
CHECKS = ("disp", "normal", "tangential", "moment_z", "centroid", "area", "in_contact")
"""Names of the per-frame acceptance checks, in table order."""


@dataclass
class TouchFrameMetrics:
    """Estimate and truth of one frame, and their errors (pad frame, SI)."""

    bag: str
    stamp_ns: int
    output: bool                   # the touch stage gave outputs for this frame
    cells: int                     # cells in both the estimated and the true field
    disp_rmse: float               # m
    force_est: np.ndarray          # (3,) N
    force_true: np.ndarray | None  # (3,) N; None: unknown (geometric indenter)
    moment_est: np.ndarray         # (3,) N m about the pad origin
    moment_true: np.ndarray | None
    centroid_est: np.ndarray       # (2,) m
    centroid_true: np.ndarray
    area_est: float                # m^2
    area_true: float
    depth_est: float               # m
    depth_true: float
    contact_est: bool
    contact_true: bool
    untouched: bool                # no traction at all in the truth
    timings_ms: dict[str, float] = field(default_factory=dict)

    # ------------------------------------------------------------ errors (est - true)

    @property
    def normal_est(self) -> float:
        """Resultant normal force the object presses with, N (= -Fz)."""
        return 0.0 - float(self.force_est[2])

    @property
    def normal_true(self) -> float:
        return NAN if self.force_true is None else 0.0 - float(self.force_true[2])

    @property
    def normal_err(self) -> float:
        """Signed normal force error, N."""
        return self.normal_est - self.normal_true

    @property
    def normal_err_pct(self) -> float:
        return _pct(self.normal_err, self.normal_true)

    @property
    def tangential_true(self) -> float:
        """Magnitude of the true tangential force, N."""
        return NAN if self.force_true is None else float(np.hypot(*self.force_true[:2]))

    @property
    def tangential_err(self) -> float:
        """Length of the tangential force error vector (Fx, Fy), N."""
        if self.force_true is None:
            return NAN
        return float(np.hypot(*(self.force_est[:2] - self.force_true[:2])))

    @property
    def tangential_err_pct(self) -> float:
        return _pct(self.tangential_err, self.tangential_true)

    @property
    def moment_z_err(self) -> float:
        """Signed error of the moment about z (pad origin), N m."""
        return NAN if self.moment_true is None else float(self.moment_est[2] - self.moment_true[2])

    @property
    def moment_z_err_pct(self) -> float:
        return NAN if self.moment_true is None else _pct(self.moment_z_err, self.moment_true[2])

    @property
    def centroid_err(self) -> float:
        """Distance between the contact centroids, m (NaN when the truth is not in contact)."""
        if not self.contact_true:
            return NAN
        return float(np.hypot(*(self.centroid_est - self.centroid_true)))

    @property
    def area_err_pct(self) -> float:
        return _pct(self.area_est - self.area_true, self.area_true) if self.contact_true else NAN

    @property
    def depth_err(self) -> float:
        """Signed max_depth error, m."""
        return self.depth_est - self.depth_true

    # ------------------------------------------------------------ acceptance

    def checks(self, limits: AcceptanceLimits = LIMITS) -> dict[str, bool | None]:
        """Each acceptance check: True / False, None where it does not apply to this frame."""
        out: dict[str, bool | None] = dict.fromkeys(CHECKS)
        if not self.output:
            return {k: False for k in CHECKS}
        if self.cells:
            out["disp"] = self.disp_rmse <= limits.disp_rmse
        if self.force_true is not None:
            out["normal"] = (abs(self.normal_err)
                             <= limits.normal_rel * abs(self.normal_true) + limits.normal_abs)
            out["tangential"] = (self.tangential_err <= limits.tangential_rel
                                 * self.tangential_true + limits.tangential_abs)
        if self.moment_true is not None:
            out["moment_z"] = (abs(self.moment_z_err) <= limits.moment_rel
                               * abs(float(self.moment_true[2])) + limits.moment_abs)
        if self.contact_true:
            out["centroid"] = self.contact_est and self.centroid_err <= limits.centroid
            out["area"] = self.contact_est and abs(self.area_err_pct) <= 100 * limits.area_rel
        if self.untouched:
            out["in_contact"] = not self.contact_est
        elif self.force_true is not None and self.normal_true > limits.contact_on:
            out["in_contact"] = self.contact_est
        return out

    def failed(self, limits: AcceptanceLimits = LIMITS) -> list[str]:
        """Names of the checks this frame fails."""
        return [k for k, v in self.checks(limits).items() if v is False]

    @property
    def passed(self) -> bool:
        return not self.failed()

    def summary(self) -> dict[str, Any]:
        """Plain dict (JSON-friendly, SI units) of the frame's figures."""
        def vec(v: np.ndarray | None) -> list[float] | None:
            return None if v is None else [float(x) for x in v]

        return {"bag": self.bag, "stamp_ns": self.stamp_ns, "output": self.output,
                "cells": self.cells, "disp_rmse_m": _num(self.disp_rmse),
                "force_est_n": vec(self.force_est), "force_true_n": vec(self.force_true),
                "moment_est_nm": vec(self.moment_est), "moment_true_nm": vec(self.moment_true),
                "normal_err_n": _num(self.normal_err), "normal_err_pct": _num(self.normal_err_pct),
                "tangential_err_n": _num(self.tangential_err),
                "tangential_err_pct": _num(self.tangential_err_pct),
                "moment_z_err_nm": _num(self.moment_z_err),
                "moment_z_err_pct": _num(self.moment_z_err_pct),
                "centroid_est_m": vec(self.centroid_est),
                "centroid_true_m": vec(self.centroid_true),
                "centroid_err_m": _num(self.centroid_err),
                "area_est_m2": self.area_est, "area_true_m2": self.area_true,
                "area_err_pct": _num(self.area_err_pct),
                "max_depth_est_m": self.depth_est, "max_depth_true_m": self.depth_true,
                "max_depth_err_m": _num(self.depth_err),
                "in_contact_est": self.contact_est, "in_contact_true": self.contact_true,
                "untouched": self.untouched, "checks": self.checks(), "passed": self.passed,
                "timings_ms": dict(self.timings_ms)}


def _pct(err: float, truth: float) -> float:
    return 100.0 * err / abs(truth) if truth and math.isfinite(truth) else NAN


def _num(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


# ---------------------------------------------------------------------- one frame


def displacement_rmse(rows: np.ndarray, cols: np.ndarray, disp: np.ndarray,
                      true_rows: np.ndarray, true_cols: np.ndarray, true_disp: np.ndarray
                      ) -> tuple[float, int]:
    """3-D displacement RMSE (m) over the cells in both fields, matched by (row, col)."""
    key = np.asarray(rows, np.int64) * 1_000_003 + np.asarray(cols, np.int64)
    tkey = np.asarray(true_rows, np.int64) * 1_000_003 + np.asarray(true_cols, np.int64)
    _, i, j = np.intersect1d(key, tkey, assume_unique=True, return_indices=True)
    if len(i) == 0:
        return NAN, 0
    d = np.asarray(disp, np.float64)[i] - np.asarray(true_disp, np.float64)[j]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1)))), int(len(i))


def compare_frame(result: Any | None, truth: Any | None, bag: str = "", stamp_ns: int = 0
                  ) -> TouchFrameMetrics:
    """Figures of one frame: a ``TouchResult`` (None: no output) against a ``TouchTruth``.

    ``truth`` None stands for an untouched pad (control bags): zero force and moment, no
    contact and zero displacement of every decoded cell.
    """
    zero3 = np.zeros(3)
    if truth is None:
        untouched = True
        force_true: np.ndarray | None = zero3
        moment_true: np.ndarray | None = zero3
        centroid_true, area_true, depth_true, contact_true = np.zeros(2), 0.0, 0.0, False
    else:
        force_true = None if truth.force is None else np.asarray(truth.force, np.float64)
        moment_true = None if truth.moment is None else np.asarray(truth.moment, np.float64)
        contact_true = bool(truth.in_contact)
        untouched = (not contact_true and force_true is not None and not np.any(force_true)
                     and moment_true is not None and not np.any(moment_true))
        centroid_true = np.asarray(truth.centroid, np.float64)[:2]
        area_true, depth_true = float(truth.area), float(truth.max_depth)
    if result is None:
        return TouchFrameMetrics(bag, stamp_ns, False, 0, NAN, zero3, force_true, zero3,
                                 moment_true, np.zeros(2), centroid_true, 0.0, area_true, 0.0,
                                 depth_true, False, contact_true, untouched)
    if truth is None:
        rmse, cells = displacement_rmse(result.rows, result.cols, result.displacement,
                                        result.rows, result.cols,
                                        np.zeros_like(result.displacement))
    else:
        rmse, cells = displacement_rmse(result.rows, result.cols, result.displacement,
                                        truth.rows, truth.cols, truth.displacement)
    c = result.contact
    return TouchFrameMetrics(
        bag, stamp_ns, True, cells, rmse, np.asarray(result.wrench_force, np.float64),
        force_true, np.asarray(result.wrench_moment, np.float64), moment_true,
        np.asarray(c.centroid, np.float64)[:2], centroid_true, float(c.area), area_true,
        float(c.max_depth), depth_true, bool(c.in_contact), contact_true, untouched)


# ---------------------------------------------------------------------- bags


def has_touch_truth(path: str | Path, namespace: str = "/tactile") -> bool:
    """The bag carries ``ground_truth/wrench`` (a touch scene of the simulator)."""
    from tactile_sl_camera.bag_io import BagReader

    return f"{namespace.rstrip('/')}/ground_truth/wrench" in BagReader(path).topics


def read_truths(path: str | Path, namespace: str = "/tactile") -> dict[int, Any]:
    """``TouchTruth`` of every frame of a bag by header stamp (ns), from its ground truth."""
    from tactile_sl_camera.bag_io import BagReader, stamp_to_ns
    from tactile_sl_camera.sim.loads import touch_truth_from_messages

    ns = namespace.rstrip("/")
    names = {f"{ns}/ground_truth/{k}": k for k in ("wrench", "field", "contact")}
    reader = BagReader(path)
    parts: dict[int, dict[str, Any]] = {}
    for raw, msg in reader.messages([t for t in names if t in reader.topics]):
        s = msg.header.stamp
        parts.setdefault(stamp_to_ns(s.sec, s.nanosec), {})[names[raw.topic]] = msg
    return {stamp: touch_truth_from_messages(p.get("wrench"), p["field"], p["contact"])
            for stamp, p in parts.items() if "field" in p and "contact" in p}


def scene_sensor(bag: str | Path) -> tuple[Any, str] | None:
    """Sensor of a simulated bag from the scenes file it was rendered from, if found.

    The simulator does not record the elastomer in the bag; ``make bags`` names each bag
    after its scene, so a ``*scenes.yaml`` beside the bag with a scene of the bag's name
    gives it.  Returns (SensorConfig, description) or None.
    """
    from tactile_sl_camera.sim.scenes import SceneError, load_scenes
    from tactile_sl_decoder.touch.sensor import SensorConfig

    p = Path(bag)
    for scenes in sorted(p.parent.glob("*scenes.yaml")):
        try:
            found = [s for s in load_scenes(scenes) if s.name == p.stem]
        except (SceneError, OSError, ValueError):
            continue
        if found:
            return (SensorConfig(found[0].elastomer, source=f"{scenes}:{p.stem}"),
                    f"elastomer of scene {p.stem!r} in {scenes}")
    return None


def resolve_sensor(bag: str | Path, sensor_path: str | Path | None) -> tuple[Any, str]:
    """(SensorConfig, where it came from): ``--sensor``, else the bag's scene, else shipped."""
    from tactile_sl_decoder.touch.sensor import default_sensor_path, load_sensor

    if sensor_path:
        return load_sensor(sensor_path), f"--sensor {sensor_path}"
    found = scene_sensor(bag)
    if found is not None:
        return found
    return load_sensor(None), f"shipped {default_sensor_path()} (pass --sensor for this bag)"


def sensor_text(sensor: Any) -> str:
    """E, nu, thickness of a sensor in one short phrase."""
    e = sensor.elastomer
    return (f"E {e.youngs_modulus / 1e3:.0f} kPa, nu {e.poisson_ratio:g}, "
            + (f"{e.thickness * 1e3:g} mm layer" if e.thickness > 0 else "half-space"))


def evaluate_touch_bag(path: str | Path, pipeline: Any, sensor: Any, reference_frames: int = 1,
                       namespace: str = "/tactile", progress: TextIO | None = None,
                       max_frames: int = 0, untouched: bool = False
                       ) -> list[TouchFrameMetrics]:
    """Pipeline + touch stage over a bag (as ``tactile-sl replay``), each frame decoded once.

    Frames used for the reference give no figures.  ``untouched``: the bag has no touch
    ground truth and the pad is at rest throughout (a control: zero truth).
    Timings per frame: ``pipeline`` (the pipeline's total) and ``touch`` (the stage's).
    """
    from tactile_sl_camera.images import to_gray
    from tactile_sl_decoder.frames import bag_frames, count_bag_frames
    from tactile_sl_decoder.tooling.e2e_metrics import progress_bar
    from tactile_sl_decoder.touch.reference import ReferenceError
    from tactile_sl_decoder.touch.stage import TouchParams, TouchStage

    truths = {} if untouched else read_truths(path, namespace)
    pattern = pipeline.pattern
    stage = TouchStage(sensor, pattern.array.shape, pattern.pitch_m,
                       bool(pipeline.params.decode.mirrored),
                       TouchParams(reference_frames=reference_frames))
    name = Path(path).stem
    total = count_bag_frames(path, namespace)
    out: list[TouchFrameMetrics] = []
    for i, frame in enumerate(bag_frames(path, namespace, ground_truth=False)):
        if max_frames and i >= max_frames:
            break
        if progress is not None:
            progress_bar(progress, i + 1, total, name)
        truth = truths.get(frame.stamp_ns)
        if truth is None and not untouched:
            continue
        result = pipeline.process(to_gray(frame.left_image), to_gray(frame.right_image),
                                  frame.left_info, frame.right_info)
        was_ready = stage.ready
        try:
            touch = stage.update(result.points)
        except ReferenceError:
            stage.tare()
            touch = None
        if not was_ready:
            continue                       # a reference frame (or the reference failed)
        m = compare_frame(touch, truth, name, frame.stamp_ns)
        m.timings_ms = {"pipeline": float(result.timings_ms.get("total", NAN))}
        if touch is not None:
            m.timings_ms["touch"] = float(touch.timings_ms.get("touch", NAN))
        out.append(m)
    if progress is not None:
        progress.write("\n")
    return out


# ---------------------------------------------------------------------- tables


def bag_totals(frames: Iterable[TouchFrameMetrics], name: str = "") -> dict[str, Any]:
    """Per-bag figures: pooled displacement RMSE, worst |error| of each figure, passes."""
    frames = list(frames)

    def worst(values: Iterable[float]) -> float:
        v = [abs(x) for x in values if x is not None and math.isfinite(x)]
        return max(v) if v else NAN

    cells = sum(f.cells for f in frames)
    sq = sum(f.disp_rmse ** 2 * f.cells for f in frames if f.cells)
    checks = [f.checks() for f in frames]
    return {
        "bag": name or (frames[0].bag if frames else ""), "frames": len(frames),
        "passed": sum(f.passed for f in frames),
        "disp_rmse_m": _num(math.sqrt(sq / cells)) if cells else None,
        "disp_rmse_max_m": _num(worst(f.disp_rmse for f in frames)),
        "normal_err_max_n": _num(worst(f.normal_err for f in frames)),
        "normal_err_max_pct": _num(worst(f.normal_err_pct for f in frames)),
        "tangential_err_max_n": _num(worst(f.tangential_err for f in frames)),
        "tangential_err_max_pct": _num(worst(f.tangential_err_pct for f in frames)),
        "moment_z_err_max_nm": _num(worst(f.moment_z_err for f in frames)),
        "moment_z_err_max_pct": _num(worst(f.moment_z_err_pct for f in frames)),
        "centroid_err_max_m": _num(worst(f.centroid_err for f in frames)),
        "area_err_max_pct": _num(worst(f.area_err_pct for f in frames)),
        "max_depth_err_max_m": _num(worst(f.depth_err for f in frames)),
        "in_contact_agree": sum(f.contact_est == f.contact_true for f in frames),
        "failed_checks": {k: sum(c[k] is False for c in checks) for k in CHECKS},
    }


def _f(v: float | None, fmt: str, width: int) -> str:
    return f"{'-':>{width}}" if v is None or not math.isfinite(v) else f"{format(v, fmt):>{width}}"


FRAME_HEADER = (f"{'bag':<18} {'t s':>5} {'cells':>5} {'dRMSE':>6} {'Fn est':>7} {'Fn true':>7} "
                f"{'dFn mN':>7} {'dFn%':>6} {'dFt mN':>7} {'dFt%':>6} {'dMz%':>6} {'dCen':>6} "
                f"{'dArea%':>7} {'dDep':>5} {'cont':>5}  result")
UNITS = (f"{'':<18} {'':>5} {'':>5} {'um':>6} {'N':>7} {'N':>7} {'':>7} {'':>6} {'':>7} "
         f"{'':>6} {'':>6} {'mm':>6} {'':>7} {'um':>5} {'e/t':>5}")


def format_frame(f: TouchFrameMetrics, t0_ns: int = 0) -> str:
    """One table row of a frame (errors are estimate - truth)."""
    if not f.output:
        return f"{f.bag:<18} {(f.stamp_ns - t0_ns) / 1e9:>5.1f} no touch output (FAIL)"
    fails = f.failed()
    cont = f"{'TF'[not f.contact_est]}/{'TF'[not f.contact_true]}"
    return (f"{f.bag:<18} {(f.stamp_ns - t0_ns) / 1e9:>5.1f} {f.cells:>5} "
            f"{_f(1e6 * f.disp_rmse, '.2f', 6)} {f.normal_est:>7.4f} "
            f"{_f(f.normal_true, '.4f', 7)} {_f(1e3 * f.normal_err, '+.2f', 7)} "
            f"{_f(f.normal_err_pct, '+.1f', 6)} {_f(1e3 * f.tangential_err, '.2f', 7)} "
            f"{_f(f.tangential_err_pct, '.1f', 6)} {_f(f.moment_z_err_pct, '+.1f', 6)} "
            f"{_f(1e3 * f.centroid_err, '.3f', 6)} {_f(f.area_err_pct, '+.1f', 7)} "
            f"{_f(1e6 * f.depth_err, '+.0f', 5)} {cont:>5}  "
            + ("pass" if not fails else "FAIL " + ",".join(fails)))


TOTAL_HEADER = (f"{'bag':<18} {'frames':>6} {'pass':>5} {'dRMSE':>6} {'max':>6} {'|dFn|':>7} "
                f"{'|dFn|%':>6} {'|dFt|':>7} {'|dFt|%':>6} {'|dMz|%':>6} {'dCen':>6} "
                f"{'|dArea|%':>8} {'|dDep|':>6} {'cont':>5}")
TOTAL_UNITS = (f"{'':<18} {'':>6} {'':>5} {'um':>6} {'um':>6} {'mN':>7} {'':>6} {'mN':>7} "
               f"{'':>6} {'':>6} {'mm':>6} {'':>8} {'um':>6} {'agree':>5}")


def format_totals(t: dict[str, Any]) -> str:
    """One table row of a bag's totals (worst |error| over its frames)."""
    def g(key: str, scale: float, fmt: str, width: int) -> str:
        v = t[key]
        return _f(None if v is None else scale * v, fmt, width)

    return (f"{t['bag']:<18} {t['frames']:>6} {t['passed']:>5} {g('disp_rmse_m', 1e6, '.2f', 6)} "
            f"{g('disp_rmse_max_m', 1e6, '.2f', 6)} {g('normal_err_max_n', 1e3, '.2f', 7)} "
            f"{g('normal_err_max_pct', 1, '.1f', 6)} {g('tangential_err_max_n', 1e3, '.2f', 7)} "
            f"{g('tangential_err_max_pct', 1, '.1f', 6)} {g('moment_z_err_max_pct', 1, '.1f', 6)} "
            f"{g('centroid_err_max_m', 1e3, '.3f', 6)} {g('area_err_max_pct', 1, '.1f', 8)} "
            f"{g('max_depth_err_max_m', 1e6, '.0f', 6)} "
            f"{t['in_contact_agree']:>2}/{t['frames']:<2}")


def format_report(per_bag: list[tuple[str, str, list[TouchFrameMetrics]]],
                  totals_only: bool = False) -> tuple[str, list[dict[str, Any]]]:
    """The touch tables: (text, per-bag totals incl. 'all bags').

    ``per_bag``: (bag name, sensor description, frames) of every bag evaluated.
    """
    out = io.StringIO()
    lim = LIMITS
    print("Touch (estimate - truth, pad frame; limits: dRMSE <= "
          f"{lim.disp_rmse * 1e6:g} um, |dFn| <= {100 * lim.normal_rel:g} % + "
          f"{lim.normal_abs * 1e3:g} mN, |dFt| <= {100 * lim.tangential_rel:g} % + "
          f"{lim.tangential_abs * 1e3:g} mN, |dMz| <= {100 * lim.moment_rel:g} % + "
          f"{lim.moment_abs * 1e3:g} mN m, dCen <= {lim.centroid * 1e3:g} mm, |dArea| <= "
          f"{100 * lim.area_rel:g} %, in_contact false untouched / true above "
          f"{lim.contact_on * 1e3:g} mN; docs/touch_evaluation.md)", file=out)
    for name, sensor, _ in per_bag:
        print(f"  {name}: sensor {sensor}", file=out)
    if not totals_only:
        print(FRAME_HEADER, file=out)
        print(UNITS, file=out)
        for _, _, frames in per_bag:
            t0 = min((f.stamp_ns for f in frames), default=0)
            t0 -= t0 % 1_000_000_000
            for f in frames:
                print(format_frame(f, t0), file=out)
        print(file=out)
    totals = [bag_totals(frames, name) for name, _, frames in per_bag]
    everything = [f for _, _, frames in per_bag for f in frames]
    totals.append(bag_totals(everything, "all bags"))
    print(TOTAL_HEADER, file=out)
    print(TOTAL_UNITS, file=out)
    for t in totals:
        print(format_totals(t), file=out)
    failing = {k: v for k, v in totals[-1]["failed_checks"].items() if v}
    print(("frames failing a limit, by check: " + ", ".join(f"{k} {v}"
                                                           for k, v in failing.items()))
          if failing else "every frame within the acceptance limits", file=out)
    return out.getvalue().rstrip("\n"), totals


def touch_section(args: Any, bags: list[Path]) -> str:
    """`tactile-sl evaluate` report section: touch figures of bags with touch ground truth.

    Reads ``args.sensor``, ``args.reference_frames``, ``args.pattern``, ``args.weights``,
    ``args.namespace``, ``args.max_frames``, ``args.totals_only`` and ``args.json`` (figures
    also written to ``<json stem>.touch.json``) when present.
    """
    from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline

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
        from tactile_sl_decoder.classify.classifier import Classifier

        classifier = Classifier.load(weights)
    pipe = StereoPipeline(PatternSpec.load(getattr(args, "pattern", None)), classifier)
    per_bag = []
    try:
        for bag, (sensor, where) in zip(touch_bags, sensors):
            frames = evaluate_touch_bag(
                bag, pipe, sensor, int(getattr(args, "reference_frames", 1) or 1), namespace,
                progress=sys.stderr, max_frames=int(getattr(args, "max_frames", 0) or 0))
            per_bag.append((Path(bag).stem, f"{sensor_text(sensor)} ({where})", frames))
    finally:
        pipe.close()
    text, totals = format_report(per_bag, bool(getattr(args, "totals_only", False)))
    skipped = [Path(b).stem for b in bags if b not in touch_bags]
    if skipped:
        text += f"\n(no touch ground truth, not in the touch figures: {', '.join(skipped)})"
    json_path = getattr(args, "json", None)
    if json_path:
        from tactile_sl_camera.safe_files import write_text

        target = Path(json_path).with_suffix(".touch.json")
        write_text(target, json.dumps({
            "limits": asdict(LIMITS),
            "sensors": {name: sensor for name, sensor, _ in per_bag},
            "bags": totals,
            "frames": [f.summary() for _, _, frames in per_bag for f in frames]}, indent=1))
        text += f"\n(touch figures also in {target})"
    return text


# ---------------------------------------------------------------------- demo pictures
# Pad-frame pictures seen from the touching object's side: x to the right, y up, z towards
# the viewer.  OpenCV and numpy only.

_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX
_GREY_BGR = (128, 128, 128)


def _nice_step(span: float, ticks: int = 6) -> float:
    raw = span / max(ticks, 1)
    mag = 10.0 ** math.floor(math.log10(raw)) if raw > 0 else 1.0
    return next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)


class _Plot:
    """A canvas with one data rectangle (mm, y up), its axes and a colour bar."""

    def __init__(self, extent_mm: tuple[float, float, float, float], title: str,
                 plot_px: int = 560) -> None:
        import cv2

        self.cv2 = cv2
        x0, x1, y0, y1 = extent_mm
        self.extent = extent_mm
        self.scale = plot_px / max(x1 - x0, y1 - y0)          # px per mm
        self.w, self.h = int(round((x1 - x0) * self.scale)), int(round((y1 - y0) * self.scale))
        self.left, self.top = 70, 60
        self.img = np.full((self.top + self.h + 75, self.left + self.w + 150, 3), 255, np.uint8)
        cv2.putText(self.img, title, (10, 25), _FONT, 0.55, (0, 0, 0), 1, cv2.LINE_AA)

    def px(self, x_mm: np.ndarray | float, y_mm: np.ndarray | float) -> tuple[Any, Any]:
        """Pixel (u, v) of pad-frame (x, y) in mm."""
        x0, _, _, y1 = self.extent
        return (self.left + (np.asarray(x_mm) - x0) * self.scale,
                self.top + (y1 - np.asarray(y_mm)) * self.scale)

    def paste(self, bgr: np.ndarray) -> None:
        """An image covering the data rectangle (row 0 = top = largest y)."""
        self.img[self.top:self.top + self.h, self.left:self.left + self.w] = self.cv2.resize(
            bgr, (self.w, self.h), interpolation=self.cv2.INTER_NEAREST)

    def axes(self) -> None:
        cv2, img = self.cv2, self.img
        x0, x1, y0, y1 = self.extent
        cv2.rectangle(img, (self.left, self.top), (self.left + self.w, self.top + self.h),
                      (0, 0, 0), 1)
        step = _nice_step(max(x1 - x0, y1 - y0), 8)
        for t in np.arange(math.ceil(x0 / step) * step, x1 + 1e-9, step):
            u = int(round(float(self.px(t, y0)[0])))
            cv2.line(img, (u, self.top + self.h), (u, self.top + self.h + 5), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (u - 10, self.top + self.h + 20), _FONT, 0.4, (0, 0, 0),
                        1, cv2.LINE_AA)
        for t in np.arange(math.ceil(y0 / step) * step, y1 + 1e-9, step):
            v = int(round(float(self.px(x0, t)[1])))
            cv2.line(img, (self.left - 5, v), (self.left, v), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (self.left - 35, v + 4), _FONT, 0.4, (0, 0, 0), 1,
                        cv2.LINE_AA)
        cv2.putText(img, "x (mm)", (self.left + self.w // 2 - 20, self.top + self.h + 42), _FONT,
                    0.45, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(img, "y (mm)", (5, self.top - 10), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)

    def colour_bar(self, vmax: float, unit: str, colormap: int, nan_label: str = "") -> None:
        cv2, img = self.cv2, self.img
        u0, v0, bw = self.left + self.w + 25, self.top, 20
        ramp = np.linspace(255, 0, self.h).astype(np.uint8).reshape(-1, 1)
        bar = cv2.applyColorMap(np.repeat(ramp, bw, axis=1), colormap)
        img[v0:v0 + self.h, u0:u0 + bw] = bar
        cv2.rectangle(img, (u0, v0), (u0 + bw, v0 + self.h), (0, 0, 0), 1)
        step = _nice_step(vmax, 5)
        for t in np.arange(0.0, vmax + 1e-9, step):
            v = int(round(v0 + self.h * (1 - t / vmax)))
            cv2.line(img, (u0 + bw, v), (u0 + bw + 5, v), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (u0 + bw + 8, v + 4), _FONT, 0.4, (0, 0, 0), 1,
                        cv2.LINE_AA)
        cv2.putText(img, unit, (u0 - 5, v0 - 10), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        if nan_label:
            v = v0 + self.h + 20
            cv2.rectangle(img, (u0, v - 12), (u0 + bw, v + 2), _GREY_BGR, -1)
            cv2.putText(img, nan_label, (u0 + bw + 6, v), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)


def _ceiling(top: float) -> float:
    """A round colour-bar maximum just above ``top`` (> 0)."""
    if top <= 0:
        return 1.0
    step = _nice_step(top, 10)
    return math.ceil(top / step) * step


def _colours(values: np.ndarray, vmax: float, colormap: int) -> np.ndarray:
    import cv2

    t = np.clip(np.nan_to_num(values / vmax), 0.0, 1.0)
    return cv2.applyColorMap((255 * t).astype(np.uint8).reshape(-1, 1), colormap)[:, 0]


def render_pressure(field_points: np.ndarray, pitch: float, title: str = "") -> np.ndarray:
    """BGR picture of the per-cell pressure (kPa) with shear arrows, pad frame, axes in mm.

    ``field_points``: the ``field`` cloud as a structured array (x, y, dx, dy, row, col,
    fx, fy, fz).  Each cell is a square of one pitch at its rest position; its pressure is
    max(0, -fz) / pitch^2.  Arrows: the tangential force (fx, fy) of every other cell
    where it exceeds 5 % of the largest one; the cross is the pressure-weighted centroid.
    """
    import cv2

    rest = np.column_stack([field_points["x"] - field_points["dx"],
                            field_points["y"] - field_points["dy"]]).astype(np.float64) * 1e3
    fz = np.asarray(field_points["fz"], np.float64)
    ft = np.column_stack([field_points["fx"], field_points["fy"]]).astype(np.float64)
    p_kpa = np.maximum(-fz, 0.0) / pitch ** 2 / 1e3
    half = pitch * 1e3 / 2
    extent = (rest[:, 0].min() - half, rest[:, 0].max() + half,
              rest[:, 1].min() - half, rest[:, 1].max() + half) if len(rest) else (-1, 1, -1, 1)
    plot = _Plot(extent, title or "pressure per cell (kPa) and shear, pad frame")
    vmax = _ceiling(float(p_kpa.max(initial=0.0)))
    cmap = cv2.COLORMAP_VIRIDIS
    colours = _colours(p_kpa, vmax, cmap)
    for (x, y), c in zip(rest, colours):                     # drawing only
        u0, v0 = plot.px(x - half, y + half)
        u1, v1 = plot.px(x + half, y - half)
        cv2.rectangle(plot.img, (int(round(float(u0))), int(round(float(v0)))),
                      (int(round(float(u1))), int(round(float(v1)))),
                      tuple(int(k) for k in c), -1)          # 1 px overlap: no seams
    mag = np.hypot(ft[:, 0], ft[:, 1])
    big = float(mag.max(initial=0.0))
    if big > 0:
        show = ((mag > 0.05 * big) & (field_points["row"] % 2 == 0)
                & (field_points["col"] % 2 == 0))
        length = 2.5 * pitch * 1e3 / big                     # mm per N: longest = 2.5 pitch
        for (x, y), f in zip(rest[show], ft[show]):
            a = plot.px(x, y)
            b = plot.px(x + f[0] * length, y + f[1] * length)
            cv2.arrowedLine(plot.img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])),
                            (255, 255, 255), 1, cv2.LINE_AA, tipLength=0.3)
    total = float(np.maximum(-fz, 0.0).sum())
    if total > 0:
        cx, cy = (np.maximum(-fz, 0.0)[:, None] * rest).sum(axis=0) / total
        u, v = plot.px(cx, cy)
        cv2.drawMarker(plot.img, (int(u), int(v)), (0, 0, 255), cv2.MARKER_CROSS, 18, 2)
    plot.axes()
    plot.colour_bar(vmax, "kPa", cmap)
    cv2.putText(plot.img, f"arrows: shear per cell (longest {1e3 * big:.2f} mN = 2.5 pitch); "
                "red cross: centroid; seen from the object (z towards you)",
                (10, plot.img.shape[0] - 10), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return plot.img


def render_depth(depth: np.ndarray, x0: float, y0: float, resolution: float,
                 title: str = "") -> np.ndarray:
    """BGR picture of a depth map (m of indentation; NaN grey), colour bar in um, axes in mm.

    Pixel (i, j) of ``depth`` lies at (x0 + j res, y0 + i res) in the pad frame (the
    ``depth`` topic's grid, docs/touch.md).
    """
    import cv2

    h, w = depth.shape
    half = resolution / 2
    extent = tuple(1e3 * v for v in (x0 - half, x0 + (w - 1) * resolution + half,
                                      y0 - half, y0 + (h - 1) * resolution + half))
    plot = _Plot(extent, title or "depth map (um of indentation), pad frame")
    um = depth.astype(np.float64) * 1e6
    finite = np.isfinite(um)
    top = float(um[finite].max(initial=0.0)) if finite.any() else 0.0
    vmax = _ceiling(top)
    cmap = cv2.COLORMAP_INFERNO
    img = _colours(um.ravel(), vmax, cmap).reshape(h, w, 3)
    img[~finite] = _GREY_BGR
    plot.paste(img[::-1])                                      # row 0 = largest y
    plot.axes()
    plot.colour_bar(vmax, "um", cmap, "not decoded")
    cv2.putText(plot.img, f"max {top:.0f} um at the cells; seen from the object (z towards you)",
                (10, plot.img.shape[0] - 10), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return plot.img
