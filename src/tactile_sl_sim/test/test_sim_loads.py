"""Traction-driven contacts in the simulator: scene keys, the field, touch ground truth."""
import numpy as np
import pytest

from tactile_sl_common.clouds import (
    FIELD_DTYPE,
    FIELD_FORCE_DTYPE,
    FLOAT32,
    INT32,
    CloudFormatError,
    cloud_fields,
    cloud_to_arrays,
    pack_field,
)
from tactile_sl_common.elasticity import Elastomer, surface_displacement
from tactile_sl_sim.artwork import load_artwork, random_values, write_artwork
from tactile_sl_sim.contact import Contact, FieldGrid, PadParams
from tactile_sl_sim.loads import (
    LoadContact,
    resultant,
    touch_truth,
    touch_truth_from_messages,
)
from tactile_sl_sim.render import Renderer
from tactile_sl_sim.scenes import SceneError, load_scenes, parse_scene
from tactile_sl_sim.synth import frame_messages, render_scene_frame

from ros_harness import BAGS

HALF = Elastomer(3.0e5, 0.49, 0.0)
SMALL = {"x0": -0.006, "y0": -0.006, "spacing": 1e-4, "nx": 121, "ny": 121}


class _Msg:
    """Attribute access over a fields dict (what a bag decoder gives)."""

    def __init__(self, d):
        for k, v in d.items():
            if isinstance(v, dict):
                v = _Msg(v)
            elif isinstance(v, list) and v and isinstance(v[0], dict) and "name" not in v[0]:
                v = [_Msg(x) for x in v]
            setattr(self, k, v)


LOAD_SCENE = {
    "name": "loads", "frames": 2,
    "elastomer": {"youngs_modulus": 3.0e5, "poisson_ratio": 0.49, "thickness": 0.0},
    "contacts": [
        {"indenter": {"kind": "load", "radius": 0.003, "profile": "hertz"},
         "keyframes": [{"frame": 0, "x": 0.001, "y": -0.0005, "force": [0, 0, 0]},
                       {"frame": 1, "force": [0.05, -0.02, -0.4], "torque": 2e-4}]},
        {"indenter": {"kind": "load", "radius": 0.0015, "profile": "uniform"},
         "keyframes": [{"frame": 0, "x": -0.003, "y": 0.003, "force": [0, 0, 0]},
                       {"frame": 1, "force": [0.0, 0.01, -0.1]}]},
    ],
}


@pytest.fixture(scope="module")
def renderer(tmp_path_factory):
    art = write_artwork(tmp_path_factory.mktemp("art") / "pattern.png", random_values(30, 28))
    return Renderer(load_artwork(art))


@pytest.fixture(scope="module")
def loaded(renderer):
    scene = parse_scene(dict(LOAD_SCENE))
    frame = render_scene_frame(scene, renderer, 1)
    return scene, frame, frame_messages(scene, renderer, frame, scene.stamp_ns(1))


def _scene(contact: dict, **extra) -> dict:
    return {"name": "s", "frames": 2, "contacts": [contact], **extra}


LOAD = {"indenter": {"kind": "load", "radius": 0.003},
        "keyframes": [{"frame": 0, "force": [0, 0, 0]}, {"frame": 1, "force": [0, 0, -1]}]}


