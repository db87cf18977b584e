"""Small valid M-arrays for decoder tests, shared by test_codewords and test_pipeline."""
import numpy as np


def make_pattern(rows=12, cols=14, seed=0, k=3, h=3):
    """Small valid M-array (3x3 windows, min Hamming h) by randomised backtracking."""
    rng = np.random.default_rng(seed)
    n = rows * cols
    a = np.zeros((rows, cols), int)
    order = [rng.permutation(k) for _ in range(n)]
    choice = [0] * n
    wins = np.zeros(((rows - 2) * (cols - 2), 9), int)
    nw = [0] * (n + 1)
    i = steps = 0
    while i < n:
        steps += 1
        assert steps < 200000, "pattern search failed"
        if choice[i] >= k:
            choice[i] = 0
            order[i] = rng.permutation(k)
            i -= 1
            choice[i] += 1
            continue
        r, c = divmod(i, cols)
        a[r, c] = order[i][choice[i]]
        m = nw[i]
        if r >= 2 and c >= 2:
            w = a[r - 2:r + 1, c - 2:c + 1].reshape(-1)
            if m and (wins[:m] != w).sum(1).min() < h:
                choice[i] += 1
                continue
            wins[m] = w
            m += 1
        nw[i + 1] = m
        i += 1
        if i < n:
            choice[i] = 0
    return a.astype(np.uint8)
