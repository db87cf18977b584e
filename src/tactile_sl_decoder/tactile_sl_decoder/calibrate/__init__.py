"""Camera calibration with the printed pattern as the target, and its health check in place.

Views of the flat artwork decode to uniquely identified planar points (partial and occluded
views included), which calibrate the stereo pair by Zhang's method (:mod:`.solve`); the
untouched pad of the assembled sensor is one more known planar view, from which
:mod:`.health` judges a calibration in place and refines the extrinsics.  Simulated views
for tests and benchmarks are in :mod:`.simulate`.  No rclpy here.
"""
from __future__ import annotations

from .solve import (  # noqa: F401
    CalibrationOptions,
    PatternCalibration,
    ViewReport,
    calibrate_pattern_stereo,
    coverage_image,
)
from .views import CameraView, PatternTarget, StereoView, ViewDecoder  # noqa: F401