@pytest.mark.parametrize("doc, message", [
    (_scene({**LOAD, "indenter": {"kind": "load", "radius": 0.003, "depth": 1}}),
     "unknown key.*depth"),
    (_scene({**LOAD, "keyframes": [{"frame": 0, "depth": 0.001}]}), "unknown key.*depth"),
    (_scene({"indenter": {"kind": "sphere"}, "keyframes": [{"frame": 0, "force": [0, 0, 1]}]}),
     "unknown key.*force"),
    (_scene({**LOAD, "indenter": {"kind": "load", "radius": 0.003, "profile": "cone"}}),
     "profile"),
    (_scene({**LOAD, "keyframes": [{"frame": 0, "force": [0, -1]}]}), "force needs 3"),
    (_scene({**LOAD, "keyframes": [{"frame": 0, "force": [0, 0, 0.5]}]}), "fz must be <= 0"),
    (_scene({**LOAD, "indenter": {"kind": "load", "radius": -0.001}}), "radius"),
    (_scene({**LOAD, "keyframes": [{"frame": 0, "x": 0.012}]}), "leaves the simulated pad"),
    (_scene({**LOAD, "indenter": {"kind": "load", "radius": 0.001, "profile": "cylinder",
                                  "length": 0.02}}), "leaves the simulated pad"),
    (_scene({**LOAD, "indenter": {"kind": "load", "radius": 0.001, "length": 0.002}}),
     "length is the axis of profile cylinder"),
    (_scene(LOAD, mirrored=True), "mirrored"),
    (_scene(LOAD, elastomer={"youngs_modulus": 3e5, "poison_ratio": 0.4}), "poison_ratio"),
    (_scene(LOAD, elastomer={"youngs_modulus": -1.0}), "youngs_modulus"),
    (_scene(LOAD, elastomer={"poisson_ratio": 0.7}), "poisson_ratio"),
    (_scene(LOAD, elastomer={"thickness": -0.001}), "thickness"),
    (_scene(LOAD, elastomer=[1, 2]), "elastomer must be a mapping"),
])
def test_bad_load_scenes_are_clear_errors(doc, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(doc)


def test_load_keyframes_interpolate_and_default_elastomer():
    scene = parse_scene(_scene({**LOAD, "keyframes": [
        {"frame": 0, "force": [0, 0, 0], "torque": 0.0},
        {"frame": 2, "force": [0.2, 0, -1], "torque": 1e-3}]}, frames=3))
    load = scene.contacts_at(1)[0]
    assert isinstance(load, LoadContact)
    assert load.force == pytest.approx((0.1, 0.0, -0.5)) and load.torque == pytest.approx(5e-4)
    assert load.elastomer == Elastomer(3.0e5, 0.49, 0.0) and scene.has_loads
    assert not parse_scene({"name": "n"}).has_loads


@pytest.mark.parametrize("profile", ["hertz", "uniform", "punch", "cylinder"])
def test_traction_carries_the_requested_force_and_moment(profile):
    length = 0.002 if profile == "cylinder" else 0.0
    load = LoadContact(radius=0.002, profile=profile, x=0.0007, y=-0.0004,
                       force=(0.1, -0.05, -0.8), torque=3e-4, length=length, angle=0.5)
    g = FieldGrid.build([load], PadParams(), **SMALL)
    X, Y = np.meshgrid(g.xs, g.ys)
    f = g.traction * g.spacing**2
    assert f.reshape(-1, 3).sum(axis=0) == pytest.approx(load.force, abs=1e-12)
    moment = np.stack([Y * f[..., 2], -X * f[..., 2], X * f[..., 1] - Y * f[..., 0]],
                      axis=-1).reshape(-1, 3).sum(axis=0)
    _, expected = resultant([load])
    assert moment == pytest.approx(expected, rel=1e-6, abs=1e-12)
    # the traction stays within the contact (a punch: the nodes its rim cuts too)
    reach = 0.002 + (g.spacing if profile == "punch" else 0.0)
    assert np.all(load.shape(X, Y)[1][np.any(g.traction != 0, axis=2)] < reach)
    # the field is the elastic response of that traction, over the whole grid
    assert np.array_equal(g.data, surface_displacement(HALF, g.traction, g.spacing))
    assert g.active_index == (0, g.ny, 0, g.nx)


def test_punch_presses_its_face_flat_and_its_truth_leaves_the_rim_out():
    """A rigid flat punch's pressure (infinite at the rim) displaces its face uniformly."""
    a = 0.0015
    punch = LoadContact(radius=a, profile="punch", x=0.0003, y=-0.0001, force=(0, 0, -1.0))
    grid = {"x0": -0.005, "y0": -0.005, "spacing": 4e-5, "nx": 251, "ny": 251}
    g = FieldGrid.build([punch], PadParams(), **grid)
    X, Y = np.meshgrid(g.xs, g.ys)
    r = np.hypot(X - punch.x, Y - punch.y)
    uz = -g.data[..., 2]
    face = uz[r < a - 3 * g.spacing]
    assert np.ptp(face) < 0.005 * face.mean()          # flat to 0.5 % (about 4 um)
    p = -g.traction[..., 2]
    assert p[r < 0.5 * a].max() < p[(r > 0.9 * a) & (r < a)].max() / 2   # peaks at the rim
    truth = touch_truth([punch], g.traction, g.data[..., 2], g.xs, g.ys, g.spacing,
                        (np.zeros(1), np.zeros(1)),
                        (np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))))
    assert truth.area == pytest.approx(np.pi * a * a, rel=0.005)
    assert truth.max_depth == pytest.approx(face.max(), rel=1e-9)     # not the rim's ripple
    assert truth.region_area[0] == pytest.approx(truth.area)


