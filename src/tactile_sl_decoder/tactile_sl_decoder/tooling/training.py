"""Training data from the simulator and training of the glyph classifier (torch, CPU).

Data: stereo frames rendered by :mod:`tactile_sl_sim` under random indenters, depths,
positions, shear and nuisances (blur, noise, vignetting, uneven light, gamma, exposure,
shadows), most of them also with the nuisances of real sensors (:func:`sensor_nuisances`:
an object seen through the pad, MJPEG, defocus, motion blur, unequal exposure, a damaged
print, dust) at a glyph spacing of 12-24 px. Each image goes through the same
:func:`extract_symbols` as at run time; a detection within a quarter spacing of an
undamaged glyph's projection is labelled with the pattern's value at that cell. Other
detections are not used. Training then adds patch-level
augmentation (small rotation, scale, shift, contrast, gamma, blur, noise).

Held-out data uses other seeds *and* other indenter kinds than training (training sees
spheres and cylinders; validation sees flat punches and edges), so the reported accuracy
measures generalisation, not memory. Everything is seeded: the same command writes the same
weights.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TextIO

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_decoder.classify.classifier import (
    ARCH,
    ARCH_DESCRIPTIONS,
    FORMAT,
    FORMAT_VERSION,
    Classifier,
)
from tactile_sl_decoder.contract import PATCH_SIZE
from tactile_sl_decoder.extract.extraction import ExtractionParams, extract_symbols
from tactile_sl_decoder.pattern.shapes import glyph
from tactile_sl_sim.artwork import load_artwork
from tactile_sl_sim.contact import Contact
from tactile_sl_sim.optics import RigParams, SimulatedCameraPair
from tactile_sl_sim.render import Nuisances, Renderer

DEFAULT_PRIMITIVES = ("line", "circle", "triangle")
TRAIN_KINDS = ("sphere", "cylinder")
HELDOUT_KINDS = ("flat", "edge")


class Progress:
    """A one-line text progress bar on stderr (no dependency)."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None) -> None:
        self.total, self.label, self.done = max(1, total), label, 0
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.monotonic()

    def update(self, n: int = 1, note: str = "") -> None:
        """Advance and redraw."""
        self.done += n
        frac = min(1.0, self.done / self.total)
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        elapsed = time.monotonic() - self.start
        self.stream.write(f"\r{self.label:>10s} [{bar}] {self.done}/{self.total} "
                          f"{elapsed:5.0f}s {note}   ")
        if self.done >= self.total:
            self.stream.write("\n")
        self.stream.flush()


@dataclass
class PatchSet:
    """Labelled patches (N, 18, 18) uint8 with labels (N,) and a source tag per patch."""

    patches: np.ndarray
    labels: np.ndarray
    frame: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    def __len__(self) -> int:
        return int(len(self.labels))

    @staticmethod
    def concat(sets: list[PatchSet]) -> PatchSet:
        """One set from many (empty list -> empty set)."""
        if not sets:
            return PatchSet(np.zeros((0, PATCH_SIZE, PATCH_SIZE), np.uint8), np.zeros(0, np.uint8))
        return PatchSet(np.concatenate([s.patches for s in sets]),
                        np.concatenate([s.labels for s in sets]),
                        np.concatenate([s.frame for s in sets]))


