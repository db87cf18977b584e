"""The contract's pattern YAML: load, validate and save.

Loading is strict: a malformed or inconsistent file raises :class:`PatternFormatError`
naming the problem (missing key, wrong type, ragged row, bad digit ...), because a
silently mis-read pattern would decode every glyph to the wrong cell.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from tactile_sl_common.safe_files import write_text

from .constraints import Constraints
from .shapes import default_primitives
from .verify import verify_pattern

FORMAT_VERSION = 1
DEFAULT_PITCH_M = 0.0005
_REQUIRED = ("tactile_sl_pattern", "symbols", "window", "min_hamming", "pitch_m",
             "primitives", "rows", "cols", "array")


class PatternFormatError(ValueError):
    """A pattern file that does not follow the contract format."""


class PatternInvalidError(PatternFormatError):
    """A well-formed pattern file whose array breaks its own ``min_hamming`` / uniqueness."""


@dataclass
class Pattern:
    """An M-array with the constraints it claims and its physical layout."""

    array: np.ndarray
    constraints: Constraints
    pitch_m: float = DEFAULT_PITCH_M
    primitives: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Normalise the array dtype and fill default primitives for the alphabet."""
        self.array = np.ascontiguousarray(self.array, dtype=np.uint8)
        if not self.primitives:
            self.primitives = default_primitives(self.constraints.symbols)

    @property
    def rows(self) -> int:
        """Number of rows of the array."""
        return int(self.array.shape[0])

    @property
    def cols(self) -> int:
        """Number of columns of the array."""
        return int(self.array.shape[1])

    @property
    def windows(self) -> int:
        """Number of (non-toroidal) windows in the array."""
        return self.constraints.window_count(self.rows, self.cols)

    def to_dict(self) -> dict[str, Any]:
        """The YAML document, contract keys first, extra keys after."""
        c = self.constraints
        doc: dict[str, Any] = {
            "tactile_sl_pattern": FORMAT_VERSION,
            "symbols": c.symbols,
            "window": [c.window[0], c.window[1]],
            "min_hamming": c.min_hamming,
            "pitch_m": float(self.pitch_m),
            "primitives": list(self.primitives),
            "rows": self.rows,
            "cols": self.cols,
            "array": ["".join(str(int(v)) for v in row) for row in self.array],
        }
        for key, value in self.extra.items():
            if key not in doc:
                doc[key] = value
        return doc


def _fail(source: str, message: str) -> PatternFormatError:
    return PatternFormatError(f"{source}: {message}")


def _int_field(doc: dict[str, Any], key: str, source: str) -> int:
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(source, f"'{key}' must be an integer, got {value!r}")
    return value


def _array_field(array: Any, rows: int, cols: int, constraints: Constraints,
                 source: str) -> np.ndarray:
    """The ``array`` rows (digit strings) as a (rows, cols) uint8 grid, every cell checked."""
    if not isinstance(array, list):
        raise _fail(source, f"'array' must be a list of strings, got {type(array).__name__}")
    if len(array) != rows:
        raise _fail(source, f"'array' has {len(array)} rows but 'rows' says {rows}")
    if rows < constraints.window[0] or cols < constraints.window[1]:
        raise _fail(source, f"array {rows}x{cols} is smaller than the window "
                            f"{constraints.window[0]}x{constraints.window[1]}")
    grid = np.zeros((rows, cols), dtype=np.uint8)
    for r, line in enumerate(array):
        if isinstance(line, int) and not isinstance(line, bool):
            raise _fail(source, f"array row {r} is a number, not a string: quote it "
                                f"(\"{line}\") so leading zeros survive")
        if not isinstance(line, str):
            raise _fail(source, f"array row {r} must be a string, got {line!r}")
        if len(line) != cols:
            raise _fail(source, f"array row {r} has {len(line)} characters but 'cols' says "
                                f"{cols} (ragged array)")
        for c, ch in enumerate(line):
            if not ch.isdigit() or int(ch) >= constraints.symbols:
                raise _fail(source, f"array row {r} column {c} has symbol {ch!r}, "
                                    f"outside 0..{constraints.symbols - 1}")
        grid[r] = np.frombuffer(line.encode("ascii"), dtype=np.uint8) - ord("0")
    return grid


