"""Scenes: what happens in front of the simulated sensor, described in YAML.

A scenes file has optional ``defaults`` (merged into every scene) and a list of ``scenes``::

    defaults: {fps: 10, seed: 0, encoding: mono8, nuisances: {noise_sigma: 0.8}}
    scenes:
      - name: sphere_press
        frames: 8
        contacts:
          - indenter: {kind: sphere, radius: 0.004}     # metres
            keyframes:                                   # linear in between; values carry on
              - {frame: 0, depth: 0.0, x: 0.0, y: 0.0}
              - {frame: 3, depth: 0.0006}
              - {frame: 5, depth: 0.0006, shear: [0.0001, 0.0]}
              - {frame: 7, depth: 0.0}

Scene keys: name, frames, fps, seed, encoding (mono8 | bgr8), start_time (seconds, stamps
of frame 0), supersample, mirrored, rig (RigParams), pad (PadParams), nuisances (Nuisances),
exposure_keyframes ([{frame, exposure}]), elastomer ({youngs_modulus, poisson_ratio,
thickness}: the pad under load contacts), contacts. Indenter keys: kind (sphere, cylinder,
edge, flat), radius, length, angle_deg, fillet. Keyframe keys: frame, depth, x, y,
shear [sx, sy], angle_deg.

Load contacts (known tractions, see ``loads.py``): indenter ``{kind: load, radius, profile:
hertz | uniform | punch | cylinder, friction, length, angle_deg}`` (``length`` and
``angle_deg``: a cylinder's axis; ``radius`` is its contact half-width), keyframe keys
frame, x, y, force [fx, fy, fz] (N, pad frame, fz <= 0 presses), torque (N m about the
disc's normal). ``friction`` (mu > 0, Hertz loads without torque; on every load of the
scene or on none) gives the tangential load Cattaneo-Mindlin partial slip, and gross slip
beyond mu P (``friction.py``; ground truth ``ground_truth/slip``)::

      - indenter: {kind: load, radius: 0.004, profile: hertz}
        keyframes:
          - {frame: 0, x: 0.0, y: 0.0, force: [0.0, 0.0, 0.0]}
          - {frame: 2, force: [0.1, 0.0, -1.0], torque: 0.0005}
"""
from __future__ import annotations

import copy
import os
import pathlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_sim.contact import Contact, FieldGrid, PadParams
from tactile_sl_sim.loads import DEFAULT_ELASTOMER, PROFILES, LoadContact
from tactile_sl_sim.optics import RigParams
from tactile_sl_sim.render import Nuisances

SCENE_KEYS = {"name", "frames", "fps", "seed", "encoding", "start_time", "supersample",
              "mirrored", "rig", "pad", "nuisances", "exposure_keyframes", "contacts",
              "artwork", "description", "elastomer"}
INDENTER_KEYS = {"kind", "radius", "length", "angle_deg", "fillet"}
KEYFRAME_KEYS = {"frame", "depth", "x", "y", "shear", "angle_deg"}
LOAD_KEYS = {"kind", "radius", "profile", "friction", "length", "angle_deg"}
LOAD_KEYFRAME_KEYS = {"frame", "x", "y", "force", "torque"}
ELASTOMER_KEYS = {"youngs_modulus", "poisson_ratio", "thickness"}
DEFAULT_START_TIME = 1_700_000_000


class SceneError(ValueError):
    """A scenes file that cannot be used; the message names the scene and the key."""


def _check_keys(doc: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(doc) - allowed)
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(unknown)} "
                         f"(allowed: {', '.join(sorted(allowed))})")


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


