"""The touch stage: one frame's decoded points in; displacement, forces, contact out.

It also gives the wrench, the depth map and the slip estimate (:mod:`.slip`); no rclpy,
used by the decoder node and ``tactile-sl replay`` alike, so both give the same bytes.

Life cycle: the first ``reference_frames`` frames that decode build the reference (the pad
must be untouched); :meth:`TouchStage.tare` starts a new one, refused while the pad is
visibly touched.  Until a reference exists :meth:`TouchStage.update` returns None.

Preparing a reference (pad pose, the elastic inversion pre-factorised for its cells, the
area threshold) takes ~1-2 s for 700-840 cells on one core.  Offline it runs in line, so
every frame after the reference frames has outputs; a live node passes ``background=True``:
the preparation runs in a worker thread (LAPACK releases the GIL) while frames keep flowing,
instead of the camera stream stalling for a second at start.  Frames that arrive meanwhile
wait in a bounded queue (``TouchParams.max_pending_frames``) and get their outputs, in
order, as soon as the reference is ready (:meth:`TouchStage.drain`): no decoded frame after
the reference frames goes without touch outputs, it only comes late.  The inversion is kept
on disk (:mod:`.solver_cache`): when a restarted node's reference has the same cells as one
before, it is read back in ~0.1 s.  A tare whose new
reference holds the same cells as the last one reuses the last inversion (it depends on the
cells only, not on where they are), so it is ready at the frame that completes it.
"""
from __future__ import annotations

import dataclasses
import functools
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from tactile_sl_common.elasticity import check_layer_resolved
from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.touch.consistent import ConsistentField, for_reference
from tactile_sl_decoder.touch.contact import (
    ContactParams,
    ContactState,
    DepthMapper,
    contact_hysteresis,
    contact_state,
    depth_grid,
    without_ripples,
)
from tactile_sl_decoder.touch.reference import (
    PadPose,
    ReferenceBuilder,
    fit_pad_pose,
    nominal_positions,
)
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.slip import SlipEstimate, SlipEstimator, SlipParams
from tactile_sl_decoder.touch.solver_cache import SolverCache
from tactile_sl_decoder.touch.traction import TractionParams, TractionSolver
from tactile_sl_decoder.touch.weights import (
    CellWeights,
    ReferenceNoise,
    WeightParams,
    reference_noise,
)


@dataclass
class TouchParams:
    """Settings of the touch stage (the decoder node exposes them as parameters)."""

    reference_frames: int = 1
    """Decoded frames averaged into the untouched reference (at start and after each
    tare)."""
    traction: TractionParams = field(default_factory=TractionParams)
    contact: ContactParams = field(default_factory=ContactParams)
    slip: SlipParams = field(default_factory=SlipParams)
    weights: WeightParams = field(default_factory=WeightParams)
    tare_max_depth: float = 5e-5
    """m: a tare is refused while the pad is pressed in deeper than this (or in contact)"""
    max_pending_frames: int = 300
    """Frames kept while a new reference is prepared in the background (about 1-2 s at
    start, or after a tare that changes the reference's cells); they get their touch
    outputs, late, once it is ready. Beyond this many the oldest are dropped (counted in
    diagnostics)."""
    solver_cache: bool = True
    """Keep each reference's inversion on disk and read it back when a reference of the
    same cells on the same pad comes again (a restart: ~0.1 s instead of ~1-2 s)."""
    solver_cache_dir: str = ""
    """Directory of the stored inversions; empty = $XDG_CACHE_HOME/tactile_sl/traction
    (~/.cache/tactile_sl/traction). At most 8 are kept, ~20-40 MB each."""

    def validate(self) -> "TouchParams":
        """Raise ValueError for values outside their ranges (:data:`TOUCH_SETTINGS`)."""
        TOUCH_SETTINGS.check(self)
        self.traction.validate()
        self.contact.validate()
        self.slip.validate()
        self.weights.validate()
        return self


TOUCH_SETTINGS = SettingsTable(
    TouchParams, ranges={"reference_frames": (1, 1000), "tare_max_depth": (1e-7, 0.01),
                         "max_pending_frames": (0, 100000)},
    read_only=("reference_frames", "max_pending_frames", "solver_cache", "solver_cache_dir"))
