"""Slip: how close the contact pressing hardest is to sliding, from its displacement field.

Under a tangential load Q rising at constant normal load P, a Hertz contact of radius a
sticks in a central disc of radius c and slides in the annulus around it, with
c / a = (1 - |Q| / (mu P))^(1/3) (Cattaneo-Mindlin; K.L. Johnson, Contact Mechanics, 1985,
section 7.2), until it slides as a whole at |Q| = mu P (gross slip).  Mindlin's tangential
traction is mu p0 / a [sqrt(a^2 - r^2) - sqrt(c^2 - r^2)] (the second term inside c only):
two Hertz-shaped terms, so the displacement field of the contact is

    u = alpha R_a + beta (T_a - (c/a) T_c)

with R_s, T_s the pad's responses to a unit-peak Hertz pressure and tangential traction of
radius s (:mod:`.hertz_response`, the same elastic model the traction inversion uses),
alpha = -p0 (pressing) and beta = mu p0 along the slip direction.  The stick disc moves
rigidly (the two terms' curvatures cancel inside c) and the annulus lags behind it: that
shape, sampled at every decoded cell with a known material identity, tells c / a.

Estimate, per frame (no rclpy):

1. the contact pressing hardest: of the 8-connected sets of cells of the traction map
   pressing by more than the contact state's area fraction of the peak, the one with the
   largest force; its force-weighted centre and a first radius sqrt(area / pi); the
   decoded cells within ``window`` radii of the centre;
2. its centre and tangential direction: a least-squares fit of a pressure and two
   tangential (x, y) Hertz terms at the first radius, with one Gauss-Newton step on the
   centre (the map's centroid moves with the tangential load); a tangential amplitude below
   ``tangential_fraction`` of the normal one means no tangential load (stick, margin 1);
3. a and c on a grid of radii (:mod:`.mindlin_fit`): for every pair c <= a the two
   amplitudes (alpha, beta) by weighted linear least squares (one Gram matrix of all terms
   for the whole grid), the pair of least residual, refined by a quadric through the
   residuals of its 3 x 3 neighbourhood;
4. stick ratio (c/a)^2, slip margin (c/a)^3 = 1 - |Q|/(mu P), Q/P = beta (1 - (c/a)^3) /
   p0 (the fitted tractions' sums), mu = (Q/P) / (1 - (c/a)^3) once a slip annulus is seen
   (stick ratio <= ``slip_seen``), gross slip when the margin is <= ``gross_margin``;
5. other contacts: each is modelled as Hertz pressure and tangential terms of its own size
   with free amplitudes, projected out of the data and of every basis before 2. and 3.

Where it stops being valid (docs/slip.md): non-spherical contacts (a flat punch's or a
cylinder's pressure is not Hertzian), torsion (a twist adds a circumferential traction),
several contacts (the others' fields leak into the window: they are modelled as Hertz terms
of their own size with free amplitudes and projected out, which removes most of it; the
strongest is still measured, less accurately), unloading and reversals of Q
(Mindlin-Deresiewicz: the traction then depends on the loading history, which a single
frame does not show), and normal loads changing while Q rises.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_NO_CONTACT, SLIP_PARTIAL, SLIP_STICK
from tactile_sl_decoder.touch.hertz_response import HertzResponse, hertz_response
from tactile_sl_decoder.touch.mindlin_fit import (
    HertzBases,
    MindlinFit,
    MindlinGrid,
    parabola_vertex,
)

STATE_NAMES = {SLIP_NO_CONTACT: "none", SLIP_STICK: "stick", SLIP_PARTIAL: "partial",
               SLIP_GROSS: "gross"}
NAN = float("nan")
HERTZ_FORCE = 2.0 * math.pi / 3.0   # integral of sqrt(1 - r^2/a^2) over the disc, over a^2
MAX_CONTACTS = 4                    # the other contacts modelled in the window: at most 3


def _identity(v: np.ndarray) -> np.ndarray:
    return v


@dataclass
class SlipParams:
    """Settings of the slip estimate (lengths in pitches or contact radii, as named)."""

    window: float = 1.3            # fit cells within this x the first contact radius
    radius_range: tuple[float, float] = (0.7, 1.3)   # a candidates, x the first radius
    radius_step: float = 0.25      # pitches between table radii ...
    radii_per_contact: float = 12.0  # ... of which every n-th is a candidate, n such that
                                     # about this many fit in the first contact radius
    max_radius: float = 12.0       # pitches: largest first contact radius measured
    tangential_fraction: float = 0.02   # |Q| / P below this: no tangential load
    slip_seen: float = 0.85        # stick ratio at or below which the slip annulus is seen
    gross_margin: float = 0.05     # slip margin at or below which the contact slides
    noise_tangential: float = 1e-6  # m, displacement noise in x, y (least-squares weight)
    noise_normal: float = 3e-6     # m, displacement noise in z
    min_cells: int = 12            # fewer decoded cells in the window: not measured
    max_cells: int = 240           # more: every other cell (checkerboard) is fitted

    def validate(self) -> "SlipParams":
        """Raise ValueError for values outside their ranges."""
        lo, hi = self.radius_range
        if not 0 < lo < 1 < hi:
            raise ValueError(f"radius_range must be (lo, hi) with 0 < lo < 1 < hi, got "
                             f"{self.radius_range}")
        if not 1 < self.window <= 4:
            raise ValueError(f"window must be in (1, 4], got {self.window}")
        if not 0.05 <= self.radius_step <= 1:
            raise ValueError(f"radius_step must be in [0.05, 1] pitches, got "
                             f"{self.radius_step}")
        if not 4 <= self.radii_per_contact <= 64:
            raise ValueError(f"radii_per_contact must be in [4, 64], got "
                             f"{self.radii_per_contact}")
        if not 1 < self.max_radius <= 64:
            raise ValueError(f"max_radius must be in (1, 64] pitches, got {self.max_radius}")
        if not 0 < self.tangential_fraction < 1:
            raise ValueError("tangential_fraction must be in (0, 1)")
        if not 0 < self.slip_seen < 1 or not 0 <= self.gross_margin < 1:
            raise ValueError("slip_seen must be in (0, 1) and gross_margin in [0, 1)")
        if self.noise_tangential <= 0 or self.noise_normal <= 0:
            raise ValueError("noise_tangential and noise_normal must be > 0")
        if self.min_cells < 4:
            raise ValueError(f"min_cells must be >= 4, got {self.min_cells}")
        if self.max_cells < 2 * self.min_cells:
            raise ValueError(f"max_cells must be >= 2 min_cells, got {self.max_cells}")
        return self


@dataclass
class SlipEstimate:
    """The contract's Slip message (pad frame, SI) plus what the estimate saw."""

    state: int = SLIP_NO_CONTACT
    stick_ratio: float = NAN
    margin: float = NAN
    friction: float = NAN
    direction: tuple[float, float, float] = (0.0, 0.0, 0.0)
    centroid: tuple[float, float, float] = (0.0, 0.0, 0.0)
    contact_radius: float = NAN     # m, a
    stick_radius: float = NAN       # m, c
    normal_force: float = NAN       # N, P of the fitted pressure
    tangential_force: float = NAN   # N, |Q| of the fitted tangential traction
    fit_residual: float = NAN       # m, RMS of the fit's residual over the window's cells
    cells: int = 0                  # decoded cells in the window

    @property
    def state_name(self) -> str:
        return STATE_NAMES.get(self.state, str(self.state))


