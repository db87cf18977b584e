"""Several sensors on one robot: the YAML list that ``sensors.launch.py`` starts (no rclpy).

One entry per sensor (config/sensors.yaml)::

    sensors:
      - namespace: left_hand                # required; topics /left_hand/points ...
        left_device: /dev/v4l/by-id/usb-...-video-index0    # stable device paths
        right_device: /dev/v4l/by-id/usb-...-video-index0
        left_camera_info_url: file:///etc/tactile_sl/left_hand/left.yaml
        right_camera_info_url: file:///etc/tactile_sl/left_hand/right.yaml
        # optional: frame_prefix (default '<namespace>_'), side_by_side, sensor_file,
        # pattern_file, classifier_weights, mirrored, camera: {...}, decoder: {...}

:func:`load_sensors` checks the list (names, duplicates, device paths) and returns, per
sensor, the namespace and the parameter overrides of its ``stereo_camera`` and ``decoder``
nodes, so the launch file only turns them into nodes. Where the machine has fewer than two
cores per sensor, each decoder runs its two images in process on one thread
(``camera_processes`` false, ``threads`` 1, unless the entry sets them; :func:`decoder_overrides`).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

CAMERA_KEYS = ("left_device", "right_device", "side_by_side", "left_camera_info_url",
               "right_camera_info_url")
DECODER_KEYS = ("sensor_file", "pattern_file", "classifier_weights", "mirrored")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")


class SensorsFileError(ValueError):
    """The sensors list cannot be used; the message names the entry and the problem."""


@dataclass
class SensorConfig:
    """One sensor: its namespace and the parameters of its two nodes."""

    namespace: str
    frame_prefix: str
    camera: dict[str, Any] = field(default_factory=dict)
    decoder: dict[str, Any] = field(default_factory=dict)


SHARED_CORE_DECODER = {"camera_processes": False, "threads": 1}
"""A decoder's settings where it shares its cores with other sensors' decoders."""


def decoder_overrides(sensors: int, cpus: int | None) -> dict[str, Any]:
    """The decoders' parameters for ``sensors`` of them on ``cpus`` cores ({}: the defaults).

    A decoder's camera worker processes (or its second thread) shorten a frame only when a
    core is free for each image; with fewer than two cores per decoder the decoders contend
    for the cores, and the handing over of images, the workers' wake-ups and their pickled
    answers cost more than the parallel images gain: each decoder then runs its frame in
    process on one thread (:data:`SHARED_CORE_DECODER`).  Measured with two sensors at
    30 Hz on a 2-vCPU AMD EPYC VM (tools/bench_graph.py --sensors 2, 60 s, two rounds
    alternating, 2026-12-03, load average 3.7-4.7): 285-456 frames dropped of 1806 per
    sensor with camera processes, 112-156 in process on one thread; p99 stamp-to-wrench
    119-133 against 95-108 ms; 855-860 against 333-344 MB resident per decoder.  (Before
    the camera processes, 2026-12-02: threads 1 dropped 669-858 frames, threads 2 850-913.)
    """
    if cpus is None or 2 * sensors <= cpus:
        return {}
    return dict(SHARED_CORE_DECODER)


def parse_sensors(doc: Any, source: str = "sensors", cpus: int | None = -1
                  ) -> list[SensorConfig]:
    """Sensor configurations from the parsed YAML document.

    ``cpus``: the cores the decoders share (-1: this machine's, None: leave the decoders' defaults).
    """
    if not isinstance(doc, dict) or not isinstance(doc.get("sensors"), list) \
            or not doc["sensors"]:
        raise SensorsFileError(f"{source}: expected a non-empty list under 'sensors:'")
    out: list[SensorConfig] = []
    for i, entry in enumerate(doc["sensors"]):
        where = f"{source}: sensor {i + 1}"
        if not isinstance(entry, dict):
            raise SensorsFileError(f"{where}: expected a mapping")
        unknown = set(entry) - {"namespace", "frame_prefix", "camera", "decoder",
                                *CAMERA_KEYS, *DECODER_KEYS}
        if unknown:
            raise SensorsFileError(f"{where}: unknown keys {sorted(unknown)}")
        ns = str(entry.get("namespace", "")).strip("/")
        if not _NAME.match(ns):
            raise SensorsFileError(f"{where}: namespace {ns!r} is not a ROS name")
        where = f"{source}: sensor {ns}"
        prefix = str(entry.get("frame_prefix", ns.replace("/", "_") + "_"))
        if prefix.startswith("/") or any(c.isspace() for c in prefix):
            raise SensorsFileError(f"{where}: frame_prefix {prefix!r} has a leading '/' or "
                                   "spaces")
        camera = {k: entry[k] for k in CAMERA_KEYS if k in entry}
        camera.update(entry.get("camera") or {})
        for side in ("left", "right"):
            if side == "right" and camera.get("side_by_side"):
                continue
            device = camera.get(f"{side}_device")
            if device in (None, ""):
                raise SensorsFileError(f"{where}: {side}_device is required (a stable "
                                       "/dev/v4l/by-id/... path)")
            camera[f"{side}_device"] = str(device)
        for key in ("left_camera_info_url", "right_camera_info_url"):
            if key in camera:
                camera[key] = str(camera[key])
        decoder = {k: entry[k] for k in DECODER_KEYS if k in entry}
        decoder.update(entry.get("decoder") or {})
        camera["frame_prefix"] = decoder["frame_prefix"] = prefix
        out.append(SensorConfig(ns, prefix, camera, decoder))
    for attr in ("namespace", "frame_prefix"):
        seen = [getattr(s, attr) for s in out]
        dup = sorted({v for v in seen if seen.count(v) > 1})
        if dup:
            raise SensorsFileError(f"{source}: {attr} used by more than one sensor: {dup}")
    devices = [d for s in out for d in (s.camera.get("left_device"),
                                        s.camera.get("right_device")) if d]
    dup = sorted({d for d in devices if devices.count(d) > 1})
    if dup:
        raise SensorsFileError(f"{source}: device used twice: {dup}")
    _set_decoder_overrides(out, os.cpu_count() if cpus == -1 else cpus)
    return out


def _set_decoder_overrides(sensors: list[SensorConfig], cpus: int | None) -> None:
    """Each decoder's :func:`decoder_overrides`, except what its entry sets itself."""
    for key, value in decoder_overrides(len(sensors), cpus).items():
        for sensor in sensors:
            sensor.decoder.setdefault(key, value)


def load_sensors(path: str | Path) -> list[SensorConfig]:
    """Sensor configurations of a sensors YAML file."""
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SensorsFileError(f"{path}: {exc}") from exc
    return parse_sensors(doc, str(path))
