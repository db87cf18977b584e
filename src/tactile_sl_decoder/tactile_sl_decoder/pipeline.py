"""The stereo pipeline, one place for the ROS node and offline replay (no rclpy).

images -> glyph extraction -> classification -> lattice + codeword decoding (per image) ->
stereo pairing by cell -> triangulation -> contract PointCloud2 points.

:class:`StereoPipeline` is used by the ``decoder`` node (both from images and from the stage
nodes' SymbolArrays) and by ``tactile-sl replay``, so the ROS graph and the offline replay
produce identical points for the same input.  Inputs are checked here (sizes against
CameraInfo, degenerate calibration) and problems raise :class:`PipelineInputError` with a
message meant for the user; callers skip the frame and carry on.

The stages it composes live in :mod:`.extract`, :mod:`.classify`, :mod:`.decode` and
:mod:`.stereo` (the stereo stage's own sequence, transfer -> rescue -> triangulation ->
outliers, is :func:`~tactile_sl_decoder.stereo.pair.pair_points`); what a camera stream keeps
of its previous frame is :class:`~tactile_sl_decoder.decode.track.StreamMemory`; glyph arrays
in :mod:`.glyphs`, bag frames and stereo pairing in :mod:`.frames`, library thread settings in
:mod:`.cpu_threads` (import them from there).
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactile_sl_common import signals
from tactile_sl_common.camera_info import CameraInfoError
from tactile_sl_decoder.camera_processes import CameraJob, CameraProcesses, camera_half
from tactile_sl_decoder.classify.carry import CarryParams, LabelCarry, label_glyphs
from tactile_sl_decoder.classify.classifier import Classifier
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.cpu_threads import set_cpu_threads, shorten_switch_interval
from tactile_sl_decoder.decode.codewords import Codebook, CodewordDecoder, DecodeParams
from tactile_sl_decoder.decode.grid import GridParams
from tactile_sl_decoder.decode.joint import decode_jointly
from tactile_sl_decoder.decode.track import StreamMemory
from tactile_sl_decoder.extract.extraction import extract_symbols
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.pattern import default_pattern_path, load_pattern
from tactile_sl_decoder.pattern.constraints import Constraints
from tactile_sl_decoder.pattern.fileio import Pattern
from tactile_sl_decoder.stereo.artwork_fit import ArtworkFitParams, ArtworkModel
from tactile_sl_decoder.stereo.outliers import OutlierParams
from tactile_sl_decoder.stereo.pair import PairSettings, pair_points
from tactile_sl_decoder.stereo.rescue import RescueParams
from tactile_sl_decoder.stereo.stereo import StereoParams, StereoRig
from tactile_sl_decoder.stereo.transfer import TransferParams


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
    artwork_fit: ArtworkFitParams = field(default_factory=ArtworkFitParams)  # images path
    extraction: Any = None          # tactile_sl_decoder.extract.extraction.ExtractionParams
    threads: int = 2                # >1: extract + classify left and right concurrently
    processes: bool = False         # each camera's extraction + classification in a process
                                    # of its own (camera_processes.py; a live node's default)
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
    primitives: tuple[str, ...] = ()
    """The glyph of each symbol (the pattern file's names); empty: the defaults for
    ``symbols`` (:class:`~tactile_sl_decoder.pattern.fileio.Pattern` fills them in)."""

    def to_pattern(self) -> Pattern:
        """The :class:`~tactile_sl_decoder.pattern.fileio.Pattern` of these parts.

        Empty :attr:`primitives` become the default glyphs of ``symbols``.
        """
        return Pattern(self.array, Constraints(self.symbols, self.window, self.min_hamming),
                       self.pitch_m, list(self.primitives))

    @classmethod
    def from_pattern(cls, pattern: Any) -> "PatternSpec":
        """From a :class:`tactile_sl_decoder.pattern.Pattern` (or anything shaped like it)."""
        if isinstance(pattern, PatternSpec):
            return pattern
        c = pattern.constraints
        return cls(np.asarray(pattern.array, np.uint8), tuple(c.window), int(c.min_hamming),
                   int(c.symbols), float(getattr(pattern, "pitch_m", 0.0)),
                   tuple(getattr(pattern, "primitives", None) or ()))

    @classmethod
    def load(cls, path: str | Path | None = None) -> "PatternSpec":
        """Load a contract pattern YAML (default: the shipped pattern)."""
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
        self.params.carry.validate()
        self.params.transfer.validate()
        self.params.rescue.validate()
        self.params.artwork_fit.validate()
        self._artwork: ArtworkModel | None = None
        self.memory = StreamMemory(self.params.carry)   # shares params.carry: live changes
        self._pool = None
        self._procs: CameraProcesses | None = None
        self.keep_patches = False    # with processes: the glyphs' patches come back too
        if self.params.processes:
            self._procs = CameraProcesses(self.params.classifier_weights,
                                          self.params.classifier_threshold,
                                          self.params.cpu_threads)
        elif self.params.threads > 1:
            self._pool = ThreadPoolExecutor(max_workers=2)
            shorten_switch_interval(self.params.switch_interval_ms)

    # ------------------------------------------------------------------ stages

    def _extract(self, gray: np.ndarray) -> Any:
        if self._extractor is None:
            self._extractor = extract_symbols
        return self._extractor(gray, self.params.extraction)

    def load_classifier(self) -> Any:
        """The classifier, loaded on first use from ``params.classifier_weights``."""
        if self.classifier is None:
            self.classifier = Classifier.load(self.params.classifier_weights,
                                              self.params.classifier_threshold)
        return self.classifier


    def _predict(self, patches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The classifier's labels and confidences of ``patches`` (loaded on first use)."""
        return self.load_classifier().predict(patches)

    def _map(self, fn: Callable[[Any], Any], a: Any, b: Any) -> tuple[Any, Any]:
        if self._pool is None:
            return fn(a), fn(b)
        fb = self._pool.submit(fn, b)
        ra = fn(a)
        return ra, fb.result()

    @signals.held()     # a signal waits for the end (tactile_sl_common.signals)
    def extract_pair(self, left_gray: np.ndarray, right_gray: np.ndarray
                     ) -> tuple[Glyphs, Glyphs]:
        """Glyph candidates (unlabelled) of both images."""
        def run(gray: np.ndarray) -> Glyphs:
            det = self._extract(gray)
            return Glyphs.from_detections(det, gray.shape)
        return self._map(run, left_gray, right_gray)

    def ready(self) -> bool:
        """Whether the camera worker process (if any) has started and warmed up.

        Never blocks.  A live node subscribes to images only once this is true, so that its
        first frames do not queue (and get dropped) behind a second of worker start-up.
        RuntimeError if a worker failed to start.
        """
        return self._procs is None or self._procs.poll_ready()

    @property
    def worker_pids(self) -> list[int]:
        """Process ids of the camera worker processes (the right camera's; none in process)."""
        return self._procs.pids if self._procs is not None else []

    def forget_frames(self) -> None:
        """Classify and decode the next frame in full (nothing carried from earlier frames)."""
        self.memory.forget()
        if self._procs is not None:
            self._procs.forget()

    def _extract_classify(self, job: tuple[np.ndarray, Any, LabelCarry | None]
                          ) -> tuple[Glyphs, int, float, float, float]:
        """One image's share of a worker thread (:func:`camera_half`).

        ``job`` is (grey image, its CameraCalibration, its camera's LabelCarry or None).
        Returns the glyphs, how many kept the previous frame's label, and the extraction,
        lattice (+ rectification) and classification milliseconds.
        """
        gray, cam, carry = job
        g, carried, (extract_ms, lattice_ms, classify_ms) = camera_half(
            gray, self._extract, self.params.grid, cam, carry, self._predict)
        return g, carried, extract_ms, lattice_ms, classify_ms

    def classify_pair(self, left: Glyphs, right: Glyphs,
                      carries: tuple[LabelCarry | None, LabelCarry | None] = (None, None)
                      ) -> int:
        """Label both images' glyphs in one batch (in place), carrying labels if given.

        Returns the number of glyphs labelled from the previous frame.
        """
        if any(len(g) and g.patches is not None for g in (left, right)):
            self.load_classifier()
        return label_glyphs([left, right], list(carries), self._predict)

    def decode_many(self, images: list[Glyphs],
                    carried: list[np.ndarray] | None = None) -> bool:
        """Decode the glyphs of several images in one pass (in place).

        See :func:`~tactile_sl_decoder.decode.joint.decode_jointly`; True if the
        ``carried`` cells were confirmed and the window search skipped.
        """
        return decode_jointly(images, self.decoder, self.params.grid, carried)

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

    # ------------------------------------------------------------------ whole frames

    @signals.held()     # a signal waits for the end (tactile_sl_common.signals)
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
        matches = None
        if self._procs is not None:
            (left, right), carried, matches, worker_ms = self._in_processes(
                left_gray, right_gray, rig)
        elif self._pool is None:
            left, right = self.extract_pair(left_gray, right_gray)
            t2 = time.perf_counter()
            carried = self.classify_pair(left, right, self.memory.label_carries())
        else:
            # One worker per image: extraction, the lattice and classification of that image
            # (OpenCV, the compiled kernels and the classifier's matrix products release the
            # GIL).  The stage times are then the slower worker's (overlapping).
            self.load_classifier()
            carry_l, carry_r = self.memory.label_carries()
            (left, carried_l, *ms_l), (right, carried_r, *ms_r) = self._map(
                self._extract_classify, (left_gray, rig.left, carry_l),
                (right_gray, rig.right, carry_r))
            carried = carried_l + carried_r
            worker_ms = [max(a, b) for a, b in zip(ms_l, ms_r)]
        if label_hook is not None:
            label_hook(left, right)
        t3 = time.perf_counter()
        result = self._finish(left, right, rig, track=True, images=(left_gray, right_gray),
                              matches=matches)
        result.carried = carried
        if self._pool is None and self._procs is None:
            result.timings_ms.update(check=1e3 * (t1 - t0), extract=1e3 * (t2 - t1),
                                     classify=1e3 * (t3 - t2))
        else:
            result.timings_ms.update(check=1e3 * (t1 - t0), extract=worker_ms[0],
                                     lattice=worker_ms[1], classify=worker_ms[2],
                                     workers=1e3 * (t3 - t1))
        result.timings_ms["total"] = 1e3 * (time.perf_counter() - t0)
        return result

    @signals.held()     # a signal waits for the end (tactile_sl_common.signals)
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
                images: tuple[np.ndarray, np.ndarray] | None = None,
                matches: tuple[Any, Any] | None = None) -> StereoResult:
        """Decode, pair and triangulate.

        ``track``: the frames of a camera stream (images path), whose cells may be carried
        from the frame before (:meth:`decode_many`); ``matches``: the cameras' matches to
        their previous frames when a worker process made one of them.
        """
        t0 = time.perf_counter()
        tracked = False
        if track:
            tracked = self.decode_many([left, right],
                                       self.memory.carried_cells([left, right],
                                                                 self.codebook.cols, matches))
            self.memory.remember([left, right], tracked)
        else:
            self.decode_pair(left, right)
        t1 = time.perf_counter()
        p = self.params
        pair = pair_points(left, right, rig, self.pattern.array,
                           PairSettings(p.transfer, p.rescue, p.stereo, p.outliers,
                                        p.extraction, p.artwork_fit, self.artwork()),
                           self._predict, images, self._map)
        t2 = time.perf_counter()
        result = StereoResult(pair.points, left, right,
                              {"decode": 1e3 * (t1 - t0), "stereo": 1e3 * (t2 - t1)},
                              pair.rejected, rig.frame_id, assisted=pair.assisted)
        result.tracked = tracked
        return result

    def artwork(self) -> ArtworkModel | None:
        """The pattern's artwork for the artwork fit, drawn when first wanted.

        None while ``params.artwork_fit`` is off.
        """
        if not self.params.artwork_fit.enabled:
            return None
        if self._artwork is None:
            self._artwork = ArtworkModel(self.pattern.to_pattern())
        return self._artwork

    def _in_processes(self, left_gray: np.ndarray, right_gray: np.ndarray, rig: StereoRig
                      ) -> tuple[tuple[Glyphs, Glyphs], int, tuple[Any, Any], list[float]]:
        """The right image's half in its worker process, the left's here (camera_processes.py)."""
        assert self._procs is not None
        classifier = self.load_classifier()       # here too: rescue classifies
        p = self.params
        if not p.carry.enabled:
            self.memory.forget()
        carry = p.carry if p.carry.enabled else None
        jobs = tuple(CameraJob(gray.shape, p.extraction, p.grid, carry, classifier.threshold,
                               self.keep_patches) for gray in (left_gray, right_gray))
        rl, rr = self._procs.run((left_gray, right_gray), (rig.left, rig.right),
                                 (jobs[0], jobs[1]), classifier, self.memory.carries[0])
        ms = [max(a, b) for a, b in zip(rl.timings_ms, rr.timings_ms)]
        return (rl.glyphs, rr.glyphs), rl.carried + rr.carried, (rl.match, rr.match), ms

    def close(self) -> None:
        """Stop the worker thread or processes."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None
        if self._procs is not None:
            self._procs.close()
            self._procs = None


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