def label_detections(det: Any, truth_px: np.ndarray, truth_values: np.ndarray,
                     tolerance: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Indices of detections matched to a true glyph, and that glyph's value.

    A detection matches the nearest true centre within ``tolerance`` spacings; when two
    detections claim one glyph only the nearer keeps it (one label per glyph).
    """
    if len(det) == 0 or len(truth_px) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.uint8)
    spacing = det.spacing_px if det.spacing_px > 0 else 18.0
    dist, idx = cKDTree(truth_px).query(np.column_stack((det.u, det.v)))
    ok = np.flatnonzero(dist < tolerance * spacing)
    order = ok[np.argsort(dist[ok])]
    _, first = np.unique(idx[order], return_index=True)
    chosen = np.sort(order[first])
    return chosen, truth_values[idx[chosen]].astype(np.uint8)


def artwork_values(art: Any, primitives: tuple[str, ...] | list[str]) -> np.ndarray:
    """The symbol value of every cell, read from the artwork itself by template matching.

    The simulator draws the artwork, so labels taken from it are right by construction,
    whatever the state of the pattern file; each cell's ink is compared with every
    primitive's shape (pad-plane pitch units) and the best normalised match wins.
    """
    size = int(round(art.pitch_px))
    g = (np.arange(size) - (size - 1) / 2.0) / art.pitch_px
    gx, gy = np.meshgrid(g, g)
    sx = -1.0 if getattr(art, "mirrored", False) else 1.0
    templates = np.stack([glyph(p).inside(sx * gx, gy).astype(np.float32).reshape(-1)
                          for p in primitives])
    templates -= templates.mean(axis=1, keepdims=True)
    templates /= np.linalg.norm(templates, axis=1, keepdims=True)
    rows, cols = np.meshgrid(np.arange(art.rows), np.arange(art.cols), indexing="ij")
    centre = art.cell_to_pixel(rows.reshape(-1), cols.reshape(-1))
    ix = np.rint(centre[:, 0:1] + (np.arange(size) - (size - 1) / 2.0)).astype(np.int64)
    iy = np.rint(centre[:, 1:2] + (np.arange(size) - (size - 1) / 2.0)).astype(np.int64)
    h, w = art.albedo.shape
    ink = 1.0 - art.albedo[np.clip(iy, 0, h - 1)[:, :, None], np.clip(ix, 0, w - 1)[:, None, :]]
    ink = ink.reshape(len(centre), -1)
    ink -= ink.mean(axis=1, keepdims=True)
    score = ink @ templates.T
    return score.argmax(axis=1).astype(np.uint8).reshape(art.rows, art.cols)


# Glyph spacings in the image (px) the training frames are rendered at: the sensor's 18 px
# most often, and the 12-24 px of other lenses and distances (docs/robustness.md).
TRAIN_SPACINGS_PX = (12.0, 14.0, 16.0, 18.0, 18.0, 18.0, 20.0, 24.0)
SENSOR_NUISANCE_SHARE = 0.6    # frames that also get the nuisances of real sensors


def random_scene(rng: np.random.Generator, kinds: tuple[str, ...]
                 ) -> tuple[list[Any], Any, float]:
    """Random contacts (0-2 indenters of the given kinds), nuisances and glyph spacing (px).

    Lighting nuisances on every frame (30 % harsh); on ``SENSOR_NUISANCE_SHARE`` of the
    frames also those of real sensors (:func:`sensor_nuisances`) and a spacing drawn from
    ``TRAIN_SPACINGS_PX`` (else the sensor's 18 px).
    """
    contacts = []
    for _ in range(int(rng.choice([0, 1, 1, 1, 2]))):
        kind = str(rng.choice(kinds))
        radius = {"sphere": rng.uniform(0.0015, 0.02), "cylinder": rng.uniform(0.001, 0.004),
                  "flat": rng.uniform(0.0008, 0.002), "edge": rng.uniform(0.0004, 0.0015)}[kind]
        contacts.append(Contact(
            kind=kind, radius=float(radius),
            length=float(rng.uniform(0.0, 0.004)) if kind == "cylinder" else 0.0,
            angle=float(rng.uniform(0, math.pi)),
            fillet=float(rng.uniform(0.0001, 0.0003)),
            x=float(rng.uniform(-0.003, 0.003)), y=float(rng.uniform(-0.003, 0.003)),
            depth=float(rng.uniform(0.0, 0.001)),
            shear=(float(rng.normal(0, 0.00008)), float(rng.normal(0, 0.00008)))))
    harsh = rng.random() < 0.3
    lighting = dict(
        blur_sigma=float(rng.uniform(0.3, 1.5 if harsh else 1.0)),
        noise_sigma=float(rng.uniform(0.3, 5.0 if harsh else 2.0)),
        shot_noise=float(rng.uniform(0.0, 0.2 if harsh else 0.05)),
        vignetting=float(rng.uniform(0.0, 0.5)),
        light=(float(rng.uniform(-0.008, 0.008)), float(rng.uniform(-0.01, 0.004)),
               float(rng.uniform(-0.016, -0.008))),
        ambient=float(rng.uniform(0.2, 0.6)),
        illumination_gradient=(float(rng.uniform(-0.08, 0.08)),
                               float(rng.uniform(-0.08, 0.08))),
        gamma=float(rng.uniform(0.8, 2.0 if harsh else 1.3)),
        exposure=float(rng.uniform(0.6, 1.3)),
        shadows=[{"x": float(rng.uniform(-0.005, 0.005)), "y": float(rng.uniform(-0.005, 0.005)),
                  "radius": float(rng.uniform(0.001, 0.003)),
                  "strength": float(rng.uniform(0.2, 0.5)), "softness": 0.0015}]
        if harsh and rng.random() < 0.5 else [])
    spacing = 18.0
    if rng.random() < SENSOR_NUISANCE_SHARE:
        lighting.update(sensor_nuisances(rng, touching=bool(contacts)))
        spacing = float(rng.choice(TRAIN_SPACINGS_PX))
    return contacts, Nuisances.from_dict(lighting), spacing


def sensor_nuisances(rng: np.random.Generator, touching: bool) -> dict[str, Any]:
    """Random nuisances of real sensors (docs/camera.md), each present on some frames.

    Ranges span the robustness sweep's mild to severe levels: an object seen through the
    pad (dark, striped, noisy, printed), MJPEG, defocus, motion blur, exposure differing
    between the cameras and from frame to frame, a damaged print (dropout, wear, scratches,
    bubbles) and dust on the optics.
    """
    u = rng.uniform
    doc: dict[str, Any] = {}
    if touching and rng.random() < 0.6:
        kind = str(rng.choice(["dark", "stripes", "noise", "text"]))
        if kind == "dark":
            doc.update(see_through=kind, object_albedo=float(u(0.08, 0.4)))
        else:
            albedo = float(u(0.5, 0.8))
            doc.update(see_through=kind, object_albedo=albedo,
                       object_contrast=float(min(albedo, u(0.15, 0.65))),
                       object_scale=float(u(2.5e-4, 5e-4)))
    if rng.random() < 0.5:
        doc["jpeg_quality"] = int(rng.integers(45, 96))
    if rng.random() < 0.4:
        doc["defocus_px"] = float(u(0.5, 2.5))
    if rng.random() < 0.4:
        doc.update(motion_blur_px=float(u(1.0, 8.0)), motion_blur_angle_deg=float(u(0.0, 180.0)))
    if rng.random() < 0.5:
        doc.update(exposure_right=float(u(0.55, 1.1)), exposure_jitter_camera=float(u(0.0, 0.2)))
    if rng.random() < 0.3:
        doc["dropout"] = float(u(0.0, 0.08))
    if rng.random() < 0.3:
        doc["wear"] = float(u(0.0, 0.15))
    if rng.random() < 0.3:
        doc["scratches"] = int(rng.integers(1, 13))
    if rng.random() < 0.3:
        doc["bubbles"] = int(rng.integers(1, 9))
    if rng.random() < 0.3:
        doc.update(dust=int(rng.integers(5, 61)), dust_radius_px=float(u(1.5, 3.5)),
                   dust_strength=float(u(0.4, 0.8)))
    return doc


def render_dataset(frames: int, seed: int, kinds: tuple[str, ...], values: np.ndarray | None,
                   artwork: str | None = None, params: ExtractionParams | None = None,
                   progress: Callable[[int, str], None] | None = None) -> PatchSet:
    """Patches labelled from ``frames`` simulated stereo frames (both cameras)."""
    art = load_artwork(artwork)
    if values is None:
        values = artwork_values(art, DEFAULT_PRIMITIVES)
    if (art.rows, art.cols) != tuple(values.shape):
        raise ValueError(f"artwork has {art.rows}x{art.cols} cells but the pattern "
                         f"{values.shape[0]}x{values.shape[1]}: labels would be wrong")
    renderers: dict[float, Any] = {}
    rng = np.random.default_rng(seed)
    sets = []
    for i in range(frames):
        contacts, nz, spacing = random_scene(rng, kinds)
        if spacing not in renderers:
            renderers[spacing] = Renderer(
                art, SimulatedCameraPair(RigParams.for_glyph_spacing(spacing)))
        frame = renderers[spacing].render(contacts, nz, seed=seed * 1000 + i, frame_index=i)
        truth = frame.truth
        # damaged glyphs (worn, scratched, under a bubble or dust) carry no reliable class
        vis = truth.visible if truth.damaged is None else truth.visible & ~truth.damaged
        true_values = values[truth.rows[vis], truth.cols[vis]]
        for image, px in ((frame.left, truth.px_left), (frame.right, truth.px_right)):
            det = extract_symbols(image, params)
            chosen, labels = label_detections(det, px[vis], true_values)
            sets.append(PatchSet(det.patches[chosen], labels,
                                 np.full(len(chosen), i, np.int32)))
        if progress:
            progress(1, f"{sum(len(s) for s in sets)} patches")
    return PatchSet.concat(sets)


def augment(x: Any, gen: Any) -> Any:
    """Random geometric and photometric jitter of standardised-to-be patches (N,1,18,18)."""
    # torch (1-2 s to import) here and below: only training needs it, the datasets do not
    import torch
    import torch.nn.functional as F

    n = x.shape[0]
    angle = (torch.rand(n, generator=gen) - 0.5) * (2 * math.radians(15))
    scale = 1.0 + (torch.rand(n, generator=gen) - 0.5) * 0.3
    aniso = 1.0 + (torch.rand(n, generator=gen) - 0.5) * 0.3
    shear = (torch.rand(n, generator=gen) - 0.5) * 0.3
    shift = (torch.rand(n, 2, generator=gen) - 0.5) * (2 * 1.2 / 9.0)  # +-1.2 px
    cos, sin = torch.cos(angle) / scale, torch.sin(angle) / scale
    # rotation @ (anisotropic scale + shear): the local stretch of a deformed pad
    a11, a12, a21, a22 = aniso, shear, torch.zeros(n), 1.0 / aniso
    theta = torch.stack([torch.stack([cos * a11 - sin * a21, cos * a12 - sin * a22,
                                      shift[:, 0]], 1),
                         torch.stack([sin * a11 + cos * a21, sin * a12 + cos * a22,
                                      shift[:, 1]], 1)], 1)
    grid = F.affine_grid(theta, list(x.shape), align_corners=False)
    x = F.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=False)
    # photometric: gamma, contrast, offset, blur, noise (patches are 0..255 here)
    gamma = torch.exp((torch.rand(n, 1, 1, 1, generator=gen) - 0.5) * 0.8)
    x = 255.0 * (x.clamp(0, 255) / 255.0) ** gamma
    x = x * (0.5 + torch.rand(n, 1, 1, 1, generator=gen)) + \
        (torch.rand(n, 1, 1, 1, generator=gen) - 0.5) * 60
    blur = torch.rand(n, generator=gen) < 0.3
    if blur.any():
        k = torch.tensor([0.25, 0.5, 0.25])
        kernel = (k[:, None] * k[None, :]).reshape(1, 1, 3, 3)
        x[blur] = F.conv2d(F.pad(x[blur], (1, 1, 1, 1), mode="replicate"), kernel)
    x = x + torch.randn(x.shape, generator=gen) * (torch.rand(n, 1, 1, 1, generator=gen) * 8)
    return x


@dataclass
class TrainResult:
    """What the model card reports."""

    blob: dict[str, Any]
    train_patches: int
    val_patches: int
    val_accuracy: float
    val_confident_accuracy: float
    val_unknown_rate: float
    confusion: np.ndarray
    seconds: float
    epochs: int


def train(train_set: PatchSet, val_set: PatchSet, classes: int, primitives: list[str],
          epochs: int = 12, seed: int = 0, threshold: float = 0.9, batch: int = 256,
          lr: float = 3e-3, progress_stream: TextIO | None = None,
          meta: dict[str, Any] | None = None, arch: str = ARCH) -> TrainResult:
    """Train the net ``arch`` with Adam and a one-cycle schedule; weights and held-out figures."""
    import torch  # only training needs torch (see augment)

    from tactile_sl_decoder.classify.model import make_model, standardise  # torch's nets

    start = time.monotonic()
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    model = make_model(arch, classes)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    steps = epochs * max(1, math.ceil(len(train_set) / batch))
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps)
    xs = torch.from_numpy(train_set.patches).float().unsqueeze(1)
    ys = torch.from_numpy(train_set.labels.astype(np.int64))
    bar = Progress(steps, "train", progress_stream)
    loss_fn = torch.nn.CrossEntropyLoss(label_smoothing=0.02)
    for _ in range(epochs):
        perm = torch.randperm(len(ys), generator=gen)
        model.train()
        for i in range(0, len(ys), batch):
            idx = perm[i:i + batch]
            x = augment(xs[idx], gen)
            loss = loss_fn(model(standardise(x.squeeze(1))), ys[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            bar.update(1, f"loss {loss.item():.4f}")
    model.eval()
    state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    blob = {"format": FORMAT, "version": FORMAT_VERSION, "arch": arch, "classes": classes,
            "primitives": list(primitives), "threshold": float(threshold),
            "state_dict": state, "meta": dict(meta or {})}
    clf = Classifier.from_blob(blob)
    prob = clf.probabilities(val_set.patches)
    pred = prob.argmax(axis=1)
    conf = prob.max(axis=1)
    truth = val_set.labels.astype(np.int64)
    confusion = np.zeros((classes, classes), np.int64)
    np.add.at(confusion, (truth, pred), 1)
    sure = conf >= threshold
    return TrainResult(
        blob, len(train_set), len(val_set),
        float((pred == truth).mean()) if len(truth) else float("nan"),
        float((pred[sure] == truth[sure]).mean()) if sure.any() else float("nan"),
        float(1.0 - sure.mean()) if len(truth) else float("nan"),
        confusion, time.monotonic() - start, epochs)


def model_card(result: TrainResult, data_note: str, data_seconds: float,
               weights_name: str = "classifier.pt") -> str:
    """Markdown model card: data, training time, held-out accuracy, confusion matrix."""
    prims = result.blob["primitives"]
    arch = result.blob["arch"]
    lines = [
        f"# Glyph classifier (`{weights_name}`)", "",
        f"Architecture `{arch}`: {ARCH_DESCRIPTIONS[arch]} -> {result.blob['classes']} outputs "
        f"({', '.join(prims)}). "
        f"Confidence threshold {result.blob['threshold']:.2f}: below it the label is 255.", "",
        "## Data", "", data_note, "",
        f"- training patches: {result.train_patches}",
        f"- held-out patches: {result.val_patches}", "",
        "## Training", "",
        f"- {result.epochs} epochs, Adam with one-cycle schedule, batch 256, fixed seed "
        f"{result.blob['meta'].get('seed', 0)}, CPU, torch "
        f"{result.blob['meta'].get('torch', '?')}",
        f"- data generation {data_seconds:.0f} s, training {result.seconds:.0f} s", "",
        "## Held-out accuracy (other seeds and other indenter kinds)", "",
        f"- accuracy (argmax): {100 * result.val_accuracy:.3f} %",
        f"- accuracy of confident labels: {100 * result.val_confident_accuracy:.3f} %",
        f"- labelled unknown (below threshold): {100 * result.val_unknown_rate:.3f} %", "",
        "Confusion matrix (rows: true, columns: predicted):", "",
        "| true \\ predicted | " + " | ".join(prims) + " |",
        "|---" * (len(prims) + 1) + "|",
    ]
    for i, name in enumerate(prims):
        lines.append(f"| {name} | " + " | ".join(str(int(v)) for v in result.confusion[i])
                     + " |")
    lines += ["", "Regenerate with `tactile-sl train` (see docs/extraction.md).", ""]
    return "\n".join(lines)


def save_blob(blob: dict[str, Any], path: str | Path) -> None:
    """Write weights with torch.save (read back with ``weights_only=True``)."""
    import torch  # only training needs torch (see augment)

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    torch.save(blob, path)
