"""Simulated calibration views: the flat printed artwork (or a checkerboard) at chosen poses.

The simulator's renderer (:meth:`tactile_sl_sim.render.Renderer.render_plane`) draws
a rigid plane seen by its stereo rig, whose calibration is exact (``rig.left_info``,
``rig.right_info``).  Poses are in the simulator's **pad frame** (origin at the rest pad's
centre, cameras at z = -rig distance, z pointing away from the cameras): the artwork point
(u, v) (artwork frame, metres) sits at ``t + R @ (sx u, v, 0)`` with sx = -1 for mirrored
views (the cameras look at the back of the print).  A straight-edged card hides a chosen
share of the cells; the paper ends 2 mm beyond the glyphs.
"""
from __future__ import annotations

import pathlib
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import yaml

from tactile_sl_common.bag_io import BagWriter
from tactile_sl_common.camera_info import camera_info_fields, save_camera_info_yaml
from tactile_sl_common.images import image_fields
from tactile_sl_decoder.calibrate.checkerboard import board_points
from tactile_sl_decoder.pattern.artwork import render_array
from tactile_sl_sim.artwork import Artwork, checkerboard_albedo, load_artwork
from tactile_sl_sim.optics import rotation_xyz
from tactile_sl_sim.render import Renderer

PAPER_MARGIN_M = 0.002     # paper beyond the outer glyph centres
BACKGROUND = 0.30          # albedo of what lies beyond the paper
CARD = 0.62                # albedo of the card that hides part of the pattern


@dataclass
class PlanePose:
    """Pose of a flat target in the simulator's pad frame, and how much of it is hidden."""

    R: np.ndarray              # (3, 3) target axes in the pad frame
    t: np.ndarray              # (3,) target origin (cell (0, 0) centre) in the pad frame, m
    hide_angle: float = 0.0    # direction of the hiding card's edge normal, rad
    hide_fraction: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"R": self.R.tolist(), "t": self.t.tolist(), "hide_angle": self.hide_angle,
                "hide_fraction": self.hide_fraction}


def artwork_of(pattern: Any = None) -> Artwork:
    """The simulator artwork of a pattern (default: the installed artwork of the shipped one).

    ``pattern`` is a :class:`tactile_sl_decoder.pattern.Pattern`; its artwork is rasterised
    in memory exactly as ``tactile-sl pattern render`` draws it.
    """
    if pattern is None:
        return load_artwork()

    image, facts = render_array(pattern, 40.0)
    return Artwork(image.astype(np.float32) / 255.0, tuple(facts["cell00_px"]),
                   float(facts["pitch_px"]), float(pattern.pitch_m), pattern.rows,
                   pattern.cols)


def random_poses(count: int, artwork: Artwork, seed: int = 0,
                 tilt_deg: tuple[float, float] = (12.0, 35.0),
                 distance_m: tuple[float, float] = (0.012, 0.020),
                 offset_m: float = 0.0015, roll_deg: float = 8.0, hide_fraction: float = 0.0,
                 rig_distance_m: float = 0.015) -> list[PlanePose]:
    """``count`` poses: tilts in evenly spread directions, distances from the cameras.

    The pattern's centre sits ``distance`` in front of the cameras' plane (z = -rig
    distance), shifted by up to ``offset_m`` sideways.
    """
    rng = np.random.default_rng(seed)
    p = artwork.pitch_m
    centre = np.array([(artwork.cols - 1) * p / 2, (artwork.rows - 1) * p / 2, 0.0])
    az0 = rng.uniform(0, 2 * np.pi)
    poses = []
    for i in range(count):
        az = az0 + 2 * np.pi * i / max(count, 1) + rng.uniform(-0.3, 0.3)
        tilt = np.radians(rng.uniform(*tilt_deg))
        R_tilt = cv2.Rodrigues(tilt * np.array([np.cos(az), np.sin(az), 0.0]))[0]
        R = R_tilt @ rotation_xyz(0.0, 0.0, np.radians(rng.uniform(-roll_deg, roll_deg)))
        position = np.array([rng.uniform(-offset_m, offset_m), rng.uniform(-offset_m, offset_m),
                             rng.uniform(*distance_m) - rig_distance_m])
        poses.append(PlanePose(R, position - R @ centre, float(rng.uniform(0, 2 * np.pi)),
                               hide_fraction))
    return poses


