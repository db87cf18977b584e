"""Pinhole cameras with plumb-bob distortion and the converging stereo rig of the sensor.

The world frame of the simulator is the pad frame: origin at the centre of the undeformed pad
surface, X right and Y down in the artwork's orientation, Z pointing from the cameras into the
pad (the cameras sit at Z = -distance). The rig's CameraInfo comes from ``cv2.stereoRectify``
on exactly the intrinsics and extrinsics used for rendering, so the published calibration is
the truth, not an estimate.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from tactile_sl_common.camera_info import CameraCalibration

UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-15)


def rotation_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rotation matrix Rz @ Ry @ Rx from angles in radians."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


@dataclass
class Camera:
    """One physical camera: intrinsics K, distortion D, pose (world->camera rotation, centre)."""

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R_cw: np.ndarray  # rotates world vectors into the camera optical frame
    C: np.ndarray  # optical centre in world coordinates (metres)
    name: str = "camera"

    def to_camera(self, Xw: np.ndarray) -> np.ndarray:
        """World points (N, 3) in this camera's optical frame."""
        return (np.asarray(Xw, dtype=np.float64) - self.C) @ self.R_cw.T

    def project(self, Xw: np.ndarray) -> np.ndarray:
        """Exact (distorted) pixel positions (N, 2) of world points, OpenCV pixel convention."""
        Xc = self.to_camera(Xw).reshape(-1, 3)
        if len(Xc) == 0:
            return np.zeros((0, 2))
        px, _ = cv2.projectPoints(Xc, np.zeros(3), np.zeros(3), self.K, self.D)
        return px.reshape(-1, 2)

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Unit-free world ray directions (N, 3) with dz = 1 through distorted pixels (N, 2)."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(pts, self.K, self.D, R=np.eye(3), P=np.eye(3),
                                   criteria=UNDISTORT_CRITERIA).reshape(-1, 2)
        d_cam = np.concatenate([norm, np.ones((len(norm), 1))], axis=1)
        d_world = d_cam @ self.R_cw  # = (R_cw.T @ d_cam.T).T
        return d_world / d_world[:, 2:3]


@dataclass
class RigParams:
    """Geometry of the sensor's camera pair (metres, radians, pixels); defaults ~ the sensor."""

    width: int = 640
    height: int = 480
    distance: float = 0.015  # optical centres to the undeformed pad surface
    baseline: float = 0.004
    convergence: float = float(np.radians(3.0))  # each camera turned this much to the centre
    focal: tuple[float, float] = (540.0, 538.0)  # left fx; right fx (fy = fx * aspect)
    aspect: float = 1.002
    principal_offset: tuple[tuple[float, float], tuple[float, float]] = ((3.2, -2.1), (-2.4, 1.7))
    distortion: tuple[tuple[float, ...], tuple[float, ...]] = (
        (-0.085, 0.021, 4e-4, -3e-4, 0.0), (-0.078, 0.018, -2e-4, 5e-4, 0.0))
    misalignment: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (float(np.radians(0.15)), 0.0, float(np.radians(0.2))),
        (float(np.radians(-0.1)), 0.0, float(np.radians(-0.12))))
    extra: dict[str, Any] = field(default_factory=dict)

    GLYPH_SPACING_PX = 18.0   # the default rig's glyph spacing at the pad (0.5 mm at 15 mm)

    @classmethod
    def for_glyph_spacing(cls, spacing_px: float) -> "RigParams":
        """The default rig with both focal lengths scaled to this glyph spacing in pixels.

        Stands for other lenses or distances (12-24 px in docs/robustness.md).
        """
        scale = float(spacing_px) / cls.GLYPH_SPACING_PX
        fx_left, fx_right = cls.focal
        return cls(focal=(fx_left * scale, fx_right * scale))

    @classmethod
    def from_dict(cls, doc: dict[str, Any] | None) -> "RigParams":
        """Rig from a YAML mapping (unknown keys rejected so typos do not pass silently)."""
        doc = dict(doc or {})
        known = {f for f in cls.__dataclass_fields__ if f != "extra"}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise ValueError(f"unknown rig parameter(s): {', '.join(unknown)} "
                             f"(known: {', '.join(sorted(known))})")
        if "convergence_deg" in doc:
            doc["convergence"] = float(np.radians(doc.pop("convergence_deg")))
        def tup(v: Any) -> Any:
            return tuple(tup(x) for x in v) if isinstance(v, (list, tuple)) else v
        return cls(**{k: tup(v) for k, v in doc.items()})


class SimulatedCameraPair:
    """The simulator's two physical cameras, and the stereo calibration they produce.

    Renders through :class:`Camera`; ``left_info``/``right_info`` are the exact CameraInfo a
    calibration of these cameras gives (what the decoder's ``stereo.StereoRig`` consumes).
    """

    def __init__(self, params: RigParams | None = None) -> None:
        self.params = p = params or RigParams()
        cams = []
        for i, side in enumerate(("left", "right")):
            sign = -1.0 if side == "left" else 1.0
            fx = float(p.focal[i])
            K = np.array([[fx, 0.0, (p.width - 1) / 2 + p.principal_offset[i][0]],
                          [0.0, fx * p.aspect, (p.height - 1) / 2 + p.principal_offset[i][1]],
                          [0.0, 0.0, 1.0]])
            D = np.asarray(p.distortion[i], dtype=np.float64)
            # A camera at x = -b/2 turns towards +x (its z axis tilts to the centre): rotate
            # the camera about its y axis by -sign * convergence, then the small misalignment.
            R_wc = rotation_xyz(0.0, -sign * p.convergence, 0.0) @ rotation_xyz(*p.misalignment[i])
            C = np.array([sign * p.baseline / 2, 0.0, -p.distance])
            cams.append(Camera(p.width, p.height, K, D, R_wc.T, C, side))
        self.left, self.right = cams
        # Extrinsics left -> right: x_r = R x_l + T
        self.R = self.right.R_cw @ self.left.R_cw.T
        self.T = self.right.R_cw @ (self.left.C - self.right.C)
        R1, R2, P1, P2, _Q, _r1, _r2 = cv2.stereoRectify(
            self.left.K, self.left.D, self.right.K, self.right.D, (p.width, p.height),
            self.R, self.T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
        self.left_info = CameraCalibration(p.width, p.height, self.left.K, self.left.D, R1, P1,
                                           camera_name="tactile_left")
        self.right_info = CameraCalibration(p.width, p.height, self.right.K, self.right.D, R2,
                                            P2, camera_name="tactile_right")

    @property
    def cameras(self) -> tuple[Camera, Camera]:
        return self.left, self.right

    def world_to_left(self, Xw: np.ndarray) -> np.ndarray:
        """World (pad) points in the physical left camera optical frame (contract frame)."""
        return self.left.to_camera(Xw)

    def pixels_per_metre_at_pad(self) -> float:
        """Approximate image scale on the undeformed pad (for choosing margins)."""
        return float(self.left.K[0, 0] / self.params.distance)
