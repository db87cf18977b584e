"""The normal displacement fitted by the contact's pressure (touch/consistent.py)."""
import numpy as np
import pytest
from test_touch_stage import _points
from test_touch_traction import PITCH, SHAPE, _displacement
from test_touch_weights import COLS, ELASTOMER, NOMINAL, ROWS, _noise_scale, _stage

from tactile_sl_decoder.touch import consistent
from tactile_sl_decoder.touch.consistent import ConsistentField
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams, TouchStage
from tactile_sl_decoder.touch.traction import TractionSolver
from tactile_sl_decoder.touch.weights import WeightParams

LOAD = (0.0, 0.0, -0.3, 2e-3, 1e-3, 0.5e-3)      # Hertz, 2 mm contact radius


@pytest.fixture(scope="module")
def solver():
    return TractionSolver(ELASTOMER, PITCH, SHAPE, np.arange(SHAPE[0] * SHAPE[1]))


def _field(solver, sigma):
    return ConsistentField(solver.normal_forward(), sigma, solver.rows, solver.cols, SHAPE)


def _contact(load, margin=0.0):
    """The cells within the load's contact radius (+ ``margin``)."""
    return np.hypot(NOMINAL[:, 0] - load[4], NOMINAL[:, 1] - load[5]) < load[3] + margin


def _sigma(seed=0):
    """Per-cell errors of u_z: 2-12 um, varying from cell to cell (harsh light)."""
    return np.random.default_rng(seed).uniform(2e-6, 12e-6, len(ROWS))


def test_the_fit_removes_the_noise_no_pressure_on_the_contact_can_make(solver):
    rng = np.random.default_rng(1)
    truth = _displacement(ELASTOMER, [LOAD], 0.0, rng)[:, 2]
    sigma = _sigma()
    field = _field(solver, sigma)
    valid = np.ones(len(ROWS), bool)
    errors = []
    for _ in range(5):
        measured = truth + rng.normal(0.0, 1.0, len(ROWS)) * sigma
        fitted = field.fit(measured, valid, _contact(LOAD))
        assert fitted is not None
        assert 0.6 < field.last_chi2 < 1.6             # the model holds: chi^2 / dof ~ 1
        errors.append((np.sqrt(np.mean((measured - truth) ** 2)),
                       np.sqrt(np.mean((fitted - truth) ** 2))))
    before, after = np.mean(errors, axis=0)
    assert after < 0.5 * before
    # without noise the fit is the field itself (the forward model's own error aside)
    exact = field.fit(truth, valid, _contact(LOAD))
    assert np.max(np.abs(exact - truth)) < 0.03 * np.max(np.abs(truth))


def test_an_untouched_pad_is_flat_and_a_missed_contact_keeps_the_measured_field(solver):
    rng = np.random.default_rng(2)
    sigma = _sigma(3)
    field = _field(solver, sigma)
    valid = np.ones(len(ROWS), bool)
    noise = rng.normal(0.0, 1.0, len(ROWS)) * sigma
    flat = field.fit(noise, valid, np.zeros(len(ROWS), bool))
    assert flat is not None and not np.any(flat)    # nothing presses: u_z = 0
    # a second contact outside the cells given: no pressure there can explain its dent
    other = (0.0, 0.0, -0.2, 1.5e-3, -2.5e-3, -2e-3)
    both = _displacement(ELASTOMER, [LOAD, other], 0.0, rng)[:, 2] + noise
    assert field.fit(both, valid, _contact(LOAD)) is None
    assert field.last_chi2 > consistent.CHI2_LIMIT
    assert field.fit(both, valid, _contact(LOAD) | _contact(other)) is not None
    # a contact over most of the pad: the fit would remove little noise; not fitted
    assert field.fit(both, valid, np.ones(len(ROWS), bool)) is None


