"""Contact area from the support of the constrained traction (touch/support.py).

The compiled ``support_regions`` is checked against the numpy version it is written from
(kept here as the reference); the edge law's tables against their definitions; and the areas
of cell-averaged pressures of a sphere, a flat punch and a uniform disc against the truth.
"""
import cv2
import numpy as np
import pytest
from scipy import ndimage

from tactile_sl_decoder.touch.support import (
    THIN_BETA,
    edge_coverage,
    edge_exponent,
    edge_ratio,
    nearest_seed_label,
    ring_ratio,
    support_regions,
)

_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)
_NEIGHBOURS = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.float32)


def _mean_of_neighbours(values, where):
    num = cv2.filter2D(np.where(where, values, 0.0).astype(np.float32), -1, _NEIGHBOURS,
                       borderType=cv2.BORDER_CONSTANT)
    den = cv2.filter2D(where.astype(np.float32), -1, _NEIGHBOURS,
                       borderType=cv2.BORDER_CONSTANT)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / den, np.nan)


def reference_support_regions(pressure, noise, sigmas):
    """The numpy version: (labels, share, support, area, cells, edge_snr, beta, peak)."""
    support = pressure > sigmas * noise
    count, labels = cv2.connectedComponents(support.astype(np.uint8), connectivity=8)
    share = np.zeros(pressure.shape)
    beta = np.full(count, THIN_BETA)
    inner = cv2.erode(support.astype(np.uint8), _CROSS, borderType=cv2.BORDER_CONSTANT,
                      borderValue=0).astype(bool)
    inner2 = cv2.erode(inner.astype(np.uint8), _CROSS, borderType=cv2.BORDER_CONSTANT,
                       borderValue=0).astype(bool)
    ring1 = inner & ~inner2
    boundary = support & ~inner

    def per_region(values, mask):
        return np.bincount(labels[mask], weights=values[mask], minlength=count)

    ring_n = np.bincount(labels[ring1], minlength=count)
    core_n = np.bincount(labels[inner2], minlength=count)
    ring_f, core_f = per_region(pressure, ring1), per_region(pressure, inner2)
    for k in np.flatnonzero((ring_n > 0) & (core_n > 0) & (core_f > 0)):
        beta[k] = edge_exponent((ring_f[k] / ring_n[k]) / (core_f[k] / core_n[k]))
    sig = np.where(np.isfinite(noise), noise, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(ring_n > 0, ring_f / per_region(sig, ring1),
                       per_region(pressure, support) / per_region(sig, support))
    snr[0] = 0.0
    share[inner] = 1.0
    inward = _mean_of_neighbours(pressure, inner)
    b = boundary & np.isfinite(inward) & (inward > 0)
    share[boundary] = 1.0
    share[b] = edge_coverage(pressure[b] / inward[b], beta[labels[b]])
    grown = cv2.dilate(support.astype(np.uint8), _CROSS, borderType=cv2.BORDER_CONSTANT,
                       borderValue=0).astype(bool)
    outer = grown & ~support & (pressure > 0)
    owner = np.zeros_like(labels)
    for r, c in zip(*np.nonzero(outer)):
        best = -1.0
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            rr, cc = r + dr, c + dc
            if 0 <= rr < labels.shape[0] and 0 <= cc < labels.shape[1] and support[rr, cc]:
                if pressure[rr, cc] > best:
                    best, owner[r, c] = pressure[rr, cc], labels[rr, cc]
    nb = _mean_of_neighbours(pressure, support)
    o = outer & np.isfinite(nb) & (nb > 0)
    labels[o] = owner[o]
    share[o] = edge_coverage(pressure[o] / nb[o], beta[owner[o]])
    area = np.bincount(labels.ravel(), weights=share.ravel(), minlength=count)
    cells = np.bincount(labels[support], minlength=count)
    peak = np.zeros(count, np.int64)
    flat = np.where(support, labels, 0).ravel()
    for k in range(1, count):
        idx = np.flatnonzero(flat == k)
        peak[k] = idx[int(np.argmax(pressure.ravel()[idx]))]
    return labels, share, support, area, cells, snr, beta, peak


def _cell_averaged(shape, profile, centre, radius, sub=20):
    """Cell-averaged pressure (1 cell = 1 unit) of 'hertz', 'punch' or 'uniform' discs."""
    rows, cols = shape
    s = (np.arange(sub) + 0.5) / sub - 0.5
    r = np.arange(rows)[:, None, None, None] + s[None, None, :, None]
    c = np.arange(cols)[None, :, None, None] + s[None, None, None, :]
    d = np.hypot(r - centre[0], c - centre[1]) / radius
    inside = d < 1
    if profile == "hertz":
        p = np.sqrt(np.clip(1 - d * d, 0, None))
    elif profile == "punch":
        p = np.where(inside, 1 / np.sqrt(np.clip(1 - d * d, 1e-4, None)), 0.0)
    else:
        p = inside.astype(float)
    return p.mean(axis=(2, 3)), inside.mean(axis=(2, 3)).sum()


def test_edge_tables_invert_their_definitions():
    c = np.linspace(0.02, 0.98, 25)
    for beta in (-0.5, -0.2, 0.0, 0.3, 0.5):
        assert edge_coverage(edge_ratio(c, beta), np.full(c.shape, beta)) == pytest.approx(
            c, abs=2e-3)
        assert edge_exponent(float(ring_ratio(beta))) == pytest.approx(beta, abs=1e-3)
    # the edge law: a uniform pressure's share is the force ratio; a punch's rim cell carries
    # more than its neighbour when it is half covered, a sphere's much less
    assert edge_ratio(0.5, 0.0) == pytest.approx(0.5)
    assert edge_ratio(0.5, -0.5) > 1.3 and edge_ratio(0.5, 0.5) < 0.3
    assert ring_ratio(-0.5) > 1.4 and ring_ratio(0.5) < 0.75


@pytest.mark.parametrize("profile, expect_beta", [("hertz", 0.5), ("punch", -0.5),
                                                   ("uniform", 0.0)])
def test_area_of_cell_averaged_discs(profile, expect_beta):
    """Exact cell averages of a disc of 4.3 cells: the area within 5 %, the edge law's sign."""
    pressure, true_cells = _cell_averaged((20, 20), profile, (9.3, 10.4), 4.3)
    pressure *= 0.05 / pressure.max()
    noise = np.full(pressure.shape, 1e-4)
    found = support_regions(pressure, noise, 2.0)
    assert found.labels.max() == 1 and found.edge_snr[1] > 20
    assert found.area_cells[1] == pytest.approx(true_cells, rel=0.05)
    assert np.sign(found.beta[1]) == np.sign(expect_beta) or abs(found.beta[1]) < 0.15


def test_faint_and_empty_maps():
    quiet = np.zeros((6, 7))
    noise = np.full((6, 7), 1e-3)
    assert support_regions(quiet, noise, 2.0).labels.max() == 0
    one = quiet.copy()
    one[3, 3] = 3e-3                     # a lone cell 3 sigma up: a region with a weak edge
    found = support_regions(one, noise, 2.0)
    assert found.cells[1] == 1 and found.edge_snr[1] == pytest.approx(3.0)


def test_compiled_regions_equal_the_numpy_version():
    rng = np.random.default_rng(0)
    for _ in range(300):
        rows, cols = rng.integers(3, 30, 2)
        r, c = np.mgrid[0:rows, 0:cols].astype(float)
        pressure = np.zeros((rows, cols))
        for _ in range(rng.integers(1, 4)):
            d = np.hypot(r - rng.uniform(0, rows), c - rng.uniform(0, cols)) / rng.uniform(0.5, 6)
            kind = rng.integers(0, 3)
            profile = (np.sqrt(np.clip(1 - d ** 2, 0, None)) if kind == 0 else
                       np.where(d < 1, 1 / np.sqrt(np.clip(1 - d ** 2, 0.05, None)), 0)
                       if kind == 1 else (d < 1) * 1.0)
            pressure += profile * rng.uniform(1e-3, 3e-2)
        noise = np.full((rows, cols), 7e-4)
        pressure = np.maximum(pressure + rng.normal(0, 7e-4, pressure.shape), 0)
        if rng.random() < 0.3:
            noise[rng.random((rows, cols)) < 0.2] = np.inf
            pressure[~np.isfinite(noise)] = 0
        labels, share, support, area, cells, snr, beta, peak = reference_support_regions(
            pressure, noise, 2.0)
        got = support_regions(pressure, noise, 2.0)
        assert np.array_equal(got.support, support)
        # the same regions, numbered in another order: a's number -> b's
        to = np.zeros(len(cells), np.int64)
        to[labels[support]] = got.labels[got.support]
        assert np.array_equal(to[labels] * (labels > 0), got.labels)
        k = np.arange(1, len(cells))
        assert np.array_equal(cells[k], got.cells[to[k]])
        assert np.array_equal(peak[k], got.peak[to[k]])
        assert np.allclose(beta[k], got.beta[to[k]], atol=1e-12)
        assert np.allclose(snr[k], got.edge_snr[to[k]], rtol=1e-12)
        # the numpy version averages neighbours in float32 (cv2.filter2D)
        assert np.allclose(share, got.share, atol=1e-5)
        assert np.allclose(area[k], got.area_cells[to[k]], atol=1e-4)


def test_nearest_seed_label_equals_the_distance_transform():
    rng = np.random.default_rng(5)
    for _ in range(200):
        rows, cols = rng.integers(2, 30, 2)
        labels = rng.integers(1, 4, (rows, cols)).astype(np.int32)
        seeds = rng.random((rows, cols)) < rng.uniform(0.02, 0.6)
        seeds[rng.integers(rows), rng.integers(cols)] = True
        r, c = (a.ravel() for a in np.mgrid[0:rows, 0:cols])
        got = nearest_seed_label(labels, seeds, r, c)
        dist, (nr, nc) = ndimage.distance_transform_edt(~seeds, return_indices=True)
        want = labels[nr, nc].ravel()
        # where two seeds of different labels are equally near either may win
        sr, sc = np.nonzero(seeds)
        d2 = (sr[None, :] - r[:, None]) ** 2 + (sc[None, :] - c[:, None]) ** 2
        nearest = d2 == d2.min(axis=1, keepdims=True)
        tie = np.array([len(set(labels[sr[m], sc[m]])) > 1 for m in nearest])
        assert np.array_equal(got[~tie], want[~tie])
        assert all(g in labels[sr[m], sc[m]] for g, m in zip(got[tie], nearest[tie]))
        assert np.allclose(dist.ravel() ** 2, d2.min(axis=1))
