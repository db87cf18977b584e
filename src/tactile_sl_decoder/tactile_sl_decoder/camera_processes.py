"""The right camera's half of each stereo frame in a process of its own (no rclpy).

The pipeline's work per frame is many small numpy and Python steps that hold the
interpreter lock: two threads decoding two images share one core's worth of it (two
threads running two independent pipelines got 0.86x the throughput of one; two processes
1.93x).  So a live node extracts, finds the k nearest neighbours of, rectifies and
classifies the right camera's glyphs in a worker process, while its own process does the
same for the left camera meanwhile (:func:`camera_half`, with its own label carry and
classifier), then decodes, pairs, triangulates and runs the touch stage.  The worker keeps
its camera's label carry, exactly as the in-process pipeline keeps it per camera, so the
results are the same bytes (test).  Until 2026-12-03 both cameras had a worker and the
node's process waited for them: each hand-off (wake-up, pickling) cost ~0.3 ms each way and
the second worker started its frame ~1 ms after the first on the 2-core VM, 2.4 ms a frame
in all.  With one worker the points come 0.6-2.5 ms sooner and the node takes 200 MB less
(same bytes; the figures, and what did not change, in docs/decoder.md).

The image goes to the worker through shared memory and its glyphs come back pickled
through shared memory too (about 0.15 MB a frame; through a pipe, whose 64 kB buffer splits
such a message into a handful of wake-ups on each side, the transfers cost ~2.5 ms); the
pipe carries only short messages.  Settings travel with every frame, so a live change
applies to the next frame as in the process; the camera calibration is sent when it changes.
The worker is started with ``spawn`` (a fork of a process with DDS threads is unsafe), takes
about a second to start, ends when the pipe closes, and its errors come back as the frame's
errors.  Before it reports ready, it runs two synthetic frames through its code (a lattice
of ink discs: extraction, patches, classification, the label carry), so that the first real
frame finds every first-call cost paid; :meth:`CameraProcesses.poll_ready` tells when it is
(a live node subscribes to images only then, after running a frame through its own half:
no frame waits for a starting worker), and :meth:`~CameraProcesses.run` waits for it.
"""
from __future__ import annotations

import multiprocessing
import pickle
import signal
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.shared_memory import SharedMemory
from typing import Any, Callable

import numpy as np

from tactile_sl_common.camera_info import CameraCalibration
from tactile_sl_common.heap import freeze_long_lived
from tactile_sl_decoder.classify.carry import CarryParams, LabelCarry, label_glyphs
from tactile_sl_decoder.classify.classifier import Classifier
from tactile_sl_decoder.cpu_threads import set_cpu_threads
from tactile_sl_decoder.decode.grid import GridParams
from tactile_sl_decoder.decode.joint import image_lattice
from tactile_sl_decoder.extract.extraction import extract_symbols
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.stereo.stereo import StereoRig

RESULT_BYTES = 4 << 20
"""Shared memory for one camera's pickled glyphs (~0.15 MB a frame; larger goes by pipe)."""


@dataclass
class CameraJob:
    """What a worker needs besides the image's bytes (the settings in force)."""

    shape: tuple[int, int]
    extraction: Any                 # ExtractionParams or None (defaults)
    grid: GridParams
    carry: CarryParams | None       # None: no labels carried (and the carry forgotten)
    threshold: float | None         # the classifier's confidence threshold in force
    patches: bool = False           # send the glyphs' patches back too (symbols_decoded)


@dataclass
class Match:
    """What the main process needs of a camera's match to its previous frame.

    The ``source`` of a :class:`~tactile_sl_decoder.classify.carry.Carried` (its normalised
    patches stay in the worker).
    """

    source: np.ndarray


@dataclass
class CameraResult:
    """One camera's half of a frame, as a worker made it.

    Its glyphs (labelled), how many kept a label, their match to the previous frame
    (``LabelCarry.last``) and the extraction / lattice / classification times.
    """

    glyphs: Glyphs
    carried: int
    match: Any
    timings_ms: tuple[float, float, float]


class _Buffers:
    """The two shared-memory blocks of one camera: its image in, its glyphs out."""

    def __init__(self) -> None:
        self.blocks: dict[str, SharedMemory] = {}

    def get(self, name: str) -> SharedMemory:
        """The block ``name`` (attached on first use; a new name replaces a grown block)."""
        if name not in self.blocks:     # the main process made it and unlinks it (spawned
            self.blocks[name] = SharedMemory(name=name)   # workers share its resource tracker)
        return self.blocks[name]

    def close(self) -> None:
        for block in self.blocks.values():
            block.close()
        self.blocks.clear()


