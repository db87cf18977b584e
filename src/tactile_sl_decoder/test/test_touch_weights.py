"""Per-cell weights (touch/weights.py): expected errors, cleaning, ripples, the stage."""
import numpy as np
import pytest
from test_touch_stage import _points
from test_touch_traction import PITCH, SHAPE, _displacement

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.touch.contact import ContactParams, contact_state
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams, TouchStage
from tactile_sl_decoder.touch.weights import (
    CellWeights,
    WeightParams,
    expected_error,
    local_fit,
)

ROWS, COLS = np.divmod(np.arange(SHAPE[0] * SHAPE[1]), SHAPE[1])
NOMINAL = nominal_positions(ROWS, COLS, SHAPE, PITCH)
ELASTOMER = Elastomer(3e5, 0.49, 0.0)


def _noise_scale(dark=30e-6, clean=1e-6):
    """Per-cell noise (N, 3): clean everywhere, ``dark`` in two patches (a shadow, dust)."""
    scale = np.full((len(ROWS), 3), clean)
    patch = (np.abs(ROWS - 6) <= 2) & (np.abs(COLS - 5) <= 2)
    dust = (np.abs(ROWS - 15) <= 1) & (np.abs(COLS - 13) <= 1)
    scale[patch | dust] = dark
    return scale, patch | dust


def test_local_fit_is_exact_on_a_quadratic_and_leaves_the_cell_out():
    x, y = NOMINAL[:, 0] / PITCH, NOMINAL[:, 1] / PITCH
    field = np.column_stack([1 + 2 * x - y + 0.3 * x * x - 0.2 * x * y + 0.1 * y * y,
                             np.zeros_like(x), 5 * np.ones_like(x)])
    spoiled = field.copy()
    spoiled[100] += 1e3                  # the cell itself takes no part in its own fit
    pred, factor = local_fit(spoiled, np.ones(len(x)), ROWS, COLS, SHAPE,
                             np.array([100, 1, 0]))
    assert np.allclose(pred[:2], field[[100, 1]], rtol=1e-6, atol=1e-6)
    assert 0 < factor[0] < factor[1] < 1     # an edge cell's fit is less certain
    assert np.all(np.isnan(pred[2])) and factor[2] == np.inf   # a corner: 8 neighbours


def test_expected_error_finds_the_noisy_cells_and_keeps_the_floor():
    rng = np.random.default_rng(3)
    scale, dark = _noise_scale()
    rest = NOMINAL + rng.normal(0.0, 1.0, NOMINAL.shape) * scale
    sigma = expected_error(ROWS, COLS, rest, NOMINAL, SHAPE, 1.5e-6)
    far = _far_from(dark)
    assert np.all(sigma >= 1.5e-6)
    assert np.median(sigma[far]) == pytest.approx(1.5e-6)      # clean: at the floor
    assert np.median(sigma[dark]) > 10e-6                      # dark: found
    # a dented reference (the pad pressed while taken) is smooth: no noise is read into it
    dent = _displacement(ELASTOMER, [(0, 0, -0.5, 3e-3, 0.0, 0.0)], 0.0, rng)
    sigma = expected_error(ROWS, COLS, NOMINAL + dent, NOMINAL, SHAPE, 1.5e-6)
    assert np.percentile(sigma, 95) < 3e-6


def _far_from(mask, cells=3):
    """Cells more than ``cells`` rows or columns from every cell of ``mask``."""
    grid = np.zeros(SHAPE, bool)
    grid[ROWS[mask], COLS[mask]] = True
    near = np.zeros(SHAPE, bool)
    for dr in range(-cells, cells + 1):
        for dc in range(-cells, cells + 1):
            near |= np.roll(np.roll(grid, dr, axis=0), dc, axis=1)
    return ~near[ROWS, COLS]


def _weights(scale, frames=1, **kw):
    rng = np.random.default_rng(5)
    rest = NOMINAL + rng.normal(0.0, 1.0, NOMINAL.shape) * scale
    return CellWeights(ROWS, COLS, SHAPE, rest, NOMINAL, frames, WeightParams(**kw))


