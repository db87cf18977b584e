"""Codeword decoding: single-error correction, erasures, voting and 'never a wrong cell'."""
import numpy as np
import pytest

from tactile_sl_decoder.decode.codewords import (
    Codebook,
    CodewordDecoder,
    DecodeParams,
    PatternError,
)
from tactile_sl_decoder.decode.grid import build_grid

from small_patterns import make_pattern

PATTERN = make_pattern()
ROWS, COLS = PATTERN.shape


@pytest.fixture(scope="module")
def codebook():
    return Codebook(PATTERN, (3, 3), 3)


def _scene(spacing=18.0, mirrored=False):
    R, C = np.meshgrid(np.arange(ROWS), np.arange(COLS), indexing="ij")
    R, C = R.ravel(), C.ravel()
    u = 30 + (COLS - 1 - C if mirrored else C) * spacing
    v = 30 + R * spacing
    return u, v, R, C


def test_every_window_decodes_exactly_and_with_any_single_substitution(codebook):
    wins = codebook.windows                      # (M, 9)
    conf = np.ones(wins.shape)
    assert np.array_equal(codebook.decode_windows(wins, conf), codebook.window_cells)
    for p in range(9):
        for shift in (1, 2):
            w = wins.copy()
            w[:, p] = (w[:, p] + shift) % 3
            assert np.array_equal(codebook.decode_windows(w, conf, retry_confidence=0),
                                  codebook.window_cells)


def test_up_to_two_unknown_cells_decode_and_three_do_not(codebook):
    wins = codebook.windows
    conf = np.ones(wins.shape)
    for a in range(9):
        for b in range(a + 1, 9):
            w = wins.copy()
            w[:, [a, b]] = 255
            assert np.array_equal(codebook.decode_windows(w, conf), codebook.window_cells)
    w = wins.copy()
    w[:, [0, 4, 8]] = 255
    assert np.all(codebook.decode_windows(w, conf) == -1)


def test_two_substitutions_never_decode_to_a_wrong_window_with_retry_off(codebook):
    """Two errors are beyond the radius: the table answers 'none' or the nearest window,
    which for h = 3 can be wrong; such windows must be caught by voting (next tests)."""
    wins = codebook.windows
    rng = np.random.default_rng(1)
    w = wins.copy()
    for i in range(len(w)):
        p = rng.choice(9, 2, replace=False)
        w[i, p] = (w[i, p] + rng.integers(1, 3, 2)) % 3
    cells = codebook.decode_windows(w, np.ones(w.shape), retry_confidence=0)
    assert np.mean(cells == -1) > 0.5           # mostly detected as undecodable


def test_low_confidence_label_is_erased_to_break_the_tie(codebook):
    wins = codebook.windows
    w = wins.copy()
    w[:, 0] = 255                                # one unknown ...
    w[:, 5] = (w[:, 5] + 1) % 3                  # ... plus one error: beyond 1-error radius
    conf = np.full(w.shape, 0.99)
    conf[:, 5] = 0.4                             # but the wrong label is the uncertain one
    assert np.array_equal(codebook.decode_windows(w, conf), codebook.window_cells)
    assert np.all(codebook.decode_windows(w, np.full(w.shape, 0.99)) == -1)


def test_invalid_patterns_are_rejected():
    with pytest.raises(PatternError, match="repeated"):
        Codebook(np.zeros((5, 5), np.uint8), (3, 3), 3)
    with pytest.raises(PatternError):
        Codebook(np.zeros((2, 2), np.uint8), (3, 3), 3)


def test_pattern_violating_its_min_hamming_never_decodes_ambiguous_codes():
    pat = PATTERN.copy()
    # make two windows differ in exactly 2 cells: copy a window and change 2 of its cells
    pat[6:9, 6:9] = pat[0:3, 0:3]
    pat[7, 7] = (pat[7, 7] + 1) % 3
    pat[8, 8] = (pat[8, 8] + 1) % 3
    try:
        cb = Codebook(pat, (3, 3), 3)
    except PatternError:
        return
    # the code halfway between the two windows must not decode
    mid = pat[6:9, 6:9].reshape(-1).copy()
    mid[4] = pat[1, 1]
    assert cb.decode_windows(mid[None, :], np.ones((1, 9)), 0)[0] == -1


