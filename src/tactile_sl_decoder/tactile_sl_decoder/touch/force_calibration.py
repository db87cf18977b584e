"""Force calibration: the elastomer's Young's modulus (optionally its thickness) from loads.

The loads are known normal forces in some frames of a recording, e.g. calibration weights
pressed on the pad.

For a fixed Poisson ratio and thickness the surface compliance is proportional to 1/E
(Johnson, Contact Mechanics, 1985, eqs. 2.18-2.19: every term carries 1/E), so the
resultant the touch stage estimates from the same displacements scales exactly with E:
F(E) = (E / E0) F(E0).  The least-squares E over the loaded frames is therefore closed form,
E = E0 sum(P_i Q_i) / sum(Q_i^2), with P_i the known and Q_i the estimated normal forces at
E0 (no iteration).  The thickness is not identifiable from forces alone (any thickness
gives forces proportional to the loads); with ``fit_thickness`` each candidate thickness
is scored by how well the fitted traction map explains the measured displacement field
(relative residual), and the best one is kept.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.touch.driver import TouchDriver
from tactile_sl_decoder.touch.sensor import SensorConfig, read_yaml_file
from tactile_sl_decoder.touch.stage import TouchParams
from tactile_sl_decoder.touch.traction import TractionParams

MIN_LOADS = 2
THICKNESS_CANDIDATES = (0.0, 0.5e-3, 1e-3, 1.5e-3, 2e-3, 3e-3, 4e-3, 6e-3, 8e-3)


class ForceCalibrationError(ValueError):
    """Loads or frames that cannot calibrate the sensor; the message says why."""


@dataclass(frozen=True)
class KnownLoad:
    """A normal force (N, pressing > 0) applied in one stereo frame of the recording."""

    frame: int
    normal_force: float


@dataclass
class LoadFit:
    """One loaded frame: known and estimated normal force at the fitted modulus."""

    frame: int
    known: float
    estimated: float

    @property
    def error(self) -> float:
        """Relative error of the fitted estimate."""
        return (self.estimated - self.known) / self.known


@dataclass
class ForceCalibration:
    """The result: a sensor file's elastomer and how well it explains the loads."""

    sensor: SensorConfig
    loads: list[LoadFit] = field(default_factory=list)
    residual_by_thickness: dict[float, float] = field(default_factory=dict)

    @property
    def rms_error(self) -> float:
        """RMS relative force error over the loads."""
        return float(np.sqrt(np.mean([f.error ** 2 for f in self.loads])))

    def report(self) -> str:
        """A few lines for the terminal."""
        e = self.sensor.elastomer
        lines = [f"Young's modulus {e.youngs_modulus:.4g} Pa (Poisson ratio "
                 f"{e.poisson_ratio:.3g}, thickness "
                 f"{'half-space' if e.thickness == 0 else f'{e.thickness * 1e3:.3g} mm'})",
                 "frame   known N   estimated N   error"]
        lines += [f"{f.frame:5d}   {f.known:7.4f}   {f.estimated:11.4f}   {f.error * 100:+6.2f} %"
                  for f in self.loads]
        lines.append(f"RMS error {self.rms_error * 100:.2f} % over {len(self.loads)} loads")
        if self.residual_by_thickness:
            lines.append("thickness candidates (relative displacement residual): " + ", ".join(
                f"{'hs' if h == 0 else f'{h * 1e3:g}mm'} {r:.4f}"
                for h, r in sorted(self.residual_by_thickness.items())))
        return "\n".join(lines)


def load_loads_file(path: str | os.PathLike) -> list[KnownLoad]:
    """The known loads: ``loads: [{frame: I, normal_force: N}, ...]`` (frames from 0)."""
    p = Path(path)
    doc = read_yaml_file(p, "loads", ForceCalibrationError)
    if not isinstance(doc, dict) or not isinstance(doc.get("loads"), list):
        raise ForceCalibrationError(f"{p}: expected a mapping with a 'loads' list of "
                                    "{frame, normal_force}")
    out = []
    for i, item in enumerate(doc["loads"]):
        try:
            frame, force = int(item["frame"]), float(item["normal_force"])
        except (TypeError, KeyError, ValueError):
            raise ForceCalibrationError(f"{p}: loads[{i}] needs an integer frame and a "
                                        f"normal_force in N, got {item!r}") from None
        if frame < 0 or not math.isfinite(force) or force <= 0:
            raise ForceCalibrationError(f"{p}: loads[{i}]: frame must be >= 0 and "
                                        f"normal_force > 0 N (pressing), got {item!r}")
        out.append(KnownLoad(frame, force))
    frames = [ld.frame for ld in out]
    if len(set(frames)) != len(frames):
        raise ForceCalibrationError(f"{p}: a frame is listed twice")
    if len(out) < MIN_LOADS:
        raise ForceCalibrationError(f"{p}: {len(out)} load(s); at least {MIN_LOADS} are needed")
    return out