class SlipEstimator:
    """Slip of the contact pressing hardest, per frame, for one elastomer and pitch."""

    def __init__(self, elastomer: Elastomer, pitch: float,
                 params: SlipParams | None = None) -> None:
        self.params = (params or SlipParams()).validate()
        self.pitch = float(pitch)
        p = self.params
        step = p.radius_step * self.pitch
        max_radius = p.max_radius * self.pitch
        self.response: HertzResponse = hertz_response(
            elastomer, step, max_radius * p.radius_range[1], max_radius * p.window)
        w = np.array([1.0 / p.noise_tangential, 1.0 / p.noise_tangential, 1.0 / p.noise_normal])
        self._weights = w * p.noise_tangential   # relative: the x, y weights are 1
        self._bases = HertzBases(self.response, float(self._weights[2]))
        self._grid = MindlinGrid()

    # ------------------------------------------------------------------ estimate

    def estimate(self, rest_xy: np.ndarray, displacement: np.ndarray, pressing: np.ndarray,
                 in_contact: bool, area_fraction: float,
                 lattice: np.ndarray | None = None) -> SlipEstimate:
        """Slip of the contact pressing hardest, from the decoded cells of one frame.

        ``rest_xy`` (M, 2) rest positions, ``displacement`` (M, 3) and ``pressing`` (M,)
        the normal force (N, >= 0 pressing) of the decoded cells (pad frame, m);
        ``in_contact`` the frame's contact state's (it gates the estimate);
        ``area_fraction`` the share of the peak above which a cell counts into a contact;
        ``lattice`` (M, 2) the cells' integer (column, row), from their rest positions if
        not given.
        Never raises on a frame's data: no contact gives ``SLIP_NO_CONTACT`` with NaN, a
        contact with too few decoded cells around it (e.g. mostly off the pad) gives
        ``SLIP_STICK`` with NaN margin and stick ratio.
        """
        if not in_contact:
            return SlipEstimate()
        p = self.params
        rest = np.asarray(rest_xy, np.float64)
        if lattice is None:
            lattice = self._lattice(rest)
        contacts = self._contacts(rest, np.asarray(pressing, np.float64), area_fraction,
                                  np.asarray(lattice))
        if not contacts:
            return SlipEstimate()
        centre, area = contacts[0]
        first = max(math.sqrt(area / math.pi), 2 * self.response.step)
        out = SlipEstimate(state=SLIP_STICK, centroid=(float(centre[0]), float(centre[1]), 0.0))
        # candidate radii: every stride-th table radius, about radii_per_contact per radius
        stride = max(1, round(first / (p.radii_per_contact * self.response.step)))
        step = stride * self.response.step
        n_max = (self.response.tables.shape[0] - 1) // stride + 1
        i_lo = max(2, int(math.floor(p.radius_range[0] * first / step)))
        i_hi = min(n_max - 2, int(math.ceil(p.radius_range[1] * first / step)))
        reach = min(p.window * first, self.response.max_distance)
        d = rest - centre
        good = (np.einsum("ij,ij->i", d, d) < reach * reach) & np.isfinite(displacement).all(1)
        out.cells = int(good.sum())
        if out.cells < p.min_cells or i_hi <= i_lo:
            return out
        if out.cells > p.max_cells:   # a large contact: half its cells carry the information
            good &= (lattice[:, 0] + lattice[:, 1]) % 2 == 0
        rest = rest[good]
        u = (np.asarray(displacement, np.float64)[good] * self._weights).ravel()
        # the other contacts' fields leak into the window: modelled as Hertz pressure and
        # tangential (x, y) terms of their own size, with free amplitudes, and projected
        # out of the data and of every basis (the same least squares as fitting them too)
        project = self._others(rest, contacts[1:])
        u = project(u)
        # 2. centre and direction: pressure + tangential x, y at the first radius
        i_first = min(max(round(first / step), i_lo), i_hi)   # (np.clip: 30 us on a scalar)
        first_table = np.array([stride * i_first])
        fitted = self._first_fit(rest, centre, u, first_table, project)
        if fitted is None:
            return out
        centre, coef, x3 = fitted
        out.centroid = (float(centre[0]), float(centre[1]), 0.0)
        alpha0, beta0 = float(coef[0]), coef[1:3]
        q_over_p = float(np.hypot(*beta0)) / max(-alpha0, 1e-300)
        if not alpha0 < 0 or not math.isfinite(q_over_p):
            return out                              # no pressing Hertz contact to fit
        d = rest - centre
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        f = self.response.sample(r, stride * np.arange(i_hi + 2))    # (i_hi + 2, 4, M)
        angles = self._bases.angles(d, r)
        pressure = project(self._bases.pressure(f[i_lo:i_hi + 1], *angles[:2]))
        if q_over_p < p.tangential_fraction:
            return self._normal_only(out, u, pressure, i_lo, step)
        e = beta0 / np.hypot(*beta0)
        # 3. the (a, c) grid: x = P_lo..hi, T_0..hi+1
        x = np.concatenate([pressure, project(self._bases.tangential(f, e, angles))])
        fit = self._grid.fit(u, x, i_lo, i_hi, step)
        return out if fit is None else self._figures(out, fit, u, e)

    def _figures(self, out: SlipEstimate, fit: MindlinFit, u: np.ndarray, e: np.ndarray
                 ) -> SlipEstimate:
        """4.: stick ratio, margin, mu, forces, direction and state of the best pair."""
        p = self.params
        ratio = fit.c / fit.a
        out.contact_radius, out.stick_radius = fit.a, fit.c
        out.stick_ratio, out.margin = ratio * ratio, ratio ** 3
        out.normal_force = HERTZ_FORCE * fit.a * fit.a * fit.p0
        out.tangential_force = abs(fit.q_over_p) * out.normal_force
        sign = 1.0 if fit.q_over_p >= 0 else -1.0
        out.direction = (float(sign * e[0]), float(sign * e[1]), 0.0)
        out.fit_residual = self._rms(u, fit.basis, fit.coef)
        if out.margin <= p.gross_margin:
            out.state = SLIP_GROSS
        elif out.stick_ratio <= p.slip_seen:
            out.state = SLIP_PARTIAL
        if out.state != SLIP_STICK:
            out.friction = abs(fit.q_over_p) / max(1.0 - out.margin, 1e-9)
        return out

    def _others(self, rest: np.ndarray, others: list[tuple[np.ndarray, float]]
                ) -> Callable[[np.ndarray], np.ndarray]:
        """The projection removing the other contacts' Hertz terms from weighted vectors."""
        if not others:
            return _identity
        n = self.response.tables.shape[0]
        terms = [self._bases.three(rest - c, np.array([int(np.clip(
            round(math.sqrt(area / math.pi) / self.response.step), 1, n - 1))]))
            for c, area in others]
        q, _ = np.linalg.qr(np.concatenate(terms).T)     # (3M, 3k) orthonormal

        def project(v: np.ndarray) -> np.ndarray:
            return v - (v @ q) @ q.T
        return project

    def _lattice(self, rest: np.ndarray) -> np.ndarray:
        """(M, 2) integer column and row of every cell, counted from the first decoded ones."""
        return np.rint((rest - rest.min(axis=0)) / self.pitch).astype(np.int64)

    def _contacts(self, rest: np.ndarray, pressing: np.ndarray, fraction: float,
                  lattice: np.ndarray) -> list[tuple[np.ndarray, float]] | None:
        """Centre (force-weighted) and area of each contact, the one pressing hardest first.

        Contacts are the 8-connected sets of cells pressing by more than ``fraction`` of
        the peak (the contact state's area rule); the traction map's low skirt can join two
        contacts into one region of the contact state, this level keeps them apart.  At
        most ``MAX_CONTACTS``; None when nothing presses.
        """
        if len(pressing) == 0 or not np.isfinite(pressing).all():
            return None
        peak = float(pressing.max())
        if peak <= 0:
            return None
        strong = pressing > fraction * peak
        grid = np.zeros((int(lattice[:, 1].max()) + 1, int(lattice[:, 0].max()) + 1), np.uint8)
        grid[lattice[strong, 1], lattice[strong, 0]] = 1
        count, labels = cv2.connectedComponents(grid, connectivity=8)
        label = np.where(strong, labels[lattice[:, 1], lattice[:, 0]], 0)
        force = np.bincount(label, weights=pressing, minlength=count)
        force[0] = 0.0
        contacts = []
        for k in np.argsort(-force)[:MAX_CONTACTS]:
            if force[k] <= 0:
                break
            sel = label == k
            w = pressing[sel]
            contacts.append(((w @ rest[sel]) / w.sum(), float(sel.sum()) * self.pitch ** 2))
        return contacts

    def _first_fit(self, rest: np.ndarray, centre: np.ndarray, u: np.ndarray,
                   table: np.ndarray, project: Callable[[np.ndarray], np.ndarray]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Centre, (alpha, beta_x, beta_y) and the bases (at the first centre) at one radius.

        The contact state's centroid comes from the traction map, which a tangential load
        shifts (on a thin layer by a tenth of a millimetre), so the centre is refined with
        the fit: one Gauss-Newton step on the centre and the amplitudes, the model's
        derivatives by forward differences.
        """
        h = 0.05 * self.pitch
        d = rest - centre
        # the bases at the centre and at the centre moved by h along x and along y, at once
        three = self._bases.three(np.concatenate([d, d - (h, 0.0), d - (0.0, h)]), table)
        three = project(three.reshape(9, -1)).reshape(3, 3, -1)   # (basis, centre, 3M)
        x3 = three[:, 0]
        try:
            coef = np.linalg.solve(x3 @ x3.T, x3 @ u)
            if coef[0] < 0:
                model = coef @ x3
                grads = (np.einsum("b,bkm->km", coef, three[:, 1:]) - model) / h
                jac = np.concatenate([x3, grads])
                step = np.linalg.solve(jac @ jac.T, jac @ u)
                centre = centre + np.clip(step[3:], -self.pitch, self.pitch)
                coef = step[:3]
        except np.linalg.LinAlgError:
            return None
        return centre, coef, x3

    def _normal_only(self, out: SlipEstimate, u: np.ndarray, pressure: np.ndarray,
                     i_lo: int, step: float) -> SlipEstimate:
        """No tangential load: stick, margin 1; the contact radius from the pressure alone."""
        pu = pressure @ u
        pp = np.einsum("ij,ij->i", pressure, pressure)
        res = np.where(pu < 0, float(u @ u) - pu * pu / pp, np.inf)
        best = int(np.argmin(res))
        if not math.isfinite(float(res[best])):
            return out
        di = 0.0
        if 0 < best < len(res) - 1:
            di = parabola_vertex(float(res[best - 1]), float(res[best]),
                                 float(res[best + 1]))
        a = (i_lo + best + di) * step
        alpha = float(pu[best] / pp[best])
        out.stick_ratio, out.margin = 1.0, 1.0
        out.contact_radius = out.stick_radius = a
        out.normal_force = HERTZ_FORCE * a * a * -alpha
        out.tangential_force = 0.0
        out.fit_residual = self._rms(u, pressure[best:best + 1], np.array([alpha]))
        return out

    def _rms(self, u: np.ndarray, basis: np.ndarray, coef: np.ndarray) -> float:
        """RMS (m) of the unweighted residual of a fit over the window's cells."""
        resid = (u - coef @ basis).reshape(-1, 3) / self._weights
        return float(np.sqrt(np.mean(resid * resid)))