"""The decoder node's ``reference_frames``, ``tare_max_depth``, ``max_pending_frames`` and
``solver_cache(_dir)``."""


@dataclass
class Reference:
    """The untouched pad: which cells, where (pad frame), and the pad pose."""

    cells: np.ndarray        # (N,) flat cell indices row * cols + col
    rest: np.ndarray         # (N, 3) reference positions, pad frame
    pose: PadPose
    frames: int
    nominal: np.ndarray      # (N, 3) nominal rest positions (z = 0): where tractions act
    weights: CellWeights | None
    """each cell's expected displacement error and the cleaning (:mod:`.weights`); None
    with the weights off"""
    noise: ReferenceNoise
    """what those errors give the resultant's moments, the map and the contact area"""
    consistent: ConsistentField | None = None
    """the normal displacement fitted by the contact's pressure (:mod:`.consistent`); only
    on a pad where most cells are noisy"""


@dataclass
class TouchResult:
    """Touch outputs of one stereo frame (pad frame, SI).

    The per-cell forces, the contact state and the depth map are made on first use, from
    what the frame left (a live node publishes ``field``, ``contact`` and ``depth`` only
    while something subscribes to them, as it builds every output; ``tactile-sl replay``
    writes them all, with the same bytes): ~2 of a frame's 2.1 ms on the 60 Hz press, ~4.6
    of 5 ms on two_contacts. The resultant and ``in_contact`` (the force hysteresis of the
    contact state) are made at once.
    """

    rows: np.ndarray           # (M,) cells decoded in this frame
    cols: np.ndarray
    position: np.ndarray       # (M, 3) current positions
    displacement: np.ndarray   # (M, 3) from the reference
    force_of: Callable[[], np.ndarray] = field(repr=False, compare=False)
    """The frame's per-cell forces (:meth:`~.traction.TractionSolver.forces`)."""
    wrench_force: np.ndarray   # (3,) N
    wrench_moment: np.ndarray  # (3,) N m about the pad origin
    in_contact: bool           # the contact state's in_contact
    contact_of: Callable[[], ContactState] = field(repr=False, compare=False)
    """The frame's contact state (:func:`~.contact.contact_state` on the frame's data)."""
    indent: np.ndarray         # (rows, cols) m of indentation per cell, NaN where not decoded
    depth_of: Callable[[np.ndarray], np.ndarray] = field(repr=False, compare=False)
    """The depth map of ``indent`` (:class:`~.contact.DepthMapper` of the stage)."""
    timings_ms: dict[str, float] = field(default_factory=dict)
    """ms per part; the time of the forces and of the contact state is added to
    ``traction``, ``contact`` and ``touch`` when they are made"""
    slip: SlipEstimate | None = field(default_factory=SlipEstimate)
    """Of the contact pressing hardest; None where it was not estimated (nobody asked:
    :attr:`TouchStage.slip_wanted`)."""

    def add_time(self, part: str, ms: float) -> None:
        """Count ``ms`` to ``part`` and to the whole touch stage."""
        for key in (part, "touch"):
            self.timings_ms[key] = self.timings_ms.get(key, 0.0) + ms

    @functools.cached_property
    def force(self) -> np.ndarray:
        """(M, 3) N on each decoded cell."""
        start = time.perf_counter()
        out = self.force_of()
        self.add_time("traction", 1e3 * (time.perf_counter() - start))
        return out

    @functools.cached_property
    def contact(self) -> ContactState:
        """The contact state (normal and shear force, area, centroid, depth, regions)."""
        _ = self.force           # its time counts to traction
        start = time.perf_counter()
        state = self.contact_of()
        self.add_time("contact", 1e3 * (time.perf_counter() - start))
        return state

    @functools.cached_property
    def depth(self) -> np.ndarray:
        """(H, W) float32 m of indentation on the depth grid, NaN where not decoded."""
        return self.depth_of(self.indent)


def _always() -> bool:
    return True


