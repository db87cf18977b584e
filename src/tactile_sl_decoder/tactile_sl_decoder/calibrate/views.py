"""Decoded views of the printed pattern as calibration correspondences (no rclpy).

Each glyph the decoder identifies gives one planar correspondence: its cell (r, c) is the
object point (c * pitch, r * pitch, 0) in the **artwork frame** (origin at the centre of cell
(0, 0), x along increasing column, y along increasing row, metres; the contract's cell
convention) and its ink centroid (u, v) is the image point (raw, distorted pixels, OpenCV
convention).  Extraction, classification and codeword decoding are the decoder's own
(:class:`~tactile_sl_decoder.pipeline.StereoPipeline`), nothing is reimplemented here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.extract.extraction import ExtractionParams
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline


@dataclass
class PatternTarget:
    """The printed pattern used as a planar calibration target."""

    pattern: PatternSpec
    mirrored: bool = False          # the cameras see the artwork mirrored (sensor setting)

    @classmethod
    def load(cls, path: str | None = None, mirrored: bool = False) -> "PatternTarget":
        """Target from a contract pattern YAML (default: the shipped pattern)."""
        spec = PatternSpec.load(path)
        if spec.pitch_m <= 0:
            raise ValueError(f"{path or 'pattern'}: pitch_m must be positive (metres)")
        return cls(spec, mirrored)

    @property
    def pitch_m(self) -> float:
        return float(self.pattern.pitch_m)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the pattern array."""
        r, c = self.pattern.array.shape
        return int(r), int(c)

    def object_points(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """(N, 3) float64 cell centres (c * pitch, r * pitch, 0) in the artwork frame, m."""
        row = np.asarray(row, np.float64)
        col = np.asarray(col, np.float64)
        return np.column_stack([col * self.pitch_m, row * self.pitch_m, np.zeros(len(row))])

    def cell_index(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Row-major cell number r * cols + c (int64)."""
        return np.asarray(row, np.int64) * self.shape[1] + np.asarray(col, np.int64)


MIN_GLYPHS_FOR_A_VIEW = 30
"""Fewer glyph candidates than this: the pattern is mostly not in the image."""
MIN_DECODABLE_SPACING_PX = 6.0
"""Median glyph spacing below which glyphs are too small to decode (simulated flat views:
every cell decodes at 6.5 px, none at 5 px)."""


@dataclass
class CameraView:
    """Cells decoded in one image: cell (row, col) and its image point (u, v) in pixels."""

    row: np.ndarray                 # (N,) int32
    col: np.ndarray                 # (N,) int32
    uv: np.ndarray                  # (N, 2) float64, raw pixels
    glyphs: int = 0                 # glyph candidates the extractor found
    spacing_px: float = 0.0         # median glyph spacing in the image
    labelled: int = 0               # glyphs the classifier gave a confident label

    @classmethod
    def from_glyphs(cls, g: Glyphs) -> "CameraView":
        """The decoded glyphs of one image (undecoded ones are left out)."""
        m = g.row >= 0
        uv = np.column_stack([g.u[m], g.v[m]]).astype(np.float64)
        labelled = int(np.count_nonzero(np.asarray(g.label) != LABEL_UNKNOWN))
        return cls(g.row[m].astype(np.int32), g.col[m].astype(np.int32), uv, len(g),
                   float(g.spacing_px), labelled)

    def why_few_cells(self) -> str:
        """Why this image decoded few cells, from what each stage found (report text)."""
        if self.glyphs == 0:
            return "no glyph found (pattern out of view, blank, dark or saturated image?)"
        if self.glyphs < MIN_GLYPHS_FOR_A_VIEW:
            return (f"only {self.glyphs} glyph candidates (pattern mostly out of view or "
                    "hidden?)")
        if self.spacing_px < MIN_DECODABLE_SPACING_PX:
            return (f"{self.glyphs} glyphs at a median spacing of {self.spacing_px:.1f} px: "
                    f"too far or too oblique (glyphs decode from about "
                    f"{MIN_DECODABLE_SPACING_PX:.0f} px)")
        if self.labelled < 0.5 * self.glyphs:
            return (f"{self.labelled} of {self.glyphs} glyphs classified (out of focus, "
                    "blurred, too oblique, or not this pattern's glyphs?)")
        return (f"{self.glyphs} glyphs, {self.labelled} classified, but no codeword window "
                "decoded (another pattern, a wrong mirrored setting, or tilted beyond about "
                "45 deg?)")

    def __len__(self) -> int:
        return int(len(self.row))


@dataclass
class StereoView:
    """One stereo view of the target: the decoded cells of both images."""

    name: str
    left: CameraView
    right: CameraView
    image_size: tuple[int, int]     # (width, height), px


class ViewDecoder:
    """Decodes stereo views of the pattern with the decoder's pipeline (one image at a time)."""

    def __init__(self, target: PatternTarget, classifier: Any = None,
                 params: PipelineParams | None = None, tilted: bool = True) -> None:
        """A decoder for calibration views of ``target``.

        ``tilted``: decode strongly tilted views too (perspective extraction and local
        lattice gates, docs/calibration.md); False decodes as the sensor's pipeline does.
        """
        params = params or PipelineParams(threads=1)
        params.decode.mirrored = bool(target.mirrored)
        if tilted:
            params.extraction = params.extraction or ExtractionParams()
            params.extraction.perspective = True
            params.grid.local_gates = True
        self.target = target
        self.pipeline = StereoPipeline(target.pattern, classifier, params)

    def decode(self, left: np.ndarray, right: np.ndarray, name: str = "") -> StereoView:
        """Decode one stereo pair of grey images (H, W) uint8."""
        if left.ndim != 2 or right.ndim != 2:
            raise ValueError(f"view {name}: expected grey images, got {left.shape} and "
                             f"{right.shape}")
        if left.shape != right.shape:
            raise ValueError(f"view {name}: left and right images differ in size "
                             f"({left.shape[1]}x{left.shape[0]} vs "
                             f"{right.shape[1]}x{right.shape[0]})")
        gl, gr = self.decode_glyphs(left, right)
        return StereoView(name, CameraView.from_glyphs(gl), CameraView.from_glyphs(gr),
                          (int(left.shape[1]), int(left.shape[0])))

    def decode_glyphs(self, left: np.ndarray, right: np.ndarray) -> tuple[Glyphs, Glyphs]:
        """Decoded glyphs (all candidates, row/col -1 where undecided) of one pair."""
        gl, gr = self.pipeline.extract_pair(left, right)
        self.pipeline.classify_pair(gl, gr)
        self.pipeline.decode_pair(gl, gr)
        return gl, gr

    def close(self) -> None:
        self.pipeline.close()


def _gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image