def pattern_from_dict(doc: Any, source: str = "<pattern>") -> Pattern:
    """Validate a parsed YAML document and build a :class:`Pattern`.

    Checks structure and internal consistency (declared sizes, alphabet, primitives);
    the window-distance property itself is checked by :mod:`.verify`.
    """
    if not isinstance(doc, dict):
        raise _fail(source, f"expected a YAML mapping at the top level, got {type(doc).__name__}")
    missing = [key for key in _REQUIRED if key not in doc]
    if missing:
        raise _fail(source, f"missing required key(s): {', '.join(missing)}")
    version = doc["tactile_sl_pattern"]
    if version != FORMAT_VERSION:
        raise _fail(source, f"unsupported tactile_sl_pattern version {version!r} "
                            f"(this reader knows {FORMAT_VERSION})")
    symbols = _int_field(doc, "symbols", source)
    min_hamming = _int_field(doc, "min_hamming", source)
    rows = _int_field(doc, "rows", source)
    cols = _int_field(doc, "cols", source)
    window = doc["window"]
    if (not isinstance(window, list) or len(window) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in window)):
        raise _fail(source, f"'window' must be a list of two integers [rows, cols], got {window!r}")
    try:
        constraints = Constraints(symbols, (window[0], window[1]), min_hamming)
    except ValueError as exc:
        raise _fail(source, str(exc)) from None
    pitch = doc["pitch_m"]
    if isinstance(pitch, bool) or not isinstance(pitch, (int, float)) or not pitch > 0:
        raise _fail(source, f"'pitch_m' must be a positive number of metres, got {pitch!r}")
    if pitch > 0.1:
        raise _fail(source, f"'pitch_m' is {pitch} m: pitch is in metres (0.0005 = 0.5 mm)")
    primitives = doc["primitives"]
    if not isinstance(primitives, list) or not all(isinstance(p, str) for p in primitives):
        raise _fail(source, f"'primitives' must be a list of names, got {primitives!r}")
    if len(primitives) != symbols:
        raise _fail(source, f"'primitives' lists {len(primitives)} names but symbols is {symbols}")
    if len(set(primitives)) != len(primitives):
        raise _fail(source, f"'primitives' has duplicate names: {primitives}")
    grid = _array_field(doc["array"], rows, cols, constraints, source)
    extra = {key: value for key, value in doc.items() if key not in _REQUIRED}
    return Pattern(grid, constraints, float(pitch), list(primitives), extra)


def load_pattern(path: str | Path, verify: bool = True) -> Pattern:
    """Read and validate a pattern file (see :func:`pattern_from_dict`).

    With ``verify`` (the default) the array is also checked against its own constraints
    (every two windows differ in at least ``min_hamming`` cells, so windows are unique) and
    :class:`PatternInvalidError` is raised when it breaks them: a decoder using such a file
    would assign glyphs to the wrong cells.  ``verify=False`` is for tools that inspect
    invalid files (``tactile-sl pattern verify``) and for experiments.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise PatternFormatError(f"{path}: cannot read pattern file "
                                 f"({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise PatternFormatError(f"{path}: not a text file (not UTF-8), "
                                 "so not a pattern file") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise PatternFormatError(f"{path}: not valid YAML ({exc})") from None
    pattern = pattern_from_dict(doc, str(path))
    if verify:
        cert = verify_pattern(pattern)
        if not cert.valid:
            raise PatternInvalidError(
                f"{path}: pattern breaks its own constraints ({'; '.join(cert.problems)}); "
                "refusing to use it (`tactile-sl pattern verify` shows the certificate; "
                "allow_invalid_pattern / --allow-invalid-pattern for experiments)")
    return pattern


def dump_pattern(pattern: Pattern) -> str:
    """The pattern as YAML text in the contract layout (array rows quoted, one per line)."""
    lines: list[str] = []
    for key, value in pattern.to_dict().items():
        if key == "array":
            lines.append("array:")
            lines.extend(f'  - "{row}"' for row in value)
        elif isinstance(value, list) and all(not isinstance(v, (list, dict)) for v in value):
            flow = yaml.safe_dump(value, default_flow_style=True, width=4096).strip()
            lines.append(f"{key}: {flow}")
        else:
            flow_style = None if isinstance(value, (dict, list)) else False
            lines.append(yaml.safe_dump({key: value}, sort_keys=False,
                                        default_flow_style=flow_style, width=4096).rstrip("\n"))
    return "\n".join(lines) + "\n"


def save_pattern(pattern: Pattern, path: str | Path) -> None:
    """Write the pattern file (the array rows as quoted strings, one per line), atomically."""
    write_text(path, dump_pattern(pattern))