def tilted_pose(artwork: Artwork, axis: str, tilt_deg: float, distance_m: float = 0.016,
                rig_distance_m: float = 0.015) -> PlanePose:
    """The whole artwork tilted ``tilt_deg`` about the pad frame's x or y axis (``axis``).

    The pattern's centre sits ``distance_m`` in front of the cameras' plane, on the rig's
    axis: tilted about x, rows foreshorten (the near end is at the image top or bottom);
    about y, columns do.
    """
    if axis not in ("x", "y"):
        raise ValueError(f"axis must be 'x' or 'y', got {axis!r}")
    p = artwork.pitch_m
    centre = np.array([(artwork.cols - 1) * p / 2, (artwork.rows - 1) * p / 2, 0.0])
    direction = np.array([1.0, 0.0, 0.0]) if axis == "x" else np.array([0.0, 1.0, 0.0])
    R = cv2.Rodrigues(np.radians(tilt_deg) * direction)[0]
    position = np.array([0.0, 0.0, distance_m - rig_distance_m])
    return PlanePose(R, position - R @ centre)


def visible_cells(renderer: Renderer, pose: PlanePose, rows: int, cols: int, pitch_m: float,
                  camera: int = 0, mirrored: bool = False, hidden: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cells whose whole glyph lies inside one camera's image: row, col, true (u, v) px.

    A cell counts when its centre projects at least half its own image spacing (the
    distance to the projection of its right or down neighbour, whichever is larger) inside
    the image, so that its glyph does not touch the border (extraction drops those), and
    the cell is not hidden by the card (``hidden``: (rows, cols) bool, optional).
    """
    cam = renderer.rig.cameras[camera]
    sx = -1.0 if mirrored else 1.0
    r, c = (a.reshape(-1) for a in np.mgrid[0:rows, 0:cols])

    def project(rr: np.ndarray, cc: np.ndarray) -> np.ndarray:
        obj = np.column_stack([sx * cc * pitch_m, rr * pitch_m, np.zeros(len(rr))])
        return cam.project(obj @ pose.R.T + pose.t)

    uv = project(r.astype(float), c.astype(float))
    step = np.maximum(np.linalg.norm(project(r + 1.0, c.astype(float)) - uv, axis=1),
                      np.linalg.norm(project(r.astype(float), c + 1.0) - uv, axis=1))
    margin = 0.5 * step
    inside = ((uv[:, 0] >= margin) & (uv[:, 0] <= cam.width - 1 - margin)
              & (uv[:, 1] >= margin) & (uv[:, 1] <= cam.height - 1 - margin))
    if hidden is not None:
        inside &= ~np.asarray(hidden, bool).reshape(-1)
    return r[inside], c[inside], uv[inside]


def score_decoded_cells(renderer: Renderer, pose: PlanePose, glyphs: Any,
                        shape: tuple[int, int], pitch_m: float, camera: int = 0,
                        mirrored: bool = False) -> tuple[int, int, int]:
    """Visible cells (:func:`visible_cells`), those decoded right, and wrong decoded cells.

    ``glyphs``: the decoded :class:`~tactile_sl_decoder.glyphs.Glyphs` of that camera's
    image.  A decoded glyph is right when its cell is visible and its centre lies within 0.3
    of that cell's image spacing (the smaller step to its right or down neighbour) of the
    cell's true projection, wrong when farther off (a wrong cell, or with a hiding card the
    right cell of a glyph the card's edge cuts, whose ink centroid is off); decoded cells
    that are not visible (glyph partly outside the image) are not counted.
    """
    rows, cols = shape
    vr, vc, vuv = visible_cells(renderer, pose, rows, cols, pitch_m, camera, mirrored)
    cam = renderer.rig.cameras[camera]
    sx = -1.0 if mirrored else 1.0

    def project(r: np.ndarray, c: np.ndarray) -> np.ndarray:
        obj = np.column_stack([sx * c * pitch_m, r * pitch_m, np.zeros(len(r))])
        return cam.project(obj @ pose.R.T + pose.t)

    r, c = vr.astype(float), vc.astype(float)
    step = np.minimum(np.linalg.norm(project(r + 1, c) - vuv, axis=1),
                      np.linalg.norm(project(r, c + 1) - vuv, axis=1))
    slot = np.full((rows, cols), -1, np.int64)
    slot[vr, vc] = np.arange(len(vr))
    decoded = np.flatnonzero(np.asarray(glyphs.row) >= 0)
    at = slot[np.asarray(glyphs.row)[decoded], np.asarray(glyphs.col)[decoded]]
    seen = at >= 0
    at, decoded = at[seen], decoded[seen]
    off = np.hypot(np.asarray(glyphs.u)[decoded] - vuv[at, 0],
                   np.asarray(glyphs.v)[decoded] - vuv[at, 1])
    good = off <= 0.3 * step[at]
    return len(vr), int(len(np.unique(at[good]))), int(np.count_nonzero(~good))


def _albedo_sampler(artwork: Artwork, pose: PlanePose, mirrored: bool) -> Any:
    """albedo_fn(u, v) for render_plane: the artwork (frame units m), the card, the paper."""
    p = artwork.pitch_m
    rows, cols = artwork.rows, artwork.cols
    ca, sa = np.cos(pose.hide_angle), np.sin(pose.hide_angle)
    threshold = -np.inf
    if pose.hide_fraction > 0:
        r, c = np.mgrid[0:rows, 0:cols]
        threshold = float(np.quantile(c * ca + r * sa, pose.hide_fraction))
    tex = np.ascontiguousarray(artwork.albedo, np.float32)

    def albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        col = (-u if mirrored else u) / p        # continuous cell coordinates
        row = v / p
        tx = artwork.cell00_px[0] + col * artwork.pitch_px
        ty = artwork.cell00_px[1] + row * artwork.pitch_px
        n = len(tx)
        width = 4096
        pad = (-n) % width
        mx = np.concatenate([tx, np.full(pad, -1e5)]).astype(np.float32).reshape(-1, width)
        my = np.concatenate([ty, np.full(pad, -1e5)]).astype(np.float32).reshape(-1, width)
        out = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=1.0).reshape(-1)[:n]
        m = PAPER_MARGIN_M / p
        paper = (col > -m) & (col < cols - 1 + m) & (row > -m) & (row < rows - 1 + m)
        out = np.where(paper, out, BACKGROUND)
        hidden = (col * ca + row * sa < threshold) & paper
        return np.where(hidden, CARD, out).astype(np.float32)

    return albedo


def render_pattern_views(renderer: Renderer, artwork: Artwork, poses: list[PlanePose],
                         mirrored: bool = False, blur_sigma: float = 0.6,
                         noise_sigma: float = 1.0, seed: int = 0
                         ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Left/right grey images of the flat artwork at every pose."""
    rng = np.random.default_rng(seed)
    out = []
    for pose in poses:
        fn = _albedo_sampler(artwork, pose, mirrored)
        left, right = (renderer.render_plane(i, pose.R, pose.t, fn, blur_sigma=blur_sigma,
                                             noise_sigma=noise_sigma, rng=rng)
                       for i in range(2))
        out.append((left, right))
    return out


def _board_translation(artwork: Artwork, pose: PlanePose, pattern: tuple[int, int],
                       square: float) -> np.ndarray:
    """Board origin (first inner corner) with the board's centre where the pattern's was."""
    cols, rows = pattern
    p = artwork.pitch_m
    shift = np.array([(artwork.cols - 1) * p / 2 - (cols - 1) * square / 2,
                      (artwork.rows - 1) * p / 2 - (rows - 1) * square / 2, 0.0])
    return pose.t + pose.R @ shift


def render_board_views(renderer: Renderer, artwork: Artwork, poses: list[PlanePose],
                       pattern: tuple[int, int] = (9, 6), square: float = 0.001,
                       blur_sigma: float = 0.6, noise_sigma: float = 1.0, seed: int = 0
                       ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Checkerboard views at the same poses: the board's centre where the pattern's was."""
    rng = np.random.default_rng(seed)
    cols, rows = pattern

    def albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return checkerboard_albedo(u, v, square, cols + 1, rows + 1)

    out = []
    for pose in poses:
        t = _board_translation(artwork, pose, pattern, square)
        left, right = (renderer.render_plane(i, pose.R, t, albedo, blur_sigma=blur_sigma,
                                             noise_sigma=noise_sigma, rng=rng)
                       for i in range(2))
        out.append((left, right))
    return out


def simulated_board_views(renderer: Renderer, pattern: tuple[int, int], square: float,
                          views: int = 15, seed: int = 0
                          ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Checkerboard image pairs rendered by the simulator at varied, fully visible poses."""
    rng = np.random.default_rng(seed)
    cols, rows = pattern
    centre = np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0.0])
    obj = board_points(pattern, square).astype(np.float64)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(out) < views and tries < views * 20:
        tries += 1
        R = rotation_xyz(np.radians(rng.uniform(-28, 28)), np.radians(rng.uniform(-28, 28)),
                         np.radians(rng.uniform(-15, 15)))
        position = np.array([rng.uniform(-0.0015, 0.0015), rng.uniform(-0.0012, 0.0012),
                             rng.uniform(-0.003, 0.002)])
        t = position - R @ centre
        corners = obj @ R.T + t
        ok = True
        for cam in renderer.rig.cameras:
            px = cam.project(corners)
            m = 2.0 * square * cam.K[0, 0] / renderer.rig.params.distance
            if not ((px[:, 0] > m).all() and (px[:, 0] < cam.width - m).all()
                    and (px[:, 1] > m).all() and (px[:, 1] < cam.height - m).all()):
                ok = False
        if not ok:
            continue
        def albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
            return checkerboard_albedo(u, v, square, cols + 1, rows + 1)
        images = [renderer.render_plane(i, R, t, albedo, rng=rng) for i in range(2)]
        out.append((images[0], images[1]))
    return out


