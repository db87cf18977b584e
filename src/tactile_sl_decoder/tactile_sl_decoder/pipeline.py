"""The stereo pipeline, one place for the ROS node and offline replay (no rclpy).

images -> glyph extraction -> classification -> lattice + codeword decoding (per image) ->
stereo pairing by cell -> triangulation -> contract PointCloud2 points.

:class:`StereoPipeline` is used by the ``decoder`` node (both from images and from the stage
nodes' SymbolArrays) and by ``tactile-sl replay``, so the ROS graph and the offline replay
produce identical points for the same input.  Inputs are checked here (sizes against
CameraInfo, degenerate calibration) and problems raise :class:`PipelineInputError` with a
message meant for the user; callers skip the frame and carry on.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactile_sl_camera.camera_info import CameraInfoError
from tactile_sl_camera.clouds import POINT_DTYPE, pack_points
from tactile_sl_decoder.codewords import Codebook, CodewordDecoder, DecodeParams
from tactile_sl_decoder.grid import GridParams, build_grid, nearest_neighbours
from tactile_sl_decoder.stereo import StereoParams, StereoRig, match_and_triangulate

LABEL_UNKNOWN = 255


def set_cpu_threads(n: int, torch_too: bool = True) -> None:
    """Intra-op threads of OpenCV, OpenBLAS and torch for this process (0 = leave them).

    Per frame the work is small (a few ms): with several threads per library on a small,
    shared machine the threads wait on each other (torch inference measured 500 ms instead of
    6 ms with 2 threads on 2 busy cores), so the pipeline runs them single-threaded.
    """
    if n <= 0:
        return
    import cv2

    if cv2.getNumThreads() != n:
        cv2.setNumThreads(n)
    _set_blas_threads(n)
    if not torch_too:
        return
    try:
        import torch

        if torch.get_num_threads() != n:
            torch.set_num_threads(n)
    except ImportError:
        pass


_BLAS_THREADS: list[int] = []      # the thread count last given to the loaded OpenBLAS copies


def _set_blas_threads(n: int) -> None:
    """Threads of every OpenBLAS copy loaded in this process (numpy's, scipy's, OpenCV's).

    numpy's matrix products (the classifier) otherwise start one BLAS thread per core: with
    the two images classified in two workers on two cores, those threads spin against each
    other (measured: extraction + classification 12 ms instead of 9 ms per stereo pair).
    Done once per count; libraries that are not loaded are left alone.
    """
    if _BLAS_THREADS == [n]:
        return
    import ctypes

    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower()}
        libs = {p for p in paths
                if p.startswith("/") and "openblas" in p.rsplit("/", 1)[-1].lower()}
    except OSError:
        libs = set()
    for path in sorted(libs):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                     "openblas_set_num_threads64_", "openblas_set_num_threads"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(ctypes.c_int(n))
                break
    _BLAS_THREADS[:] = [n]


def _shorten_switch_interval(ms: float) -> None:
    """Lower Python's GIL switch interval (process-wide) to at most ``ms`` milliseconds.

    A worker returning from a GIL-free call (OpenCV, the k-d tree, a matrix product) waits
    for the GIL until the other worker, busy with small numpy operations, is forced to hand
    it over: by default after 5 ms.  With the two images in two workers that wait dominated
    (stereo pair 21 ms at 5 ms, 16 ms at 1 ms; 0.2 ms gains nothing more).
    """
    import sys

    if ms > 0 and sys.getswitchinterval() > 1e-3 * ms:
        sys.setswitchinterval(1e-3 * ms)


class PipelineInputError(ValueError):
    """A stereo frame the pipeline cannot process (the message says why)."""


@dataclass
class Glyphs:
    """Glyphs of one image as flat arrays (the SymbolArray fields, without ROS).

    Coordinates are raw (distorted) pixels, OpenCV convention.  ``row``/``col`` are -1 until
    decoded, ``label`` 255 and ``confidence`` 0 until classified.
    """

    u: np.ndarray
    v: np.ndarray
    label: np.ndarray
    confidence: np.ndarray
    spacing_px: float = 0.0
    image_width: int = 0
    image_height: int = 0
    area: np.ndarray | None = None
    patches: np.ndarray | None = None     # (N, P, P) uint8
    row: np.ndarray | None = None
    col: np.ndarray | None = None
    neighbours: tuple[np.ndarray, np.ndarray] | None = None
    """k-NN table of (u, v) (:func:`~tactile_sl_decoder.grid.nearest_neighbours`), if the
    pipeline computed it already (in a worker thread); else decoding computes it."""
    rectified: np.ndarray | None = None
    """(N, 2) undistorted + rectified pixels of (u, v), if a worker computed them already."""

    def __post_init__(self) -> None:
        self.u = np.asarray(self.u, dtype=np.float32).reshape(-1)
        self.v = np.asarray(self.v, dtype=np.float32).reshape(-1)
        n = len(self.u)
        if len(self.v) != n:
            raise PipelineInputError(f"glyph arrays differ in length (u {n}, v {len(self.v)})")
        self.label = _field(self.label, n, np.uint8, LABEL_UNKNOWN, "label")
        self.confidence = _field(self.confidence, n, np.float32, 0.0, "confidence")
        self.area = _field(self.area, n, np.float32, 0.0, "area")
        self.row = _field(self.row, n, np.int32, -1, "row")
        self.col = _field(self.col, n, np.int32, -1, "col")

    def __len__(self) -> int:
        return len(self.u)

    @property
    def decoded(self) -> np.ndarray:
        """Mask of glyphs with a cell."""
        return self.row >= 0


def _field(value: Any, n: int, dtype: Any, fill: Any, name: str) -> np.ndarray:
    if value is None:
        return np.full(n, fill, dtype=dtype)
    arr = np.asarray(value, dtype=dtype).reshape(-1)
    if len(arr) != n:
        raise PipelineInputError(f"glyph field {name!r} has {len(arr)} values, expected {n}")
    return arr


@dataclass
class PipelineParams:
    """Everything tunable in the pipeline (the node exposes these as ROS parameters)."""

    grid: GridParams = field(default_factory=GridParams)
    decode: DecodeParams = field(default_factory=DecodeParams)
    stereo: StereoParams = field(default_factory=StereoParams)
    extraction: Any = None          # tactile_sl_decoder.extraction.ExtractionParams
    threads: int = 2                # >1: extract + classify left and right concurrently
    cpu_threads: int = 1            # OpenCV/torch intra-op threads (process-wide; 0 = leave)
    switch_interval_ms: float = 1.0  # with threads > 1: Python's GIL switch interval at most
                                     # this (process-wide; 0 = leave), see _shorten_switch_interval
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
        set_cpu_threads(self.params.cpu_threads, torch_too=False)   # torch: when classifying
        self.codebook = Codebook(self.pattern.array, self.pattern.window,
                                 self.pattern.min_hamming, self.pattern.symbols,
                                 self.params.decode.max_errors, self.params.decode.max_erasures)
        self.decoder = CodewordDecoder(self.codebook, self.params.decode)
        self.classifier = classifier
        self._extractor = extractor
        self._rig: StereoRig | None = None
        self._rig_key: tuple | None = None
        self._pool = None
        if self.params.threads > 1:
            self._pool = ThreadPoolExecutor(max_workers=2)
            _shorten_switch_interval(self.params.switch_interval_ms)

    # ------------------------------------------------------------------ stages

    def _extract(self, gray: np.ndarray) -> Any:
        if self._extractor is None:
            from tactile_sl_decoder.extraction import extract_symbols

            self._extractor = extract_symbols
        return self._extractor(gray, self.params.extraction)

    def load_classifier(self) -> Any:
        """The classifier, loaded on first use from ``params.classifier_weights``."""
        if self.classifier is None:
            from tactile_sl_decoder.classifier import Classifier

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
            return Glyphs(det.u, det.v, None, None, float(det.spacing_px), gray.shape[1],
                          gray.shape[0], det.area, det.patches)
        return self._map(run, left_gray, right_gray)

    def _extract_classify(self, job: tuple[np.ndarray, Any]
                          ) -> tuple[Glyphs, float, float, float]:
        """One image's share of a worker: extract, find neighbours, rectify, classify.

        ``job`` is (grey image, its CameraCalibration).  The k-NN table and the rectified
        pixels of the glyph centres are kept with the glyphs for decoding and stereo.
        Returns the glyphs and the extraction, k-NN (+ rectification) and classification
        milliseconds.
        """
        gray, cam = job
        t0 = time.perf_counter()
        det = self._extract(gray)
        g = Glyphs(det.u, det.v, None, None, float(det.spacing_px), gray.shape[1],
                   gray.shape[0], det.area, det.patches)
        t1 = time.perf_counter()
        g.neighbours = self._neighbours(g)
        g.rectified = StereoRig.rectify(cam, np.column_stack([g.u, g.v]).astype(np.float64))
        t2 = time.perf_counter()
        if len(g) and g.patches is not None:
            label, conf = self._classifier().predict(g.patches)
            g.label = np.asarray(label, np.uint8)
            g.confidence = np.asarray(conf, np.float32)
        return g, 1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (time.perf_counter() - t2)

    def _neighbours(self, g: Glyphs) -> tuple[np.ndarray, np.ndarray]:
        """k-NN table of one image's glyphs (the lattice search's first step)."""
        return nearest_neighbours(g.u, g.v, self.params.grid.k_neighbours, g.spacing_px)

    def classify_pair(self, left: Glyphs, right: Glyphs) -> None:
        """Label both images' glyphs in one batch (in place)."""
        n = len(left)
        patches = [g.patches for g in (left, right) if g.patches is not None and len(g)]
        if not patches:
            return
        classifier = self._classifier()
        set_cpu_threads(self.params.cpu_threads)
        label, conf = classifier.predict(np.concatenate(patches))
        label = np.asarray(label, np.uint8)
        conf = np.asarray(conf, np.float32)
        if len(left) and left.patches is not None:
            left.label, left.confidence = label[:n], conf[:n]
            label, conf = label[n:], conf[n:]
        if len(right) and right.patches is not None:
            right.label, right.confidence = label, conf

    def decode(self, glyphs: Glyphs) -> Glyphs:
        """Give each glyph of one image its cell (in place; returns it)."""
        return self.decode_many([glyphs])[0]

    def decode_many(self, images: list[Glyphs]) -> list[Glyphs]:
        """Decode the glyphs of several images in one pass (in place; returns them).

        The images' glyphs are laid side by side, far apart, and go through one lattice
        search and one decoding call: the cost of these is mostly per numpy operation, so
        this is much cheaper than one call per image, and the result is the same (nothing
        links glyphs of different images; cells are unique per image).
        """
        sizes = [len(g) for g in images]
        if sum(sizes) == 0:
            return images
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
        res = self.decoder.decode(grid, label, conf, groups)
        start = 0
        for g, n in zip(images, sizes):
            g.row, g.col = res.row[start:start + n], res.col[start:start + n]
            if g.spacing_px <= 0:
                g.spacing_px = grid.spacing_px
            start += n
        return images

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

    def triangulate(self, left: Glyphs, right: Glyphs, rig: StereoRig
                    ) -> tuple[np.ndarray, int]:
        """Contract points from two decoded images, and the count of rejected pairs."""
        ncols = self.codebook.cols
        cl = np.where(left.row >= 0, left.row.astype(np.int64) * ncols + left.col, -1)
        cr = np.where(right.row >= 0, right.row.astype(np.int64) * ncols + right.col, -1)
        uv_l = np.column_stack([left.u, left.v]).astype(np.float64)
        uv_r = np.column_stack([right.u, right.v]).astype(np.float64)
        rect_l, rect_r = left.rectified, right.rectified
        if rect_l is None or rect_r is None or len(rect_l) != len(uv_l) or len(rect_r) != len(
                uv_r):
            rect_l = rect_r = None                       # rectify the matched ones only
        m = match_and_triangulate(rig, uv_l, cl, uv_r, cr, ncols, self.params.stereo,
                                  rect_l, rect_r)
        return pack_points(m.xyz, m.row, m.col), m.rejected

    # ------------------------------------------------------------------ whole frames

    def process(self, left_gray: np.ndarray, right_gray: np.ndarray, left_info: Any,
                right_info: Any,
                label_hook: Callable[[Glyphs, Glyphs], None] | None = None) -> StereoResult:
        """One stereo pair of grey images (H, W) uint8 + CameraInfo -> points.

        ``label_hook`` (tests, robustness benchmarks) may alter labels after classification.
        """
        t0 = time.perf_counter()
        rig = self.rig(left_info, right_info)
        _check_image(left_gray, rig.left, "left")
        _check_image(right_gray, rig.right, "right")
        t1 = time.perf_counter()
        if self._pool is None:
            left, right = self.extract_pair(left_gray, right_gray)
            t2 = time.perf_counter()
            self.classify_pair(left, right)
        else:
            # One worker per image: extraction, the lattice's k-NN search and classification
            # of that image (OpenCV, the k-d tree and the classifier's matrix products
            # release the GIL).  The stage times are then the slower worker's (overlapping).
            self._classifier()
            set_cpu_threads(self.params.cpu_threads)
            (left, *ms_l), (right, *ms_r) = self._map(
                self._extract_classify, (left_gray, rig.left), (right_gray, rig.right))
            worker_ms = [max(a, b) for a, b in zip(ms_l, ms_r)]
        if label_hook is not None:
            label_hook(left, right)
        t3 = time.perf_counter()
        result = self._finish(left, right, rig)
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

    def _finish(self, left: Glyphs, right: Glyphs, rig: StereoRig) -> StereoResult:
        t0 = time.perf_counter()
        self.decode_pair(left, right)
        t1 = time.perf_counter()
        points, rejected = self.triangulate(left, right, rig)
        t2 = time.perf_counter()
        return StereoResult(points, left, right,
                            {"decode": 1e3 * (t1 - t0), "stereo": 1e3 * (t2 - t1)},
                            rejected, rig.frame_id)

    def close(self) -> None:
        """Stop the worker thread."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None


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


def _check_image(gray: np.ndarray, cam: Any, side: str) -> None:
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


# ---------------------------------------------------------------------- bags (offline)


@dataclass
class BagFrame:
    """One stereo frame of a bag: the four input messages (decoded) and ground truth."""

    stamp: tuple[int, int]
    left_image: Any
    right_image: Any
    left_info: Any
    right_info: Any
    ground_truth: Any = None

    @property
    def stamp_ns(self) -> int:
        """Stamp in nanoseconds (for sorting and keys; the message keeps the exact ints)."""
        return self.stamp[0] * 1_000_000_000 + self.stamp[1]


def bag_topics(namespace: str = "/tactile") -> dict[str, str]:
    """Topic of each frame part in a bag recorded in ``namespace``."""
    ns = namespace.rstrip("/")
    return {"left_image": f"{ns}/left/image_raw", "right_image": f"{ns}/right/image_raw",
            "left_info": f"{ns}/left/camera_info", "right_info": f"{ns}/right/camera_info",
            "ground_truth": f"{ns}/ground_truth/points"}


def count_bag_frames(path: str | Path, namespace: str = "/tactile") -> int:
    """Number of left images in a bag (for progress bars)."""
    from tactile_sl_camera.bag_io import BagReader

    reader = BagReader(path)
    topic = bag_topics(namespace)["left_image"]
    return reader.topics[topic].message_count if topic in reader.topics else 0


def bag_frames(path: str | Path, namespace: str = "/tactile",
               ground_truth: bool = True) -> Any:
    """Stereo frames of a bag, grouped by exact header stamp, in stamp order.

    Messages of one frame may come in any order; a frame is complete once both images are
    there.  CameraInfo may be sent less often than images: the latest one of each side is
    used then.  Raises ``BagError`` for unreadable bags or missing image topics.
    """
    from tactile_sl_camera.bag_io import BagReader, header_stamp_of_cdr

    reader = BagReader(path)
    topics = bag_topics(namespace)
    reader.require_topics([topics["left_image"], topics["right_image"],
                           topics["left_info"], topics["right_info"]])
    wanted = [topics[k] for k in ("left_image", "right_image", "left_info", "right_info")]
    if ground_truth and topics["ground_truth"] in reader.topics:
        wanted.append(topics["ground_truth"])
    part_of = {v: k for k, v in topics.items()}
    pending: dict[tuple[int, int], dict[str, Any]] = {}
    latest_info: dict[str, Any] = {}

    def flush(up_to: tuple[int, int] | None) -> Any:
        for stamp in sorted(pending):
            if up_to is not None and stamp >= up_to:
                break
            parts = pending.pop(stamp)
            for side in ("left_info", "right_info"):
                if side in parts:
                    latest_info[side] = parts[side]
            if "left_image" in parts and "right_image" in parts:
                left_info = parts.get("left_info", latest_info.get("left_info"))
                right_info = parts.get("right_info", latest_info.get("right_info"))
                yield BagFrame(stamp, parts["left_image"], parts["right_image"], left_info,
                               right_info, parts.get("ground_truth"))

    for raw, msg in reader.messages(wanted):
        stamp = tuple(int(x) for x in header_stamp_of_cdr(raw.data))
        # log time = stamp in our bags, but be tolerant: only flush frames well behind.
        yield from flush(_minus(stamp, 1))
        pending.setdefault(stamp, {})[part_of[raw.topic]] = msg
    yield from flush(None)


def _minus(stamp: tuple[int, ...], seconds: int) -> tuple[int, int]:
    return (stamp[0] - seconds, stamp[1])


# ---------------------------------------------------------------------- stereo pairing


@dataclass
class SyncEvent:
    """What :class:`StereoSync` decided for an incoming message."""

    pairs: list[tuple[int, Any, Any]] = field(default_factory=list)   # (stamp_ns, left, right)
    dropped: list[tuple[str, int, str]] = field(default_factory=list)  # (side, stamp, reason)
    reset: bool = False            # time jumped back by more than max_age: state cleared


class StereoSync:
    """Pairs left/right messages by header stamp: exact stamps first, then within a slop.

    Unpaired messages wait in bounded per-side queues; a message older than the newest
    paired frame, or pushed out of a full queue, or older than ``max_age_ns`` behind the
    newest message seen, is dropped (stale frames are never queued without bound).  A stamp
    more than ``max_age_ns`` *before* the last paired frame means time jumped back (a bag
    played again): the state is reset rather than every later frame dropped as stale.
    """

    def __init__(self, slop_ns: int = 0, queue_size: int = 5, max_age_ns: int = 500_000_000):
        self.slop_ns = int(slop_ns)
        self.queue_size = max(1, int(queue_size))
        self.max_age_ns = int(max_age_ns)
        self.pending: dict[str, dict[int, Any]] = {"left": {}, "right": {}}
        self.last_paired_ns: int | None = None
        self.newest_ns: int | None = None

    def add(self, side: str, stamp_ns: int, item: Any) -> SyncEvent:
        """Offer one message; returns the pairs completed and the messages dropped."""
        ev = SyncEvent()
        other = "right" if side == "left" else "left"
        if self.last_paired_ns is not None and stamp_ns < self.last_paired_ns - self.max_age_ns:
            # Time jumped back by more than max_age (a bag played again, a looping replay,
            # a restarted camera clock): start over instead of dropping everything.
            for s in ("left", "right"):
                for old in self.pending[s]:
                    ev.dropped.append((s, old, "time jumped back (sync reset)"))
                self.pending[s].clear()
            self.last_paired_ns = None
            self.newest_ns = None
            ev.reset = True
        if self.last_paired_ns is not None and stamp_ns <= self.last_paired_ns:
            ev.dropped.append((side, stamp_ns, "stale (not newer than the last frame)"))
            return ev
        self.newest_ns = stamp_ns if self.newest_ns is None else max(self.newest_ns, stamp_ns)
        mine, theirs = self.pending[side], self.pending[other]
        partner: int | None = stamp_ns if stamp_ns in theirs else None
        if partner is None and self.slop_ns > 0 and theirs:
            cand = min(theirs, key=lambda s: abs(s - stamp_ns))
            if abs(cand - stamp_ns) <= self.slop_ns and cand not in mine:
                partner = cand
        if partner is not None:
            other_item = theirs.pop(partner)
            stamp = stamp_ns if side == "left" else partner   # the left image's stamp
            left, right = (item, other_item) if side == "left" else (other_item, item)
            ev.pairs.append((stamp, left, right))
            self.last_paired_ns = max(stamp_ns, partner)
            for s in ("left", "right"):                          # older ones are now stale
                for old in [t for t in self.pending[s] if t <= self.last_paired_ns]:
                    del self.pending[s][old]
                    ev.dropped.append((s, old, "no stereo partner (unsynchronised)"))
            return ev
        mine[stamp_ns] = item
        while len(mine) > self.queue_size:
            old = min(mine)
            del mine[old]
            ev.dropped.append((side, old, "no stereo partner before the queue filled"))
        for s in ("left", "right"):
            for old in [t for t in self.pending[s] if t < self.newest_ns - self.max_age_ns]:
                del self.pending[s][old]
                ev.dropped.append((s, old, "no stereo partner in time (unsynchronised)"))
        return ev


# ---------------------------------------------------------------------- SymbolArray


def _array(value: Any, dtype: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value.astype(dtype, copy=False).reshape(-1)
    try:
        return np.frombuffer(memoryview(value), dtype=dtype).copy()
    except (TypeError, ValueError):
        return np.asarray(list(value), dtype=dtype)


def glyphs_from_symbol_array(msg: Any) -> Glyphs:
    """Glyphs of a tactile_sl_msgs/SymbolArray (rclpy or bag-decoded), checked."""
    u = _array(msg.u, np.float32)
    n = len(u)
    fields = {"v": np.float32, "area": np.float32, "label": np.uint8,
              "confidence": np.float32, "row": np.int32, "col": np.int32}
    arrays = {}
    for name, dtype in fields.items():
        arr = _array(getattr(msg, name), dtype)
        if len(arr) not in (n, 0) or (name in ("v", "label") and len(arr) != n):
            raise PipelineInputError(f"SymbolArray field {name!r} has {len(arr)} values but "
                                     f"there are {n} glyphs")
        arrays[name] = arr if len(arr) == n else None
    ps = int(msg.patch_size)
    patches = None
    if ps > 0:
        raw = _array(msg.patches, np.uint8)
        if len(raw) == n * ps * ps:
            patches = raw.reshape(n, ps, ps)
    return Glyphs(u, arrays["v"], arrays["label"], arrays["confidence"], float(msg.spacing_px),
                  int(msg.image_width), int(msg.image_height), arrays["area"], patches,
                  arrays["row"], arrays["col"])