def test_cylinder_presses_a_strip_with_rounded_ends():
    cyl = LoadContact(radius=0.001, profile="cylinder", length=0.004, angle=np.radians(30),
                      force=(0, 0, -0.5))
    g = FieldGrid.build([cyl], PadParams(), **SMALL)
    X, Y = np.meshgrid(g.xs, g.ys)
    pressed = g.traction[..., 2] < 0
    area = pressed.sum() * g.spacing ** 2
    assert area == pytest.approx(2 * 0.001 * 0.004 + np.pi * 0.001 ** 2, rel=0.02)
    along = (X * np.cos(np.radians(30)) + Y * np.sin(np.radians(30)))[pressed]
    assert along.max() == pytest.approx(0.003, abs=2e-4)       # half length + half-width
    with pytest.raises(ValueError, match="length"):
        LoadContact(radius=0.001, profile="hertz", length=0.002)


def test_loads_superpose_with_indenters():
    load = LoadContact(radius=0.002, force=(0.0, 0.0, -0.5))
    sphere = Contact("sphere", radius=0.004, depth=0.0003, x=0.002)
    both = FieldGrid.build([load, sphere], PadParams(), **SMALL).data
    parts = (FieldGrid.build([load], PadParams(), **SMALL).data
             + FieldGrid.build([sphere], PadParams(), **SMALL).data)
    assert np.allclose(both, parts, rtol=0, atol=1e-15)


@pytest.mark.slow
def test_truth_wrench_and_contact_match_the_requested_loads(loaded):
    scene, frame, msgs = loaded
    touch = frame.truth.touch
    loads = scene.contacts_at(1)
    force, moment = resultant(loads)
    assert force == pytest.approx([0.05, -0.01, -0.5])
    assert np.array_equal(touch.force, force) and np.array_equal(touch.moment, moment)
    assert touch.in_contact and touch.normal_force == pytest.approx(0.5, rel=1e-9)
    assert touch.shear_force == pytest.approx([0.05, -0.01, 0.0], abs=1e-12)
    assert touch.area == pytest.approx(np.pi * (0.003**2 + 0.0015**2), rel=0.02)
    centroid = (0.4 * np.array([0.001, -0.0005]) + 0.1 * np.array([-0.003, 0.003])) / 0.5
    assert touch.centroid[:2] == pytest.approx(centroid, abs=1e-6)
    assert touch.region_force == pytest.approx([0.4, 0.1], rel=1e-9)
    assert touch.region_centroid[0, :2] == pytest.approx([0.001, -0.0005], abs=1e-6)
    assert touch.max_depth == pytest.approx(-frame.field.data[..., 2].min())
    rows, cols = frame.truth.rows, frame.truth.cols
    rest_x = (cols - 13.5) * 0.0005
    rest_y = (rows - 14.5) * 0.0005
    inside = ((np.hypot(rest_x - 0.001, rest_y + 0.0005) < 0.003)
              | (np.hypot(rest_x + 0.003, rest_y - 0.003) < 0.0015))
    assert touch.cells_in_contact == int(inside.sum()) > 0