@dataclass
class ContactTrack:
    """One indenter and its keyframed trajectory."""

    indenter: dict[str, Any]
    keyframes: list[dict[str, Any]]

    @property
    def is_load(self) -> bool:
        return self.indenter.get("kind") == "load"

    def _state(self, frame: int) -> dict[str, Any]:
        """Keyframe values in a frame: carried forward, linear in between."""
        if self.is_load:
            state: dict[str, Any] = {"x": 0.0, "y": 0.0, "force": (0.0, 0.0, 0.0),
                                     "torque": 0.0}
            vectors = {"force": 3}
        else:
            state = {"depth": 0.0, "x": 0.0, "y": 0.0, "shear": (0.0, 0.0),
                     "angle_deg": float(self.indenter.get("angle_deg", 0.0))}
            vectors = {"shear": 2}
        filled = []
        for kf in self.keyframes:  # carry values forward so every keyframe is complete
            state = {**state, **{k: v for k, v in kf.items() if k != "frame"}}
            for key, n in vectors.items():
                vec = tuple(float(s) for s in state[key])
                if len(vec) != n:
                    raise ValueError(f"{key} needs {n} numbers, got {state[key]!r}")
                state[key] = vec
            filled.append((int(kf["frame"]), dict(state)))
        s = filled[0][1]
        if frame >= filled[-1][0]:
            s = filled[-1][1]
        else:
            for (f0, s0), (f1, s1) in zip(filled, filled[1:]):
                if f0 <= frame < f1:
                    t = (frame - f0) / (f1 - f0)
                    s = {k: (tuple((1 - t) * np.asarray(s0[k]) + t * np.asarray(s1[k]))
                             if k in vectors else (1 - t) * float(s0[k]) + t * float(s1[k]))
                         for k in s0}
                    break
        return s

    def at(self, frame: int, elastomer: Elastomer = DEFAULT_ELASTOMER
           ) -> Contact | LoadContact:
        """The indenter's (or load's) state in a frame (linear between keyframes)."""
        s = self._state(frame)
        if self.is_load:
            return LoadContact(radius=float(self.indenter.get("radius", 0.004)),
                               profile=str(self.indenter.get("profile", "hertz")),
                               x=float(s["x"]), y=float(s["y"]),
                               force=tuple(float(v) for v in s["force"]),  # type: ignore
                               torque=float(s["torque"]), elastomer=elastomer,
                               friction=float(self.indenter.get("friction", 0.0)),
                               length=float(self.indenter.get("length", 0.0)),
                               angle=float(np.radians(self.indenter.get("angle_deg", 0.0))))
        return Contact(kind=str(self.indenter.get("kind", "sphere")),
                       radius=float(self.indenter.get("radius", 0.005)),
                       length=float(self.indenter.get("length", 0.0)),
                       fillet=float(self.indenter.get("fillet", 1e-4)),
                       angle=float(np.radians(s["angle_deg"])),
                       x=float(s["x"]), y=float(s["y"]), depth=max(0.0, float(s["depth"])),
                       shear=(float(s["shear"][0]), float(s["shear"][1])))


@dataclass
class Scene:
    """A validated scene."""

    name: str
    frames: int = 1
    fps: float = 10.0
    seed: int = 0
    encoding: str = "mono8"
    start_time: float = DEFAULT_START_TIME
    supersample: int = 2
    mirrored: bool = False
    artwork: str | None = None
    rig: RigParams = field(default_factory=RigParams)
    pad: PadParams = field(default_factory=PadParams)
    nuisances: Nuisances = field(default_factory=Nuisances)
    exposure_keyframes: list[dict[str, float]] = field(default_factory=list)
    contacts: list[ContactTrack] = field(default_factory=list)
    description: str = ""
    elastomer: Elastomer = DEFAULT_ELASTOMER

    def contacts_at(self, frame: int) -> list[Contact | LoadContact]:
        return [track.at(frame, self.elastomer) for track in self.contacts]

    @property
    def has_loads(self) -> bool:
        """Whether any contact is a load (the scene then carries touch ground truth)."""
        return any(track.is_load for track in self.contacts)

    def nuisances_at(self, frame: int) -> Nuisances:
        """Nuisances of one frame (exposure keyframes applied)."""
        if not self.exposure_keyframes:
            return self.nuisances
        kf = sorted(self.exposure_keyframes, key=lambda k: k["frame"])
        frames = [float(k["frame"]) for k in kf]
        values = [float(k["exposure"]) for k in kf]
        nz = copy.copy(self.nuisances)
        nz.exposure = float(np.interp(frame, frames, values))
        return nz

    def stamp_ns(self, frame: int) -> int:
        """Integer nanosecond stamp of a frame (exact, no float accumulation)."""
        start = int(round(self.start_time * 1e9))
        return start + int(round(frame * 1e9 / self.fps))

    def renderer_key(self) -> tuple[Any, ...]:
        return (repr(self.rig), repr(self.pad), self.supersample, self.mirrored, self.artwork)


def _check_on_grid(load: LoadContact, frame: int) -> None:
    """A load's disc must lie on the simulator's field grid, or its traction is cut off."""
    x1 = FieldGrid.x0 + (FieldGrid.nx - 1) * FieldGrid.spacing
    y1 = FieldGrid.y0 + (FieldGrid.ny - 1) * FieldGrid.spacing
    reach = load.reach
    if (load.x - reach < FieldGrid.x0 or load.x + reach > x1
            or load.y - reach < FieldGrid.y0 or load.y + reach > y1):
        raise ValueError(f"frame {frame}: the load disc (radius {reach} m at "
                         f"({load.x}, {load.y}) m) leaves the simulated pad "
                         f"[{FieldGrid.x0}, {x1:.4f}] x [{FieldGrid.y0}, {y1:.4f}] m")