def true_cells_left(renderer: Renderer, pose: PlanePose, row: np.ndarray, col: np.ndarray,
                    pitch_m: float, mirrored: bool = False) -> np.ndarray:
    """True 3-D cell centres (N, 3) in the physical left optical frame (m)."""
    sx = -1.0 if mirrored else 1.0
    obj = np.column_stack([sx * np.asarray(col, float) * pitch_m,
                           np.asarray(row, float) * pitch_m, np.zeros(len(row))])
    return renderer.rig.world_to_left(obj @ pose.R.T + pose.t)


def write_views(out: str | pathlib.Path, views: list[tuple[np.ndarray, np.ndarray]],
                renderer: Renderer, poses: list[PlanePose] | None = None) -> pathlib.Path:
    """left_NNN.png / right_NNN.png, truth_left.yaml / truth_right.yaml (and poses.yaml)."""
    d = pathlib.Path(out)
    d.mkdir(parents=True, exist_ok=True)
    for i, (left, right) in enumerate(views):
        cv2.imwrite(str(d / f"left_{i:03d}.png"), left)
        cv2.imwrite(str(d / f"right_{i:03d}.png"), right)
    save_camera_info_yaml(d / "truth_left.yaml", renderer.rig.left_info)
    save_camera_info_yaml(d / "truth_right.yaml", renderer.rig.right_info)
    if poses is not None:
        doc = {"frame": "simulator pad frame (cameras at z = -distance)",
               "poses": [p.to_dict() for p in poses]}
        (d / "poses.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return d


def write_untouched_bag(path: str | pathlib.Path, renderer: Renderer, frames: int = 2,
                        left_info: Any = None, right_info: Any = None, seed: int = 0
                        ) -> pathlib.Path:
    """A bag of untouched sensor frames (the pad at rest) with the given CameraInfo.

    Default CameraInfo: the true calibration.  For ``calibrate --check`` tests and demos.
    """
    left_info = left_info or renderer.rig.left_info
    right_info = right_info or renderer.rig.right_info
    p = pathlib.Path(path)
    with BagWriter(p) as bag:
        for i in range(frames):
            frame = renderer.render([], seed=seed, frame_index=i)
            stamp = {"sec": 100 + i, "nanosec": 0}
            t_ns = (100 + i) * 10**9
            for side, img, info in (("left", frame.left, left_info),
                                    ("right", frame.right, right_info)):
                bag.write(f"/tactile/{side}/image_raw", "sensor_msgs/msg/Image",
                          {"header": {"stamp": stamp, "frame_id": f"tactile_{side}_optical"},
                           **image_fields(img, "mono8")}, t_ns)
                bag.write(f"/tactile/{side}/camera_info", "sensor_msgs/msg/CameraInfo",
                          camera_info_fields(info, (100 + i, 0), f"tactile_{side}_optical"),
                          t_ns)
    return p