@pytest.mark.slow
def test_truth_displacement_at_cells_is_the_field_sample(loaded, renderer):
    _, frame, _ = loaded
    touch = frame.truth.touch
    rows, cols, X, Y = renderer.cell_rest_positions()
    v = frame.truth.visible
    assert np.array_equal(touch.rows, rows[v]) and np.array_equal(touch.cols, cols[v])
    assert np.array_equal(touch.displacement, frame.field.sample(X[v], Y[v]))
    assert np.allclose(touch.position, frame.truth.world[v], rtol=0, atol=1e-15)
    assert np.abs(touch.displacement[:, 2]).max() > 1e-5


@pytest.mark.slow
def test_touch_topics_layout_and_round_trip(loaded):
    scene, frame, msgs = loaded
    by_topic = {t: (schema, fields) for t, schema, fields in msgs}
    assert {"ground_truth/wrench", "ground_truth/field", "ground_truth/contact"} <= set(by_topic)
    stamp = by_topic["left/image_raw"][1]["header"]["stamp"]
    for t in ("ground_truth/wrench", "ground_truth/field", "ground_truth/contact"):
        assert by_topic[t][1]["header"] == {"stamp": stamp, "frame_id": "tactile_pad"}
    assert by_topic["ground_truth/wrench"][0] == "geometry_msgs/msg/WrenchStamped"
    assert by_topic["ground_truth/contact"][0] == "tactile_sl_msgs/msg/Contact"
    cloud = by_topic["ground_truth/field"][1]
    assert [(f["name"], f["offset"], f["datatype"]) for f in cloud["fields"]] == [
        ("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("dx", 12, FLOAT32),
        ("dy", 16, FLOAT32), ("dz", 20, FLOAT32), ("row", 24, INT32), ("col", 28, INT32)]
    assert cloud["point_step"] == 32 and cloud["width"] == int(frame.truth.visible.sum())
    points = by_topic["ground_truth/points"][1]
    assert points["width"] == cloud["width"]
    back = touch_truth_from_messages(_Msg(by_topic["ground_truth/wrench"][1]), _Msg(cloud),
                                     _Msg(by_topic["ground_truth/contact"][1]))
    touch = frame.truth.touch
    assert np.array_equal(back.force, touch.force) and back.area == touch.area
    assert np.allclose(back.displacement, touch.displacement, rtol=1e-6, atol=1e-12)
    assert np.array_equal(back.rows, touch.rows)
    assert back.region_centroid.shape == (2, 3)


@pytest.mark.slow
def test_untouched_frame_and_mixed_scene(renderer):
    scene = parse_scene(dict(LOAD_SCENE))
    frame = render_scene_frame(scene, renderer, 0)
    touch = frame.truth.touch
    assert not touch.in_contact and touch.area == 0 and touch.max_depth == 0
    assert np.array_equal(touch.force, np.zeros(3)) and len(touch.region_force) == 0
    mixed = [LoadContact(radius=0.002, force=(0, 0, -0.2)),
             Contact("sphere", radius=0.004, depth=0.0002, x=0.003)]
    t = renderer.touch_truth(mixed, renderer.build_field(mixed),
                             renderer.ground_truth(renderer.build_field(mixed)))
    assert t.force is None and t.moment is None and t.normal_force == pytest.approx(0.2)


def test_pack_field_layout():
    xyz = np.array([[0.001, 0.002, -0.0001], [0.0, 0.0, 0.0]])
    d = np.array([[1e-5, -2e-5, -1e-4], [0.0, 0.0, 0.0]])
    rows, cols = np.array([3, 4]), np.array([5, 6])
    packed = pack_field(xyz, d, rows, cols)
    assert packed.dtype == FIELD_DTYPE and FIELD_DTYPE.itemsize == 32
    f = np.array([[0.1, 0.0, -0.5], [0.0, 0.0, 0.0]])
    with_force = pack_field(xyz, d, rows, cols, force=f)
    assert with_force.dtype == FIELD_FORCE_DTYPE and FIELD_FORCE_DTYPE.itemsize == 44
    msg = cloud_fields(with_force, (1, 2), "tactile_pad")
    assert [f["name"] for f in msg["fields"]] == ["x", "y", "z", "dx", "dy", "dz", "row", "col",
                                                  "fx", "fy", "fz"]
    assert msg["fields"][-1] == {"name": "fz", "offset": 40, "datatype": FLOAT32, "count": 1}
    back = cloud_to_arrays(_Msg(msg), FIELD_FORCE_DTYPE)
    assert np.array_equal(back, with_force)
    assert np.array_equal(cloud_to_arrays(_Msg(msg))["row"], rows)  # points view
    with pytest.raises(CloudFormatError, match="dxyz"):
        pack_field(xyz, d[:1], rows, cols)
    with pytest.raises(CloudFormatError, match="force"):
        pack_field(xyz, d, rows, cols, force=f[:1])
    with pytest.raises(CloudFormatError, match="non-finite"):
        pack_field(xyz, np.full((2, 3), np.nan), rows, cols)
    with pytest.raises(CloudFormatError, match="lacks"):
        cloud_to_arrays(_Msg(cloud_fields(packed, (0, 0), "p")), FIELD_FORCE_DTYPE)


def test_shape_scenes_file_is_valid():
    """bags/shape_scenes.yaml (bench_touch): a punch, a cylinder, an edge, two contacts."""
    scenes = {s.name: s for s in load_scenes(BAGS / "shape_scenes.yaml")}
    profiles = {c.profile for s in scenes.values() for c in s.contacts_at(1)}
    assert {"hertz", "punch", "cylinder"} <= profiles
    cyl = scenes["shape_cylinder"].contacts_at(1)[0]
    assert cyl.length == pytest.approx(0.005) and cyl.angle == pytest.approx(np.radians(30))
    assert len(scenes["shape_two_contacts"].contacts_at(1)) == 2
    assert scenes["shape_layer"].elastomer.thickness == pytest.approx(0.002)


def test_light_scenes_file_is_valid():
    """bags/light_scenes.yaml (bench_touch): the same loads under clean and harsh light."""
    scenes = {s.name: s for s in load_scenes(BAGS / "light_scenes.yaml")}
    assert set(scenes) == {"light_clean", "light_harsh", "light_harsh_mjpeg"}
    clean, harsh, mjpeg = (scenes[n] for n in ("light_clean", "light_harsh",
                                               "light_harsh_mjpeg"))
    for frame in range(clean.frames):
        loads = [[(c.force, c.x, c.y) for c in s.contacts_at(frame)]
                 for s in (clean, harsh, mjpeg)]
        assert loads[0] == loads[1] == loads[2]
    assert clean.nuisances.noise_sigma < harsh.nuisances.noise_sigma == 4.0
    assert harsh.nuisances.shadows and harsh.nuisances.jpeg_quality == 0
    assert mjpeg.nuisances.jpeg_quality == 70
    assert mjpeg.nuisances.shadows == harsh.nuisances.shadows


def test_touch_scenes_file_is_valid():
    path = BAGS / "touch_scenes.yaml"
    if not path.is_file():
        pytest.skip("bags/touch_scenes.yaml not present")
    scenes = {s.name: s for s in load_scenes(path)}
    assert {"touch_halfspace", "touch_layer", "touch_calibration"} <= set(scenes)
    for s in scenes.values():
        assert s.has_loads and all(not c.active for c in s.contacts_at(0))
