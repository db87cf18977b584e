"""The untouched reference state and the pad frame's pose in the left optical frame.

Every decoded cell is a material point with a known identity, so the reference is simply
each cell's 3-D position averaged over the first ``reference_frames`` decoded frames.  The
pad frame (contract "Touch") is fitted to it: the rigid motion that best maps the cells'
nominal rest positions ((c - (cols-1)/2) p, (r - (rows-1)/2) p, 0) onto their measured
positions (least squares, Arun, Huang & Blostein 1987, "Least-squares fitting of two 3-D
point sets", IEEE PAMI 9(5), with Umeyama's 1991 reflection fix, eq. 39-40).  The fit's
residual checks the calibration and the pitch at once: a flat pad seen by a correct rig
fits to a few micrometres.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class ReferenceError(ValueError):
    """A reference that cannot define the pad frame (too few or degenerate cells)."""


MIN_REFERENCE_CELLS = 16
RESIDUAL_WARN_M = 2e-5
"""RMS residual (m) of the pad-frame fit above which a reference is suspect.  A flat,
untouched pad seen through a correct calibration fits to 2 um on the bundled bags; a
reference taken while pressed fits to 47 um at 0.5 N and 190 um at 2 N on the half-space
(every later wrench is then off by that load).  A light press (0.05 N: 4.9 um) stays below
it: the residual cannot tell it from noise."""


def residual_warning(residual_rms: float, limit: float = RESIDUAL_WARN_M) -> str | None:
    """The warning for a reference whose fit residual is ``residual_rms`` (m), or None.

    None while the residual is at most ``limit``; a NaN residual is suspect too.
    """
    if residual_rms <= limit:
        return None
    return (f"pad frame fit residual {residual_rms * 1e6:.1f} um RMS > {limit * 1e6:g} um: "
            f"the pad was touched when the reference was taken, or the calibration or the "
            f"pattern's pitch is off; forces and contact will be wrong (release the pad and "
            f"call tare, or check the calibration)")


@dataclass(frozen=True)
class PadPose:
    """p_left = rotation @ p_pad + translation (metres, left optical frame)."""

    rotation: np.ndarray      # (3, 3)
    translation: np.ndarray   # (3,)
    residual_rms: float       # m, RMS distance of the reference cells from the fitted plane grid
    residual_max: float       # m

    def to_pad(self, xyz_left: np.ndarray) -> np.ndarray:
        """Points of the left optical frame in the pad frame."""
        return (np.asarray(xyz_left, np.float64) - self.translation) @ self.rotation

    def quaternion(self) -> tuple[float, float, float, float]:
        """(x, y, z, w) of the rotation (Shepperd's method, numerically safe)."""
        m = self.rotation
        tr = float(np.trace(m))
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s,
                 0.25 * s)
        else:
            i = int(np.argmax(np.diag(m)))
            j, k = (i + 1) % 3, (i + 2) % 3
            s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
            v = [0.0, 0.0, 0.0]
            v[i] = 0.25 * s
            v[j] = (m[j, i] + m[i, j]) / s
            v[k] = (m[k, i] + m[i, k]) / s
            q = (v[0], v[1], v[2], (m[k, j] - m[j, k]) / s)
        n = float(np.linalg.norm(q))
        w_sign = 1.0 if q[3] >= 0 else -1.0
        return tuple(float(w_sign * c / n) for c in q)  # type: ignore[return-value]


def nominal_positions(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], pitch: float,
                      mirrored: bool = False) -> np.ndarray:
    """Rest positions of cells in the pad frame (z = 0).

    x runs along increasing column; for a pad seen mirrored (through the elastomer) it runs
    along decreasing column so that the frame stays right-handed with z pointing away from
    the cameras (the simulator's convention).
    """
    n_rows, n_cols = shape
    sx = -1.0 if mirrored else 1.0
    x = sx * (np.asarray(cols, np.float64) - (n_cols - 1) / 2.0) * pitch
    y = (np.asarray(rows, np.float64) - (n_rows - 1) / 2.0) * pitch
    return np.column_stack([x, y, np.zeros_like(x)])


def fit_pad_pose(nominal: np.ndarray, measured: np.ndarray) -> PadPose:
    """Rigid motion (no scale) taking nominal pad positions to measured left-frame points."""
    nominal = np.asarray(nominal, np.float64)
    measured = np.asarray(measured, np.float64)
    if len(nominal) < MIN_REFERENCE_CELLS:
        raise ReferenceError(f"only {len(nominal)} reference cells; the pad frame needs at "
                             f"least {MIN_REFERENCE_CELLS}")
    spread = nominal[:, :2] - nominal[:, :2].mean(axis=0)
    if np.linalg.svd(spread, compute_uv=False)[-1] < 1e-9 * np.sqrt(len(nominal)):
        raise ReferenceError("reference cells lie on one line; the pad frame is undefined")
    cn, cm = nominal.mean(axis=0), measured.mean(axis=0)
    h = (nominal - cn).T @ (measured - cm)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    translation = cm - rotation @ cn
    resid = np.linalg.norm(measured - (nominal @ rotation.T + translation), axis=1)
    return PadPose(rotation, translation, float(np.sqrt(np.mean(resid ** 2))),
                   float(resid.max()))


class ReferenceBuilder:
    """Averages the first N decoded frames cell by cell into the reference."""

    def __init__(self, frames: int, shape: tuple[int, int]) -> None:
        if frames < 1:
            raise ValueError(f"reference_frames must be >= 1, got {frames}")
        self.frames = int(frames)
        self.shape = shape
        n = shape[0] * shape[1]
        self._sum = np.zeros((n, 3))
        self._sum_sq = np.zeros((n, 3))
        self._count = np.zeros(n, np.int64)
        self.collected = 0

    def add(self, rows: np.ndarray, cols: np.ndarray, xyz: np.ndarray) -> bool:
        """Add one decoded frame; True once enough frames are in."""
        idx = np.asarray(rows, np.int64) * self.shape[1] + np.asarray(cols, np.int64)
        xyz = np.asarray(xyz, np.float64)
        np.add.at(self._sum, idx, xyz)
        np.add.at(self._sum_sq, idx, xyz * xyz)
        np.add.at(self._count, idx, 1)
        self.collected += 1
        return self.collected >= self.frames

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """(cell indices, mean positions) of cells seen in at least half the frames."""
        keep = self._count * 2 >= max(self.collected, 1)
        keep &= self._count > 0
        idx = np.flatnonzero(keep)
        return idx, self._sum[idx] / self._count[idx, None]

    def scatter(self, idx: np.ndarray) -> np.ndarray:
        """Variance (len(idx), 3) m^2 of one frame's position of each cell about its mean.

        The sample variance over the frames that saw the cell, per axis of the input frame;
        NaN for a cell seen fewer than twice.  What a single frame's noise is, whatever the
        print's and the decoder's fixed errors (which the mean keeps and a displacement
        cancels).
        """
        count = self._count[idx].astype(np.float64)[:, None]
        mean = self._sum[idx] / np.maximum(count, 1.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            var = (self._sum_sq[idx] - count * mean * mean) / (count - 1.0)
        var[np.broadcast_to(count < 2, var.shape)] = np.nan
        out: np.ndarray = np.maximum(var, 0.0)
        return out
