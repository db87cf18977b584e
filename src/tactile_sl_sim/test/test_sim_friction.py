"""Friction at simulated loads: Cattaneo-Mindlin traction against its closed form, the truth."""
import math

import numpy as np
import pytest

from tactile_sl_common.elasticity import Elastomer, surface_displacement
from tactile_sl_sim import friction
from tactile_sl_sim.contact import FieldGrid, PadParams
from tactile_sl_sim.loads import LoadContact, resultant, strongest_slip
from tactile_sl_sim.scenes import SceneError, parse_scene
from tactile_sl_sim.synth import slip_truth_fields

# nu = 0.5: no normal-tangential coupling, so Mindlin's traction is exact (Johnson 7.2)
INCOMPRESSIBLE = Elastomer(3.0e5, 0.5, 0.0)
GRID = {"x0": -0.006, "y0": -0.006, "spacing": 2.5e-5, "nx": 481, "ny": 481}
A, P, MU = 0.003, 0.5, 0.5


def _load(ratio: float, angle: float = 0.4, elastomer: Elastomer = INCOMPRESSIBLE,
          **kw: float) -> LoadContact:
    q = ratio * MU * P
    return LoadContact(radius=A, x=kw.get("x", 0.0), y=kw.get("y", 0.0),
                       force=(q * math.cos(angle), q * math.sin(angle), -P),
                       elastomer=elastomer, friction=MU)


@pytest.mark.parametrize("ratio, state, margin", [
    (0.0, friction.STATE_STICK, 1.0), (0.5, friction.STATE_PARTIAL_SLIP, 0.5),
    (0.999, friction.STATE_PARTIAL_SLIP, 0.001), (1.0, friction.STATE_GROSS_SLIP, 0.0),
    (1.7, friction.STATE_GROSS_SLIP, 0.0)])
def test_cattaneo_mindlin_closed_form(ratio, state, margin):
    s = _load(ratio).slip
    assert s.state == state and s.margin == pytest.approx(margin, abs=1e-12)
    k = max(1.0 - ratio, 0.0) ** (1.0 / 3.0)           # c / a = (1 - Q / mu P)^(1/3)
    assert s.stick_ratio == pytest.approx(k * k, abs=1e-12)
    assert s.friction == MU and s.normal_force == P and s.radius == A
    carried = min(ratio, 1.0) * MU * P                 # gross slip carries mu P, no more
    assert math.hypot(*s.transmitted) == pytest.approx(carried, abs=1e-12)
    assert s.direction == ((0.0, 0.0, 0.0) if ratio == 0 else
                           pytest.approx((math.cos(0.4), math.sin(0.4), 0.0)))


def test_no_normal_load_is_no_contact_and_bad_friction_is_refused():
    s = friction.cattaneo_mindlin((0.1, 0.0, 0.0), 0.5)
    assert s.state == friction.STATE_NO_CONTACT and math.isnan(s.margin)
    assert math.isnan(s.stick_ratio) and math.isnan(s.friction) and s.transmitted == (0, 0)
    with pytest.raises(ValueError, match="friction"):
        friction.cattaneo_mindlin((0.0, 0.0, -1.0), 0.0)
    with pytest.raises(ValueError, match="friction"):
        LoadContact(force=(0.0, 0.0, -1.0), friction=-0.2)
    with pytest.raises(ValueError, match="hertz"):
        LoadContact(force=(0.0, 0.0, -1.0), profile="uniform", friction=0.5)
    with pytest.raises(ValueError, match="torque"):
        LoadContact(force=(0.0, 0.0, -1.0), torque=1e-4, friction=0.5)


@pytest.mark.parametrize("ratio", [0.3, 0.8, 1.4])
def test_mindlin_traction_against_the_closed_form(ratio):
    """q = mu p0 / a [sqrt(a^2 - r^2) - sqrt(c^2 - r^2)] on the grid; it carries Q exactly."""
    load = _load(ratio)
    g = FieldGrid.build([load], PadParams(), **GRID)
    f = g.traction * g.spacing ** 2
    applied = load.applied_force
    assert f.reshape(-1, 3).sum(axis=0) == pytest.approx(applied, abs=1e-12)
    force, _ = resultant([load])
    assert force == pytest.approx(applied, abs=1e-15)
    X, Y = np.meshgrid(g.xs, g.ys)
    r = np.hypot(X, Y)
    p0 = 3 * P / (2 * np.pi * A ** 2)                   # Hertz peak pressure
    k = max(1.0 - ratio, 0.0) ** (1.0 / 3.0)
    c = k * A
    closed = MU * p0 / A * (np.sqrt(np.clip(A * A - r * r, 0, None))
                            - np.sqrt(np.clip(c * c - r * r, 0, None)))
    q = np.hypot(g.traction[..., 0], g.traction[..., 1])
    assert np.max(np.abs(q - closed)) < 0.01 * MU * p0  # the grid's sampling of the profile
    # parallel to Q everywhere, and mu p exactly in the slip annulus
    e = np.array([math.cos(0.4), math.sin(0.4)])
    assert np.allclose(g.traction[..., 0] * e[1], g.traction[..., 1] * e[0], atol=1e-9)
    annulus = (r > c + 2 * g.spacing) & (r < A)
    assert np.allclose(q[annulus], -MU * g.traction[..., 2][annulus], rtol=1e-9)


