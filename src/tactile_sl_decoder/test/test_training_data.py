"""Training data of the glyph classifier: scenes with real-sensor nuisances, damaged glyphs."""
from __future__ import annotations

import numpy as np

from tactile_sl_decoder.tooling import training


def test_sensor_nuisances_are_valid_and_cover_every_kind():
    from tactile_sl_sim.render import Nuisances

    rng = np.random.default_rng(3)
    seen: set[str] = set()
    for _ in range(300):
        doc = training.sensor_nuisances(rng, touching=True)
        Nuisances.from_dict(doc)                  # in range (ValueError otherwise)
        seen |= set(doc)
        if "jpeg_quality" in doc:
            assert 45 <= doc["jpeg_quality"] <= 95
        if "see_through" in doc and doc["see_through"] != "dark":
            assert doc["object_contrast"] <= doc["object_albedo"]
    assert {"see_through", "jpeg_quality", "defocus_px", "motion_blur_px", "exposure_right",
            "dropout", "wear", "scratches", "bubbles", "dust"} <= seen
    # no object is seen through the pad where nothing touches it
    assert not any("see_through" in training.sensor_nuisances(rng, touching=False)
                   for _ in range(100))


def test_random_scenes_vary_the_glyph_spacing():
    rng = np.random.default_rng(4)
    spacings = [training.random_scene(rng, training.TRAIN_KINDS)[2] for _ in range(200)]
    assert set(spacings) <= set(training.TRAIN_SPACINGS_PX)
    assert min(spacings) == 12.0 and max(spacings) == 24.0
    assert 0.4 < np.mean(np.asarray(spacings) == 18.0) < 0.8    # the sensor's own most often


def test_frames_render_at_the_drawn_spacing_without_damaged_glyphs(monkeypatch):
    """A 12 px frame with 40 % of the glyphs partly worn: the glyphs are extracted at that
    spacing, and only the undamaged ones give patches (with their pattern symbols)."""
    from tactile_sl_sim.artwork import load_artwork
    from tactile_sl_sim.render import Nuisances, Renderer

    nz = Nuisances.from_dict({"wear": 0.4})
    monkeypatch.setattr(training, "random_scene", lambda rng, kinds: ([], nz, 12.0))
    rendered, spacings = [], []
    real_render, real_extract = Renderer.render, training.extract_symbols

    def render_spy(self, *args, **kwargs):
        rendered.append(real_render(self, *args, **kwargs))
        return rendered[-1]

    def extract_spy(image, params=None):
        det = real_extract(image, params)
        spacings.append(det.spacing_px)
        return det

    monkeypatch.setattr(Renderer, "render", render_spy)
    monkeypatch.setattr(training, "extract_symbols", extract_spy)
    data = training.render_dataset(1, 11, training.TRAIN_KINDS, None)
    assert len(spacings) == 2 and all(abs(s - 12.0) < 1.5 for s in spacings)
    truth = rendered[0].truth
    undamaged = int((truth.visible & ~truth.damaged).sum())
    assert truth.damaged[truth.visible].mean() > 0.2
    # both images; a few undamaged glyphs may be missed, no damaged one may come in
    assert 2 * undamaged * 0.95 <= len(data) <= 2 * undamaged
    values = training.artwork_values(load_artwork(), training.DEFAULT_PRIMITIVES)
    assert set(np.unique(data.labels)) <= set(np.unique(values))