def test_cells_not_decoded_do_not_count_in_the_test(solver):
    rng = np.random.default_rng(4)
    sigma = _sigma(5)
    field = _field(solver, sigma)
    truth = _displacement(ELASTOMER, [LOAD], 0.0, rng)[:, 2]
    measured = truth + rng.normal(0.0, 1.0, len(ROWS)) * sigma
    valid = np.ones(len(ROWS), bool)
    valid[::7] = False
    measured[~valid] = 1.0                    # a fill far off: not a measurement
    field.fit(measured, valid, _contact(LOAD))
    assert field.last_chi2 > consistent.CHI2_LIMIT   # (the fill pulls the fit itself)
    measured[~valid] = truth[~valid]
    assert field.fit(measured, valid, _contact(LOAD)) is not None
    assert field.last_chi2 < 1.6


def test_the_stage_reports_the_fitted_normal_displacement_on_a_noisy_pad(monkeypatch):
    # the same frames with the fit and without it: u_z, the normal force and the centroid
    # closer to the truth; the shear and the resultant's line of action the same
    scale, _ = _noise_scale(dark=12e-6, clean=3e-6)
    rng = np.random.default_rng(11)
    truth = _displacement(ELASTOMER, [LOAD], 0.0, rng)
    reference = rng.normal(0.0, 1.0, truth.shape) * scale
    frames = [truth + rng.normal(0.0, 1.0, truth.shape) * scale for _ in range(4)]

    def run():
        stage = _stage(True)
        stage.update(_points(reference))
        return stage, [stage.update(_points(f)) for f in frames]

    stage, fitted = run()
    assert stage.reference.consistent is not None
    monkeypatch.setattr(ConsistentField, "fit", lambda self, *args, **kwargs: None)
    _, measured = run()
    for a, b in zip(fitted, measured):
        assert np.array_equal(a.force[:, :2], b.force[:, :2])
        assert np.array_equal(a.wrench_force[:2], b.wrench_force[:2])
        assert a.force[:, 2].sum() == pytest.approx(a.wrench_force[2], rel=1e-9)
        assert np.allclose(np.divide(a.wrench_moment[:2], a.wrench_force[2]),
                           np.divide(b.wrench_moment[:2], b.wrench_force[2]), rtol=1e-9)
        assert a.wrench_moment[2] == b.wrench_moment[2]
        assert np.array_equal(a.displacement[:, :2], b.displacement[:, :2])
    err = {name: np.sqrt(np.mean([np.mean((o.displacement[:, 2] - truth[:, 2]) ** 2)
                                  for o in outs]))
           for name, outs in (("fitted", fitted), ("measured", measured))}
    assert err["fitted"] < 0.6 * err["measured"]
    # the centroid takes the fitted pressure's as a third estimate
    off = {name: np.mean([np.hypot(o.contact.centroid[0] - LOAD[4],
                                   o.contact.centroid[1] - LOAD[5]) for o in outs])
           for name, outs in (("fitted", fitted), ("measured", measured))}
    assert off["fitted"] < 0.8 * off["measured"]
    normal = {name: np.mean([abs(-o.wrench_force[2] - 0.3) for o in outs])
              for name, outs in (("fitted", fitted), ("measured", measured))}
    assert normal["fitted"] < 0.8 * normal["measured"]


def _noisy_fit(solver, load, seed: int, sigma_seed: int):
    """A random generator, the load's true dz, the cells' noise, a fit with positions."""
    rng = np.random.default_rng(seed)
    truth = _displacement(ELASTOMER, [load], 0.0, rng)[:, 2]
    sigma = _sigma(sigma_seed)
    field = ConsistentField(solver.normal_forward(), sigma, solver.rows, solver.cols, SHAPE,
                            NOMINAL)
    return rng, truth, sigma, field, np.ones(len(ROWS), bool)


