"""Traction-driven contacts: known forces on the pad, their displacement field and ground truth.

A load contact is a disc of radius a on the pad surface at (x, y) carrying a known force
(fx, fy, fz) (N, pad frame, what the object exerts on the pad: fz < 0 presses) and a torque
mz (N m) about the disc's normal. Its traction (Pa) on the simulator's field grid:

* normal: p(r) = p0 sqrt(1 - r^2/a^2) (``hertz``, the pressure under a sphere: K.L. Johnson,
  Contact Mechanics, 1985, eq. 4.20) or uniform (``uniform``), scaled so that it sums to fz;
  or the pressure of a rigid indenter of another shape:

  - ``punch``: a flat-ended cylindrical punch of radius a, p(r) = p0 / sqrt(1 - r^2/a^2)
    (the axisymmetric pressure p0 (1 - r^2/a^2)^n with n = -1/2, which displaces the disc
    uniformly: Johnson 1985, chapter 3), infinite at the rim but integrable: each node
    of the field grid carries the profile's mean over its ring [r - h/2, r + h/2] (inside
    the disc), so the rim's singularity is resolved to the grid's spacing h;
  - ``cylinder``: a cylinder of length ``length`` lying on the pad along ``angle``, with
    rounded ends, p = p0 sqrt(1 - d^2/a^2) where d is the distance to its axis segment
    (across the axis the two-dimensional Hertz pressure of a cylinder, Johnson 1985,
    chapter 4, over a strip of half-width a; half discs at the ends). A long cylinder is a
    rounded edge pressed across the pad;
* tangential: the same profile scaled to (fx, fy) (the simplest load a sensor calibration
  cares about), or, with a friction coefficient (``friction`` > 0, Hertz only), the
  Cattaneo-Mindlin traction of partial or gross slip (:mod:`.friction`): a tangential load
  beyond mu P is not transmitted (the object slides);
* torsion: a circumferential traction q_theta = c r sqrt(1 - r^2/a^2) (``hertz``; c r for
  ``uniform``, rigid-rotation-like), scaled so that its moment about the centre is mz.

The scaling is done on the grid itself (sums over the nodes times the cell area), so the
field's traction carries exactly the requested force and moment. The displacement is the
elastic surface response of :mod:`tactile_sl_common.elasticity` (the same kernels the decoder
inverts), so a decoder that inverts them correctly recovers the loads.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from tactile_sl_common.clouds import FIELD_DTYPE, cloud_to_arrays
from tactile_sl_common.elasticity import Elastomer
from tactile_sl_sim.friction import (
    STATE_NO_CONTACT,
    STATE_PARTIAL_SLIP,
    ContactSlip,
    cattaneo_mindlin,
    slip_from_message,
    tangential_traction,
)

if TYPE_CHECKING:  # typing.TypeIs is Python 3.13; annotations are not evaluated at run time
    from typing_extensions import TypeIs

PROFILES = ("hertz", "uniform", "punch", "cylinder")
DEFAULT_ELASTOMER = Elastomer(youngs_modulus=3.0e5, poisson_ratio=0.49, thickness=0.0)


@dataclass
class LoadContact:
    """A disc (or a cylinder's strip) of known traction on the pad (m, N, N m; pad frame)."""

    radius: float = 0.004
    profile: str = "hertz"
    x: float = 0.0
    y: float = 0.0
    force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    torque: float = 0.0
    elastomer: Elastomer = DEFAULT_ELASTOMER
    friction: float = 0.0   # mu; 0 = no friction model (the tangential profile as above)
    length: float = 0.0     # m, ``cylinder`` only: length of its axis segment
    angle: float = 0.0      # rad, ``cylinder`` only: the axis' direction from the pad's x

    kind = "load"

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ValueError(f"unknown load profile {self.profile!r} "
                             f"(expected one of {', '.join(PROFILES)})")
        if not np.isfinite(self.radius) or self.radius <= 0:
            raise ValueError(f"load radius must be positive, got {self.radius}")
        f = np.asarray(self.force, dtype=np.float64)
        if f.shape != (3,) or not np.isfinite(f).all():
            raise ValueError(f"load force must be three finite numbers [fx, fy, fz], "
                             f"got {self.force!r}")
        if f[2] > 0:
            raise ValueError(f"load force fz must be <= 0 (a load presses; adhesion is not "
                             f"modelled), got {f[2]}")
        if not np.isfinite(self.torque):
            raise ValueError(f"load torque must be finite, got {self.torque}")
        if not isinstance(self.elastomer, Elastomer):
            raise ValueError("load elastomer must be an Elastomer")
        if not np.isfinite(self.friction) or self.friction < 0:
            raise ValueError(f"load friction must be a finite number >= 0, got {self.friction}")
        if self.friction > 0 and self.profile != "hertz":
            raise ValueError("load friction needs profile hertz (Cattaneo-Mindlin slip of a "
                             "Hertz contact)")
        if self.friction > 0 and self.torque != 0:
            raise ValueError("load friction with torque is not modelled (torsional slip)")
        if not (np.isfinite(self.length) and self.length >= 0 and np.isfinite(self.angle)):
            raise ValueError(f"load length must be a finite number >= 0 and angle finite, got "
                             f"{self.length} and {self.angle}")
        if self.length > 0 and self.profile != "cylinder":
            raise ValueError(f"load length is the axis of profile cylinder, not of "
                             f"{self.profile!r}")
        self.force = (float(f[0]), float(f[1]), float(f[2]))

    @property
    def slip(self) -> ContactSlip | None:
        """Cattaneo-Mindlin state of a load with friction (None without a friction model)."""
        if self.friction <= 0:
            return None
        return cattaneo_mindlin(self.force, self.friction, self.radius, (self.x, self.y))

    @property
    def applied_force(self) -> tuple[float, float, float]:
        """The force the contact transmits: the requested one, tangential part capped at mu P."""
        slip = self.slip
        if slip is None:
            return self.force
        return (slip.transmitted[0], slip.transmitted[1], self.force[2])

    @property
    def active(self) -> bool:
        return bool(np.any(np.asarray(self.force) != 0) or self.torque != 0)

    @property
    def reach(self) -> float:
        """Distance from (x, y) beyond which the load carries no traction (m)."""
        return self.radius + self.length / 2.0

    def shape(self, X: np.ndarray, Y: np.ndarray, radius: float | None = None,
              spacing: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Profile weight w >= 0 (zero outside the contact) and r, at rest points.

        r is the distance to the load's centre, or for a ``cylinder`` to its axis segment.
        ``radius`` (default the load's) draws the same profile on a smaller disc (the stick
        disc of a load in partial slip).  ``spacing``: the grid's node spacing h, over which
        a ``punch`` profile is averaged (0: sampled at the nodes, infinite at the rim).
        """
        radius = self.radius if radius is None else radius
        if self.profile == "cylinder":
            c, s = np.cos(self.angle), np.sin(self.angle)
            dx, dy = X - self.x, Y - self.y
            along = dx * c + dy * s
            r = np.hypot(along - np.clip(along, -self.length / 2, self.length / 2),
                         -dx * s + dy * c)
        else:
            r = np.hypot(X - self.x, Y - self.y)
        inside = r < radius
        if self.profile == "punch" and spacing > 0:   # nodes the rim cuts keep their share
            inside = r < radius + spacing
        if self.profile in ("hertz", "cylinder"):
            w = np.sqrt(np.clip(1.0 - (r / radius) ** 2, 0.0, None))
        elif self.profile == "punch":
            w = _punch_weights(np.asarray(X - self.x, np.float64),
                               np.asarray(Y - self.y, np.float64), radius, spacing)
        else:
            w = inside.astype(np.float64)
        return np.where(inside, w, 0.0), r

    def coverage(self, X: np.ndarray, Y: np.ndarray, spacing: float) -> np.ndarray:
        """Share of each grid node's square (side ``spacing``) inside the contact.

        Only a ``punch`` gives shares: the rim's force is spread over the nodes whose squares
        it cuts (:func:`_punch_weights`), so they press but are only partly in contact.
        Other profiles press exactly at the nodes inside (1 there, 0 elsewhere).
        """
        w, r = self.shape(X, Y, spacing=spacing)
        if self.profile != "punch" or spacing <= 0:
            return (w > 0).astype(np.float64)
        share = (r < self.radius).astype(np.float64)
        near = np.abs(r - self.radius) < spacing
        if near.any():
            sub = ((np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5) * spacing
            sx, sy = (v.reshape(1, -1) for v in np.meshgrid(sub, sub))
            dx = np.asarray(X - self.x, np.float64)[near][:, None] + sx
            dy = np.asarray(Y - self.y, np.float64)[near][:, None] + sy
            share[near] = (np.hypot(dx, dy) < self.radius).mean(axis=1)
        return share

    def rim_band(self, X: np.ndarray, Y: np.ndarray, spacing: float) -> np.ndarray:
        """Nodes within two grid spacings of a ``punch``'s rim (none for other profiles).

        There the sampled singular pressure makes the tabulated surface ripple by about
        +-2 % of the indentation (a grid artefact: a rigid punch's face is flat), so the
        largest indentation of the truth is taken elsewhere.
        """
        if self.profile != "punch" or spacing <= 0:
            return np.zeros(np.shape(X), bool)
        return np.abs(np.hypot(X - self.x, Y - self.y) - self.radius) < 2 * spacing

    def _centred(self, w: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """``w`` tilted by a tiny linear factor so that its centroid on the grid is the centre."""
        m = np.array([[(w * dx * dx).sum(), (w * dx * dy).sum()],
                      [(w * dx * dy).sum(), (w * dy * dy).sum()]])
        if np.linalg.cond(m) < 1e12:
            a, b = np.linalg.solve(m, -np.array([(w * dx).sum(), (w * dy).sum()]))
            w = w * (1.0 + a * dx + b * dy)
        return w

    def traction(self, X: np.ndarray, Y: np.ndarray, cell_area: float) -> np.ndarray:
        """(..., 3) traction (Pa) at grid nodes whose forces (times ``cell_area``) sum exactly.

        The sampled profile is tilted by a tiny linear factor so that its centroid on the
        grid is exactly the disc's centre: the resultant and its moment are then exactly the
        requested ones (:attr:`applied_force`, with friction), whatever the grid.
        """
        w, r = self.shape(X, Y, spacing=float(np.sqrt(cell_area)))
        if w.sum() <= 0:
            raise ValueError(f"load disc of radius {self.radius} m at ({self.x}, {self.y}) m "
                             "covers no node of the field grid (too small or off the grid)")
        dx, dy = X - self.x, Y - self.y
        w = self._centred(w, dx, dy)
        total = w.sum() * cell_area
        out = np.zeros(np.shape(X) + (3,))
        slip = self.slip
        for i in range(3) if slip is None else (2,):
            if self.force[i]:
                out[..., i] = self.force[i] * w / total
        if slip is not None:
            stick = None
            if slip.state == STATE_PARTIAL_SLIP:
                c, _ = self.shape(X, Y, self.radius * float(np.sqrt(slip.stick_ratio)))
                stick = self._centred(c, dx, dy) if c.sum() > 0 else None
            out[..., :2] = tangential_traction(-out[..., 2], stick, slip, self.friction,
                                               cell_area)
        if self.torque:
            # q = c w (-dy, dx), |q| = c r w(r) (the profiles above); zero net force as w is
            # centred; c makes the moment sum(dx q_y - dy q_x) A = c sum(w r^2) A equal mz
            if self.profile == "cylinder":     # r: from the centre, not from the axis
                r = np.hypot(dx, dy)
            c = self.torque / ((w * r * r).sum() * cell_area)
            out[..., 0] -= c * w * dy
            out[..., 1] += c * w * dx
        return out


def _punch_weights(dx: np.ndarray, dy: np.ndarray, radius: float, spacing: float
                   ) -> np.ndarray:
    """1 / sqrt(1 - r^2/a^2) averaged over each grid node's square of side h = ``spacing``.

    ``dx``, ``dy``: the nodes' offsets from the punch's centre.  The profile is singular at
    the rim but integrable: int s ds / sqrt(a^2 - s^2) = -sqrt(a^2 - s^2), so its mean over
    the ring [r1, r2] (within r < a) is a (sqrt(a^2 - r1^2) - sqrt(a^2 - r2^2)) /
    ((r2^2 - r1^2) / 2).  A node is given that mean over its radial extent [r - h/2, r + h/2];
    a node within h of the rim, whose square the rim cuts, the mean over SUBSAMPLES^2 points of
    its square (each the ring mean over its own h / SUBSAMPLES), so that its weight is the
    profile's integral over the part of its square inside the disc: the rim's force is not
    lumped onto the few nodes nearest to it.  With h = 0 the profile at the nodes.
    """
    a = radius
    r = np.hypot(dx, dy)
    if spacing <= 0:
        return np.where(r < a, 1.0 / np.sqrt(np.clip(1.0 - (r / a) ** 2, 1e-300, None)), 0.0)
    w = _ring_mean(r, a, spacing)
    near = np.abs(r - a) < spacing
    if near.any():
        sub = ((np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5) * spacing
        sx, sy = (v.reshape(1, -1) for v in np.meshgrid(sub, sub))
        rs = np.hypot(dx[near][:, None] + sx, dy[near][:, None] + sy)
        w[near] = _ring_mean(rs, a, spacing / SUBSAMPLES).mean(axis=1)
    return w


SUBSAMPLES = 8


def _ring_mean(r: np.ndarray, a: float, h: float) -> np.ndarray:
    """Mean of 1 / sqrt(1 - s^2/a^2) over [r - h/2, r + h/2] cut to [0, a] (0 for r >= a)."""
    inside = r < a
    r1 = np.clip(r - h / 2, 0.0, a)
    r2 = np.clip(r + h / 2, 0.0, a)
    span = np.where(inside, (r2 * r2 - r1 * r1) / 2.0, 1.0)
    mean = a * (np.sqrt(np.clip(a * a - r1 * r1, 0.0, None))
                - np.sqrt(np.clip(a * a - r2 * r2, 0.0, None))) / span
    return np.where(inside, mean, 0.0)


def is_load(contact: object) -> TypeIs[LoadContact]:
    return isinstance(contact, LoadContact)


def load_traction(loads: list[LoadContact], xs: np.ndarray, ys: np.ndarray,
                  spacing: float) -> np.ndarray:
    """Superposed traction (ny, nx, 3) Pa of load contacts on the grid (xs, ys); checks cover."""
    X, Y = np.meshgrid(xs, ys)
    q = np.zeros(X.shape + (3,))
    half = spacing / 2
    for load in loads:
        reach = load.reach
        if (load.x - reach < xs[0] - half or load.x + reach > xs[-1] + half
                or load.y - reach < ys[0] - half or load.y + reach > ys[-1] + half):
            raise ValueError(f"load disc of radius {reach} m at ({load.x}, {load.y}) m "
                             f"leaves the field grid [{xs[0]}, {xs[-1]}] x [{ys[0]}, {ys[-1]}] m")
        if load.active:
            q += load.traction(X, Y, spacing * spacing)
    return q


# --------------------------------------------------------------------------- ground truth


@dataclass
class TouchTruth:
    """What a touch decoder should report for one frame (pad frame, SI units).

    ``force``/``moment`` are None when a geometric indenter (whose force is unknown) is in
    the frame. Contact figures come from the applied traction on the simulator's fine grid.
    Per-cell arrays cover the cells of ``ground_truth/points`` (visible in both images).
    """

    force: np.ndarray | None  # (3,) N, resultant the object exerts on the pad
    moment: np.ndarray | None  # (3,) N m about the pad origin (tractions at z = 0)
    in_contact: bool = False
    area: float = 0.0  # m^2 where the normal traction presses
    centroid: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m, z = 0
    max_depth: float = 0.0  # m >= 0, over the fine grid
    normal_force: float = 0.0  # N >= 0
    shear_force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # N (x, y, 0)
    peak_pressure: float = 0.0  # Pa, largest pressure on the fine grid
    cells_in_contact: int = 0  # artwork cells whose rest centre is inside a pressing disc
    region_force: np.ndarray = field(default_factory=lambda: np.zeros(0))  # N
    region_area: np.ndarray = field(default_factory=lambda: np.zeros(0))  # m^2
    region_centroid: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # m
    slip: ContactSlip | None = None  # of the load pressing hardest; None: no friction model
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cols: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # m, current
    displacement: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # m


def resultant(loads: list[LoadContact]) -> tuple[np.ndarray, np.ndarray]:
    """Resultant force and moment about the pad origin: M = sum r x f + torsion.

    The requested forces, but a load in gross slip transmits only mu P sideways.
    """
    force = np.zeros(3)
    moment = np.zeros(3)
    for load in loads:
        f = np.asarray(load.applied_force, dtype=np.float64)
        force += f
        moment += np.cross([load.x, load.y, 0.0], f)
        moment[2] += load.torque
    return force, moment


def strongest_slip(loads: Sequence[LoadContact]) -> ContactSlip | None:
    """Slip truth of a frame: that of the load with the largest normal force (the contract's).

    None when no load has a friction model; no contact when no load presses; None when the
    load pressing hardest has no friction model (its slip is not defined).
    """
    if not any(load.friction > 0 for load in loads):
        return None
    pressing = [load for load in loads if load.force[2] < 0]
    if not pressing:
        return ContactSlip(STATE_NO_CONTACT, float("nan"), float("nan"), float("nan"),
                           (0.0, 0.0, 0.0), (0.0, 0.0))
    strongest = max(pressing, key=lambda load: -load.force[2])
    return strongest.slip


def touch_truth(contacts: Sequence[object], traction: np.ndarray, uz: np.ndarray, xs: np.ndarray,
                ys: np.ndarray, spacing: float, cell_rest: tuple[np.ndarray, np.ndarray],
                visible: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> TouchTruth:
    """Ground truth of a frame from its contacts and the field grid's traction and uz.

    ``cell_rest``: rest (X, Y) of every artwork cell; ``visible``: (rows, cols, position
    (N, 3), displacement (N, 3)) of the cells in ``ground_truth/points``.
    """
    loads = [c for c in contacts if is_load(c)]
    geometric = [c for c in contacts if not is_load(c)]
    force, moment = resultant(loads) if not geometric else (None, None)
    area_cell = spacing * spacing
    p = np.clip(-traction[..., 2], 0.0, None)
    pressed = p > 0
    total = float(p.sum() * area_cell)
    t = TouchTruth(force=force, moment=moment, slip=strongest_slip(loads))
    t.rows, t.cols, t.position, t.displacement = visible
    punches = [c for c in loads if c.profile == "punch" and c.force[2] < 0]
    share: np.ndarray = pressed   # the area each pressing node counts with
    if punches:
        X, Y = np.meshgrid(xs, ys)
        rim = np.zeros(np.shape(uz), bool)
        cover = np.zeros(np.shape(uz))
        for punch in punches:
            rim |= punch.rim_band(X, Y, spacing)
            cover = np.maximum(cover, punch.coverage(X, Y, spacing))
        share = np.where(cover > 0, np.minimum(cover, pressed), pressed.astype(np.float64))
        uz = np.where(rim, 0.0, uz)
    t.max_depth = float(max(0.0, -float(uz.min(initial=0.0))))
    t.shear_force = np.array([traction[..., 0].sum() * area_cell,
                              traction[..., 1].sum() * area_cell, 0.0])
    if total > 0:
        X, Y = np.meshgrid(xs, ys)
        t.in_contact = True
        t.area = float(share.sum() * area_cell)
        t.normal_force = total
        t.centroid = np.array([(p * X).sum() * area_cell / total,
                               (p * Y).sum() * area_cell / total, 0.0])
        t.peak_pressure = float(p.max())
        labels, n = ndimage.label(pressed, structure=np.ones((3, 3), bool))
        idx = np.arange(1, n + 1)
        rf = np.asarray(ndimage.sum(p, labels, idx)) * area_cell
        ra = np.asarray(ndimage.sum(share, labels, idx)) * area_cell
        cx = np.asarray(ndimage.sum(p * X, labels, idx)) * area_cell / rf
        cy = np.asarray(ndimage.sum(p * Y, labels, idx)) * area_cell / rf
        order = np.argsort(-rf, kind="stable")
        t.region_force, t.region_area = rf[order], ra[order]
        t.region_centroid = np.stack([cx[order], cy[order], np.zeros(n)], axis=1)
        CX, CY = cell_rest
        inside = np.zeros(np.shape(CX), bool)
        for load in loads:
            if load.force[2] < 0:
                inside |= load.shape(CX, CY)[1] < load.radius
        t.cells_in_contact = int(inside.sum())
    return t


def _xyz(v: object) -> np.ndarray:
    get = (lambda k: v[k]) if isinstance(v, dict) else (lambda k: getattr(v, k))
    return np.array([float(get("x")), float(get("y")), float(get("z"))])


def touch_truth_from_messages(wrench: object | None, field_cloud: object, contact: object,
                              slip: object | None = None) -> TouchTruth:
    """The :class:`TouchTruth` of one frame from its ``ground_truth/{wrench,field,contact}``.

    Accepts bag-decoded or rclpy messages (``wrench`` None where the bag has none: a frame
    with geometric indenters; ``slip`` its ``ground_truth/slip``, None without friction),
    so an evaluation reads bags and renders alike.
    """
    cells = cloud_to_arrays(field_cloud, FIELD_DTYPE)
    w = None if wrench is None else wrench.wrench  # type: ignore[attr-defined]
    c = contact
    return TouchTruth(
        force=None if w is None else _xyz(w.force),
        moment=None if w is None else _xyz(w.torque),
        in_contact=bool(c.in_contact), area=float(c.area),  # type: ignore[attr-defined]
        centroid=_xyz(c.centroid), max_depth=float(c.max_depth),  # type: ignore[attr-defined]
        normal_force=float(c.normal_force),  # type: ignore[attr-defined]
        shear_force=_xyz(c.shear_force),  # type: ignore[attr-defined]
        peak_pressure=float(c.peak_pressure),  # type: ignore[attr-defined]
        cells_in_contact=int(c.cells_in_contact),  # type: ignore[attr-defined]
        region_force=np.asarray(c.region_force, dtype=np.float64),  # type: ignore[attr-defined]
        region_area=np.asarray(c.region_area, dtype=np.float64),  # type: ignore[attr-defined]
        region_centroid=np.array([_xyz(p) for p in c.region_centroid]  # type: ignore
                                 ).reshape(-1, 3),
        slip=None if slip is None else slip_from_message(slip),
        rows=cells["row"].astype(np.int64), cols=cells["col"].astype(np.int64),
        position=np.stack([cells["x"], cells["y"], cells["z"]], axis=1).astype(np.float64),
        displacement=np.stack([cells["dx"], cells["dy"], cells["dz"]], axis=1
                              ).astype(np.float64))
