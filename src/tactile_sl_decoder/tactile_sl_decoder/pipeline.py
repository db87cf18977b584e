"""The stereo pipeline, one place for the ROS node and offline replay (no rclpy).

images -> glyph extraction -> classification -> lattice + codeword decoding (per image) ->
stereo pairing by cell -> triangulation -> contract PointCloud2 points.

:class:`StereoPipeline` is used by the ``decoder`` node (both from images and from the stage
nodes' SymbolArrays) and by ``tactile-sl replay``, so the ROS graph and the offline replay
produce identical points for the same input.  Inputs are checked here (sizes against
CameraInfo, degenerate calibration) and problems raise :class:`PipelineInputError` with a
message meant for the user; callers skip the frame and carry on.

The stages it composes live in :mod:`.extract`, :mod:`.classify`, :mod:`.decode` and
:mod:`.stereo`; glyph arrays in :mod:`.glyphs`, bag frames and stereo pairing in
:mod:`.frames`, library thread settings in :mod:`.cpu_threads` (import them from there).
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactile_sl_common.camera_info import CameraInfoError
from tactile_sl_common.clouds import POINT_DTYPE, pack_points
from tactile_sl_decoder.classify.carry import CarryParams, LabelCarry
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.cpu_threads import set_cpu_threads, shorten_switch_interval
from tactile_sl_decoder.decode.codewords import Codebook, CodewordDecoder, DecodeParams
from tactile_sl_decoder.decode.grid import GridParams, build_grid, nearest_neighbours
from tactile_sl_decoder.decode.track import carried_cells
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.stereo.outliers import OutlierParams, surface_outliers
from tactile_sl_decoder.stereo.rescue import Rescued, RescueParams, rescue_pair
from tactile_sl_decoder.stereo.stereo import StereoParams, StereoRig, match_and_triangulate
from tactile_sl_decoder.stereo.transfer import TransferParams, needs_transfer, transfer_cells


@dataclass
class PipelineParams:
    """Everything tunable in the pipeline (the node exposes these as ROS parameters)."""

    grid: GridParams = field(default_factory=GridParams)
    decode: DecodeParams = field(default_factory=DecodeParams)
    stereo: StereoParams = field(default_factory=StereoParams)
    outliers: OutlierParams = field(default_factory=OutlierParams)
    carry: CarryParams = field(default_factory=CarryParams)   # labels from the last frame
    transfer: TransferParams = field(default_factory=TransferParams)  # cells across the pair
    rescue: RescueParams = field(default_factory=RescueParams)  # undetected glyphs, images path
    extraction: Any = None          # tactile_sl_decoder.extract.extraction.ExtractionParams
    threads: int = 2                # >1: extract + classify left and right concurrently
    cpu_threads: int = 1            # OpenCV/torch intra-op threads (process-wide; 0 = leave)
    switch_interval_ms: float = 1.0  # with threads > 1: Python's GIL switch interval at most
                                     # this (process-wide; 0 = leave), see shorten_switch_interval
    classifier_weights: str | None = None      # loaded when needed; None = shipped weights
    classifier_threshold: float | None = None  # None = the threshold stored with the weights


@dataclass
class StereoResult:
    """What one stereo frame produced."""

    points: np.ndarray             # structured POINT_DTYPE array (x, y, z, row, col)
    left: Glyphs
    right: Glyphs
    timings_ms: dict[str, float]
    rejected_pairs: int = 0        # cell pairs dropped by the stereo plausibility gates
    frame_id: str = ""
    carried: int = 0               # glyphs (both images) labelled from the previous frame
    tracked: bool = False          # cells carried from the previous frame (no window search)
    assisted: tuple[int, int] = (0, 0)  # cells of the left / right image that came from the
                                        # other camera (transfer + rescue): that camera saw
                                        # the glyph too poorly to decode or to find it


@dataclass
class PatternSpec:
    """The parts of a pattern the decoder needs."""

    array: np.ndarray
    window: tuple[int, int] = (3, 3)
    min_hamming: int = 3
    symbols: int = 3
    pitch_m: float = 0.0

    @classmethod
    def from_pattern(cls, pattern: Any) -> "PatternSpec":
        """From a :class:`tactile_sl_decoder.pattern.Pattern` (or anything shaped like it)."""
        if isinstance(pattern, PatternSpec):
            return pattern
        c = pattern.constraints
        return cls(np.asarray(pattern.array, np.uint8), tuple(c.window), int(c.min_hamming),
                   int(c.symbols), float(getattr(pattern, "pitch_m", 0.0)))

    @classmethod
    def load(cls, path: str | Path | None = None) -> "PatternSpec":
        """Load a contract pattern YAML (default: the shipped pattern)."""
        from tactile_sl_decoder.pattern import default_pattern_path, load_pattern

        return cls.from_pattern(load_pattern(path or default_pattern_path()))


class StereoPipeline:
    """Stereo frames in, contract points out; holds the codebook, classifier and rig cache."""

    def __init__(self, pattern: Any, classifier: Any = None,
                 params: PipelineParams | None = None,
                 extractor: Callable[[np.ndarray, Any], Any] | None = None) -> None:
        self.pattern = PatternSpec.from_pattern(pattern)
        self.params = params or PipelineParams()
        set_cpu_threads(self.params.cpu_threads)
        self.codebook = Codebook(self.pattern.array, self.pattern.window,
                                 self.pattern.min_hamming, self.pattern.symbols,
                                 self.params.decode.max_errors, self.params.decode.max_erasures)
        self.decoder = CodewordDecoder(self.codebook, self.params.decode)
        self.classifier = classifier
        self._extractor = extractor
        self._rig: StereoRig | None = None
        self._rig_key: tuple | None = None
        # one per camera, sharing params.carry (live changes apply to both)
        self.params.carry.validate()
        self.params.transfer.validate()
        self.params.rescue.validate()
        self._carry = (LabelCarry(self.params.carry), LabelCarry(self.params.carry))
        self._prev_cells: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]
        self._full_decode_in = 0     # frames until the window search runs regardless
        self._pool = None
        if self.params.threads > 1:
            self._pool = ThreadPoolExecutor(max_workers=2)
            shorten_switch_interval(self.params.switch_interval_ms)

    # ------------------------------------------------------------------ stages

    def _extract(self, gray: np.ndarray) -> Any:
        if self._extractor is None:
            from tactile_sl_decoder.extract.extraction import extract_symbols

            self._extractor = extract_symbols
        return self._extractor(gray, self.params.extraction)

    def load_classifier(self) -> Any:
        """The classifier, loaded on first use from ``params.classifier_weights``."""
        if self.classifier is None:
            from tactile_sl_decoder.classify.classifier import Classifier

            self.classifier = Classifier.load(self.params.classifier_weights,
                                              self.params.classifier_threshold)
        return self.classifier

    _classifier = load_classifier

    def _map(self, fn: Callable[[Any], Any], a: Any, b: Any) -> tuple[Any, Any]:
        if self._pool is None:
            return fn(a), fn(b)
        fb = self._pool.submit(fn, b)
        ra = fn(a)
        return ra, fb.result()

    def extract_pair(self, left_gray: np.ndarray, right_gray: np.ndarray
                     ) -> tuple[Glyphs, Glyphs]:
        """Glyph candidates (unlabelled) of both images."""
        def run(gray: np.ndarray) -> Glyphs:
            det = self._extract(gray)
            return Glyphs.from_detections(det, gray.shape)
        return self._map(run, left_gray, right_gray)

    def _carries(self) -> tuple[LabelCarry | None, LabelCarry | None]:
        """The two cameras' label carries, or None when carrying is off (then forgotten)."""
        if self.params.carry.enabled:
            return self._carry
        self.forget_frames()
        return None, None

    def forget_frames(self) -> None:
        """Classify and decode the next frame in full (nothing carried from earlier frames)."""
        for c in self._carry:
            c.reset()
        self._prev_cells = [None, None]
        self._full_decode_in = 0

    def _label(self, images: list[Glyphs], carries: list[LabelCarry | None]) -> int:
        """Label the glyphs of one or more images (in place), one classifier batch.

        With a :class:`LabelCarry` per image, glyphs that keep the previous frame's label
        are not classified (classify/carry.py); the classifier sees the others only.
        Returns the number of glyphs labelled from the previous frame.
        """
        work = [(g, c) for g, c in zip(images, carries) if len(g) and g.patches is not None]
        for g, c in zip(images, carries):
            if c is not None and not (len(g) and g.patches is not None):
                c.reset()
        if not work:
            return 0
        patches = [np.asarray(g.patches) for g, _ in work]
        frames = [c.carry(g.u, g.v, p, g.spacing_px) if c is not None else None
                  for (g, c), p in zip(work, patches)]
        todo = [np.flatnonzero(~f.carried) if f is not None else slice(None) for f in frames]
        batch = [p[t] for p, t in zip(patches, todo)]
        sizes = [len(b) for b in batch]
        label, conf = (self._classifier().predict(np.concatenate(batch)) if sum(sizes)
                       else (np.zeros(0, np.uint8), np.zeros(0, np.float32)))
        start = carried = 0
        for (g, c), f, t, k in zip(work, frames, todo, sizes):
            if f is None:
                g.label = np.asarray(label[start:start + k], np.uint8)
                g.confidence = np.asarray(conf[start:start + k], np.float32)
            else:
                g.label, g.confidence = f.label.copy(), f.confidence.copy()
                g.label[t] = label[start:start + k]
                g.confidence[t] = conf[start:start + k]
                assert c is not None     # f is None exactly where c is
                c.remember(f, g.label, g.confidence)
                carried += int(f.carried.sum())
            start += k
        return carried

    def _extract_classify(self, job: tuple[np.ndarray, Any, LabelCarry | None]
                          ) -> tuple[Glyphs, int, float, float, float]:
        """One image's share of a worker: extract, find neighbours, rectify, classify.

        ``job`` is (grey image, its CameraCalibration, its camera's LabelCarry or None).  The
        k-NN table and the rectified pixels of the glyph centres are kept with the glyphs
        for decoding and stereo.  Returns the glyphs, how many kept the previous frame's
        label, and the extraction, k-NN (+ rectification) and classification milliseconds.
        """
        gray, cam, carry = job
        t0 = time.perf_counter()
        det = self._extract(gray)
        g = Glyphs.from_detections(det, gray.shape)
        t1 = time.perf_counter()
        g.neighbours = self._neighbours(g)
        g.rectified = StereoRig.rectify(cam, np.column_stack([g.u, g.v]).astype(np.float64))
        t2 = time.perf_counter()
        carried = self._label([g], [carry])
        return g, carried, 1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (time.perf_counter() - t2)

    def _neighbours(self, g: Glyphs) -> tuple[np.ndarray, np.ndarray]:
        """k-NN table of one image's glyphs (the lattice search's first step)."""
        return nearest_neighbours(g.u, g.v, self.params.grid.k_neighbours, g.spacing_px)

    def classify_pair(self, left: Glyphs, right: Glyphs,
                      carries: tuple[LabelCarry | None, LabelCarry | None] = (None, None)
                      ) -> int:
        """Label both images' glyphs in one batch (in place), carrying labels if given.

        Returns the number of glyphs labelled from the previous frame.
        """
        if any(len(g) and g.patches is not None for g in (left, right)):
            self._classifier()
        return self._label([left, right], list(carries))

    def decode(self, glyphs: Glyphs) -> Glyphs:
        """Give each glyph of one image its cell (in place; returns it)."""
        self.decode_many([glyphs])
        return glyphs

    def decode_many(self, images: list[Glyphs],
                    carried: list[np.ndarray] | None = None) -> bool:
        """Decode the glyphs of several images in one pass (in place).

        The images' glyphs are laid side by side, far apart, and go through one lattice
        search and one decoding call: the cost of these is mostly per numpy operation, so
        this is much cheaper than one call per image, and the result is the same (nothing
        links glyphs of different images; cells are unique per image).

        ``carried``: per image, each glyph's cell carried from the previous frame (flat, -1
        none; :mod:`.decode.track`).  If this frame's lattice and labels confirm every one
        of them, the glyphs take them and the window search is skipped; returns whether it
        was (else the frame was decoded in full).
        """
        sizes = [len(g) for g in images]
        if sum(sizes) == 0:
            return False
        offsets = []
        shift = 0.0
        for g in images:
            offsets.append(shift)
            span = float(np.max(g.u)) if len(g) else 0.0
            shift += max(span, float(g.image_width)) + 1e4       # far beyond any spacing
        u = np.concatenate([g.u.astype(np.float64) + o for g, o in zip(images, offsets)])
        v = np.concatenate([g.v.astype(np.float64) for g in images])
        label = np.concatenate([g.label for g in images])
        conf = np.concatenate([g.confidence for g in images])
        groups = np.repeat(np.arange(len(images)), sizes)
        hints = [g.spacing_px for g in images if g.spacing_px > 0]
        # k-NN per image (within an image's 3 spacings: never across images), unless a
        # worker thread already did it; indices shifted to the joint numbering.
        dists, idxs = [], []
        start = 0
        for g, n in zip(images, sizes):
            dist, idx = g.neighbours if g.neighbours is not None else self._neighbours(g)
            dists.append(dist)
            idxs.append(idx + start)
            start += n
        grid = build_grid(u, v, self.params.grid, max(hints) if hints else 0.0,
                          neighbours=(np.concatenate(dists), np.concatenate(idxs)))
        tracked = False
        if carried is not None:
            cell = np.concatenate(carried)
            ok = self.decoder.confirm(grid, cell, label, conf, groups)
            tracked = bool(np.all(ok | (cell == -1)))
        if tracked:
            cols = self.codebook.cols
            row = np.where(cell >= 0, cell // cols, -1).astype(np.int32)
            col = np.where(cell >= 0, cell % cols, -1).astype(np.int32)
        else:
            res = self.decoder.decode(grid, label, conf, groups)
            row, col = res.row, res.col
        start = 0
        for g, n in zip(images, sizes):
            g.row, g.col = row[start:start + n], col[start:start + n]
            if g.spacing_px <= 0:
                g.spacing_px = grid.spacing_px
            start += n
        return tracked

    def _carried_cells(self, images: list[Glyphs]) -> list[np.ndarray] | None:
        """Cells carried from the previous frame per image, or None: decode in full.

        In full when cells are not carried, every ``refresh_frames`` frames, or when a glyph
        has no glyph of the previous frame at its place (new, or moved too far).
        """
        p = self.params.carry
        if not (p.enabled and p.cells) or self._full_decode_in <= 0:
            return None
        out = []
        for g, carry, prev in zip(images, self._carry, self._prev_cells):
            last = carry.last
            if prev is None or last is None or len(last.source) != len(g) or np.any(
                    last.source < 0):
                return None
            out.append(carried_cells(last.source, prev[0], prev[1], self.codebook.cols))
        return out

    def decode_pair(self, left: Glyphs, right: Glyphs) -> None:
        """Decode both images of a stereo frame (one joint pass)."""
        self.decode_many([left, right])

    def rig(self, left_info: Any, right_info: Any) -> StereoRig:
        """Stereo rig of two CameraInfo messages (or a StereoRig), cached across frames."""
        if isinstance(left_info, StereoRig):
            return left_info
        key = (_info_key(left_info), _info_key(right_info))
        if key != self._rig_key or self._rig is None:
            try:
                self._rig = StereoRig.from_msgs(left_info, right_info)
            except CameraInfoError as exc:
                self._rig, self._rig_key = None, None
                raise PipelineInputError(str(exc)) from exc
            self._rig_key = key
        return self._rig

    def triangulate(self, left: Glyphs, right: Glyphs, rig: StereoRig,
                    images: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray, int, tuple[int, int]]:
        """Contract points, rejected pairs, and per image the cells from the other camera.

        The last is :attr:`StereoResult.assisted`.

        First a glyph one image could not decode takes the cell the other image decoded
        where the pair's geometry puts it (:func:`~.stereo.transfer.transfer_cells`); the
        images' ``row`` / ``col`` are then new arrays (the decoder's own cells, carried to
        the next frame, stay as decoded).  With the grey ``images``, a cell one image
        decoded and the other holds no glyph for is then measured in that image where the
        other puts it (:func:`~.stereo.rescue.rescue_pair`; the glyph arrays stay as
        extracted).
        """
        ncols = self.codebook.cols
        assisted = (0, 0)
        uv_l = np.column_stack([left.u, left.v]).astype(np.float64)
        uv_r = np.column_stack([right.u, right.v]).astype(np.float64)
        rect_l, rect_r = left.rectified, right.rectified
        if rect_l is None or rect_r is None or len(rect_l) != len(uv_l) or len(rect_r) != len(
                uv_r):
            rect_l = rect_r = None                       # rectify the matched ones only
        if self.params.transfer.enabled and len(uv_l) and len(uv_r) and needs_transfer(
                left, right):
            if rect_l is None or rect_r is None:
                rect_l = StereoRig.rectify(rig.left, uv_l)
                rect_r = StereoRig.rectify(rig.right, uv_r)
            before = [int(np.count_nonzero(g.row >= 0)) for g in (left, right)]
            for g in (left, right):
                g.row, g.col = g.row.copy(), g.col.copy()
            if transfer_cells(left, right, rect_l, rect_r, self.pattern.array,
                              self.params.transfer):
                assisted = (int(np.count_nonzero(left.row >= 0)) - before[0],
                            int(np.count_nonzero(right.row >= 0)) - before[1])
        cl = np.where(left.row >= 0, left.row.astype(np.int64) * ncols + left.col, -1)
        cr = np.where(right.row >= 0, right.row.astype(np.int64) * ncols + right.col, -1)
        if images is not None and self.params.rescue.enabled and len(uv_l) and len(uv_r):
            extraction = self.params.extraction or _default_extraction()
            predict = self._classifier().predict
            found = rescue_pair(left, right, images, self.pattern.array, extraction, predict,
                                self.params.rescue)
            if len(found[0].cell) or len(found[1].cell):
                uv_l, cl, rect_l = _with_rescued(uv_l, cl, rect_l, found[0], rig.left)
                uv_r, cr, rect_r = _with_rescued(uv_r, cr, rect_r, found[1], rig.right)
                assisted = (assisted[0] + len(found[0].cell),
                            assisted[1] + len(found[1].cell))
        m = match_and_triangulate(rig, uv_l, cl, uv_r, cr, ncols, self.params.stereo,
                                  rect_l, rect_r)
        # Points off the smooth surface their lattice neighbours define are dropped: a glyph
        # centre pulled aside in one image (shadow edge, dust, texture) or a wrong cell.
        off = surface_outliers(m.xyz, m.row, m.col, (self.codebook.rows, ncols),
                               self.params.outliers)
        if off.any():
            keep = ~off
            return (pack_points(m.xyz[keep], m.row[keep], m.col[keep]),
                    m.rejected + int(off.sum()), assisted)
        return pack_points(m.xyz, m.row, m.col), m.rejected, assisted

    # ------------------------------------------------------------------ whole frames

    def process(self, left_gray: np.ndarray, right_gray: np.ndarray, left_info: Any,
                right_info: Any,
                label_hook: Callable[[Glyphs, Glyphs], None] | None = None) -> StereoResult:
        """One stereo pair of grey images (H, W) uint8 + CameraInfo -> points.

        ``label_hook`` (tests, robustness benchmarks) may alter labels after classification.
        """
        t0 = time.perf_counter()
        rig = self.rig(left_info, right_info)
        check_image(left_gray, rig.left, "left")
        check_image(right_gray, rig.right, "right")
        t1 = time.perf_counter()
        if self._pool is None:
            left, right = self.extract_pair(left_gray, right_gray)
            t2 = time.perf_counter()
            carried = self.classify_pair(left, right, self._carries())
        else:
            # One worker per image: extraction, the lattice's k-NN search and classification
            # of that image (OpenCV, the k-d tree and the classifier's matrix products
            # release the GIL).  The stage times are then the slower worker's (overlapping).
            self._classifier()
            carry_l, carry_r = self._carries()
            (left, carried_l, *ms_l), (right, carried_r, *ms_r) = self._map(
                self._extract_classify, (left_gray, rig.left, carry_l),
                (right_gray, rig.right, carry_r))
            carried = carried_l + carried_r
            worker_ms = [max(a, b) for a, b in zip(ms_l, ms_r)]
        if label_hook is not None:
            label_hook(left, right)
        t3 = time.perf_counter()
        result = self._finish(left, right, rig, track=True, images=(left_gray, right_gray))
        result.carried = carried
        if self._pool is None:
            result.timings_ms.update(check=1e3 * (t1 - t0), extract=1e3 * (t2 - t1),
                                     classify=1e3 * (t3 - t2))
        else:
            result.timings_ms.update(check=1e3 * (t1 - t0), extract=worker_ms[0],
                                     knn=worker_ms[1], classify=worker_ms[2],
                                     workers=1e3 * (t3 - t1))
        result.timings_ms["total"] = 1e3 * (time.perf_counter() - t0)
        return result

    def process_symbols(self, left: Glyphs, right: Glyphs, left_info: Any,
                        right_info: Any, classify_unlabelled: bool = True) -> StereoResult:
        """Two labelled SymbolArrays (as :class:`Glyphs`) + CameraInfo -> points.

        This is the path of the chained stage nodes; it runs exactly the same decoding and
        triangulation as :meth:`process`.  Arrays straight from the extractor (no label at
        all, patches present) are classified first when ``classify_unlabelled``.
        """
        t0 = time.perf_counter()
        rig = self.rig(left_info, right_info)
        for g, cam, side in ((left, rig.left, "left"), (right, rig.right, "right")):
            if g.image_width and g.image_height and (g.image_width, g.image_height) != (
                    cam.width, cam.height):
                raise PipelineInputError(
                    f"{side} symbols come from a {g.image_width}x{g.image_height} image but "
                    f"the {side} CameraInfo is {cam.width}x{cam.height}")
        left = Glyphs(left.u, left.v, left.label, left.confidence, left.spacing_px,
                      left.image_width, left.image_height, left.area, left.patches)
        right = Glyphs(right.u, right.v, right.label, right.confidence, right.spacing_px,
                       right.image_width, right.image_height, right.area, right.patches)
        # Unlabelled glyphs with patches (straight from the extractor): classify them here.
        unlabelled = [g for g in (left, right) if len(g) and g.patches is not None
                      and np.all(g.label == LABEL_UNKNOWN) and not np.any(g.confidence)]
        if unlabelled and classify_unlabelled:
            self.classify_pair(left, right)
        result = self._finish(left, right, rig)
        result.timings_ms["total"] = 1e3 * (time.perf_counter() - t0)
        return result

    def _finish(self, left: Glyphs, right: Glyphs, rig: StereoRig,
                track: bool = False,
                images: tuple[np.ndarray, np.ndarray] | None = None) -> StereoResult:
        """Decode, pair and triangulate.

        ``track``: the frames of a camera stream (images path), whose cells may be carried
        from the frame before (:meth:`decode_many`).
        """
        t0 = time.perf_counter()
        tracked = False
        if track:
            tracked = self.decode_many([left, right], self._carried_cells([left, right]))
            self._prev_cells = [(g.row, g.col) for g in (left, right)]
            self._full_decode_in = (self._full_decode_in - 1 if tracked
                                    else self.params.carry.refresh_frames - 1)
        else:
            self.decode_pair(left, right)
        t1 = time.perf_counter()
        points, rejected, assisted = self.triangulate(left, right, rig, images)
        t2 = time.perf_counter()
        result = StereoResult(points, left, right,
                              {"decode": 1e3 * (t1 - t0), "stereo": 1e3 * (t2 - t1)},
                              rejected, rig.frame_id, assisted=assisted)
        result.tracked = tracked
        return result

    def close(self) -> None:
        """Stop the worker thread."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None


def _default_extraction() -> Any:
    from tactile_sl_decoder.extract.extraction import ExtractionParams

    return ExtractionParams()


def _with_rescued(uv: np.ndarray, cell: np.ndarray, rect: np.ndarray | None, found: Rescued,
                  cam: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One image's centres, cells and rectified centres with its rescued glyphs appended."""
    if len(found.cell) == 0:
        return uv, cell, rect
    if rect is not None:
        rect = np.concatenate([rect, StereoRig.rectify(cam, found.uv)])
    return np.concatenate([uv, found.uv]), np.concatenate([cell, found.cell]), rect


def _info_key(info: Any) -> tuple:
    def get(name: str) -> Any:
        if isinstance(info, dict):
            return info.get(name, info.get(name.upper()))
        return getattr(info, name, None)
    header = get("header")
    frame = ""
    if header is not None:
        frame = header["frame_id"] if isinstance(header, dict) else getattr(header, "frame_id", "")
    vals = []
    for name in ("k", "d", "r", "p"):
        value = get(name)
        vals.append(tuple(float(x) for x in value) if value is not None else None)
    return (get("width"), get("height"), get("distortion_model"), frame, *vals)


def check_image(gray: np.ndarray, cam: Any, side: str) -> None:
    """Raise PipelineInputError unless ``gray`` is a grey image of its CameraInfo's size."""
    if gray.ndim != 2 or gray.size == 0:
        raise PipelineInputError(f"{side} image is empty or not a grey image "
                                 f"(shape {gray.shape})")
    h, w = gray.shape
    if (w, h) != (cam.width, cam.height):
        raise PipelineInputError(f"{side} image is {w}x{h} but its CameraInfo says "
                                 f"{cam.width}x{cam.height}")


def empty_points() -> np.ndarray:
    """A cloud with no point (frames that decoded nothing)."""
    return np.zeros(0, dtype=POINT_DTYPE)