def _serve(conn: Connection, weights: str | None, threshold: float | None,
           cpu_threads: int) -> None:
    """The worker's loop: one camera's frames, in order, until the pipe closes.

    The main process alone decides when its workers stop (a "stop", or its end of the pipe
    closing when it ends), so a Ctrl-C in the terminal, which reaches the whole process
    group, is ignored here; and a main process that ended while this one was starting or
    computing ends this one quietly, without a traceback.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    set_cpu_threads(cpu_threads)
    try:
        classifier = Classifier.load(weights, threshold)
        _warm_up(classifier)
    except Exception as exc:         # reported by the main process (poll_ready)
        _send(conn, ("error", exc))
        return
    carry = LabelCarry(CarryParams())
    camera: Any = None
    buffers = _Buffers()
    freeze_long_lived()        # no full collection of the imports between two frames
    if not _send(conn, ("ready", None)):
        return
    frames = 0
    try:
        while True:
            try:
                kind, payload = conn.recv()
            except (EOFError, OSError):
                return
            if kind == "stop":
                return
            if kind == "camera":
                camera = payload
            elif kind == "forget":
                carry.reset()
            else:
                job, image_name, result_name = payload
                if not _send(conn, _answer(job, buffers.get(image_name),
                                           buffers.get(result_name), camera, classifier,
                                           carry)):
                    return
                frames += 1
                if frames == 1:        # and what the first frame set up (compiled kernels)
                    freeze_long_lived(collect=False)
    finally:
        buffers.close()


def _send(conn: Connection, message: tuple[str, Any]) -> bool:
    """Send ``message`` to the main process; False if it has gone (its end closed)."""
    try:
        conn.send(message)
    except (BrokenPipeError, ConnectionResetError, EOFError):
        return False
    return True


def _warm_up(classifier: Classifier) -> None:
    """Two synthetic frames through :func:`_half` (the second with carried labels).

    A 17 px lattice of ink discs on a 640 x 480 image, a camera without distortion: every
    step of a frame runs once (numba dispatch, OpenCV and BLAS first calls, the allocator's
    pools), and nothing of it is kept.
    """
    rows, cols = np.mgrid[0:480, 0:640]
    disc = (rows % 17 - 8.0) ** 2 + (cols % 17 - 8.0) ** 2 < 20.0
    gray = np.where(disc, 60, 200).astype(np.uint8)
    focal = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    camera = CameraCalibration(640, 480, focal, np.zeros(5))
    job = CameraJob(gray.shape, None, GridParams(), CarryParams(), None)
    carry = LabelCarry(CarryParams())
    for _ in range(2):
        _half(gray, job, camera, classifier, carry)


def _answer(job: CameraJob, image: SharedMemory, out: SharedMemory, camera: Any,
            classifier: Classifier, carry: LabelCarry) -> tuple[str, Any]:
    """Run one camera's half; its result pickled into ``out`` (its length sent), or why not."""
    gray = np.ndarray(job.shape, np.uint8, buffer=_view(image))
    try:
        blob = pickle.dumps(_half(gray, job, camera, classifier, carry), protocol=5)
    except Exception as exc:          # the frame's error, raised in the main process
        return "error", exc
    if len(blob) > out.size:
        return "inline", blob             # larger than the block: through the pipe
    _view(out)[:len(blob)] = blob
    return "ok", len(blob)


def _view(block: SharedMemory) -> memoryview:
    assert block.buf is not None
    return block.buf


def camera_half(gray: np.ndarray, detect: Callable[[np.ndarray], Any], grid: GridParams,
                camera: Any, carry: LabelCarry | None,
                predict: Callable[[np.ndarray], tuple[np.ndarray, Any]]
                ) -> tuple[Glyphs, int, tuple[float, float, float]]:
    """One camera's half of a frame: extract, build the lattice, rectify, classify.

    What a worker (thread or process) does per image: ``detect`` (grey image -> detections)
    finds the glyphs, whose lattice and rectified centres (``camera``, a CameraCalibration)
    are kept with them for decoding and stereo; they are labelled with ``predict``, keeping
    the previous frame's labels where ``carry`` has them.  Returns the glyphs, how many kept
    a label, and the extraction, lattice (+ rectification) and classification milliseconds.
    """
    t0 = time.perf_counter()
    g = Glyphs.from_detections(detect(gray), gray.shape)
    t1 = time.perf_counter()
    g.lattice = image_lattice(g, grid)
    g.rectified = StereoRig.rectify(camera, np.column_stack([g.u, g.v]).astype(np.float64))
    t2 = time.perf_counter()
    carried = label_glyphs([g], [carry], predict)
    return g, carried, (1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (time.perf_counter() - t2))


def _half(image: np.ndarray, job: CameraJob, camera: Any, classifier: Classifier,
          carry: LabelCarry) -> CameraResult:
    # ``image`` lies in shared memory the main process rewrites for the next frame: nothing
    # computed here keeps a view of it (extraction copies what it keeps)
    """:func:`camera_half` with the job's settings: in the worker, or the left half here."""
    if job.threshold is not None:
        classifier.threshold = job.threshold
    if job.carry is None:
        carry.reset()
    else:
        carry.params = job.carry
    g, carried, timings = camera_half(image, lambda gray: extract_symbols(gray, job.extraction),
                                      job.grid, camera, None if job.carry is None else carry,
                                      classifier.predict)
    match = Match(carry.last.source) if job.carry is not None and carry.last is not None \
        else None
    if not job.patches:
        g.patches = None                    # a quarter of a megabyte less over the pipe
    return CameraResult(g, carried, match, timings)