def _run(decoder, labels, u, v):
    grid = build_grid(u, v)
    return decoder.decode(grid, labels, np.full(len(u), 0.95, np.float32))


@pytest.mark.parametrize("rate", [0.05, 0.10, 0.20])
def test_flipped_labels_are_corrected_without_wrong_cells(codebook, rate):
    u, v, R, C = _scene()
    dec = CodewordDecoder(codebook)
    right_total = 0
    for seed in range(30):
        rng = np.random.default_rng(seed)
        lab = PATTERN[R, C].copy()
        flip = rng.random(len(lab)) < rate
        lab[flip] = (lab[flip] + rng.integers(1, 3, flip.sum())) % 3
        d = _run(dec, lab, u, v)
        right = (d.row == R) & (d.col == C)
        assert not np.any(d.decoded & ~right)
        right_total += right.sum()
    assert right_total / (30 * len(u)) > {0.05: 0.99, 0.10: 0.98, 0.20: 0.95}[rate]


def test_random_labels_decode_nothing(codebook):
    u, v, R, C = _scene()
    dec = CodewordDecoder(codebook)
    for seed in range(40):
        lab = np.random.default_rng(seed).integers(0, 3, len(u)).astype(np.uint8)
        assert _run(dec, lab, u, v).decoded.sum() == 0


@pytest.mark.parametrize("size", [3, 4])
def test_pasted_pattern_fragment_never_gives_wrong_cells(codebook, size):
    """Adversarial: a block reads exactly like another place of the pattern."""
    u, v, R, C = _scene()
    dec = CodewordDecoder(codebook)
    for seed in range(60):
        rng = np.random.default_rng(seed)
        lab = PATTERN.copy()
        r1, c1 = rng.integers(0, ROWS - size + 1), rng.integers(0, COLS - size + 1)
        r2, c2 = rng.integers(0, ROWS - size + 1), rng.integers(0, COLS - size + 1)
        lab[r1:r1 + size, c1:c1 + size] = PATTERN[r2:r2 + size, c2:c2 + size]
        d = _run(dec, lab.reshape(-1), u, v)
        assert not np.any(d.decoded & ~((d.row == R) & (d.col == C)))


def test_unknown_labels_and_missing_glyphs(codebook):
    u, v, R, C = _scene()
    rng = np.random.default_rng(7)
    keep = rng.random(len(u)) > 0.05
    lab = PATTERN[R, C].copy()
    lab[rng.random(len(u)) < 0.05] = 255
    u, v, R, C, lab = u[keep], v[keep], R[keep], C[keep], lab[keep]
    d = _run(CodewordDecoder(codebook), lab, u, v)
    right = (d.row == R) & (d.col == C)
    assert not np.any(d.decoded & ~right)
    assert right.mean() > 0.9


def test_mirrored_setting_reverses_columns(codebook):
    u, v, R, C = _scene(mirrored=True)
    lab = PATTERN[R, C]
    d = _run(CodewordDecoder(codebook, DecodeParams(mirrored=True)), lab, u, v)
    assert np.all((d.row == R) & (d.col == C))
    d = _run(CodewordDecoder(codebook, DecodeParams(mirrored=False)), lab, u, v)
    assert d.decoded.sum() == 0


def test_a_decoder_reused_across_frames_and_image_counts_decodes_like_a_new_one(codebook):
    """The decoder keeps per-frame tables between calls: reuse must not change any cell."""
    u, v, R, C = _scene()
    frames = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        lab = PATTERN[R, C].copy()
        flip = rng.random(len(lab)) < 0.1
        lab[flip] = (lab[flip] + rng.integers(1, 3, flip.sum())) % 3
        frames.append(lab)
    reused = CodewordDecoder(codebook)
    two = np.concatenate([u, u + 1e4]), np.concatenate([v, v])
    for lab in frames + frames[::-1]:
        for labels, (uu, vv), groups in ((lab, (u, v), None),
                                         (np.concatenate([lab, lab[::-1]]), two,
                                          np.repeat([0, 1], len(u)))):
            conf = np.full(len(uu), 0.95, np.float32)
            grid = build_grid(uu, vv)
            a = reused.decode(grid, labels, conf, groups)
            b = CodewordDecoder(codebook).decode(grid, labels, conf, groups)
            assert np.array_equal(a.row, b.row) and np.array_equal(a.col, b.col)
            assert a.decoded.sum() > 0
