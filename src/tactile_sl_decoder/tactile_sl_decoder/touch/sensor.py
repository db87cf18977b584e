"""The sensor file: the elastomer's properties and the pad frame's name (contract "Touch").

Loaded once at start; every problem is a :class:`SensorFileError` naming the file and the key,
so a node or the CLI can print one line and stop.
"""
from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from tactile_sl_common.elasticity import Elastomer

FORMAT_VERSION = 1
TOP_KEYS = ("tactile_sl_sensor", "elastomer", "pad_frame")
ELASTOMER_KEYS = ("youngs_modulus", "poisson_ratio", "thickness")
DEFAULT_PAD_FRAME = "tactile_pad"


class SensorFileError(ValueError):
    """A sensor file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class SensorConfig:
    """What the touch stage needs to know about the pad."""

    elastomer: Elastomer
    pad_frame: str = DEFAULT_PAD_FRAME
    source: str = "<defaults>"

    def with_overrides(self, youngs_modulus: float | None = None,
                       poisson_ratio: float | None = None, thickness: float | None = None,
                       pad_frame: str | None = None) -> "SensorConfig":
        """A copy with node parameters applied (None = keep the file's value)."""
        e = self.elastomer
        try:
            elastomer = Elastomer(
                youngs_modulus=e.youngs_modulus if youngs_modulus is None else youngs_modulus,
                poisson_ratio=e.poisson_ratio if poisson_ratio is None else poisson_ratio,
                thickness=e.thickness if thickness is None else thickness)
        except ValueError as exc:
            raise SensorFileError(f"elastomer parameters: {exc}") from exc
        return SensorConfig(elastomer, pad_frame or self.pad_frame, self.source)


def default_sensor_path() -> Path:
    """The sensor file the package ships (``data/sensor.yaml``)."""
    return Path(__file__).resolve().parent.parent / "data" / "sensor.yaml"


def _unknown(keys: Any, allowed: tuple[str, ...], where: str) -> None:
    for key in keys:
        if key in allowed:
            continue
        close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        if close:
            # A misspelt known key would otherwise be ignored silently.
            raise SensorFileError(f"unknown key {where}.{key}{hint}; known: "
                                  f"{', '.join(allowed)}")


def _number(doc: dict[str, Any], key: str, where: str) -> float:
    if key not in doc:
        raise SensorFileError(f"{where}.{key} is missing")
    value = doc[key]
    if isinstance(value, str):
        # YAML 1.1 (PyYAML) reads exponents without a sign, like the contract's 3.0e5, as
        # strings; accept any text that is a plain decimal number.
        try:
            value = float(value.strip())
        except ValueError:
            raise SensorFileError(f"{where}.{key} must be a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SensorFileError(f"{where}.{key} must be a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise SensorFileError(f"{where}.{key} must be finite, got {value!r}")
    return float(value)


def parse_sensor(doc: Any, source: str = "<memory>") -> SensorConfig:
    """Validate a sensor mapping (contract format version 1)."""
    def fail(text: str) -> SensorFileError:
        return SensorFileError(f"{source}: {text}")

    if not isinstance(doc, dict):
        raise fail("expected a mapping with tactile_sl_sensor, elastomer and pad_frame")
    if doc.get("tactile_sl_sensor") != FORMAT_VERSION:
        raise fail(f"tactile_sl_sensor must be {FORMAT_VERSION} (format version), got "
                   f"{doc.get('tactile_sl_sensor')!r}")
    try:
        _unknown(doc, TOP_KEYS, "sensor")
        el = doc.get("elastomer")
        if not isinstance(el, dict):
            raise SensorFileError("elastomer must be a mapping with youngs_modulus, "
                                  "poisson_ratio and thickness")
        _unknown(el, ELASTOMER_KEYS, "elastomer")
        values = {k: _number(el, k, "elastomer") for k in ELASTOMER_KEYS}
        frame = doc.get("pad_frame", DEFAULT_PAD_FRAME)
        if not isinstance(frame, str) or not frame.strip() or " " in frame:
            raise SensorFileError(f"pad_frame must be a frame name, got {frame!r}")
        try:
            elastomer = Elastomer(**values)
        except ValueError as exc:
            raise SensorFileError(f"elastomer: {exc}") from exc
    except SensorFileError as exc:
        raise fail(str(exc)) from None
    return SensorConfig(elastomer, frame, source)


def read_yaml_file(path: Path, what: str, error: type[ValueError]) -> Any:
    """The YAML document of a small settings file; ``error`` names a missing or bad file."""
    if not path.is_file():
        raise error(f"{path}: no such {what} file")
    try:
        return yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not a YAML {what} file ({exc})") from exc


def load_sensor(path: str | os.PathLike | None = None) -> SensorConfig:
    """Load and validate a sensor file (default: the shipped one)."""
    p = Path(path) if path else default_sensor_path()
    return parse_sensor(read_yaml_file(p, "sensor", SensorFileError), str(p))


def sensor_yaml_text(config: SensorConfig, comment: str = "") -> str:
    """The contract's sensor file for ``config`` (what ``calibrate --loads`` writes)."""
    e = config.elastomer
    head = "".join(f"# {line}\n" for line in comment.splitlines()) if comment else ""
    return (f"{head}tactile_sl_sensor: {FORMAT_VERSION}\n"
            f"elastomer:\n"
            f"  youngs_modulus: {e.youngs_modulus:.6g}   # Pa\n"
            f"  poisson_ratio: {e.poisson_ratio:.6g}\n"
            f"  thickness: {e.thickness:.6g}          # m; 0 = elastic half-space\n"
            f"pad_frame: {config.pad_frame}\n")