def test_the_fitted_pressure_gives_a_centroid_with_its_variance(solver):
    rng, truth, sigma, field, valid = _noisy_fit(solver, LOAD, 21, 22)
    z, zf = [], []
    for _ in range(20):
        measured = truth + rng.normal(0.0, 1.0, len(ROWS)) * sigma
        assert field.fit(measured, valid, _contact(LOAD)) is not None
        centre, var = field.last_centroid
        assert np.all(var > 0)
        z.append((centre - LOAD[4:6]) / np.sqrt(var))
        force, force_var = field.last_force
        zf.append((force + LOAD[2]) / np.sqrt(force_var))
    # (the cells' pressure at cell resolution: exact to well below its noise here)
    assert 0.5 < np.sqrt(np.mean(np.square(z))) < 2.0
    assert 0.5 < np.sqrt(np.mean(np.square(zf))) < 2.0
    assert _field(solver, sigma).fit(truth, valid, _contact(LOAD)) is not None
    assert _field(solver, sigma).last_centroid is None           # no positions given


def test_a_clean_pad_or_a_few_noisy_cells_get_no_fit():
    stage = _stage(True)
    stage.update(_points(_displacement(ELASTOMER, [], 1e-6, np.random.default_rng(13))))
    assert len(stage.reference.weights.noisy) == 0 and stage.reference.consistent is None
    # a speck of dust: cleaned from its clean neighbours, the field kept
    scale = np.full((len(ROWS), 3), 1e-6)
    scale[(np.abs(ROWS - 15) <= 1) & (np.abs(COLS - 13) <= 1)] = 30e-6
    stage = _stage(True)
    stage.update(_points(np.random.default_rng(14).normal(0.0, 1.0, scale.shape) * scale))
    noisy = len(stage.reference.weights.noisy)
    assert 0 < noisy <= consistent.MIN_NOISY_SHARE * len(ROWS)
    assert stage.reference.consistent is None


def test_the_fit_can_be_turned_off():
    scale, _ = _noise_scale(dark=12e-6, clean=3e-6)
    reference = np.random.default_rng(15).normal(0.0, 1.0, scale.shape) * scale
    on, off = (TouchStage(SensorConfig(ELASTOMER), SHAPE, PITCH,
                          params=TouchParams(weights=WeightParams(fit_normal=fit),
                                             solver_cache=False)) for fit in (True, False))
    for stage in (on, off):
        stage.update(_points(reference))
    assert on.reference.consistent is not None and off.reference.consistent is None


def test_the_normal_force_combines_the_resultant_and_the_fit_by_their_variances(solver):
    field = ConsistentField(solver.normal_forward(), _sigma(), solver.rows, solver.cols,
                            SHAPE, NOMINAL, resultant_sd=0.02)
    assert field.normal_force(0.3) is None                     # nothing fitted yet
    field.last_force = (0.25, 0.01 ** 2)                        # 4 x the resultant's weight
    assert field.normal_force(0.3) == pytest.approx((0.3 + 4 * 0.25) / 5)
    assert field.normal_force(-0.1) is None                     # the resultant pulls
    field.resultant_sd = 0.0
    assert field.normal_force(0.3) is None                      # no noise model: as it was


def test_a_faint_contact_is_fitted_per_block_of_cells(solver):
    # a wide, faint load under strong noise: its pressure uniform over 2 x 2 cells, a
    # quarter of the unknowns, still explains the field and removes more of the noise
    faint = (0.0, 0.0, -0.05, 3e-3, 0.5e-3, 0.0)
    rng, truth, sigma, field, valid = _noisy_fit(solver, faint, 31, 32)
    core = _contact(faint)
    errors, forces = [], []
    for _ in range(5):
        measured = truth + rng.normal(0.0, 1.0, len(ROWS)) * sigma
        fine = field.fit(measured, valid, core)
        cells = field.last_cells
        coarse = field.fit(measured, valid, core, coarse=True)
        assert fine is not None and coarse is not None
        assert cells / 4 <= field.last_cells < cells / 2       # blocks of 2 x 2 cells
        assert field.last_chi2 < 1.6
        forces.append(field.last_force[0])
        errors.append([np.sqrt(np.mean((x - truth) ** 2)) for x in (measured, fine, coarse)])
    measured_err, fine_err, coarse_err = np.mean(errors, axis=0)
    assert coarse_err < fine_err < measured_err
    assert np.mean(forces) == pytest.approx(0.05, rel=0.05)
