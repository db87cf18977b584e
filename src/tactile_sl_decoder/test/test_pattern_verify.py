"""Verifier: exact minimum distance, and it catches every kind of broken pattern."""
from __future__ import annotations

import numpy as np
import pytest

from tactile_sl_decoder.pattern import Constraints, load_default_pattern, verify_array
from tactile_sl_decoder.pattern.verify import window_matrix

K3H3 = Constraints(3, (3, 3), 3)


def brute_min_distance(array: np.ndarray, window: tuple[int, int]) -> int:
    w = window_matrix(array, window)
    best = w.shape[1]
    for i in range(len(w)):
        d = (w[i + 1:] != w[i]).sum(axis=1)
        if len(d):
            best = min(best, int(d.min()))
    return best


@pytest.mark.parametrize("k,window,shape,seed", [
    (2, (3, 3), (9, 11), 0), (3, (3, 3), (12, 10), 1), (5, (3, 4), (10, 12), 2),
    (8, (4, 3), (9, 9), 3), (2, (7, 7), (12, 13), 4), (6, (3, 3), (20, 20), 5),
])
def test_min_distance_matches_brute_force(k, window, shape, seed):
    rng = np.random.default_rng(seed)
    array = rng.integers(0, k, shape)
    cert = verify_array(array, Constraints(k, window, 1))
    assert cert.min_distance == brute_min_distance(array, window)
    n_windows = cert.windows
    assert sum(cert.histogram.values()) == n_windows * (n_windows - 1) // 2


def test_shipped_pattern_is_valid_and_large():
    pattern = load_default_pattern()
    cert = verify_array(pattern.array, pattern.constraints)
    assert cert.valid, cert.problems
    assert pattern.constraints == K3H3
    assert cert.windows >= 676  # acceptance: at least 28x28
    assert cert.min_distance >= 3
    assert "VALID" in cert.text()


def test_planted_duplicate_window_is_caught():
    array = load_default_pattern().array.copy()
    array[20:23, 15:18] = array[0:3, 0:3]
    cert = verify_array(array, K3H3)
    assert not cert.valid
    assert cert.min_distance == 0
    assert cert.histogram[0] >= 1
    assert any("identical" in p for p in cert.problems)
    assert cert.closest_pair is not None
    (r0, c0), (r1, c1) = cert.closest_pair
    assert np.array_equal(array[r0:r0 + 3, c0:c0 + 3], array[r1:r1 + 3, c1:c1 + 3])


def test_planted_distance_two_pair_is_caught():
    array = load_default_pattern().array.copy()
    array[20:23, 15:18] = array[0:3, 0:3]
    array[20, 15] = (array[20, 15] + 1) % 3
    array[22, 17] = (array[22, 17] + 1) % 3
    cert = verify_array(array, K3H3)
    assert not cert.valid
    assert cert.min_distance <= 2
    assert any("minimum distance" in p for p in cert.problems)
    # the same array passes plain uniqueness if no duplicate was created
    if cert.min_distance > 0:
        assert verify_array(array, Constraints(3, (3, 3), 1)).valid


def test_bad_symbol_and_bad_shapes():
    array = load_default_pattern().array.copy().astype(np.int64)
    array[4, 5] = 3
    cert = verify_array(array, K3H3)
    assert not cert.valid and "outside 0..2" in cert.problems[0]
    assert "(row 4, col 5)" in cert.problems[0]
    assert not verify_array(np.zeros(10), K3H3).valid
    assert "smaller" in verify_array(np.zeros((2, 9), int), K3H3).problems[0]


def test_verifier_is_fast_for_100x100():
    import time
    array = np.random.default_rng(0).integers(0, 6, (100, 100))
    start = time.monotonic()
    cert = verify_array(array, Constraints(6, (3, 3), 3))
    assert time.monotonic() - start < 10
    assert cert.windows == 98 * 98