def test_several_reference_frames_give_each_frame_its_own_noise():
    """An averaged reference is smoother than one frame: its roughness is no frame's noise."""
    from tactile_sl_decoder.touch.reference import ReferenceBuilder

    rng = np.random.default_rng(11)
    scale, dark = _noise_scale(dark=20e-6, clean=1e-6)
    frames = 5
    builder = ReferenceBuilder(frames, SHAPE)
    for _ in range(frames):
        builder.add(ROWS, COLS, NOMINAL + rng.normal(0.0, 1.0, NOMINAL.shape) * scale)
    cells, mean = builder.result()
    weights = CellWeights(ROWS, COLS, SHAPE, mean, NOMINAL, frames, WeightParams(),
                          builder.scatter(cells))
    far = _far_from(dark, 1)
    inner = dark & _far_from(~dark, 1)                        # the patches' inner cells
    # a displacement's error: sqrt(1 + 1 / frames) x the frame's noise
    expected = 20e-6 * np.sqrt(1 + 1 / frames)
    assert np.median(weights.error[inner]) == pytest.approx(expected, rel=0.2)
    assert np.median(weights.error[far]) == pytest.approx(1.5e-6 * np.sqrt(1.2), rel=0.05)
    # from the averaged reference's roughness alone it would be sqrt(frames) x too small
    smooth = CellWeights(ROWS, COLS, SHAPE, mean, NOMINAL, frames, WeightParams())
    assert np.median(smooth.error[inner]) < 0.6 * expected


def test_a_clean_pad_is_taken_as_measured():
    weights = _weights(np.full((len(ROWS), 3), 1e-6))
    assert len(weights.noisy) == 0
    disp = np.random.default_rng(0).normal(0.0, 1e-6, (len(ROWS), 3))
    assert weights.clean(disp) is disp


def test_cleaning_lowers_the_error_of_noisy_cells_and_keeps_the_others():
    scale, dark = _noise_scale()
    weights = _weights(scale)
    assert not np.any(_far_from(dark, 3)[weights.noisy]) and len(weights.noisy) > 25
    rng = np.random.default_rng(7)
    truth = _displacement(ELASTOMER, [(0, 0, -0.5, 2e-3, -1e-3, -1.5e-3)], 0.0, rng)
    measured = truth + rng.normal(0.0, 1.0, truth.shape) * scale * np.sqrt(2)
    measured[weights.noisy[3]] += (0.0, 0.0, 300e-6)           # a gross stereo error
    cleaned = weights.clean(measured)
    keep = np.setdiff1d(np.arange(len(ROWS)), weights.noisy)
    assert np.array_equal(cleaned[keep], measured[keep])
    before = np.sqrt(np.mean((measured[weights.noisy] - truth[weights.noisy]) ** 2))
    after = np.sqrt(np.mean((cleaned[weights.noisy] - truth[weights.noisy]) ** 2))
    assert after < 0.4 * before
    # bounded by the Huber weight (without it about a third of the error would stay)
    assert abs(cleaned[weights.noisy[3], 2] - truth[weights.noisy[3], 2]) < 60e-6
    # the effective errors: lower where cleaned, the same elsewhere
    assert np.all(weights.effective[weights.noisy] < weights.error[weights.noisy])
    assert np.array_equal(weights.effective[keep], weights.error[keep])


def test_more_reference_frames_lower_the_expected_error():
    scale, _ = _noise_scale(dark=20e-6, clean=4e-6)
    one, four = _weights(scale, frames=1), _weights(scale, frames=4)
    assert np.allclose(four.error / one.error, np.sqrt(1.25 / 2.0))


def test_propagated_noise_of_a_linear_functional():
    scale, _ = _noise_scale()
    weights = _weights(scale)
    rows = np.zeros((2, 3 * len(ROWS)))
    rows[0, 2] = 1.0                       # u_z of cell 0
    rows[1, 2::3] = 1.0                    # sum of u_z
    sd = weights.propagated(rows)
    assert sd[0] == pytest.approx(weights.effective[0, 2])
    assert sd[1] == pytest.approx(np.sqrt(np.sum(weights.effective[:, 2] ** 2)))


def test_bad_weight_settings_are_refused():
    for bad in ({"min_error": 0.0}, {"model_error": -1.0}, {"noisy_factor": 0.5},
                {"model_error_relative": 1.0},
                {"huber_k": 0.0}):
        with pytest.raises(ValueError):
            WeightParams(**bad).validate()


