"""Mindlin's partial-slip field of a Hertz contact, fitted over a grid of (a, c) (no rclpy).

The model of :mod:`.slip`: with P applied and Q rising, the traction of a Hertz contact is
a pressure p0 sqrt(1 - r^2/a^2) and the tangential traction
mu p0 / a [sqrt(a^2 - r^2) - sqrt(c^2 - r^2)] (K.L. Johnson, Contact Mechanics, 1985,
section 7.2), both Hertz-shaped, so the contact's displacement is

    u = alpha R_a + beta (T_a - (c/a) T_c),   alpha = -p0, beta = mu p0,

with R_s, T_s the responses to unit-peak Hertz pressure and tangential traction of radius s
(:mod:`.hertz_response`).  :class:`HertzBases` evaluates them at the cells, weighted per
component; :class:`MindlinGrid` fits (alpha, beta) for every pair (a, c) of a grid of radii
by linear least squares from one Gram matrix, picks the pair of least residual and refines
it with a quadric through its 3 x 3 neighbourhood.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_sl_decoder.touch.hertz_response import HertzResponse


class HertzBases:
    """Weighted surface responses of Hertz-profile tractions at a set of cells.

    Vectors are flattened (M, 3) arrays (x, y, z per cell), the z component multiplied by
    its least-squares weight relative to x and y, ``normal_weight`` (noise in x, y over
    noise in z).
    """

    def __init__(self, response: HertzResponse, normal_weight: float) -> None:
        self.response = response
        self.wz = float(normal_weight)

    @staticmethod
    def angles(d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, ...]:
        """cos, sin, cos 2, sin 2 of every cell's angle around the centre.

        All zero at the centre itself, where every angular term's radial factor vanishes.
        """
        inv = 1.0 / np.maximum(r, 1e-12)
        cos, sin = d[:, 0] * inv, d[:, 1] * inv
        return cos, sin, cos * cos - sin * sin, 2.0 * sin * cos

    def pressure(self, f: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
        """(n, 3M) responses to unit-peak Hertz pressures (traction q_z = +w).

        ``f`` (n, 4, M): the radial functions A, B, C, D of n radii at the cells.
        """
        C, D = f[:, 2], f[:, 3]
        out = np.empty((f.shape[0], f.shape[2], 3))
        out[..., 0] = C * cos
        out[..., 1] = C * sin
        out[..., 2] = D * self.wz
        return out.reshape(f.shape[0], -1)

    def tangential(self, f: np.ndarray, e: np.ndarray, angles: tuple[np.ndarray, ...]
                   ) -> np.ndarray:
        """(n, 3M) responses to unit-peak Hertz tractions along the unit vector ``e``.

        e_x (A - B cos 2, -B sin 2, -C cos) + e_y (-B sin 2, A + B cos 2, -C sin).
        """
        cos, sin, cos2, sin2 = angles
        A, B, C = f[:, 0], f[:, 1], f[:, 2]
        out = np.empty((f.shape[0], f.shape[2], 3))
        out[..., 0] = e[0] * A - B * (e[0] * cos2 + e[1] * sin2)
        out[..., 1] = e[1] * A - B * (e[0] * sin2 - e[1] * cos2)
        out[..., 2] = C * (-self.wz * (e[0] * cos + e[1] * sin))
        return out.reshape(f.shape[0], -1)

    def three(self, d: np.ndarray, table: np.ndarray) -> np.ndarray:
        """Pressure, x- and y-tangential responses (3, 3N) of one table radius.

        ``d`` (N, 2): the points relative to the centre of the traction; ``table`` the
        radius's index (a one-element array).
        """
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        A, B, C, D = self.response.sample(r, table)[0]
        cos, sin, cos2, sin2 = self.angles(d, r)
        wz = self.wz
        out = np.empty((3, len(r), 3))
        out[0, :, 0], out[0, :, 1], out[0, :, 2] = C * cos, C * sin, wz * D
        out[1, :, 0], out[1, :, 1], out[1, :, 2] = A - B * cos2, -B * sin2, -wz * C * cos
        out[2, :, 0], out[2, :, 1], out[2, :, 2] = -B * sin2, A + B * cos2, -wz * C * sin
        return out.reshape(3, -1)


@dataclass
class MindlinFit:
    """The best (a, c) of a grid, refined, and the fit at its grid pair."""

    a: float                  # m, contact radius (refined)
    c: float                  # m, stick radius (refined, 0 <= c <= a)
    p0: float                 # Pa, pressure peak (> 0)
    q_over_p: float           # |Q| / P of the fitted tractions, signed along the direction
    basis: np.ndarray         # (2, 3M) pressure and tangential term of the grid pair
    coef: np.ndarray          # (alpha, beta) of the grid pair


def parabola_vertex(r_minus: float, r0: float, r_plus: float) -> float:
    """Offset (-1..1 steps) of the vertex of the parabola through three residuals."""
    den = r_minus - 2.0 * r0 + r_plus
    if not math.isfinite(den) or den <= 0:
        return 0.0
    return min(max(float(0.5 * (r_minus - r_plus) / den), -1.0), 1.0)   # NaN stays NaN


_DI, _DJ = (v.ravel() for v in np.mgrid[-1:2, -1:2])
_QUADRIC = np.column_stack([np.ones(9), _DI, _DJ, _DI ** 2, _DJ ** 2, _DI * _DJ])
_QUADRIC_PINV = np.linalg.pinv(_QUADRIC)


def refine(grid: np.ndarray, i: int, j: int, i_lo: int, i_hi: int) -> tuple[float, float]:
    """Sub-step offsets (di, dj) of the residual's minimum around grid pair (i, j).

    A quadric fitted by least squares to the 3 x 3 neighbourhood (the residual is even in c,
    so c = -1 step mirrors c = 1 step; rows outside the a candidates are left out): its
    stationary point when it is a minimum within one step (the residual's valley is diagonal
    in (a, c), which separate parabolas miss); otherwise a parabola along c.
    """
    rows = i + _DI
    cols = np.abs(j + _DJ)
    ok = (rows >= i_lo) & (rows <= i_hi) & (cols < grid.shape[1])
    z = np.full(9, np.inf)
    z[ok] = grid[rows[ok], cols[ok]]
    ok &= np.isfinite(z)
    if ok.sum() >= 7:
        coef = (_QUADRIC_PINV @ (z - z[4]) if ok.all()
                else np.linalg.lstsq(_QUADRIC[ok], z[ok] - z[4], rcond=None)[0])
        h = np.array([[2 * coef[3], coef[5]], [coef[5], 2 * coef[4]]])
        if h[0, 0] > 0 and np.linalg.det(h) > 0:
            d = -np.linalg.solve(h, coef[1:3])
            if np.all(np.abs(d) <= 1.0):
                return float(d[0]), float(d[1])
    dj = parabola_vertex(z[3], z[4], z[5]) if np.isfinite(z[3]) and np.isfinite(z[5]) else 0.0
    return 0.0, dj


class MindlinGrid:
    """Least-squares fits of Mindlin's field over a grid of (a, c) pairs."""

    def __init__(self) -> None:
        self._pairs: dict[tuple[int, int], tuple[Any, ...]] = {}

    def fit(self, u: np.ndarray, x: np.ndarray, i_lo: int, i_hi: int, step: float
            ) -> MindlinFit | None:
        """The best pair of the grid, refined; None when no pair fits a pressing contact.

        ``u`` (3M,) the weighted displacements; ``x`` the weighted pressure responses of
        radii ``i_lo`` .. ``i_hi`` (index times ``step``, m), then the tangential ones of
        radii 0 .. ``i_hi`` + 1 (c may exceed a by one step, so that a stick disc filling
        the contact has a minimum to refine; c is then clamped to a).
        """
        na = i_hi - i_lo + 1
        gram = x @ x.T
        xu = x @ u
        uu = float(u @ u)
        ia, jc, rows, w, force_share, gather = self._pair_terms(i_lo, i_hi)
        pp, t, i11, i12, i22, ww = gather
        flat = gram.ravel()
        a11 = flat[i11]
        a12 = (w * flat[i12]).sum(axis=0)
        a22 = (ww * flat[i22]).sum(axis=(0, 1))
        b1 = xu[pp]
        b2 = (w * xu[t]).sum(axis=0)
        det = a11 * a22 - a12 * a12
        with np.errstate(divide="ignore", invalid="ignore"):
            alpha = (a22 * b1 - a12 * b2) / det
            beta = (a11 * b2 - a12 * b1) / det
            res = uu - (alpha * b1 + beta * b2)
        res = np.where((det > 1e-12 * a11 * np.maximum(a22, 1e-300)) & np.isfinite(res),
                       res, np.inf)
        best = int(np.argmin(res))
        if not math.isfinite(float(res[best])) or not alpha[best] < 0:
            return None
        grid = np.full((i_hi + 1, i_hi + 2), np.inf)
        grid[ia, jc] = res
        i, j = int(ia[best]), int(jc[best])
        di, dj = refine(grid, i, j, i_lo, i_hi)
        a = (i + di) * step
        p0 = -float(alpha[best])
        basis = np.stack([x[i - i_lo], w[:, best] @ x[na + rows[:, best]]])
        return MindlinFit(a=a, c=min(max((j + dj) * step, 0.0), a), p0=p0,
                          q_over_p=float(beta[best]) * float(force_share[best]) / p0,
                          basis=basis, coef=np.array([alpha[best], beta[best]]))

    def _pair_terms(self, i_lo: int, i_hi: int) -> tuple[Any, ...]:
        """The (a, c) pairs of a grid and their tangential terms (cached per grid).

        Pairs c = jc <= a = ia + 1 with a a candidate (ia >= i_lo).  The tangential term
        T_a - (c/a) T_c is written sum_m w_m T_m over three rows; at c = a it vanishes with
        the slip annulus, so there it is replaced by its limit divided by 1 - (c/a)^3,
        (T_a + a dT/da) / 3, the derivative by central difference.  ``force_share`` is
        sum_m w_m (s_m / a)^2, the share of the Hertz force 2 pi a^2 / 3 (per unit peak) the
        term carries: 1 - (c/a)^3 for a regular pair, 1 at c = a.
        """
        key = (i_lo, i_hi)
        if key not in self._pairs:
            ia, jc = np.tril_indices(i_hi + 1, 1, i_hi + 2)
            keep = ia >= i_lo
            ia, jc = ia[keep], jc[keep]
            k = jc / ia
            edge = jc == ia
            rows = np.stack([ia, jc, ia])
            w = np.stack([np.ones(len(ia)), -k, np.zeros(len(ia))])
            rows[:, edge] = np.stack([ia[edge], ia[edge] + 1, ia[edge] - 1])
            w[:, edge] = np.stack([np.full(edge.sum(), 1.0 / 3.0), ia[edge] / 6.0,
                                   -ia[edge] / 6.0])
            force_share = np.einsum("mp,mp->p", w, (rows / ia) ** 2)
            # flat indices into the Gram matrix of [P_lo .. P_hi, T_0 .. T_hi+1]
            na, size = i_hi - i_lo + 1, 2 * i_hi - i_lo + 3
            pp, t = ia - i_lo, na + rows
            gather = (pp, t, pp * size + pp, pp * size + t,
                      t[:, None] * size + t[None, :], w[:, None] * w[None, :])
            if len(self._pairs) > 64:
                self._pairs.clear()
            self._pairs[key] = (ia, jc, rows, w, force_share, gather)
        return self._pairs[key]
