"""Upper bounds on how many windows (hence how large an array) the constraints allow.

The windows of a valid pattern form a code of length m*n over k symbols with minimum
distance h, so (rows-m+1)*(cols-n+1) <= A_k(m*n, h), the largest such code. We use the
sphere-packing (Hamming) and Singleton bounds, exact values for h <= 2, and a small table
of best-known bounds from the coding-theory tables for the cases this project cares about.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import comb, isqrt

from .constraints import Constraints

KNOWN_BOUNDS: dict[tuple[int, int, int], tuple[int, int, str]] = {
    # (q, n, d): (best known lower bound, best known upper bound, source)
    (3, 9, 3): (729, 937, "ternary code tables (Brouwer): 729 <= A_3(9,3) <= 937; "
                          "729 from the linear [9,6,3] shortened Hamming code"),
}


@dataclass(frozen=True)
class CodeBounds:
    """Bounds on A_k(n, d) for a window code: ``lower`` is achievable by a known code."""

    sphere_packing: int
    singleton: int
    lower: int | None
    upper: int
    note: str


def ball_volume(length: int, symbols: int, radius: int) -> int:
    """Number of words within Hamming distance ``radius`` of a word."""
    return sum(comb(length, i) * (symbols - 1) ** i for i in range(radius + 1))


def code_bounds(constraints: Constraints) -> CodeBounds:
    """Best bounds we know on the number of distinct windows."""
    q, n, d = constraints.symbols, constraints.cells, constraints.min_hamming
    sphere = q ** n // ball_volume(n, q, (d - 1) // 2)
    singleton = q ** (n - d + 1)
    upper = min(sphere, singleton)
    lower: int | None = None
    note = "sphere-packing and Singleton bounds"
    if d == 1:
        lower = upper = q ** n
        note = "h=1: every window distinct, A = k^(m*n) exactly"
    elif d == 2:
        lower = upper = q ** (n - 1)
        note = "h=2: A = k^(m*n-1) exactly (Singleton bound met by a parity-check code)"
    known = KNOWN_BOUNDS.get((q, n, d))
    if known:
        lower, table_upper, note = known
        upper = min(upper, table_upper)
    return CodeBounds(sphere, singleton, lower, upper, note)


def largest_square(constraints: Constraints, windows: int) -> int:
    """Side of the largest square array with at most ``windows`` windows (0 if none)."""
    m, n = constraints.window
    lo, hi = max(m, n) - 1, max(m, n) + isqrt(windows) + 1
    while lo < hi:  # binary search: the window count grows with the side
        mid = (lo + hi + 1) // 2
        if (mid - m + 1) * (mid - n + 1) <= windows:
            lo = mid
        else:
            hi = mid - 1
    return lo if lo >= max(m, n) else 0


def largest_rectangle(constraints: Constraints, windows: int,
                      max_aspect: float = 2.0, max_tries: int = 100_000) -> tuple[int, int]:
    """Rows x cols with the most windows <= ``windows``, aspect ratio at most ``max_aspect``.

    Scans window-grid heights downwards from sqrt(windows); for huge bounds only the first
    ``max_tries`` heights (the near-square ones) are scanned.
    """
    m, n = constraints.window
    best = (0, 0, 0)
    top = isqrt(windows)
    for a in range(top, max(top - max_tries, 0), -1):
        b = min(windows // a, int(a * max_aspect))
        if b < a:
            break
        if a * b > best[0]:
            best = (a * b, a, b)
        if a * a * max_aspect < best[0]:
            break
    _, a, b = best
    if a == 0:
        return (0, 0)
    return (b + m - 1, a + n - 1)  # more rows than columns, like the shipped 30x28


def bound_report(constraints: Constraints) -> str:
    """The text ``tactile-sl pattern bound`` prints."""
    m, n = constraints.window
    b = code_bounds(constraints)
    lines = [f"constraints: {constraints.describe()} (code length {constraints.cells})",
             f"sphere-packing bound: A_{constraints.symbols}({constraints.cells},"
             f"{constraints.min_hamming}) <= {b.sphere_packing}",
             f"Singleton bound:      A <= {b.singleton}"]
    if b.lower is not None:
        lines.append(f"best known:           {b.lower} <= A <= {b.upper}  ({b.note})")
    else:
        lines.append(f"upper bound used:     A <= {b.upper}  ({b.note})")
    lines.append(f"windows = (rows-{m - 1})*(cols-{n - 1}) must be <= {b.upper}")
    side = largest_square(constraints, b.upper)
    rect = largest_rectangle(constraints, b.upper)
    lines.append(f"largest square allowed by the upper bound: {side}x{side} "
                 f"({constraints.window_count(side, side)} windows)")
    lines.append(f"largest rectangle (aspect <= 2) allowed: {rect[0]}x{rect[1]} "
                 f"({constraints.window_count(*rect)} windows)")
    if b.lower is not None and b.lower < b.upper:
        side_l = largest_square(constraints, b.lower)
        rect_l = largest_rectangle(constraints, b.lower)
        lines.append(f"within the best known code size {b.lower}: square {side_l}x{side_l} "
                     f"({constraints.window_count(side_l, side_l)} windows), rectangle "
                     f"{rect_l[0]}x{rect_l[1]} ({constraints.window_count(*rect_l)} windows)")
    if (constraints.symbols, constraints.cells, constraints.min_hamming) == (3, 9, 3):
        need = constraints.window_count(42, 42)
        lines.append(f"note: a 42x42 array (as once claimed for k=3, 3x3, h=3) would need {need} "
                     f"windows > {b.upper}: impossible")
    return "\n".join(lines) + "\n"