def test_a_ripple_of_the_noise_is_no_contact():
    # a real contact and a faint blob far from it; with the map's noise the blob is dropped
    xy = NOMINAL[:, :2]
    forces = np.zeros((len(ROWS), 3))
    main = np.exp(-np.sum((xy - [1e-3, 1e-3]) ** 2, axis=1) / (2 * (1e-3) ** 2))
    blob = (np.abs(ROWS - 2) <= 0) & (np.abs(COLS - 2) <= 1)
    forces[:, 2] = -0.5 * main / main.sum()
    forces[blob, 2] = -6e-3
    forces[np.abs(forces[:, 2]) < 1e-5, 2] = 0.0
    wrench = np.zeros(6)
    wrench[:3] = forces.sum(axis=0)
    wrench[3] = np.sum(xy[:, 1] * forces[:, 2])
    wrench[4] = -np.sum(xy[:, 0] * forces[:, 2])
    args = (xy, ROWS, COLS, forces, wrench, SHAPE, PITCH, np.zeros(SHAPE), False,
            ContactParams(area_fraction=0.2), (1e3, 1e3))
    assert len(contact_state(*args).region_force) == 2
    state = contact_state(*args, map_noise=np.full(len(ROWS), 2e-3))
    assert len(state.region_force) == 1 and state.region_force[0] > 0.4
    # every region a ripple: the resultant's centroid
    state = contact_state(*args, map_noise=np.full(len(ROWS), 1.0))
    assert state.region_force == []
    assert state.centroid[0] == pytest.approx(wrench[4] / -wrench[2])


def _stage(enabled):
    return TouchStage(SensorConfig(ELASTOMER), SHAPE, PITCH,
                      params=TouchParams(weights=WeightParams(enabled=enabled),
                                         solver_cache=False))


def test_the_stage_weighs_noisy_cells_out_of_force_and_centroid():
    # errors against the same frames without noise (the forward model's own error aside)
    scale, _ = _noise_scale(dark=100e-6)
    rng = np.random.default_rng(11)
    load = (0.0, 0.0, -0.3, 2e-3, 1e-3, 1e-3)
    truth = _displacement(ELASTOMER, [load], 0.0, rng)
    exact = _stage(False)
    exact.update(_points(np.zeros_like(truth)))
    want = exact.update(_points(truth))
    reference = rng.normal(0.0, 1.0, truth.shape) * scale
    frames = [truth + rng.normal(0.0, 1.0, truth.shape) * scale for _ in range(6)]
    errors = {}
    for enabled in (False, True):
        stage = _stage(enabled)
        stage.update(_points(reference))
        outs = [stage.update(_points(f)) for f in frames]
        errors[enabled] = (
            np.mean([np.linalg.norm(o.wrench_force - want.wrench_force) for o in outs]),
            np.mean([np.hypot(*np.subtract(o.contact.centroid[:2], want.contact.centroid[:2]))
                     for o in outs]),
            np.sqrt(np.mean([np.mean((o.displacement - truth) ** 2) for o in outs])),
            np.mean([abs(o.contact.area - want.contact.area) for o in outs]))
    # (a 5 x 5 dark patch is cleaned from its dark neighbours too: the resultant gains less
    # than the field)
    assert errors[True][0] < 0.85 * errors[False][0]
    assert errors[True][1] < 0.7 * errors[False][1]
    assert errors[True][2] < 0.4 * errors[False][2]
    assert errors[True][3] < 0.15 * want.contact.area


def test_the_stage_takes_the_noise_of_several_reference_frames_from_their_scatter():
    scale, dark = _noise_scale(dark=20e-6, clean=1e-6)
    rng = np.random.default_rng(4)
    stage = TouchStage(SensorConfig(ELASTOMER), SHAPE, PITCH,
                       params=TouchParams(reference_frames=4, solver_cache=False))
    for _ in range(4):
        stage.update(_points(rng.normal(0.0, 1.0, NOMINAL.shape) * scale))
    weights = stage.reference.weights
    inner = dark & _far_from(~dark, 1)
    assert np.median(weights.error[inner]) == pytest.approx(20e-6 * np.sqrt(1.25), rel=0.25)