class CameraProcesses:
    """Both cameras' halves of a frame: the right camera's in a worker process, the left's here.

    :meth:`run` sends the right image to its worker and meanwhile runs the left half in the
    calling process, with the caller's label carry and classifier, then collects the right.
    One hand-off a frame instead of two: on the 2-core VM a second worker started its frame
    about 1 ms after the first, and each hand-off cost ~0.3 ms each way (measured with
    ``tools/bench_pipeline.py --processes``: see docs/decoder.md).
    """

    def __init__(self, weights: str | None, threshold: float | None,
                 cpu_threads: int = 1) -> None:
        context = multiprocessing.get_context("spawn")
        self._conn, theirs = context.Pipe()
        self._proc: Any = context.Process(target=_serve, args=(theirs, weights, threshold,
                                                               cpu_threads),
                                          name="tactile-sl right camera", daemon=True)
        self._proc.start()
        theirs.close()
        self._camera: Any = None               # the worker's camera calibration, as sent
        self._image: SharedMemory | None = None
        self._result: SharedMemory | None = SharedMemory(create=True, size=RESULT_BYTES)
        self._started = False                  # the worker's "ready" received
        self._closed = False

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Wait until the worker has started and warmed up (RuntimeError if it failed).

        :meth:`run` waits for it too.
        """
        deadline = time.monotonic() + timeout
        while not self.poll_ready(max(0.0, deadline - time.monotonic())):
            if time.monotonic() >= deadline:
                raise RuntimeError(f"the {self._proc.name} worker process did not start "
                                   f"within {timeout:.0f} s")

    @property
    def pids(self) -> list[int]:
        """The worker process's id (the right camera's), as a list."""
        return [] if self._closed else [int(self._proc.pid)]

    def poll_ready(self, timeout: float = 0.0) -> bool:
        """Whether the worker is ready, waiting at most ``timeout`` s for its answer.

        A live node polls it from a timer and subscribes to images once it is true (it keeps
        answering its services meanwhile).  RuntimeError if the worker failed to start.
        """
        if self._started:
            return True
        proc = self._proc
        try:
            if not self._conn.poll(timeout):
                return False
            status, value = self._conn.recv()
        except (EOFError, OSError):
            raise RuntimeError(f"the {proc.name} worker process ended while starting "
                               f"(exit code {proc.exitcode})") from None
        if status == "error":
            raise RuntimeError(f"the {proc.name} worker process failed to start: "
                               f"{value}") from value
        self._started = True
        return True

    def run(self, images: tuple[np.ndarray, np.ndarray], cameras: tuple[Any, Any],
            jobs: tuple[CameraJob, CameraJob], classifier: Classifier,
            left_carry: LabelCarry) -> tuple[CameraResult, CameraResult]:
        """Both cameras' halves of one frame, computed side by side.

        The left half runs here with ``classifier`` and ``left_carry`` (the caller's, as in
        process), exactly as the worker runs the right one with its own.  An error of either
        half is raised once both have ended (the worker's pipe stays in step).
        """
        if self._closed or self._result is None:
            raise RuntimeError("the camera processes were closed")
        self.wait_ready()
        conn, proc, result = self._conn, self._proc, self._result
        if cameras[1] is not self._camera:
            conn.send(("camera", cameras[1]))
            self._camera = cameras[1]
        block = self._image_block(images[1].nbytes)
        np.copyto(np.ndarray(images[1].shape, np.uint8, buffer=_view(block)), images[1])
        conn.send(("frame", (jobs[1], block.name, result.name)))
        left: CameraResult | None = None
        error: BaseException | None = None
        try:
            left = _half(images[0], jobs[0], cameras[0], classifier, left_carry)
        except Exception as exc:          # raised once the worker has answered
            error = exc
        try:
            status, value = conn.recv()
        except (EOFError, OSError):
            raise RuntimeError(f"the {proc.name} worker process ended (exit code "
                               f"{proc.exitcode})") from None
        if status == "error":
            error = error or value
        if error is not None:
            raise error
        assert left is not None
        return left, pickle.loads(value if status == "inline" else _view(result)[:value])

    def _image_block(self, size: int) -> SharedMemory:
        """The worker's image block, made (again) when an image does not fit."""
        block = self._image
        if block is None or block.size < size:
            if block is not None:
                block.close()
                block.unlink()
            block = self._image = SharedMemory(create=True, size=size)
        return block

    def forget(self) -> None:
        """Nothing carried to the next frame: the worker forgets its camera's labels.

        The caller forgets the left camera's (its own label carry).
        """
        if not self._closed:
            self._conn.send(("forget", None))

    def close(self) -> None:
        """Stop the worker (it also ends when this process does)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._conn.send(("stop", None))
        except (OSError, ValueError):
            pass
        self._conn.close()
        self._proc.join(timeout=2.0)
        if self._proc.is_alive():
            self._proc.terminate()
        for block in (self._image, self._result):
            if block is not None:
                block.close()
                block.unlink()
        self._image = self._result = None
