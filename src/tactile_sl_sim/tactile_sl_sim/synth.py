"""Turn scenes into messages and MCAP bags: images, camera_info and ground truth per frame.

Shared by ``tactile-sl synth`` (bags) and the ``sim_camera`` node (live topics), so both
publish exactly the same thing for the same scene.
"""
from __future__ import annotations

import os
import pathlib
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import cv2
import numpy as np

from tactile_sl_common.bag_io import BagWriter
from tactile_sl_common.camera_info import camera_info_fields
from tactile_sl_common.clouds import cloud_fields, pack_field, pack_points
from tactile_sl_common.images import image_fields
from tactile_sl_sim.artwork import load_artwork
from tactile_sl_sim.contact import Contact
from tactile_sl_sim.friction import ContactSlip
from tactile_sl_sim.loads import TouchTruth
from tactile_sl_sim.optics import SimulatedCameraPair
from tactile_sl_sim.render import Nuisances, Renderer, StereoFrame
from tactile_sl_sim.scenes import Scene

LEFT_FRAME = "tactile_left_optical_frame"
RIGHT_FRAME = "tactile_right_optical_frame"
IMAGE = "sensor_msgs/msg/Image"
INFO = "sensor_msgs/msg/CameraInfo"
CLOUD = "sensor_msgs/msg/PointCloud2"
WRENCH = "geometry_msgs/msg/WrenchStamped"
CONTACT = "tactile_sl_msgs/msg/Contact"
SLIP = "tactile_sl_msgs/msg/Slip"
PAD_FRAME = "tactile_pad"


@dataclass
class FrameIds:
    """Frame ids of the two optical frames (the cloud uses the left one, per contract)."""

    left: str = LEFT_FRAME
    right: str = RIGHT_FRAME
    pad: str = PAD_FRAME  # touch ground truth (CONTRACT.md "Touch")


class RendererCache:
    """Renderers keyed by their optics/artwork, so scenes sharing a rig share ray tables."""

    def __init__(self, artwork: str | os.PathLike | None = None) -> None:
        self.artwork = artwork
        self._renderers: dict[Any, Renderer] = {}

    def get(self, scene: Scene) -> Renderer:
        key = scene.renderer_key() + (str(self.artwork),)
        if key not in self._renderers:
            art = load_artwork(scene.artwork or self.artwork)
            self._renderers[key] = Renderer(art, SimulatedCameraPair(scene.rig), scene.pad,
                                            supersample=scene.supersample,
                                            mirrored=scene.mirrored)
        return self._renderers[key]


def render_scene_frame(scene: Scene, renderer: Renderer, frame: int) -> StereoFrame:
    """Render frame ``frame`` of a scene (deterministic for the scene's seed)."""
    return renderer.render(scene.contacts_at(frame), scene.nuisances_at(frame), seed=scene.seed,
                           frame_index=frame, color=scene.encoding == "bgr8")


def frame_messages(scene: Scene, renderer: Renderer, frame: StereoFrame, stamp_ns: int,
                   ids: FrameIds | None = None) -> list[tuple[str, str, dict[str, Any]]]:
    """(relative topic, type, fields) of one stereo frame, all with the same stamp."""
    ids = ids or FrameIds()
    stamp = (int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000))
    header_l = {"stamp": {"sec": stamp[0], "nanosec": stamp[1]}, "frame_id": ids.left}
    header_r = {"stamp": {"sec": stamp[0], "nanosec": stamp[1]}, "frame_id": ids.right}
    xyz, rows, cols = frame.truth.visible_points()
    rig = renderer.rig
    return [
        ("left/image_raw", IMAGE, {"header": header_l, **image_fields(frame.left, scene.encoding)}),
        ("right/image_raw", IMAGE,
         {"header": header_r, **image_fields(frame.right, scene.encoding)}),
        ("left/camera_info", INFO, camera_info_fields(rig.left_info, stamp, ids.left)),
        ("right/camera_info", INFO, camera_info_fields(rig.right_info, stamp, ids.right)),
        ("ground_truth/points", CLOUD,
         cloud_fields(pack_points(xyz, rows, cols), stamp, ids.left)),
    ] + (touch_messages(frame.truth.touch, stamp, ids.pad) if scene.has_loads else [])