def test_a_clean_pad_gives_the_same_bytes_with_or_without_weights():
    rng = np.random.default_rng(13)
    rest = _displacement(ELASTOMER, [], 1e-6, rng)
    disp = _displacement(ELASTOMER, [(0.02, 0.0, -0.4, 2e-3, 0.0, 5e-4)], 1e-6, rng)
    outs = []
    for enabled in (False, True):
        stage = _stage(enabled)
        stage.update(_points(rest))
        outs.append(stage.update(_points(disp)))
    a, b = outs
    assert np.array_equal(a.displacement, b.displacement)
    assert np.array_equal(a.force, b.force) and np.array_equal(a.wrench_force, b.wrench_force)
    assert a.contact == b.contact


def test_the_support_takes_each_cells_own_noise():
    # the contact area's constrained inversion judges its edge by each cell's noise: the
    # cells' expected errors where given, else displacement_noise on every cell
    stage = _stage(True)
    rng = np.random.default_rng(17)
    stage.update(_points(np.zeros((len(ROWS), 3))))
    disp = _displacement(ELASTOMER, [(0, 0, -0.3, 2e-3, 0.0, 0.0)], 0.0, rng)
    stage.update(_points(disp))
    solver, gain = stage.solver, stage.solver.support_gain
    nominal = solver.support_pressure(3e-6, 2.0, 5.0)
    same = solver.support_pressure(3e-6, 2.0, 5.0, cell_noise=3e-6 * gain)
    assert nominal is not None and np.array_equal(nominal, same)
    assert solver.support_pressure(3e-6, 2.0, 5.0, cell_noise=1e3 * 3e-6 * gain) is None


def test_a_noisy_map_leans_the_centroid_on_the_resultant():
    # the map puts the contact at (1, 1) mm, the resultant's moments at (1.3, 0.8) mm
    xy = NOMINAL[:, :2]
    forces = np.zeros((len(ROWS), 3))
    main = np.exp(-np.sum((xy - [1e-3, 1e-3]) ** 2, axis=1) / (2 * (1e-3) ** 2))
    forces[:, 2] = -0.5 * main / main.sum()
    wrench = np.zeros(6)
    wrench[2] = -0.5
    wrench[3], wrench[4] = 0.8e-3 * -0.5, -1.3e-3 * -0.5      # M_x = y F_z, M_y = -x F_z
    args = (xy, ROWS, COLS, forces, wrench, SHAPE, PITCH, np.zeros(SHAPE), False,
            ContactParams(area_fraction=0.2), (100.0, 100.0))   # resultant: 0.6 mm sd
    quiet = contact_state(*args, map_noise=np.full(len(ROWS), 1e-5),
                          centroid_noise=np.zeros(len(ROWS)))
    assert quiet.centroid[:2] == contact_state(*args).centroid[:2]
    noisy = contact_state(*args, map_noise=np.full(len(ROWS), 1e-5),
                          centroid_noise=np.full(len(ROWS), 2e-2))
    assert abs(quiet.centroid[0] - 1e-3) < 0.1e-3
    assert abs(noisy.centroid[0] - 1.3e-3) < abs(quiet.centroid[0] - 1.3e-3) - 0.1e-3
    # a third estimate, the pressure fitted on the contact's cells (touch/consistent.py),
    # counts by its variance: a sharp one decides, a vague one leaves the two others
    sharp = contact_state(*args, map_noise=np.full(len(ROWS), 1e-5),
                          centroid_noise=np.full(len(ROWS), 2e-2),
                          fit_centroid=(np.array([0.9e-3, 1.1e-3]), np.full(2, 1e-12)))
    assert np.allclose(sharp.centroid[:2], (0.9e-3, 1.1e-3), atol=5e-6)
    vague = contact_state(*args, map_noise=np.full(len(ROWS), 1e-5),
                          centroid_noise=np.full(len(ROWS), 2e-2),
                          fit_centroid=(np.array([0.9e-3, 1.1e-3]), np.full(2, 1.0)))
    assert np.allclose(vague.centroid[:2], noisy.centroid[:2], atol=1e-7)
