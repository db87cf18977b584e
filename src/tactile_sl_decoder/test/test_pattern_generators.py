"""Generators: verified output, determinism per seed, honest failures; the window index."""
from __future__ import annotations

import numpy as np
import pytest

from tactile_sl_decoder.pattern import Constraints, load_default_pattern, verify_array
from tactile_sl_decoder.pattern.generators import (
    GENERATORS,
    GenerationFailed,
    base,
    dfs,
    generate,
    linear,
    pyramid,
)

SMALL = [
    (Constraints(3, (3, 3), 3), (10, 10)),
    (Constraints(3, (3, 3), 1), (20, 18)),
    (Constraints(2, (3, 4), 1), (9, 10)),
    (Constraints(5, (3, 3), 3), (16, 16)),
    (Constraints(4, (3, 3), 3), (14, 14)),
]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(GENERATORS))
@pytest.mark.parametrize("constraints,size", SMALL)
def test_each_generator_output_verifies_and_is_deterministic(name, constraints, size):
    first = generate(name, constraints, *size, seed=7, time_limit=20)
    assert first.array.shape == size
    cert = verify_array(first.array, constraints)
    assert cert.valid, cert.problems
    again = generate(name, constraints, *size, seed=7, time_limit=20)
    assert np.array_equal(first.array, again.array)


@pytest.mark.parametrize("name", ["fill-and-test", "pyramid", "dfs"])
def test_seeds_change_the_pattern(name):
    c = Constraints(3, (3, 3), 1)
    a = generate(name, c, 12, 12, seed=1, time_limit=10).array
    b = generate(name, c, 12, 12, seed=2, time_limit=10).array
    assert not np.array_equal(a, b)


def test_shipped_size_is_reached_by_our_generator():
    c = Constraints(3, (3, 3), 3)
    result = generate("auto", c, 30, 28, seed=0, time_limit=30)
    cert = verify_array(result.array, c)
    assert cert.valid and cert.windows == 728
    # the shipped file records how it was made; that recipe must still reproduce it
    shipped = load_default_pattern()
    recipe = shipped.extra["generator"]
    assert (recipe["algorithm"], recipe["seed"]) == ("auto", 0)
    assert np.array_equal(result.array, shipped.array)


@pytest.mark.slow
def test_k6_100x100_under_a_minute():
    c = Constraints(6, (3, 3), 3)
    result = generate("auto", c, 100, 100, seed=0, time_limit=60)
    assert result.seconds < 60
    assert verify_array(result.array, c).valid


@pytest.mark.parametrize("name", ["fill-and-test", "pyramid", "dfs", "auto"])
def test_impossible_size_fails_with_reason(name):
    # 38 x 38 windows > sphere-packing bound 512 / 10 = 51 for binary 3x3 h=3
    c = Constraints(2, (3, 3), 3)
    with pytest.raises(GenerationFailed) as info:
        generate(name, c, 40, 40, seed=0, time_limit=0.5)
    assert info.value.reason


def test_linear_rejects_non_prime_power_alphabet():
    with pytest.raises(GenerationFailed, match="prime-power"):
        linear.generate(Constraints(6, (3, 3), 3), 10, 10)


def test_sizes_beyond_the_code_bound_fail_immediately():
    with pytest.raises(GenerationFailed, match="impossible.*1600 windows.*937"):
        generate("dfs", Constraints(3, (3, 3), 3), 42, 42, time_limit=60)


@pytest.mark.parametrize("q", [4, 8])
def test_extension_fields_and_their_m_sequences(q):
    F = linear.field(q)
    for a in range(1, q):  # every non-zero element has an inverse, mul distributes
        assert sum(F.mul[a][b] == 1 for b in range(q)) == 1
        for b in range(q):
            for c in range(q):
                assert F.mul[a][F.add[b][c]] == F.add[F.mul[a][b]][F.mul[a][c]]
    poly = linear.primitive_polynomials(q, 3, 1)[0]
    seq = linear.m_sequence(poly, q)
    ext = np.concatenate([seq, seq[:2]])
    assert len(seq) == q ** 3 - 1
    assert len({tuple(ext[i:i + 3]) for i in range(len(seq))}) == q ** 3 - 1


def test_unknown_algorithm():
    with pytest.raises(ValueError, match="unknown algorithm"):
        generate("magic", Constraints(3, (3, 3), 1), 5, 5)


def test_m_sequence_is_maximal():
    polys = linear.primitive_polynomials(3, 6)
    assert len(polys) == 48  # phi(728) / 6
    seq = linear.m_sequence(polys[0], 3)
    assert len(seq) == 728
    ext = np.concatenate([seq, seq[:5]])
    states = {tuple(ext[i:i + 6]) for i in range(728)}
    assert len(states) == 728 and (0,) * 6 not in states
    assert not linear.is_primitive([1, 0, 1], 2)  # x^2 + 1 = (x + 1)^2 over GF(2)
    assert linear.is_primitive([1, 1, 1], 2)      # x^2 + x + 1


def test_luby_sequence():
    assert [dfs.luby(i) for i in range(1, 16)] == [1, 1, 2, 1, 1, 2, 4, 1, 1, 2, 1, 1, 2, 4, 8]


@pytest.mark.slow
@pytest.mark.parametrize("h", [1, 2, 3, 4, 5])
def test_window_index_dense_and_scan_agree_with_brute_force(monkeypatch, h):
    c = Constraints(3, (3, 3), h)
    rng = np.random.default_rng(h)
    dense = base.WindowIndex(c, 64)
    monkeypatch.setattr(base, "DENSE_LIMIT", 0)
    scan = base.WindowIndex(c, 4)  # small capacity: exercises growth
    assert dense.dense and not scan.dense
    placed: list[np.ndarray] = []
    for _ in range(300):
        cand = rng.integers(0, 3, (5, 9)).astype(np.uint8)
        truth = np.array([all((w != x).sum() >= h for w in placed) for x in cand])
        assert np.array_equal(dense.allowed(cand), truth)
        assert np.array_equal(scan.allowed(cand), truth)
        hit = np.flatnonzero(truth)
        if len(hit):
            dense.add(cand[hit[0]])
            scan.add(cand[hit[0]])
            placed.append(cand[hit[0]])
        if len(placed) > 3 and rng.random() < 0.3:  # removal, as backtracking does
            gone = placed.pop(int(rng.integers(len(placed))))
            dense.remove(gone)
            scan.remove(gone)


def test_pyramid_regions_cover_the_interior():
    from tactile_sl_decoder.pattern.generators.steps import StepFiller
    c = Constraints(3, (3, 3), 1)
    filler = StepFiller(c, 12, 10, np.random.default_rng(0))
    base_steps, regions = pyramid._regions(filler, 3)
    assert len(base_steps) + sum(map(len, regions)) == len(filler.steps)
    assert len(regions) == 3  # interior rows 3..11 in bands of 3


@pytest.mark.slow
def test_tidy_keeps_validity_and_puts_the_constant_row_on_circles():
    c = Constraints(3, (3, 3), 3)
    plain = generate("linear", c, 30, 28, seed=0, time_limit=30).array
    tidy = generate("linear", c, 30, 28, seed=0, time_limit=30, tidy=True).array
    assert verify_array(tidy, c).valid
    constant = [row[0] for row in tidy if (row == row[0]).all()]
    assert constant == [1]
    assert linear.quality_penalty(tidy) <= linear.quality_penalty(plain)
    with pytest.raises(ValueError, match="tidy"):
        generate("dfs", c, 10, 10, tidy=True)
