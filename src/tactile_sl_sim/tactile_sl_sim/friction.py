"""Friction at a load contact: Cattaneo-Mindlin partial slip, gross slip, and their truth.

A Hertz load (:mod:`.loads`, profile ``hertz``) with a friction coefficient mu > 0 presses
with P = -f_z and is pulled sideways by the requested tangential load Q = (f_x, f_y). With
P applied first and Q then rising monotonically from zero (Cattaneo 1938; R.D. Mindlin,
Compliance of elastic bodies in contact, J. Appl. Mech. 16, 1949; K.L. Johnson, Contact
Mechanics, 1985, section 7.2):

* **partial slip** (0 < |Q| < mu P): a central disc of radius c sticks, the annulus
  c < r < a slides, and the tangential traction, parallel to Q everywhere, is
  q(r) = mu p0 / a [sqrt(a^2 - r^2) - sqrt(c^2 - r^2)], the second term only for r < c,
  with c / a = (1 - |Q| / (mu P))^(1/3); in the slip annulus q = mu p exactly;
* **gross slip** (|Q| >= mu P): the whole contact slides, q = mu p everywhere, and the
  contact carries mu P (the object slides; the requested excess is not transmitted).

Mindlin's distribution moves the stick disc rigidly: the two Hertz-profile terms give equal
and opposite quadratic displacements inside c, leaving the uniform shift
3 mu P (2 - nu) (1 - (c/a)^2) / (16 G a) on an elastic half-space against a rigid indenter
(tests check it through :func:`tactile_sl_common.elasticity.surface_displacement`). The
normal-tangential coupling of a compressible pad (terms in 1 - 2 nu, zero at nu = 0.5) is
neglected, as in Mindlin's solution; the simulator keeps no loading history, so unloading
and reversals (Mindlin-Deresiewicz) are not modelled.

Ground truth per contact (:class:`ContactSlip`): state, stick ratio (c/a)^2, slip margin
1 - |Q|/(mu P), mu, the slip direction Q/|Q|; per frame, of the load with the largest
normal force (the contract's ``Slip`` message, ``ground_truth/slip``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STATE_NO_CONTACT = 0
STATE_STICK = 1
STATE_PARTIAL_SLIP = 2
STATE_GROSS_SLIP = 3
STATE_NAMES = {STATE_NO_CONTACT: "none", STATE_STICK: "stick", STATE_PARTIAL_SLIP: "partial",
               STATE_GROSS_SLIP: "gross"}
NAN = float("nan")


@dataclass(frozen=True)
class ContactSlip:
    """Cattaneo-Mindlin state of one contact (pad frame, SI); NaN fields without contact."""

    state: int
    stick_ratio: float           # (c/a)^2: stick area over contact area
    margin: float                # 1 - |Q| / (mu P)
    friction: float              # mu
    direction: tuple[float, float, float]   # unit Q / |Q|, zero without tangential load
    transmitted: tuple[float, float]        # N, the tangential force the contact carries
    normal_force: float = 0.0    # N, P
    radius: float = NAN          # m, a
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)   # m, z = 0

    @property
    def stick_radius(self) -> float:
        """C = a sqrt(stick ratio), m (NaN without contact)."""
        return self.radius * math.sqrt(self.stick_ratio) if self.stick_ratio >= 0 else NAN


def cattaneo_mindlin(force: tuple[float, float, float], friction: float, radius: float = NAN,
                     centre: tuple[float, float] = (0.0, 0.0)) -> ContactSlip:
    """The slip state of a Hertz contact under ``force`` (N, what the object exerts) and mu.

    Closed form of Johnson 1985, section 7.2: c / a = (1 - |Q| / (mu P))^(1/3) for a
    tangential load rising monotonically at constant normal load P = -f_z.
    """
    if not (math.isfinite(friction) and friction > 0):
        raise ValueError(f"friction coefficient must be a finite number > 0, got {friction!r}")
    fx, fy, fz = (float(v) for v in force)
    normal = max(-fz, 0.0)
    q = math.hypot(fx, fy)
    where = (float(centre[0]), float(centre[1]), 0.0)
    if normal <= 0.0:
        return ContactSlip(STATE_NO_CONTACT, NAN, NAN, NAN, (0.0, 0.0, 0.0), (0.0, 0.0), 0.0,
                           NAN, where)
    if q == 0.0:
        return ContactSlip(STATE_STICK, 1.0, 1.0, float(friction), (0.0, 0.0, 0.0), (0.0, 0.0),
                           normal, radius, where)
    direction = (fx / q, fy / q, 0.0)
    ratio = q / (friction * normal)
    if ratio >= 1.0:
        carried = friction * normal
        return ContactSlip(STATE_GROSS_SLIP, 0.0, 0.0, float(friction), direction,
                           (carried * direction[0], carried * direction[1]), normal, radius,
                           where)
    k = (1.0 - ratio) ** (1.0 / 3.0)
    return ContactSlip(STATE_PARTIAL_SLIP, k * k, 1.0 - ratio, float(friction), direction,
                       (fx, fy), normal, radius, where)


def tangential_traction(pressure: np.ndarray, stick_profile: np.ndarray | None,
                        slip: ContactSlip, friction: float, cell_area: float) -> np.ndarray:
    """(..., 2) tangential traction (Pa) of a contact in partial or gross slip.

    ``pressure`` (Pa, >= 0) is the contact's Hertz pressure on the grid (summing to P);
    ``stick_profile`` the weights sqrt(1 - r^2/c^2) of the stick disc (centred on the
    contact; None in gross slip). Mindlin's traction is mu p minus the stick disc's
    correction, scaled on the grid so that it carries mu P (c/a)^3: the traction then sums
    to the transmitted force exactly, whatever the grid.
    """
    q = friction * np.asarray(pressure, np.float64)
    if slip.state == STATE_PARTIAL_SLIP and stick_profile is not None:
        total = float(np.sum(stick_profile)) * cell_area
        if total > 0:   # the stick term carries mu P (c/a)^3 = mu P x margin
            q = q - friction * slip.normal_force * slip.margin * stick_profile / total
    elif slip.state not in (STATE_PARTIAL_SLIP, STATE_GROSS_SLIP):
        return np.zeros(np.shape(pressure) + (2,))
    return np.stack([q * slip.direction[0], q * slip.direction[1]], axis=-1)


def slip_from_message(msg: object) -> ContactSlip:
    """The :class:`ContactSlip` of a ``tactile_sl_msgs/Slip`` (rclpy, bag-decoded or dict)."""
    get = (lambda m, k: m[k]) if isinstance(msg, dict) else getattr

    def vec(v: object) -> tuple[float, float, float]:
        return (float(get(v, "x")), float(get(v, "y")), float(get(v, "z")))

    direction, centre = vec(get(msg, "direction")), vec(get(msg, "centroid"))
    q = float(get(msg, "tangential_force"))
    return ContactSlip(int(get(msg, "state")), float(get(msg, "stick_ratio")),
                       float(get(msg, "slip_margin")), float(get(msg, "friction_coefficient")),
                       direction, (q * direction[0], q * direction[1]),
                       float(get(msg, "normal_force")), float(get(msg, "contact_radius")),
                       centre)