@pytest.mark.parametrize("ratio", [0.3, 0.7])
def test_the_stick_disc_moves_rigidly_by_mindlins_shift(ratio):
    """Johnson 1985 section 7.2: inside c the tangential displacement is uniform,
    3 mu P (2 - nu) (1 - (c/a)^2) / (16 G a) for one elastic body against a rigid one."""
    load = _load(ratio, angle=0.0)
    g = FieldGrid.build([load], PadParams(), **GRID)
    u = surface_displacement(INCOMPRESSIBLE, g.traction, g.spacing)
    X, Y = np.meshgrid(g.xs, g.ys)
    k = (1.0 - ratio) ** (1.0 / 3.0)
    stick = np.hypot(X, Y) < 0.8 * k * A
    nu, shear = 0.5, INCOMPRESSIBLE.shear_modulus
    shift = 3 * MU * P * (2 - nu) * (1 - k * k) / (16 * shear * A)
    assert np.abs(u[..., 0][stick] - shift).max() < 0.01 * shift
    assert np.abs(u[..., 1][stick]).max() < 0.01 * shift
    # the slip annulus lags behind the stick disc
    rim = (np.hypot(X, Y) > 1.05 * k * A) & (np.hypot(X, Y) < A)
    assert u[..., 0][rim].max() < shift


def test_gross_slip_displacement_at_the_centre():
    """q = mu p everywhere: u_x(0) = pi mu p0 (2 - nu) a / (8 G) (Hertz-profile traction)."""
    g = FieldGrid.build([_load(1.2, angle=0.0)], PadParams(), **GRID)
    u = surface_displacement(INCOMPRESSIBLE, g.traction, g.spacing)
    p0 = 3 * P / (2 * np.pi * A ** 2)
    expected = np.pi * MU * p0 * 1.5 * A / (8 * INCOMPRESSIBLE.shear_modulus)
    assert u[240, 240, 0] == pytest.approx(expected, rel=2e-3)


def test_frame_truth_is_the_load_pressing_hardest_and_round_trips():
    strong = _load(0.5, x=-0.002)
    weak = LoadContact(radius=0.002, x=0.003, force=(0.0, 0.05, -0.2), friction=0.4)
    assert strongest_slip([weak, strong]) == strong.slip
    released = LoadContact(radius=0.003, x=-0.002, force=(0.0, 0.0, 0.0), friction=0.5)
    assert strongest_slip([released, weak]) == weak.slip
    assert strongest_slip([released]).state == friction.STATE_NO_CONTACT
    assert strongest_slip([LoadContact(force=(0.0, 0.0, -1.0))]) is None   # no friction model
    header = {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "tactile_pad"}
    fields = slip_truth_fields(strong.slip, header)
    assert list(fields)[:7] == ["header", "state", "stick_ratio", "slip_margin",
                                "friction_coefficient", "direction", "centroid"]
    back = friction.slip_from_message(fields)
    assert back.state == strong.slip.state and back.margin == strong.slip.margin
    assert back.centre == (-0.002, 0.0, 0.0) and back.stick_radius == strong.slip.stick_radius


def test_state_numbers_are_the_messages():
    msg = pytest.importorskip("tactile_sl_msgs.msg")
    assert (friction.STATE_NO_CONTACT, friction.STATE_STICK, friction.STATE_PARTIAL_SLIP,
            friction.STATE_GROSS_SLIP) == (msg.Slip.STATE_NO_CONTACT, msg.Slip.STATE_STICK,
                                           msg.Slip.STATE_PARTIAL_SLIP,
                                           msg.Slip.STATE_GROSS_SLIP)


SCENE = {"name": "s", "frames": 2, "contacts": [
    {"indenter": {"kind": "load", "radius": 0.003, "friction": 0.5},
     "keyframes": [{"frame": 0, "force": [0, 0, 0]}, {"frame": 1, "force": [0.4, 0, -0.5]}]}]}


def test_scene_friction_key():
    scene = parse_scene(dict(SCENE))
    load = scene.contacts_at(1)[0]
    assert isinstance(load, LoadContact) and load.friction == 0.5
    assert load.slip.state == friction.STATE_GROSS_SLIP and load.applied_force[0] == 0.25
    other = {"indenter": {"kind": "load", "radius": 0.002},
             "keyframes": [{"frame": 0, "x": 0.004, "force": [0, 0, -0.1]}]}
    with pytest.raises(SceneError, match="every load"):
        parse_scene({**SCENE, "contacts": SCENE["contacts"] + [other]})
    bad = {"indenter": {"kind": "load", "radius": 0.003, "friction": 0.5, "profile": "uniform"},
           "keyframes": [{"frame": 0, "force": [0, 0, -0.5]}]}
    with pytest.raises(SceneError, match="hertz"):
        parse_scene({**SCENE, "contacts": [bad]})
