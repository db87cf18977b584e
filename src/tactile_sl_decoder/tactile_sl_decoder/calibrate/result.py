"""The result of a stereo calibration, whichever the target (checkerboard or printed pattern).

Both calibration paths (:mod:`.checkerboard`, :mod:`.solve`) and the in-place refinement of
:mod:`.health` return a :class:`StereoCalibrationResult` and raise :class:`CalibrationError`.
"""
from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass

import numpy as np

from tactile_sl_common.camera_info import CameraCalibration, camera_info_yaml_text
from tactile_sl_common.safe_files import write_files


class CalibrationError(RuntimeError):
    """Calibration that cannot be done with the given data; the message says why."""


@dataclass
class StereoCalibrationResult:
    """Estimated calibration with its quality figures."""

    left: CameraCalibration
    right: CameraCalibration
    R: np.ndarray  # left -> right rotation
    T: np.ndarray  # left -> right translation (metres)
    rms_stereo: float  # joint reprojection RMS (px)
    rms_left: float
    rms_right: float
    pairs_used: int
    pairs_total: int

    @property
    def baseline(self) -> float:
        return float(np.linalg.norm(self.T))

    def summary(self) -> str:
        kl, kr = self.left.K, self.right.K
        return (f"pairs used {self.pairs_used}/{self.pairs_total}; reprojection RMS: stereo "
                f"{self.rms_stereo:.3f} px, left {self.rms_left:.3f} px, right "
                f"{self.rms_right:.3f} px; baseline {self.baseline * 1e3:.4f} mm; "
                f"left fx {kl[0, 0]:.2f} fy {kl[1, 1]:.2f}; right fx {kr[0, 0]:.2f} "
                f"fy {kr[1, 1]:.2f}")

    def save(self, directory: str | os.PathLike, left_name: str = "left.yaml",
             right_name: str = "right.yaml") -> tuple[pathlib.Path, pathlib.Path]:
        """Write both camera_calibration YAML files, both or neither (safe_files.write_files)."""
        left, right = write_files(directory, {
            left_name: camera_info_yaml_text(self.left).encode(),
            right_name: camera_info_yaml_text(self.right).encode()})
        return left, right
