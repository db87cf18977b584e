"""Surface traction from measured displacements: the linear-elastic inverse problem.

Forward model (pad frame): the displacement of reference cell i is
u_i = sum_j G(r_i - r_j) f_j, where f_j (N) is the force the object exerts on cell j, spread
uniformly over the cell, and G the surface Green's function of the elastomer
(:func:`tactile_sl_common.elasticity.cell_kernel`: Boussinesq-Cerruti for a half-space,
the bonded layer's Fourier-domain compliance for ``thickness > 0``).  Every reference cell
carries three unknowns; the system is square and solved by Tikhonov regularisation,
f = (G^T G + a s I)^-1 G^T u with s = mean(diag G^T G) (Hansen, Rank-Deficient and Discrete
Ill-Posed Problems, SIAM 1998, eq. 5.1), in two strengths, both pre-factorised at tare so
that a frame costs two matrix-vector products:

* **Resultant** (``wrench_weight`` a_w = 1e-3): the resultant force and moment are linear
  functionals of f, so they come from one 6 x 3N matrix.  A weak weight keeps them
  unbiased: the whole displacement field, far field included, is fitted (on the simulated
  scenes the resultant is within 1 % for 0.05-2 N, and 2 mN on an untouched pad with 3 um
  displacement noise).
* **Map** (``map_weight`` a_m = 1): per-cell traction for the ``field`` cloud and the
  contact state's forces and centroids.  Per cell, the weakly regularised solution is
  dominated by noise; the strong weight trades resolution (about one cell) for a clean map.
  The map is restricted to the contact support (cells pressing by more than
  ``support_fraction`` of the peak and ``support_floor``, grown by one cell), pulling cells
  are set to zero (pressure is non-negative), and the map is scaled so that its sums equal
  the resultant.

* **Support** (``support_weight`` a_s = 1e-2): the normal traction near the contact, constrained
  to press (p >= 0), whose support gives the contact area for any indenter (:mod:`.support`).
  The unconstrained solution's normal rows are pre-computed like the map's; the constraint is
  met by an active set on the pre-computed inverse: with the cells N held at zero,
  p = p0 + M[:, N] nu and M[N, N] nu = -p0[N], M = ((G^T G + a_s s I)^-1)_zz, releasing a cell
  whose multiplier nu pulls and holding one that would pull (Lawson and Hanson, Solving Least
  Squares Problems, 1974, ch. 23, in the dual form), so a frame costs one product over the
  cells near the contact and a few solves of the size of the cells held.  a_s from 1e-3 to
  1e-2 gives areas within 15 % on the simulated shapes (sphere, flat punch, cylinder, two
  contacts); 1e-1 smooths the edge away (a flat punch +24 to +69 %).

The weights were chosen on simulated Hertz contacts (docs/touch.md): a_w from 1e-5 to 1e-2
gives the same half-space resultant within 0.1 % but a_w >= 1e-2 biases the stiffer 2 mm
layer by 5-50 %; a_m = 1 gives the best contact areas (within about 20 %) with the contact
rule of :func:`~tactile_sl_decoder.touch.contact.contact_state`.  Reference cells not
decoded in a frame get their displacement from decoded neighbours (normalised
convolution) before the products.
"""
from __future__ import annotations

import dataclasses
import functools
import sys
from dataclasses import dataclass

import cv2
import numpy as np

from tactile_sl_common.elasticity import Elastomer, cell_kernel
from tactile_sl_decoder.cpu_threads import single_blas_thread
from tactile_sl_decoder.touch import cholesky
from tactile_sl_decoder.touch.cholesky import cho_factor_upper, cho_solve_upper
from tactile_sl_decoder.touch.solver_cache import SolverCache, entry_key, source_digest
from tactile_sl_decoder.touch.support import constrained_edge


@dataclass
class TractionParams:
    """Weights and thresholds of the inversion (see the module docstring)."""

    wrench_weight: float = 1e-3      # a_w: Tikhonov weight of the resultant (x mean diag)
    map_weight: float = 1.0          # a_m: Tikhonov weight of the per-cell map
    support_fraction: float = 0.05   # support: pressing force > this x the peak cell ...
    support_floor: float = 5e-5      # ... and > this, N per cell
    support_weight: float = 1e-2     # a_s: the constrained inversion for the contact area;
                                     # 0 = none (area from the map's threshold alone)

    def validate(self) -> "TractionParams":
        """Raise ValueError for values outside their ranges."""
        for name in ("wrench_weight", "map_weight"):
            value = getattr(self, name)
            if not 0 < value < 1e3:
                raise ValueError(f"{name} must be in (0, 1e3), got {value}")
        if not 0 <= self.support_weight < 1e3:
            raise ValueError(f"support_weight must be in [0, 1e3), got {self.support_weight}")
        if not 0 <= self.support_fraction < 1:
            raise ValueError(f"support_fraction must be in [0, 1), got {self.support_fraction}")
        if self.support_floor < 0:
            raise ValueError(f"support_floor must be >= 0, got {self.support_floor}")
        return self


