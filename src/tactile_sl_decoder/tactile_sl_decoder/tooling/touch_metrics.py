"""Touch figures against the simulator's ground truth: displacement, force, moment, contact.

Tooling for ``tactile-sl evaluate``, ``tools/bench_touch.py`` and the demo; the touch stage
never imports it.  Definitions of every figure and of the acceptance limits (issue 10):
``docs/touch_evaluation.md``.  One frame's estimate is a
:class:`~tactile_sl_decoder.touch.stage.TouchResult`, its truth a
:class:`~tactile_sl_sim.loads.TouchTruth` rebuilt from the bag's
``ground_truth/{wrench,field,contact}`` (or an untouched pad, for control bags without them).
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from tactile_sl_common.bag_io import BagReader, stamp_to_ns
from tactile_sl_decoder.touch.sensor import SensorConfig, default_sensor_path, load_sensor
from tactile_sl_sim.loads import touch_truth_from_messages
from tactile_sl_sim.scenes import SceneError, load_scenes

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
    slip_est: Any = None           # the stage's SlipEstimate (None: no output)
    slip_true: Any = None          # the truth's ContactSlip (None: no friction model)
    regions_est: int = 0           # contact regions reported
    regions_true: int = 0          # pressing regions of the truth

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


_KEY_COLS = 1_000_003
"""Cell keys: row * this + col (more columns than any pattern has)."""


def cell_keys(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """One int64 key per (row, col) cell, ordered as the cells are by (row, col)."""
    return np.asarray(rows, np.int64) * _KEY_COLS + np.asarray(cols, np.int64)


def key_cells(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of :func:`cell_keys`' keys."""
    return np.divmod(np.asarray(keys, np.int64), _KEY_COLS)


def matched_cells(rows: np.ndarray, cols: np.ndarray, true_rows: np.ndarray,
                  true_cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cells in both lists (keys, ascending) and their indices in each: (keys, i, j)."""
    keys, i, j = np.intersect1d(cell_keys(rows, cols), cell_keys(true_rows, true_cols),
                                assume_unique=True, return_indices=True)
    return keys, i, j


def displacement_rmse(rows: np.ndarray, cols: np.ndarray, disp: np.ndarray,
                      true_rows: np.ndarray, true_cols: np.ndarray, true_disp: np.ndarray
                      ) -> tuple[float, int]:
    """3-D displacement RMSE (m) over the cells in both fields, matched by (row, col)."""
    _, i, j = matched_cells(rows, cols, true_rows, true_cols)
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
        float(c.max_depth), depth_true, bool(c.in_contact), contact_true, untouched,
        slip_est=getattr(result, "slip", None),
        slip_true=None if truth is None else getattr(truth, "slip", None),
        regions_est=len(c.region_force),
        regions_true=0 if truth is None else len(truth.region_force))


# ---------------------------------------------------------------------- bags


def has_touch_truth(path: str | Path, namespace: str = "/tactile") -> bool:
    """The bag carries ``ground_truth/wrench`` (a touch scene of the simulator)."""
    return f"{namespace.rstrip('/')}/ground_truth/wrench" in BagReader(path).topics


def read_truths(path: str | Path, namespace: str = "/tactile") -> dict[int, Any]:
    """``TouchTruth`` of every frame of a bag by header stamp (ns), from its ground truth.

    With ``ground_truth/slip`` (scenes with friction) the truth carries the slip state.
    """
    ns = namespace.rstrip("/")
    names = {f"{ns}/ground_truth/{k}": k for k in ("wrench", "field", "contact", "slip")}
    reader = BagReader(path)
    parts: dict[int, dict[str, Any]] = {}
    for raw, msg in reader.messages([t for t in names if t in reader.topics]):
        s = msg.header.stamp
        parts.setdefault(stamp_to_ns(s.sec, s.nanosec), {})[names[raw.topic]] = msg
    return {stamp: touch_truth_from_messages(p.get("wrench"), p["field"], p["contact"],
                                             p.get("slip"))
            for stamp, p in parts.items() if "field" in p and "contact" in p}


def scene_sensor(bag: str | Path) -> tuple[Any, str] | None:
    """Sensor of a simulated bag from the scenes file it was rendered from, if found.

    The simulator does not record the elastomer in the bag; ``make bags`` names each bag
    after its scene, so a ``*scenes.yaml`` beside the bag with a scene of the bag's name
    gives it.  Returns (SensorConfig, description) or None.
    """
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


# ---------------------------------------------------------------------- any indenter


@dataclass(frozen=True)
class ShapeLimits:
    """Issue 25's limits for the contact area and the largest indentation, any indenter."""

    area_rel: float = 0.15
    depth: float = 10e-6      # m


SHAPE_LIMITS = ShapeLimits()
SHAPE_HEADER = (f"{'scene':<20} {'t s':>4} {'Fn true':>7} {'area true':>9} {'est':>7} "
                f"{'dArea%':>7} {'regions':>7} {'depth true':>10} {'est':>7} {'dDep':>6}  result")
SHAPE_UNITS = (f"{'':<20} {'':>4} {'N':>7} {'mm2':>9} {'mm2':>7} {'':>7} {'e/t':>7} "
               f"{'um':>10} {'um':>7} {'um':>6}")


def shape_checks(f: TouchFrameMetrics, limits: ShapeLimits = SHAPE_LIMITS) -> list[str]:
    """Names of the limits a frame in contact misses: ``area``, ``depth`` (no output: both)."""
    if not f.output:
        return ["area", "depth"]
    failed = []
    if f.contact_true and not (f.contact_est and abs(f.area_err_pct) <= 100 * limits.area_rel):
        failed.append("area")
    if abs(f.depth_err) > limits.depth:
        failed.append("depth")
    return failed


def format_shape_report(per_scene: list[tuple[str, list[TouchFrameMetrics]]],
                        limits: ShapeLimits = SHAPE_LIMITS) -> str:
    """Area and largest indentation per frame of each scene, then the worst of each scene."""
    lines = [f"contact area and largest indentation (limits |dArea| <= "
             f"{100 * limits.area_rel:g} %, |dDep| <= {limits.depth * 1e6:g} um; "
             "docs/touch_evaluation.md)", SHAPE_HEADER, SHAPE_UNITS]
    worst = []
    for name, frames in per_scene:
        t0 = min((f.stamp_ns for f in frames), default=0)
        t0 -= t0 % 1_000_000_000
        for f in frames:
            failed = shape_checks(f, limits)
            lines.append(
                f"{name:<20} {(f.stamp_ns - t0) / 1e9:>4.1f} {_f(f.normal_true, '.3f', 7)} "
                f"{f.area_true * 1e6:>9.2f} {f.area_est * 1e6:>7.2f} "
                f"{_f(f.area_err_pct, '+.1f', 7)} "
                f"{f'{f.regions_est}/{f.regions_true}':>7} "
                f"{f.depth_true * 1e6:>10.1f} {f.depth_est * 1e6:>7.1f} "
                f"{_f(1e6 * f.depth_err, '+.1f', 6)}  "
                + ("pass" if not failed else "FAIL " + ",".join(failed)))
        area = [abs(f.area_err_pct) for f in frames if math.isfinite(f.area_err_pct)]
        depth = [abs(f.depth_err) * 1e6 for f in frames]
        within = sum(not shape_checks(f, limits) for f in frames)
        worst.append(f"{name:<20} worst |dArea| {max(area, default=NAN):5.1f} %, |dDep| "
                     f"{max(depth, default=NAN):5.1f} um, {within}/{len(frames)} frames "
                     "within the limits")
    return "\n".join(lines + [""] + worst)