def parse_scene(doc: dict[str, Any], where: str = "scene") -> Scene:
    """Validate one scene mapping (defaults already merged)."""
    if not isinstance(doc, dict):
        raise SceneError(f"{where}: a scene must be a mapping")
    name = str(doc.get("name", "")).strip()
    where = f"{where} {name!r}" if name else where
    if not name or any(c in name for c in "/\\ "):
        raise SceneError(f"{where}: needs a name usable as a file name")
    _check_keys(doc, SCENE_KEYS, where)
    elastomer = _parse_elastomer(doc.get("elastomer") or {}, where)
    try:
        scene = Scene(
            name=name, frames=int(doc.get("frames", 1)), fps=float(doc.get("fps", 10.0)),
            seed=int(doc.get("seed", 0)), encoding=str(doc.get("encoding", "mono8")),
            start_time=float(doc.get("start_time", DEFAULT_START_TIME)),
            supersample=int(doc.get("supersample", 2)), mirrored=bool(doc.get("mirrored", False)),
            artwork=doc.get("artwork"), rig=RigParams.from_dict(doc.get("rig")),
            pad=PadParams(**(doc.get("pad") or {})),
            nuisances=Nuisances.from_dict(doc.get("nuisances")),
            exposure_keyframes=list(doc.get("exposure_keyframes") or []),
            description=str(doc.get("description", "")), elastomer=elastomer)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where}: {exc}") from exc
    if scene.frames < 1 or scene.fps <= 0:
        raise SceneError(f"{where}: frames must be >= 1 and fps > 0")
    if scene.encoding not in ("mono8", "bgr8"):
        raise SceneError(f"{where}: encoding must be mono8 or bgr8, not {scene.encoding!r}")
    for i, c in enumerate(doc.get("contacts") or []):
        scene.contacts.append(_parse_contact(c, scene, f"{where} contact {i}"))
    frictional = {bool(t.indenter.get("friction")) for t in scene.contacts if t.is_load}
    if len(frictional) > 1:
        raise SceneError(f"{where}: friction must be set on every load contact of the scene "
                         "or on none (the slip truth is that of the load pressing hardest)")
    return scene


def _parse_elastomer(el_doc: Any, where: str) -> Elastomer:
    """The scene's elastomer mapping (missing keys from DEFAULT_ELASTOMER)."""
    if not isinstance(el_doc, dict):
        raise SceneError(f"{where}: elastomer must be a mapping "
                         f"({', '.join(sorted(ELASTOMER_KEYS))})")
    _check_keys(el_doc, ELASTOMER_KEYS, f"{where} elastomer")
    try:
        defaults = DEFAULT_ELASTOMER
        return Elastomer(
            youngs_modulus=float(el_doc.get("youngs_modulus", defaults.youngs_modulus)),
            poisson_ratio=float(el_doc.get("poisson_ratio", defaults.poisson_ratio)),
            thickness=float(el_doc.get("thickness", defaults.thickness)))
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where} elastomer: {exc}") from exc


def _parse_contact(contact: Any, scene: Scene, where: str) -> ContactTrack:
    """One contact mapping of a scene, checked in every frame of the scene."""
    if not isinstance(contact, dict) or "indenter" not in contact:
        raise SceneError(f"{where}: needs an indenter mapping and keyframes")
    _check_keys(contact, {"indenter", "keyframes"}, where)
    if not isinstance(contact["indenter"], dict):
        raise SceneError(f"{where}: indenter must be a mapping")
    load = contact["indenter"].get("kind") == "load"
    _check_keys(contact["indenter"], LOAD_KEYS if load else INDENTER_KEYS, f"{where} indenter")
    if load and contact["indenter"].get("profile", "hertz") not in PROFILES:
        raise SceneError(f"{where} indenter: profile must be one of {', '.join(PROFILES)}, "
                         f"not {contact['indenter'].get('profile')!r}")
    if load and scene.mirrored:
        raise SceneError(f"{where}: load contacts need mirrored: false (their ground truth "
                         "is in the pad frame, which a mirrored view would flip)")
    kfs = contact.get("keyframes") or [{"frame": 0}]
    for kf in kfs:
        if not isinstance(kf, dict):
            raise SceneError(f"{where}: every keyframe must be a mapping")
        _check_keys(kf, LOAD_KEYFRAME_KEYS if load else KEYFRAME_KEYS, f"{where} keyframe")
        if "frame" not in kf:
            raise SceneError(f"{where}: every keyframe needs a frame index")
    frames = [int(k["frame"]) for k in kfs]
    if frames != sorted(frames) or len(set(frames)) != len(frames):
        raise SceneError(f"{where}: keyframe frames must increase strictly")
    track = ContactTrack(dict(contact["indenter"]), list(kfs))
    try:
        for f in range(scene.frames):
            state = track.at(f, scene.elastomer)
            if isinstance(state, LoadContact):
                _check_on_grid(state, f)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where}: {exc}") from exc
    return track


def load_scenes(path: str | os.PathLike) -> list[Scene]:
    """All scenes of a scenes YAML file, validated."""
    p = pathlib.Path(path)
    if not p.is_file():
        raise SceneError(f"{p}: no such scenes file")
    try:
        doc = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise SceneError(f"{p}: not valid YAML ({exc})") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("scenes"), list):
        raise SceneError(f"{p}: expected a mapping with a 'scenes' list")
    defaults = doc.get("defaults") or {}
    scenes = [parse_scene(_merge(defaults, s if isinstance(s, dict) else {}), f"{p}")
              for s in doc["scenes"]]
    names = [s.name for s in scenes]
    if len(set(names)) != len(names):
        raise SceneError(f"{p}: scene names must be unique")
    return scenes