# The area threshold is chosen per solver from these (fractions of a region's peak), on
# Hertz discs of these radii (m) pushed through the forward model (see _area_fraction).
AREA_FRACTIONS = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35)
TEST_RADII = (2e-3, 3e-3, 4e-3)
_STORED = ("scale", "wrench_rows", "map_0", "map_1", "map_2", "area_fraction",
           "support_rows", "support_inverse")


@functools.cache
def _code_digest() -> str:
    """The source of the code an inversion comes from (part of its cache key)."""
    return source_digest(sys.modules[__name__], cholesky)


def _runs(values: np.ndarray, max_step: int = 1) -> list[tuple[int, int]]:
    """(first, last + 1) index pairs of the runs of sorted ``values`` stepping <= ``max_step``."""
    if len(values) == 0:
        return []
    cut = (np.flatnonzero(np.diff(values) > max_step) + 1).tolist()
    return list(zip([0] + cut, cut + [len(values)]))


def _rows_product(matrix: np.ndarray, rows: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``(matrix[rows] @ vector)`` in float64 without copying the rows (sorted, unique).

    One product per run of consecutive rows (the cells of one grid row near a contact): the
    rows are read in place, and rows between the runs (between two contacts) not at all.
    """
    out = np.empty(len(rows))
    for start, stop in _runs(rows):
        out[start:stop] = matrix[rows[start]:rows[stop - 1] + 1] @ vector
    return out


def _band_rows(matrix: np.ndarray, start: int, stop: int, rows: np.ndarray,
               vector: np.ndarray) -> np.ndarray:
    """``(matrix[start:stop] @ vector)[rows]``, the same bits, reading only the rows needed.

    ``rows`` (sorted, unique) count from ``start``.  OpenBLAS's gemv computes a product's rows
    four at a time and its last ``len % 4`` rows by a remainder kernel: a row gets the same
    bits from any product in which it falls in a block of four, and a remainder row from any
    product that ends with the same remainder after at least one block.  So the blocks of
    the band holding ``rows`` are read (runs of them, one product per run), and its remainder
    once with the block before it: on the 60 Hz press the contact's cells are a third of the
    band between its first and last.  Where a BLAS build computes otherwise
    (:func:`_blocks_are_exact`), the band's product as it is.
    """
    body = (stop - start) - (stop - start) % 4
    if body == 0 or not _blocks_are_exact(matrix.shape[1], matrix.dtype.str):
        return (matrix[start:stop] @ vector)[rows]
    out = np.empty(len(rows), np.result_type(matrix, vector))
    inside = np.flatnonzero(rows < body)
    block = rows[inside] // 4
    # one product per run of blocks (gaps of one block are read through: a call costs about
    # what two rows do)
    for first, last in _runs(block, max_step=2):
        b0 = int(block[first])
        seg = matrix[start + 4 * b0:start + 4 * (int(block[last - 1]) + 1)] @ vector
        out[inside[first:last]] = seg[rows[inside[first:last]] - 4 * b0]
    tail = np.flatnonzero(rows >= body)
    if len(tail):
        seg = matrix[start + body - 4:stop] @ vector
        out[tail] = seg[rows[tail] - body + 4]
    return out


@functools.cache
def _blocks_are_exact(width: int, dtype: str) -> bool:
    """Whether :func:`_band_rows`' products give this BLAS's band product bit for bit.

    Checked once per process and matrix width, on random bands and rows of a random matrix.
    """
    rng = np.random.default_rng(0)
    matrix = rng.standard_normal((61, width)).astype(dtype)
    for _ in range(12):
        vector = rng.standard_normal(width).astype(dtype)
        start = int(rng.integers(0, 20))
        stop = int(rng.integers(start + 4, 62))
        rows = np.flatnonzero(rng.random(stop - start) < 0.4)
        want = (matrix[start:stop] @ vector)[rows]
        body = (stop - start) - (stop - start) % 4
        got = np.empty(len(rows), want.dtype)
        for i, t in enumerate(rows):            # every row from its own block, or the tail
            lo = start + 4 * (t // 4) if t < body else start + body - 4
            hi = lo + 4 if t < body else stop
            got[i] = (matrix[lo:hi] @ vector)[start + t - lo]
        if not np.array_equal(got, want):
            return False
    return True


class TractionSolver:
    """Per-cell forces from per-cell displacements, for one reference cell set."""

    def __init__(self, elastomer: Elastomer, pitch: float, shape: tuple[int, int],
                 cells: np.ndarray, params: TractionParams | None = None,
                 mirrored: bool = False, cache: SolverCache | None = None) -> None:
        """Prepare the inversion for ``cells``; ``cache``: read it from there, or store it.

        An entry of the cache holds the very arrays computed here (:mod:`.solver_cache`),
        so a solver read back gives the same bytes as one computed.
        """
        self.params = (params or TractionParams()).validate()
        self.shape = (int(shape[0]), int(shape[1]))
        self.cells = np.asarray(cells, np.int64)          # flat indices row * cols + col
        self.rows = self.cells // self.shape[1]
        self.cols = self.cells % self.shape[1]
        n = len(self.cells)
        kernel = cell_kernel(elastomer, pitch, *self.shape)
        self._kernel = kernel
        self._g32_made: np.ndarray | None = None
        self._grid_index = np.full(self.shape, -1, np.int64)
        self._grid_index[self.rows, self.cols] = np.arange(n)
        self.last_support = np.zeros(n, bool)
        # Resultant: rows sum fx, fy, fz and the moments r x f about the pad origin (z = 0).
        x = (self.cols - (self.shape[1] - 1) / 2.0) * pitch * (-1.0 if mirrored else 1.0)
        y = (self.rows - (self.shape[0] - 1) / 2.0) * pitch
        key = None
        if cache is not None:
            settings = {"elastomer": dataclasses.asdict(elastomer), "pitch": float(pitch),
                        "shape": list(self.shape), "mirrored": bool(mirrored),
                        "params": dataclasses.asdict(self.params)}
            key = entry_key(kernel, self.cells, settings, _code_digest())
            stored = cache.load(key, _STORED)
            if stored is not None:
                self._install(stored)
                return
        with single_blas_thread():        # the same bytes in any process (cache key)
            g = self._forward()
            self._install(self._invert(g, x, y))
            self.area_fraction = self._area_fraction(g, x, y, pitch)
        if cache is not None and key is not None:
            cache.store(key, self._stored())

    def _forward(self) -> np.ndarray:
        """G (3N, 3N) float64: G[3i + a, 3j + b] = u_a at cell i per unit f_b on cell j."""
        n = len(self.cells)
        dr = self.rows[:, None] - self.rows[None, :] + self.shape[0] - 1
        dc = self.cols[:, None] - self.cols[None, :] + self.shape[1] - 1
        return self._kernel[dr, dc].transpose(0, 2, 1, 3).reshape(3 * n, 3 * n)

    @property
    def _g32(self) -> np.ndarray:
        """G in float32, the forward model of fit residuals (calibration, noisy pads).

        Made on first use: an inversion read back from the cache needs no G, and building
        it (38 MB for 728 cells) took half of a start's reference preparation, in the
        thread beside the node's frames.
        """
        if self._g32_made is None:
            self._g32_made = self._forward().astype(np.float32)
        return self._g32_made

    def _invert(self, g: np.ndarray, x: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
        """The regularised inverses (resultant, map and, if wanted, support rows).

        With ``support_weight`` > 0 also the constrained inversion's normal rows and the
        normal block of its inverse (:meth:`support_pressure`).
        """
        n = len(self.cells)
        h = g.T @ g
        scale = float(np.mean(np.diag(h)))
        eye = scale * np.eye(3 * n)
        s: np.ndarray = np.zeros((6, n, 3))  # per point, then flattened to (6, 3n)
        s[0, :, 0] = s[1, :, 1] = s[2, :, 2] = 1.0
        s[3, :, 2] = y                     # Mx = sum y fz
        s[4, :, 2] = -x                    # My = -sum x fz
        s[5, :, 0], s[5, :, 1] = -y, x     # Mz = sum x fy - y fx
        s = s.reshape(6, 3 * n)
        # (the factorisations release the GIL: touch/cholesky.py; a node prepares this in a
        # worker thread while frames keep coming)
        fw = cho_factor_upper(h + self.params.wrench_weight * eye)
        wrench_rows = cho_solve_upper(fw, s.T).T @ g.T
        fm = cho_factor_upper(h + self.params.map_weight * eye)
        full = cho_solve_upper(fm, g.T)
        # One contiguous matrix per force component: the normal one finds the support, the
        # tangential ones are then needed only on its rows (the map is memory-bound).
        arrays: dict[str, np.ndarray] = {
            f"map_{axis}": np.ascontiguousarray(full[axis::3], dtype=np.float32)
            for axis in range(3)}
        arrays.update(scale=np.array(scale), wrench_rows=wrench_rows,
                      area_fraction=np.array(np.nan),
                      support_rows=np.zeros((0, 0), np.float32),
                      support_inverse=np.zeros((0, 0)))
        if self.params.support_weight > 0:
            fs = (fw if self.params.support_weight == self.params.wrench_weight
                  else cho_factor_upper(h + self.params.support_weight * eye))
            unit = np.zeros((3 * n, n))
            unit[2::3] = np.eye(n)
            columns = cho_solve_upper(fs, unit)        # (Q^-1)[:, z]: Q symmetric
            # pressing p = -f_z = -(Q^-1 G^T u)_z, one row per cell
            arrays["support_rows"] = np.ascontiguousarray(-(columns.T @ g.T),
                                                          dtype=np.float32)
            arrays["support_inverse"] = np.ascontiguousarray(columns[2::3])
        return arrays

    def _install(self, arrays: dict[str, np.ndarray]) -> None:
        self.scale = float(arrays["scale"])
        self._wrench_rows = np.asarray(arrays["wrench_rows"], np.float64)
        # standard deviation of (M_x, M_y) per metre of i.i.d. displacement noise
        self.moment_noise = (float(np.linalg.norm(self._wrench_rows[3])),
                             float(np.linalg.norm(self._wrench_rows[4])))
        self._map_rows = [np.ascontiguousarray(arrays[f"map_{axis}"], dtype=np.float32)
                          for axis in range(3)]
        self._near: tuple[np.ndarray, np.ndarray] | None = None   # last frame: u32, window
        # the constrained inversion for the contact area (empty arrays: none prepared)
        support_rows = np.asarray(arrays["support_rows"], np.float32)
        self._support_rows: np.ndarray | None = (
            np.ascontiguousarray(support_rows) if support_rows.size else None)
        self._support_inverse = np.ascontiguousarray(arrays["support_inverse"], np.float64)
        # N of pressure per metre of i.i.d. displacement noise, per cell (from the stored
        # float32 rows, so the same bytes whether computed or read back)
        self.support_gain = (np.linalg.norm(support_rows.astype(np.float64), axis=1)
                             if support_rows.size else np.zeros(len(self.cells)))
        self.area_fraction = float(arrays["area_fraction"])

    def _stored(self) -> dict[str, np.ndarray]:
        arrays: dict[str, np.ndarray] = {f"map_{axis}": rows
                                         for axis, rows in enumerate(self._map_rows)}
        arrays.update(scale=np.array(self.scale), wrench_rows=self._wrench_rows,
                      area_fraction=np.array(self.area_fraction),
                      support_rows=(self._support_rows if self._support_rows is not None
                                    else np.zeros((0, 0), np.float32)),
                      support_inverse=self._support_inverse)
        return arrays

    # ------------------------------------------------------------------ helpers

    def normal_force_row(self) -> np.ndarray:
        """(3N,): the resultant's F_z as a functional of the displacement."""
        return self._wrench_rows[2]

    def moment_rows(self) -> np.ndarray:
        """(2, 3N): the resultant's M_x and M_y as functionals of the displacement."""
        return self._wrench_rows[3:5]

    def support_pressure_rows(self) -> np.ndarray | None:
        """(N, 3N) float32: each cell's constrained-inversion pressure per displacement."""
        return self._support_rows

    def normal_forward(self) -> np.ndarray:
        """(N, N) float32: u_z of each cell per unit normal force on each (G's zz block)."""
        return self._g32[2::3, 2::3]

    def normal_map_rows(self) -> np.ndarray:
        """(N, 3N) float32: each cell's normal map force (-pressing) per displacement."""
        return self._map_rows[2]

    def fill_missing(self, disp: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Displacement with missing cells filled from decoded neighbours (step 1 only)."""
        if valid.all():
            return disp
        grid = np.zeros(self.shape + (3,), np.float32)
        weight = np.zeros(self.shape, np.float32)
        grid[self.rows[valid], self.cols[valid]] = disp[valid]
        weight[self.rows[valid], self.cols[valid]] = 1.0
        out = disp.copy()
        todo = ~valid
        for _ in range(4):              # normalised convolution, growing into larger holes
            num = cv2.blur(grid, (3, 3), borderType=cv2.BORDER_CONSTANT)
            den = cv2.blur(weight, (3, 3), borderType=cv2.BORDER_CONSTANT)
            r, c = self.rows[todo], self.cols[todo]
            ok = den[r, c] > 1e-6
            idx = np.flatnonzero(todo)[ok]
            out[idx] = num[r[ok], c[ok]] / den[r[ok], c[ok], None]
            grid[r[ok], c[ok]] = out[idx]
            weight[r[ok], c[ok]] = 1.0
            todo[idx] = False
            if not todo.any():
                break
        out[todo] = 0.0
        return out

    def linear_products(self, u: np.ndarray, u32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The two products every frame needs: resultant (6,) and normal pressure map (N,).

        ``u`` is the flattened (3N,) displacement in float64 and ``u32`` the same in float32
        (the map is stored in float32: it is memory-bound).  Everything else :meth:`solve`
        does is per support cell; ``tools/bench_pipeline.py`` times these as the floor.
        """
        return self._wrench_rows @ u, self._normal_map(u32)

    def _normal_map(self, u32: np.ndarray) -> np.ndarray:
        """Each cell's pressing normal map force (N,), float64, of a float32 displacement."""
        return -(self._map_rows[2] @ u32).astype(np.float64)

    def solve(self, disp: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-cell forces (N, 3) N and the resultant (6,) = (F, M about the pad origin).

        ``disp`` (N, 3) m at the reference cells; ``valid`` marks those decoded in this
        frame (the others are filled from their neighbours).  The per-cell forces are zero
        outside the contact support, never pull (f_z <= 0) and sum to the resultant force.
        :meth:`resultant`, then :meth:`forces` (a caller may leave the second for later).
        """
        wrench, u, u32 = self.resultant(disp, valid)
        return self.forces(u, u32, wrench)[0], wrench

    def resultant(self, disp: np.ndarray, valid: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The resultant (6,) and the filled displacement, (3N,) float64 and float32.

        One product of six rows: all a frame's wrench needs.
        """
        disp = self.fill_missing(np.asarray(disp, np.float64), np.asarray(valid, bool))
        u = disp.reshape(-1)
        return self._wrench_rows @ u, u, u.astype(np.float32)

    def forces(self, u: np.ndarray, u32: np.ndarray, wrench: np.ndarray
               ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """Per-cell forces (N, 3) of :meth:`resultant`'s outputs, and their window.

        The window (``u32`` and the cells near the contact map, None without a map) is what
        :meth:`support_pressure` works on.
        """
        press = self._normal_map(u32)
        n = len(self.cells)
        forces = np.zeros((n, 3))
        self.last_support = np.zeros(n, bool)
        self._near = None
        peak = float(press.max()) if n else 0.0
        threshold = max(self.params.support_floor, self.params.support_fraction * peak)
        core = press > threshold
        if wrench[2] >= 0.0 or not core.any():   # nothing presses overall: no contact map
            return forces, None
        grid: np.ndarray = np.zeros(self.shape, np.uint8)
        grid[self.rows[core], self.cols[core]] = 1
        grid = cv2.dilate(grid, np.ones((3, 3), np.uint8))
        near = grid[self.rows, self.cols].astype(bool)
        keep = np.flatnonzero(near & (press > 0.0))
        self.last_support[keep] = True
        self._near = (u32, np.flatnonzero(near))
        forces[keep, 2] = -press[keep] * (-wrench[2] / press[keep].sum())
        weight = forces[keep, 2] / forces[keep, 2].sum()
        start, stop = int(keep[0]), int(keep[-1]) + 1   # cells are row-major: views, no copy
        for axis in (0, 1):
            shear = _band_rows(self._map_rows[axis], start, stop, keep - start,
                               u32).astype(np.float64)
            forces[keep, axis] = shear + (wrench[axis] - shear.sum()) * weight
        return forces, self._near

    @property
    def has_support(self) -> bool:
        """The constrained inversion is prepared (``support_weight`` > 0)."""
        return self._support_rows is not None

    def support_pressure(self, noise: float, sigmas: float, min_snr: float,
                         max_rounds: int = 30, cell_noise: np.ndarray | None = None,
                         window: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> np.ndarray | None:
        """Normal pressure (N per cell, >= 0) near the last frame's contact, constrained.

        The cells where it is wanted and held >= 0 are those of the last :meth:`solve`'s
        map support (zero elsewhere); ``noise`` (m per axis) gives each cell's noise,
        ``noise`` x :attr:`support_gain`, and the cells held are those next to the cells that
        press by ``sigmas`` x their noise.  None without a contact map, without the
        constrained inversion, or when no cell presses by ``min_snr`` x its noise before the
        constraint (the support could not locate an edge: the area comes from the map; this
        also spares the active set on faint, wide contacts, whose window is the largest).
        The active set is :func:`~tactile_sl_decoder.touch.support.constrained_edge`
        (compiled); after ``max_rounds`` a cell still pulling is clipped to zero.
        ``cell_noise`` (N,): each cell's noise (N) instead of ``noise`` x
        :attr:`support_gain` (the cells' own expected errors: :mod:`.weights`).
        ``window``: a frame's window from :meth:`forces` (default: the last one's), so that
        the pressure of a frame can be made after later frames were solved.
        """
        near = self._near if window is None else window
        if self._support_rows is None or near is None or len(near[1]) == 0:
            return None
        u32, near_cells = near
        free = _rows_product(self._support_rows, near_cells, u32)
        spread = (noise * self.support_gain[near_cells] if cell_noise is None
                  else cell_noise[near_cells])
        if not np.any(free > min_snr * spread):
            return None
        out = np.zeros(len(self.cells))
        # only cells at the edge of those that clearly press are held (one cell either side):
        # noise pulling farther away is left as it is (those cells do not press anyway), and
        # the inside of a contact presses clearly
        clear = free > sigmas * spread
        p = constrained_edge(free, clear, self.rows[near_cells], self.cols[near_cells],
                             self.shape[0], self.shape[1], self._support_inverse, near_cells,
                             int(max_rounds))
        out[near_cells] = np.maximum(p, 0.0)
        return out

    def _area_fraction(self, g: np.ndarray, x: np.ndarray, y: np.ndarray,
                       pitch: float) -> float:
        """The fraction of a region's peak above which a cell counts into the contact area.

        The map is sharper or blurrier depending on the elastomer (a half-space's kernel is
        long and smooth, a thin layer's short) and on the pitch, so the threshold is
        calibrated for this solver: Hertz discs (``TEST_RADII``, at the centre of the
        reference cells) go through the forward model G and this solver, and the fraction
        (``AREA_FRACTIONS``) with the smallest worst relative area error is kept.  Noise is
        left out: it only adds a symmetric scatter.
        """
        sub = (np.arange(6) + 0.5) / 6 - 0.5
        sx = x[:, None, None] + sub[None, :, None] * pitch - x.mean()
        sy = y[:, None, None] + sub[None, None, :] * pitch - y.mean()
        worst = np.zeros(len(AREA_FRACTIONS))
        valid = np.ones(len(x), bool)
        for radius in TEST_RADII:
            w = np.sqrt(np.clip(1.0 - (sx ** 2 + sy ** 2) / radius ** 2, 0.0, None)).mean(
                axis=(1, 2))
            if w.sum() <= 0:
                continue
            f = np.zeros((len(x), 3))
            f[:, 2] = -w / w.sum()
            forces, _ = self.solve((g @ f.reshape(-1)).reshape(-1, 3), valid)
            press = -forces[:, 2]
            if press.max() <= 0:
                continue
            true_cells = np.pi * radius ** 2 / pitch ** 2
            cells = np.array([(press > fr * press.max()).sum() for fr in AREA_FRACTIONS])
            worst = np.maximum(worst, np.abs(cells / true_cells - 1.0))
        self.last_support = np.zeros(len(x), bool)
        return float(AREA_FRACTIONS[int(np.argmin(worst))])

    def map_residual(self, disp: np.ndarray, valid: np.ndarray, forces: np.ndarray) -> float:
        """||G f - u|| / ||u|| over the decoded cells: how well forces explain a field."""
        pred = (self._g32 @ forces.astype(np.float32).reshape(-1)).reshape(-1, 3)
        u = np.asarray(disp)[valid]
        norm = float(np.linalg.norm(u))
        return float(np.linalg.norm(pred[valid] - u)) / norm if norm > 0 else 0.0
