"""Camera calibration data: ROS camera_calibration YAML files and CameraInfo messages.

One representation (:class:`CameraCalibration`, numpy K, D, R, P) is shared by the camera
nodes (which load YAML files and publish CameraInfo), the simulator (which builds it from its
optics), the calibration tool (which writes YAML) and the decoder (which reads CameraInfo
messages, from rclpy or from bags). No rclpy import: messages are duck-typed.

Convention (ROS stereo, REP 104): K and D describe the physical camera, R rotates the physical
camera frame into the rectified frame, P is the rectified projection; for the right camera
``P[0, 3] = -fx' * baseline``.
"""
from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

try:  # package:// URLs only; the libraries work without ROS
    from ament_index_python.packages import get_package_share_directory
except ImportError:  # pragma: no cover - without a ROS install
    get_package_share_directory = None  # type: ignore[assignment]  # checked where used

from tactile_sl_common.safe_files import write_files

DISTORTION_MODELS = {"plumb_bob": (5,), "rational_polynomial": (8,), "equidistant": (4,)}


class CameraInfoError(ValueError):
    """Calibration data that is missing, malformed or degenerate; the message says which."""


@dataclass
class CameraCalibration:
    """Intrinsics, distortion, rectification and projection of one camera of a stereo pair.

    P left out is the monocular ``[K | 0]``.
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    P: np.ndarray = field(default_factory=lambda: np.empty((0, 4)))
    distortion_model: str = "plumb_bob"
    camera_name: str = "camera"

    def __post_init__(self) -> None:
        self.K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        self.D = np.asarray(self.D, dtype=np.float64).reshape(-1)
        self.R = np.asarray(self.R, dtype=np.float64).reshape(3, 3)
        if self.P is None or np.size(self.P) == 0:  # monocular default: P = [K | 0]
            self.P = np.hstack([self.K, np.zeros((3, 1))])
        self.P = np.asarray(self.P, dtype=np.float64).reshape(3, 4)
        self.width = int(self.width)
        self.height = int(self.height)

    @property
    def is_calibrated(self) -> bool:
        """False for the all-zero CameraInfo an uncalibrated driver publishes."""
        return bool(self.K[0, 0] > 0 and self.K[1, 1] > 0)

    def validate(self, what: str = "camera calibration") -> "CameraCalibration":
        """Raise CameraInfoError if the data cannot be used for geometry; returns self."""
        if self.width <= 0 or self.height <= 0:
            raise CameraInfoError(f"{what}: image size {self.width}x{self.height} is not positive")
        for name in ("K", "D", "R", "P"):
            if not np.isfinite(getattr(self, name)).all():
                raise CameraInfoError(f"{what}: {name} has non-finite entries")
        if not self.is_calibrated:
            raise CameraInfoError(f"{what}: K has no focal length (fx={self.K[0, 0]}, "
                                  f"fy={self.K[1, 1]}); the camera is not calibrated")
        if abs(self.K[2, 2] - 1.0) > 1e-9 or np.any(self.K[2, :2]) or self.K[1, 0]:
            raise CameraInfoError(f"{what}: K is not an upper-triangular camera matrix "
                                  f"with K[2,2] = 1: {self.K.tolist()}")
        if self.P[0, 0] <= 0 or self.P[1, 1] <= 0 or abs(self.P[2, 2] - 1.0) > 1e-9:
            raise CameraInfoError(f"{what}: P is not a rectified projection matrix "
                                  f"(fx'={self.P[0, 0]}, fy'={self.P[1, 1]}, "
                                  f"P[2,2]={self.P[2, 2]})")
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6) or \
                abs(np.linalg.det(self.R) - 1) > 1e-6:
            raise CameraInfoError(f"{what}: R is not a rotation matrix: {self.R.tolist()}")
        expected = DISTORTION_MODELS.get(self.distortion_model)
        if expected is None:
            raise CameraInfoError(f"{what}: unsupported distortion model "
                                  f"{self.distortion_model!r} (expected one of "
                                  f"{', '.join(DISTORTION_MODELS)})")
        if self.distortion_model == "plumb_bob" and len(self.D) not in (0, 4, 5, 8):
            raise CameraInfoError(f"{what}: plumb_bob needs 5 distortion coefficients, "
                                  f"got {len(self.D)}")
        return self

    def opencv_distortion(self) -> np.ndarray:
        """D as OpenCV wants it (empty D means no distortion)."""
        return self.D if len(self.D) else np.zeros(5)


# --------------------------------------------------------------------------- messages


def _stamp_dict(stamp: Any) -> dict[str, int]:
    if isinstance(stamp, dict):
        return {"sec": int(stamp["sec"]), "nanosec": int(stamp["nanosec"])}
    if isinstance(stamp, (tuple, list)):
        return {"sec": int(stamp[0]), "nanosec": int(stamp[1])}
    return {"sec": int(stamp.sec), "nanosec": int(stamp.nanosec)}


def camera_info_fields(calib: CameraCalibration, stamp: Any, frame_id: str) -> dict[str, Any]:
    """sensor_msgs/CameraInfo fields as a dict (bags; rclpy via :func:`fill_camera_info`)."""
    return {
        "header": {"stamp": _stamp_dict(stamp), "frame_id": frame_id},
        "height": calib.height,
        "width": calib.width,
        "distortion_model": calib.distortion_model,
        "d": [float(x) for x in calib.D],
        "k": [float(x) for x in calib.K.reshape(-1)],
        "r": [float(x) for x in calib.R.reshape(-1)],
        "p": [float(x) for x in calib.P.reshape(-1)],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def fill_camera_info(msg: Any, fields: dict[str, Any]) -> Any:
    """Copy :func:`camera_info_fields` output into an rclpy CameraInfo message."""
    msg.header.stamp.sec = fields["header"]["stamp"]["sec"]
    msg.header.stamp.nanosec = fields["header"]["stamp"]["nanosec"]
    msg.header.frame_id = fields["header"]["frame_id"]
    msg.height, msg.width = fields["height"], fields["width"]
    msg.distortion_model = fields["distortion_model"]
    msg.d = list(fields["d"])
    msg.k = list(fields["k"])
    msg.r = list(fields["r"])
    msg.p = list(fields["p"])
    return msg


def _get(msg: Any, *names: str) -> Any:
    for name in names:
        if isinstance(msg, dict) and name in msg:
            return msg[name]
        if hasattr(msg, name):
            return getattr(msg, name)
    raise CameraInfoError(f"CameraInfo lacks field {names[0]!r}")


def calibration_from_msg(msg: Any, what: str | None = None) -> CameraCalibration:
    """K, D, R, P of a CameraInfo message (rclpy, bag-decoded or dict), validated.

    Raises CameraInfoError for an uncalibrated (all-zero) or degenerate CameraInfo.
    """
    try:
        frame = _get(_get(msg, "header"), "frame_id")
    except CameraInfoError:
        frame = "?"
    what = what or f"CameraInfo ({frame})"
    try:
        calib = CameraCalibration(
            width=int(_get(msg, "width")), height=int(_get(msg, "height")),
            K=np.asarray(list(_get(msg, "k", "K")), dtype=np.float64),
            D=np.asarray(list(_get(msg, "d", "D")), dtype=np.float64),
            R=np.asarray(list(_get(msg, "r", "R")), dtype=np.float64),
            P=np.asarray(list(_get(msg, "p", "P")), dtype=np.float64),
            distortion_model=str(_get(msg, "distortion_model")) or "plumb_bob",
            camera_name=str(frame))
    except ValueError as exc:  # wrong sizes in reshape
        raise CameraInfoError(f"{what}: malformed matrices ({exc})") from exc
    return calib.validate(what)


def stereo_baseline(left: CameraCalibration, right: CameraCalibration) -> float:
    """Baseline in metres from the right camera's P (P[0,3] = -fx' * baseline)."""
    if right.P[0, 0] <= 0:
        raise CameraInfoError("right camera P has no focal length")
    baseline = -right.P[0, 3] / right.P[0, 0]
    if abs(baseline) < 1e-9:
        raise CameraInfoError("right CameraInfo P[0,3] is zero: not the right camera of a "
                              "rectified stereo pair (no baseline)")
    return float(baseline)


# --------------------------------------------------------------------------- YAML files


def _matrix(node: Any, rows: int, cols: int | None, name: str, path: str) -> np.ndarray:
    if not isinstance(node, dict) or "data" not in node:
        raise CameraInfoError(f"{path}: {name} must be a mapping with rows, cols and data")
    data = np.asarray(node["data"], dtype=np.float64).reshape(-1)
    r = int(node.get("rows", rows))
    c = int(node.get("cols", cols if cols is not None else len(data)))
    if r * c != len(data) or (rows and r != rows) or (cols is not None and c != cols):
        raise CameraInfoError(f"{path}: {name} should be {rows}x{cols if cols else 'N'}, "
                              f"has rows={r} cols={c} and {len(data)} values")
    return data.reshape(r, c) if rows > 1 else data


def resolve_url(url: str) -> pathlib.Path:
    """A camera_info_url (``file://``, ``package://pkg/path`` or a plain path) as a path."""
    if url.startswith("file://"):
        return pathlib.Path(os.path.expanduser(url[len("file://"):]))
    if url.startswith("package://"):
        rest = url[len("package://"):]
        package, _, relative = rest.partition("/")
        try:
            if get_package_share_directory is None:
                raise LookupError("ament_index_python is not installed")
            share = get_package_share_directory(package)
        except Exception as exc:  # PackageNotFoundError or ament_index missing
            raise CameraInfoError(f"{url}: package {package!r} not found ({exc})") from exc
        return pathlib.Path(share) / relative
    return pathlib.Path(os.path.expanduser(url))


def load_camera_info_yaml(path: str | os.PathLike) -> CameraCalibration:
    """Read a camera_calibration YAML file (as ROS camera_calibration writes it), validated."""
    path_s = str(path)
    p = resolve_url(path_s) if isinstance(path, str) else pathlib.Path(path)
    if not p.is_file():
        raise CameraInfoError(f"{path_s}: no such camera_info file")
    try:
        doc = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise CameraInfoError(f"{p}: not valid YAML ({exc})") from exc
    if not isinstance(doc, dict):
        raise CameraInfoError(f"{p}: expected a mapping with camera_matrix etc.")
    missing = [k for k in ("image_width", "image_height", "camera_matrix") if k not in doc]
    if missing:
        raise CameraInfoError(f"{p}: missing key(s) {', '.join(missing)}")
    try:
        K = _matrix(doc["camera_matrix"], 3, 3, "camera_matrix", str(p))
        D = (_matrix(doc["distortion_coefficients"], 1, None, "distortion_coefficients", str(p))
             if "distortion_coefficients" in doc else np.zeros(5))
        R = (_matrix(doc["rectification_matrix"], 3, 3, "rectification_matrix", str(p))
             if "rectification_matrix" in doc else np.eye(3))
        P = (_matrix(doc["projection_matrix"], 3, 4, "projection_matrix", str(p))
             if "projection_matrix" in doc else np.hstack([K, np.zeros((3, 1))]))  # [K | 0]
        calib = CameraCalibration(
            width=int(doc["image_width"]), height=int(doc["image_height"]), K=K, D=D, R=R,
            P=P, distortion_model=str(doc.get("distortion_model", "plumb_bob")),
            camera_name=str(doc.get("camera_name", "camera")))
    except (TypeError, ValueError) as exc:
        if isinstance(exc, CameraInfoError):
            raise
        raise CameraInfoError(f"{p}: malformed calibration ({exc})") from exc
    return calib.validate(str(p))


def camera_info_yaml_text(calib: CameraCalibration) -> str:
    """The YAML text ROS camera_calibration writes for one camera."""
    def block(name: str, m: np.ndarray, rows: int, cols: int) -> str:
        values = ", ".join(repr(float(x)) for x in np.asarray(m).reshape(-1))
        return f"{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [{values}]\n"

    return (f"image_width: {calib.width}\nimage_height: {calib.height}\n"
            f"camera_name: {calib.camera_name}\n"
            + block("camera_matrix", calib.K, 3, 3)
            + f"distortion_model: {calib.distortion_model}\n"
            + block("distortion_coefficients", calib.D, 1, len(calib.D))
            + block("rectification_matrix", calib.R, 3, 3)
            + block("projection_matrix", calib.P, 3, 4))


def save_camera_info_yaml(path: str | os.PathLike, calib: CameraCalibration) -> pathlib.Path:
    """Write one camera's calibration as camera_calibration YAML (atomically); the path."""
    p = pathlib.Path(path)
    return write_files(p.parent, {p.name: camera_info_yaml_text(calib).encode()})[0]