def _estimates(frames: list[np.ndarray], loads: list[KnownLoad], sensor: SensorConfig,
               shape: tuple[int, int], pitch: float, mirrored: bool,
               reference_frames: int) -> tuple[np.ndarray, float]:
    """Estimated normal forces of the loaded frames, and the mean relative residual.

    An unusable reference (:class:`~tactile_sl_decoder.touch.reference.ReferenceError`) ends
    the fit: the recording's first frames must show the untouched pad.
    """
    # forces only: the contact area's constrained inversion is not prepared (0.3-0.5 s each)
    driver = TouchDriver(sensor, shape, pitch, mirrored,
                         TouchParams(reference_frames=reference_frames,
                                     traction=TractionParams(support_weight=0.0)))
    stage = driver.stage
    wanted = {ld.frame: k for k, ld in enumerate(loads)}
    q = np.full(len(loads), np.nan)
    residuals = []
    for i, points in enumerate(frames):
        touch = driver.frame(points)
        if touch.reference_failed is not None:
            raise touch.reference_failed
        out = touch.result
        if i < reference_frames and i in wanted:
            raise ForceCalibrationError(f"frame {i} carries a load but is one of the "
                                        f"{reference_frames} untouched reference frame(s)")
        if out is None or i not in wanted:
            continue
        q[wanted[i]] = -float(out.wrench_force[2])
        assert stage.solver is not None and stage.last_solve is not None
        residuals.append(stage.solver.map_residual(*stage.last_solve))
    missing = [loads[k].frame for k in np.flatnonzero(np.isnan(q))]
    if missing:
        raise ForceCalibrationError(f"no decoded frame for load(s) at frame(s) {missing} "
                                    f"(the recording has {len(frames)} decoded frames)")
    return q, float(np.mean(residuals)) if residuals else float("nan")


def calibrate_forces(frames: Iterable[np.ndarray], loads: list[KnownLoad], start: SensorConfig,
                     shape: tuple[int, int], pitch: float, mirrored: bool = False,
                     reference_frames: int = 1, fit_thickness: bool = False,
                     progress: Any = None) -> ForceCalibration:
    """Fit E (and optionally the thickness) to frames' decoded points with known loads.

    ``frames`` are the contract points of every stereo frame in order; the first
    ``reference_frames`` are the untouched reference.  ``start`` gives the Poisson ratio, the
    pad frame and (unless fitted) the thickness; its modulus is only the scale E0.
    """
    frames = list(frames)
    if len(loads) < MIN_LOADS:
        raise ForceCalibrationError(f"{len(loads)} load(s); at least {MIN_LOADS} are needed")
    known = np.array([ld.normal_force for ld in loads])
    if np.ptp(known) <= 0.05 * known.max():
        raise ForceCalibrationError("the loads are (nearly) all equal; use loads that differ "
                                    "by more than 5 % so the fit is not one point")
    thicknesses = THICKNESS_CANDIDATES if fit_thickness else (start.elastomer.thickness,)
    best: tuple[float, float, np.ndarray] | None = None
    residual_by_h = {}
    for h in thicknesses:
        sensor = start.with_overrides(thickness=h)
        q, residual = _estimates(frames, loads, sensor, shape, pitch, mirrored,
                                 reference_frames)
        residual_by_h[h] = residual
        if progress is not None:
            progress(h, residual)
        if best is None or residual < best[1]:
            best = (h, residual, q)
    assert best is not None
    h, _, q = best
    if not np.all(q > 0):
        raise ForceCalibrationError("a loaded frame shows no pressing force at all; are the "
                                    "frames and loads matched (frame 0 = first decoded frame)?")
    e0 = start.elastomer.youngs_modulus
    e = e0 * float(np.dot(known, q) / np.dot(q, q))
    elastomer = Elastomer(e, start.elastomer.poisson_ratio, h)
    sensor = SensorConfig(elastomer, start.pad_frame, "tactile-sl calibrate --loads")
    fits = [LoadFit(ld.frame, ld.normal_force, float(qi * e / e0)) for ld, qi in zip(loads, q)]
    return ForceCalibration(sensor, fits, residual_by_h if fit_thickness else {})
