"""Artwork: glyph geometry, ink centroids on cell centres, sidecar, SVG, shipped artwork."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tactile_sl_decoder.pattern import Constraints, Pattern, load_default_pattern
from tactile_sl_decoder.pattern.artwork import render_png, render_svg
from tactile_sl_decoder.pattern.shapes import GLYPHS, INK_AREA, default_primitives

from ros_harness import REPO

CAMERA_ARTWORK = REPO / "src" / "tactile_sl_sim" / "artwork" / "pattern.png"


@pytest.mark.parametrize("name", list(GLYPHS))
def test_glyph_centroid_area_extent(name):
    g = GLYPHS[name]
    xs = (np.arange(2000) + 0.5) / 2000 - 0.5
    x, y = np.meshgrid(xs, xs)
    ink = g.inside(x, y)
    area = ink.mean()
    assert area == pytest.approx(INK_AREA, rel=0.02)
    assert abs(x[ink].mean()) < 1e-3 and abs(y[ink].mean()) < 1e-3
    w, h = g.extent()
    assert 0.3 <= min(w, h) and max(w, h) <= 0.75


def test_k3_uses_line_circle_triangle():
    assert default_primitives(3) == ["line", "circle", "triangle"]
    assert len(set(default_primitives(8))) == 8


def cell_measurements(image: np.ndarray, side: dict) -> np.ndarray:
    ink = (255.0 - image.astype(np.float64)) / 255.0
    pitch = side["pitch_px"]
    x0, y0 = side["cell00_px"]
    out = []
    for r in range(side["rows"]):
        for c in range(side["cols"]):
            cx, cy = x0 + c * pitch, y0 + r * pitch
            ys = slice(int(np.ceil(cy - pitch / 2)), int(np.floor(cy + pitch / 2)) + 1)
            xs = slice(int(np.ceil(cx - pitch / 2)), int(np.floor(cx + pitch / 2)) + 1)
            tile = ink[ys, xs]
            yy, xx = np.mgrid[ys, xs]
            total = tile.sum()
            out.append(((tile * xx).sum() / total - cx, (tile * yy).sum() / total - cy,
                        total / pitch ** 2))
    return np.array(out)


@pytest.mark.parametrize("kwargs", [{"pitch_px": 24}, {"dpi": 1000.0}])
def test_png_ink_centroids_on_cell_centres(tmp_path, kwargs):
    pattern = load_default_pattern()
    small = Pattern(pattern.array[:8, :9], pattern.constraints, pattern.pitch_m)
    out = tmp_path / "a.png"
    side = render_png(small, out, **kwargs)
    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint8 and image.ndim == 2
    assert image.shape == (side["height_px"], side["width_px"])
    meas = cell_measurements(image, side)
    assert np.abs(meas[:, :2]).max() < 0.05  # pixels
    assert meas[:, 2] == pytest.approx(INK_AREA, rel=0.03)
    on_disk = yaml.safe_load(Path(str(out) + ".yaml").read_text())
    assert on_disk["cell00_px"] == side["cell00_px"]
    for key in ("pitch_px", "pitch_m", "rows", "cols", "symbols", "primitives",
                "values_meaning", "mirrored"):
        assert key in on_disk
    assert on_disk["mirrored"] is False
    assert on_disk["values_meaning"] == {0: "line", 1: "circle", 2: "triangle"}
    assert on_disk["rows"] == 8 and on_disk["cols"] == 9
    # orientation mark stays in the top-left margin, clear of glyph (0, 0)
    mx0, my0, mx1, my1 = on_disk["orientation_mark_px"]
    x0, y0 = side["cell00_px"]
    assert mx1 < x0 - 0.15 * side["pitch_px"] and my1 < y0 - 0.15 * side["pitch_px"]
    assert mx0 > 0 and my0 > 0
    # the PNG carries its DPI
    raw = out.read_bytes()
    assert b"pHYs" in raw


def test_each_value_draws_its_own_glyph(tmp_path):
    c = Constraints(8, (3, 3), 1)
    arr = np.arange(24).reshape(3, 8) % 8
    side = render_png(Pattern(arr, c), tmp_path / "k8.png", pitch_px=40)
    image = cv2.imread(str(tmp_path / "k8.png"), cv2.IMREAD_GRAYSCALE)
    tiles = []
    x0, y0 = side["cell00_px"]
    for v in range(8):
        cx, cy = int(x0 + v * 40 + 0.5), int(y0 + 0.5)
        tiles.append(image[cy - 18:cy + 18, cx - 18:cx + 18].astype(float))
    for a in range(8):
        for b in range(a + 1, 8):
            assert np.abs(tiles[a] - tiles[b]).mean() > 5, (a, b)


def test_svg_in_millimetres(tmp_path):
    pattern = load_default_pattern()
    out = tmp_path / "a.svg"
    render_svg(pattern, out)
    root = ET.parse(out).getroot()
    width_mm = (pattern.cols - 1 + 3.0) * pattern.pitch_m * 1000
    assert root.get("width") == f"{width_mm:.4f}mm"
    ns = "{http://www.w3.org/2000/svg}"
    group = root.find(f"{ns}g")
    shapes = [e for e in group if e.tag != f"{ns}rect"]
    assert len(shapes) == pattern.rows * pattern.cols
    assert len(group.findall(f"{ns}rect")) == 2  # the orientation mark


@pytest.mark.skipif(not CAMERA_ARTWORK.exists(), reason="camera package artwork not present")
def test_shipped_camera_artwork_matches_shipped_pattern():
    pattern = load_default_pattern()
    side = yaml.safe_load(Path(str(CAMERA_ARTWORK) + ".yaml").read_text())
    assert side["array"] == ["".join(map(str, row)) for row in pattern.array]
    assert side["pitch_m"] == pattern.pitch_m
    assert side["rows"] == pattern.rows and side["cols"] == pattern.cols
    assert 40 <= side["pitch_px"] <= 56
    assert side["mirrored"] is False
    image = cv2.imread(str(CAMERA_ARTWORK), cv2.IMREAD_GRAYSCALE)
    assert image.shape == (side["height_px"], side["width_px"])
    meas = cell_measurements(image, side)
    assert np.abs(meas[:, :2]).max() < 0.05