class _Preparation:
    """A reference being prepared in a worker thread: its result or its exception."""

    def __init__(self, work: Any) -> None:
        self.result: Any = None
        self.error: BaseException | None = None
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(work,), daemon=True,
                                       name="touch-reference")
        self.thread.start()

    def _run(self, work: Any) -> None:
        try:
            self.result = work()
        except BaseException as exc:   # re-raised in the frame thread by take()
            self.error = exc
        finally:
            self.done.set()

    def take(self) -> Any:
        """The result (or raise what the work raised); only once ``done`` is set."""
        if self.error is not None:
            raise self.error
        return self.result


class TouchStage:
    """Keeps the reference and turns each frame's points into touch outputs."""

    def __init__(self, sensor: SensorConfig, shape: tuple[int, int], pitch: float,
                 mirrored: bool = False, params: TouchParams | None = None,
                 background: bool = False) -> None:
        if pitch <= 0:
            raise ValueError(f"the pattern's pitch must be > 0 for touch outputs, got {pitch}")
        try:    # at load, not when the first reference is prepared
            check_layer_resolved(sensor.elastomer, pitch)
        except ValueError as exc:
            raise ValueError(f"{sensor.source}: {exc}") from None
        self.sensor = sensor
        self.shape = (int(shape[0]), int(shape[1]))
        self.pitch = float(pitch)
        self.mirrored = bool(mirrored)
        self.params = (params or TouchParams()).validate()
        self.depth_grid = depth_grid(self.shape, self.pitch, self.params.contact.depth_upsample,
                                     self.mirrored)
        self._depth = DepthMapper(self.shape, self.params.contact.depth_upsample, self.mirrored)
        # response tables of the elastomer: built once per pad (cached), ~10-50 ms
        self.slip = SlipEstimator(sensor.elastomer, self.pitch, self.params.slip)
        # whether a frame's slip is estimated (~0.5 ms of a frame's touch stage): always,
        # unless a node asks only while something subscribes to it
        self.slip_wanted: Callable[[], bool] = _always
        self.reference: Reference | None = None
        self.solver: TractionSolver | None = None
        self._area_fraction = 0.0        # the solver's choice, set with each reference
        self._builder = ReferenceBuilder(self.params.reference_frames, self.shape)
        self.background = bool(background)
        self._preparing: _Preparation | None = None
        # frames (tag, points) that came while the reference was prepared in the background,
        # and their outputs once it is ready, until drain() hands them out
        self._pending: deque[tuple[Any, np.ndarray]] = deque()
        self._caught_up: list[tuple[Any, TouchResult]] = []
        self.pending_dropped = 0       # queued frames dropped: the queue was full
        self._in_contact = False
        self._last: TouchResult | None = None
        self._last_solve: tuple[np.ndarray, np.ndarray, Callable[[], Any]] | None = None
        self._index = np.full(self.shape[0] * self.shape[1], -1, np.int64)
        self._last_solver: TractionSolver | None = None
        self.solver_cache = (SolverCache(self.params.solver_cache_dir or None)
                             if self.params.solver_cache else None)
        all_rows, all_cols = np.divmod(np.arange(self.shape[0] * self.shape[1]), self.shape[1])
        # rest position of every cell: the reference's where it has one, else the nominal
        self._rest_table = nominal_positions(all_rows, all_cols, self.shape, self.pitch,
                                             self.mirrored)

    @property
    def last_solve(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The last frame's (disp (N, 3), valid (N,), forces (N, 3)) per reference cell.

        Its displacement, which cells it decoded and its forces: the force calibration's
        input (the forces are made here if nothing asked for them yet).
        """
        if self._last_solve is None:
            return None
        disp, valid, solved = self._last_solve
        return disp, valid, solved()[0]

    # ------------------------------------------------------------------ reference

    @property
    def ready(self) -> bool:
        """A reference exists and frames produce touch outputs."""
        return self.reference is not None

    def tare(self) -> tuple[bool, str]:
        """Start a new reference from the next frames; refused while visibly touched."""
        last = self._last
        if last is not None and (last.in_contact
                                 or last.contact.max_depth > self.params.tare_max_depth):
            return False, (f"refused: the pad is touched (normal force "
                           f"{last.contact.normal_force * 1e3:.1f} mN, indentation "
                           f"{last.contact.max_depth * 1e6:.0f} um); release it and tare again")
        self._builder = ReferenceBuilder(self.params.reference_frames, self.shape)
        self._preparing = None         # a preparation still running is dropped ...
        self._pending.clear()          # ... with the frames that waited for it
        self.reference = None
        if self.solver is not None:    # kept for a new reference of the same cells
            self._last_solver = self.solver
        self.solver = None
        self._last = None
        self._in_contact = False
        return True, (f"new reference from the next {self.params.reference_frames} decoded "
                      f"frame(s)")

    @property
    def preparing(self) -> bool:
        """The reference frames are in and the reference is being prepared (background)."""
        return self._preparing is not None

    def poll(self) -> bool:
        """Install a reference prepared in the background if it is done; True if it was.

        Called by :meth:`update`, and by a node's timer so that the reference is announced
        as soon as it is ready.  Raises ReferenceError if the reference is unusable.
        """
        if self._preparing is None or not self._preparing.done.is_set():
            return False
        preparing, self._preparing = self._preparing, None
        try:
            self._set_reference(preparing.take())
        except BaseException:
            self._pending.clear()          # their reference is unusable: nothing to give
            raise
        self._catch_up()
        return True

    def _catch_up(self) -> None:
        """Outputs of the frames that waited for the reference, in their order (drain())."""
        while self._pending:
            tag, points = self._pending.popleft()
            result = self._outputs(points)
            if result is not None:
                self._caught_up.append((tag, result))

    def drain(self, limit: int | None = None) -> list[tuple[Any, TouchResult]]:
        """(tag, outputs) of frames that waited for a reference prepared in the background.

        Filled when the reference is installed (:meth:`poll`, also called by
        :meth:`update`), oldest first; at most ``limit`` of them per call (a node publishes
        the backlog a few frames per wake-up, so that no subscriber's queue overflows).
        """
        count = len(self._caught_up) if limit is None else max(0, int(limit))
        out, self._caught_up = self._caught_up[:count], self._caught_up[count:]
        return out

    @property
    def caught_up(self) -> int:
        """Frames with outputs not yet handed out by :meth:`drain`."""
        return len(self._caught_up)

    @property
    def pending(self) -> int:
        """Frames waiting for the reference being prepared."""
        return len(self._pending)

    def _prepare_reference(self, cells: np.ndarray, mean: np.ndarray, frames: int,
                           solver: TractionSolver | None = None,
                           scatter: np.ndarray | None = None) -> tuple[Any, ...]:
        """The costly part of a new reference, touching no state of the stage.

        ``solver``: an inversion already made for exactly these cells (reused as it is);
        ``scatter``: the cells' variance over the reference frames (left optical frame).
        """
        rows, cols = cells // self.shape[1], cells % self.shape[1]
        nominal = nominal_positions(rows, cols, self.shape, self.pitch, self.mirrored)
        pose = fit_pad_pose(nominal, mean)
        rest = pose.to_pad(mean)
        # per-axis variances into the pad frame: the diagonal of R^T diag(v) R
        frame_variance = None if scatter is None else scatter @ pose.rotation ** 2
        if solver is None:
            solver = TractionSolver(self.sensor.elastomer, self.pitch, self.shape, cells,
                                    self.params.traction, self.mirrored, self.solver_cache)
        weights = (CellWeights(solver.rows, solver.cols, self.shape, rest, nominal, frames,
                               self.params.weights, frame_variance)
                   if self.params.weights.enabled else None)
        noise = reference_noise(weights, solver, self.params.contact.displacement_noise)
        consistent = for_reference(solver, weights, self.shape, nominal,
                                   self.params.contact.displacement_noise)
        return cells, rest, pose, frames, nominal, solver, weights, noise, consistent

    def _reusable_solver(self, cells: np.ndarray) -> TractionSolver | None:
        """The last reference's inversion if it was made for these very cells."""
        last = self._last_solver
        if last is None or not np.array_equal(last.cells, cells) or (
                last.params != self.params.traction):
            return None
        return last

    def _set_reference(self, prepared: tuple[Any, ...]) -> None:
        cells, rest, pose, frames, nominal, solver, weights, noise, consistent = prepared
        self.solver = solver
        self._area_fraction = solver.area_fraction
        self._index[:] = -1
        self._index[cells] = np.arange(len(cells))
        self._rest_table = nominal_positions(*np.divmod(np.arange(len(self._index)),
                                                        self.shape[1]),
                                             self.shape, self.pitch, self.mirrored)
        self._rest_table[cells] = rest
        self.reference = Reference(cells, rest, pose, frames, nominal, weights, noise,
                                   consistent)

    @property
    def contact_params(self) -> ContactParams:
        """The contact thresholds in force: ``params.contact`` as it is now.

        A live change applies from the next frame; the area fraction is the reference's
        solver's unless ``params.contact`` sets one.
        """
        contact = self.params.contact
        if contact.area_fraction or not self._area_fraction:
            return contact
        return dataclasses.replace(contact, area_fraction=self._area_fraction)

    def _frame_contact_params(self) -> ContactParams:
        """:attr:`contact_params` as a copy of its own.

        A frame's contact state may be made after a later live change (on first use), and
        must use the settings of its frame.
        """
        return dataclasses.replace(self.params.contact,
                                   area_fraction=self.contact_params.area_fraction)

    # ------------------------------------------------------------------ frames

    def update(self, points: np.ndarray, tag: Any = None) -> TouchResult | None:
        """Touch outputs of one frame's contract points (None while building a reference).

        While a reference is prepared in the background the frame is queued with its
        ``tag`` (e.g. its stamp) and None returned; its outputs come from :meth:`drain`.
        """
        if len(points) == 0:
            return None
        if self.reference is None and self._preparing is not None:
            if not self.poll():
                self._queue(tag, points)         # outputs once the reference is ready
                return None
        elif self.reference is None:
            rows = points["row"].astype(np.int64)
            cols = points["col"].astype(np.int64)
            xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)
            if self._builder.add(rows, cols, xyz):
                cells, mean = self._builder.result()
                frames = self._builder.collected
                scatter = self._builder.scatter(cells) if frames > 1 else None
                solver = self._reusable_solver(cells)
                if self.background and solver is None:
                    self._preparing = _Preparation(
                        lambda: self._prepare_reference(cells, mean, frames, None, scatter))
                else:
                    self._set_reference(self._prepare_reference(cells, mean, frames, solver,
                                                                scatter))
            return None
        return self._outputs(points)

    def _queue(self, tag: Any, points: np.ndarray) -> None:
        if self.params.max_pending_frames <= 0:
            self.pending_dropped += 1
            return
        while len(self._pending) >= self.params.max_pending_frames:
            self._pending.popleft()
            self.pending_dropped += 1
        self._pending.append((tag, points))

    def _outputs(self, points: np.ndarray) -> TouchResult | None:
        """Touch outputs of one frame against the installed reference.

        Made at once: the displacement, the resultant (one product of six rows) and
        ``in_contact``. The per-cell forces, the contact state and the depth map are made on
        first use (:class:`TouchResult`), each from this frame's data and settings.
        """
        if len(points) == 0:
            return None
        rows = points["row"].astype(np.int64)
        cols = points["col"].astype(np.int64)
        xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)
        ref = self.reference
        solver = self.solver
        assert solver is not None and ref is not None
        t0 = time.perf_counter()
        position = ref.pose.to_pad(xyz)
        flat = rows * self.shape[1] + cols
        k = self._index[flat]
        known = k >= 0
        # A cell missing from the reference is measured against its nominal rest position.
        displacement = position - self._rest_table[flat]
        n = len(ref.cells)
        disp_ref = np.zeros((n, 3))
        valid = np.zeros(n, bool)
        disp_ref[k[known]] = displacement[known]
        valid[k[known]] = True
        if ref.weights is not None and len(ref.weights.noisy):
            disp_ref = ref.weights.clean(solver.fill_missing(disp_ref, valid))
            displacement[known] = disp_ref[k[known]]
        t1 = time.perf_counter()
        wrench, u, u32 = solver.resultant(disp_ref, valid)
        # the per-cell forces and their window, made once when first asked for
        solved = functools.cache(lambda w=wrench: solver.forces(u, u32, w))
        self._last_solve = (disp_ref, valid, solved)
        t2 = time.perf_counter()
        params = self._frame_contact_params()
        ref_noise = ref.noise

        @functools.cache
        def support() -> tuple[np.ndarray, np.ndarray] | None:
            """The constrained pressure near the contact and its noise (:mod:`.support`)."""
            window = solved()[1]
            noise, cell_noise = params.displacement_noise, ref_noise.support
            pressure = solver.support_pressure(noise, params.support_sigmas,
                                               params.support_edge_snr, cell_noise=cell_noise,
                                               window=window)
            return None if pressure is None else (
                pressure, noise * solver.support_gain if cell_noise is None else cell_noise)

        scaled: np.ndarray | None = None        # the forces with a fitted normal force

        def forces_of() -> np.ndarray:
            return solved()[0] if scaled is None else scaled

        fit_centroid = None
        if ref.consistent is not None:
            # the normal displacement the contact's pressure explains (:mod:`.consistent`)
            forces_ref = solved()[0]
            found = support()
            if found is not None:
                core = found[0] > params.support_sigmas * found[1]
            else:
                press = -forces_ref[:, 2]
                peak = float(press.max()) if len(press) else 0.0
                core = press > params.area_fraction * peak if peak > 0 else (
                    np.zeros(n, bool))
                if ref_noise.map is not None:       # not the noise's scattered peaks
                    core = without_ripples(core, press, ref_noise.map, solver.rows,
                                           solver.cols, self.shape)
            # (a contact whose edge the support cannot locate: its pressure at half the
            # resolution, which the data cannot resolve finer; without a support inversion,
            # support_weight 0, per cell)
            fitted = ref.consistent.fit(disp_ref[:, 2], valid, core,
                                        coarse=found is None and solver.has_support)
            if fitted is not None:
                displacement[known, 2] = fitted[k[known]]
            normal = ref.consistent.normal_force(-float(wrench[2]))
            if normal is not None:
                # the normal force with the fitted pressure's; the resultant's line of action
                # (M_x, M_y scale with it) and the map's shares are kept
                scale = normal / -float(wrench[2])
                wrench = wrench.copy()
                wrench[2:5] *= scale
                scaled = forces_ref.copy()
                scaled[:, 2] *= scale
            fit_centroid = ref.consistent.last_centroid
        indent = np.full(self.shape, np.nan)
        indent[rows, cols] = -displacement[:, 2]
        was_in_contact = self._in_contact
        self._in_contact = contact_hysteresis(max(-float(wrench[2]), 0.0), was_in_contact,
                                              params)
        nominal_xy, shape, pitch = ref.nominal[:, :2], self.shape, self.pitch

        def contact(wrench: np.ndarray = wrench) -> ContactState:
            return contact_state(nominal_xy, solver.rows, solver.cols, forces_of(), wrench,
                                 shape, pitch, indent, was_in_contact, params,
                                 ref_noise.moment, support(), ref_noise.map,
                                 ref_noise.centroid, fit_centroid)

        def force() -> np.ndarray:
            out = np.zeros((len(rows), 3))
            out[known] = forces_of()[k[known]]
            return out

        t3 = time.perf_counter()
        result = TouchResult(rows, cols, position, displacement, force, wrench[:3],
                             wrench[3:], self._in_contact, contact, indent, self._depth,
                             {"displacement": 1e3 * (t1 - t0), "traction": 1e3 * (t2 - t1),
                              "contact": 1e3 * (t3 - t2), "slip": 0.0,
                              "touch": 1e3 * (t3 - t0)}, None)
        if self.slip_wanted():
            pressing = -result.force[:, 2]
            t4 = time.perf_counter()
            result.slip = self.slip.estimate(self._rest_table[flat, :2], displacement,
                                             pressing, self._in_contact,
                                             params.area_fraction,
                                             np.column_stack([cols, rows]))
            result.add_time("slip", 1e3 * (time.perf_counter() - t4))
        self._last = result
        return result