def _vec(v: np.ndarray) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def touch_messages(touch: TouchTruth | None, stamp: tuple[int, int], frame_id: str
                   ) -> list[tuple[str, str, dict[str, Any]]]:
    """Touch ground truth of a load scene's frame: wrench (all-load frames), field, contact.

    With friction (``friction`` on the loads) also ``ground_truth/slip``.
    """
    if touch is None:
        raise ValueError("a frame of a load scene has no touch ground truth")
    header = {"stamp": {"sec": stamp[0], "nanosec": stamp[1]}, "frame_id": frame_id}
    out: list[tuple[str, str, dict[str, Any]]] = []
    if touch.force is not None and touch.moment is not None:
        out.append(("ground_truth/wrench", WRENCH, {
            "header": header, "wrench": {"force": _vec(touch.force),
                                         "torque": _vec(touch.moment)}}))
    out.append(("ground_truth/field", CLOUD, cloud_fields(
        pack_field(touch.position, touch.displacement, touch.rows, touch.cols), stamp,
        frame_id)))
    out.append(("ground_truth/contact", CONTACT, {
        "header": header, "in_contact": bool(touch.in_contact), "area": float(touch.area),
        "centroid": _vec(touch.centroid), "max_depth": float(touch.max_depth),
        "normal_force": float(touch.normal_force), "shear_force": _vec(touch.shear_force),
        "peak_pressure": float(touch.peak_pressure),
        "cells_in_contact": int(touch.cells_in_contact),
        "region_force": [float(v) for v in touch.region_force],
        "region_area": [float(v) for v in touch.region_area],
        "region_centroid": [_vec(c) for c in touch.region_centroid]}))
    if touch.slip is not None:
        out.append(("ground_truth/slip", SLIP, slip_truth_fields(touch.slip, header)))
    return out


def slip_truth_fields(slip: ContactSlip, header: dict[str, Any]) -> dict[str, Any]:
    """tactile_sl_msgs/Slip of a frame's slip truth (NaN where the contract says)."""
    c = slip.centre
    return {"header": header, "state": int(slip.state),
            "stick_ratio": float(slip.stick_ratio), "slip_margin": float(slip.margin),
            "friction_coefficient": float(slip.friction),
            "direction": _vec(np.asarray(slip.direction, np.float64)),
            "centroid": {"x": float(c[0]), "y": float(c[1]), "z": 0.0},
            "contact_radius": float(slip.radius), "stick_radius": float(slip.stick_radius),
            "normal_force": float(slip.normal_force),
            "tangential_force": float(np.hypot(*slip.transmitted)), "fit_residual": 0.0}


def iter_scene(scene: Scene, renderer: Renderer, ids: FrameIds | None = None
               ) -> Iterator[tuple[int, int, list[tuple[str, str, dict[str, Any]]]]]:
    """(frame index, stamp ns, messages) for every frame of a scene."""
    for i in range(scene.frames):
        frame = render_scene_frame(scene, renderer, i)
        stamp = scene.stamp_ns(i)
        yield i, stamp, frame_messages(scene, renderer, frame, stamp, ids)


class Progress:
    """A small progress bar on stderr (a line per update when stderr is not a terminal)."""

    def __init__(self, total: int, stream: Any = None, width: int = 30) -> None:
        self.total = max(1, total)
        self.done = 0
        self.stream = stream or sys.stderr
        self.width = width
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = time.monotonic()

    def update(self, n: int = 1, label: str = "") -> None:
        self.done += n
        frac = self.done / self.total
        filled = int(round(frac * self.width))
        rate = self.done / max(time.monotonic() - self.start, 1e-9)
        line = (f"[{'#' * filled}{'.' * (self.width - filled)}] {self.done}/{self.total} "
                f"frames {rate:.1f}/s {label}")
        if self.tty:
            self.stream.write("\r" + line.ljust(78))
            if self.done >= self.total:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def write_scene_bag(scene: Scene, renderer: Renderer, path: str | os.PathLike,
                    namespace: str = "/tactile", ids: FrameIds | None = None,
                    on_frame: Callable[[int], None] | None = None) -> pathlib.Path:
    """Write a scene as a rosbag2-compatible MCAP bag; log time = stamp."""
    p = pathlib.Path(path)
    tmp = p.with_name(p.name + ".partial")
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    with BagWriter(tmp) as bag:
        for i, stamp, messages in iter_scene(scene, renderer, ids):
            for topic, schema, fields in messages:
                bag.write(f"{ns}/{topic}", schema, fields, stamp)
            if on_frame:
                on_frame(i)
    os.replace(tmp, p)
    return p


def benchmark(renderer: Renderer, frames: int = 20, contacts: list[Contact] | None = None,
              nuisances: Nuisances | None = None) -> tuple[float, float]:
    """Stereo frames per second (rendering plus ground truth) on one core.

    Returns (per wall-clock second, per CPU second); OpenCV is limited to one thread, so on a
    busy machine the CPU figure is the one that says what one free core does.
    """
    if contacts is None:
        contacts = [Contact("sphere", radius=0.004, x=0.0005, y=-0.0003, depth=0.0006)]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        renderer.render(contacts, nuisances, seed=0, frame_index=0)  # warm caches
        wall, cpu = time.perf_counter(), time.process_time()
        for i in range(frames):
            moved = [Contact(c.kind, c.radius, c.length, c.angle, c.fillet, c.x + 1e-5 * i,
                             c.y, c.depth, c.shear) for c in contacts]
            renderer.render(moved, nuisances, seed=0, frame_index=i)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        cv2.setNumThreads(threads)
    return frames / wall, frames / max(cpu, 1e-9)


def stats(frame: StereoFrame) -> dict[str, float]:
    """A few numbers about a frame (for logs)."""
    return {"visible": int(frame.truth.visible.sum()),
            "max_indent_mm": float(-np.min(frame.field.data[:, :, 2], initial=0.0) * 1e3)}
