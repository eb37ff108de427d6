"""Closed-form view factors used as known answers by the benchmark (docs/known-answers.md §2, §3).

Howell's catalogue, configurations C-11 (directly opposed parallel equal rectangles) and
C-14 (perpendicular rectangles sharing an edge). Each formula is checked against the
tabulated values of docs/known-answers.md §2, §3 by `self_check()` before the benchmark uses it.
"""

from __future__ import annotations

import math


def parallel_rectangles(a: float, b: float, c: float) -> float:
    """Howell C-11: a x b rectangles, directly opposed, at distance c."""
    x, y = a / c, b / c
    x2, y2 = x * x, y * y
    s = math.log(math.sqrt((1 + x2) * (1 + y2) / (1 + x2 + y2)))
    s += x * math.sqrt(1 + y2) * math.atan(x / math.sqrt(1 + y2))
    s += y * math.sqrt(1 + x2) * math.atan(y / math.sqrt(1 + x2))
    s -= x * math.atan(x) + y * math.atan(y)
    return 2.0 / (math.pi * x * y) * s


def perpendicular_rectangles(w: float, h: float, l: float) -> float:
    """Howell C-14: emitter w x l, receiver h x l, sharing the edge of length l at 90 deg."""
    ww, hh = w / l, h / l
    w2, h2 = ww * ww, hh * hh
    r2 = w2 + h2
    s = ww * math.atan(1 / ww) + hh * math.atan(1 / hh) - math.sqrt(r2) * math.atan(1 / math.sqrt(r2))
    # The logarithm of the product, written as a sum of logarithms (no overflow).
    lg = math.log((1 + w2) * (1 + h2) / (1 + w2 + h2))
    lg += w2 * math.log(w2 * (1 + w2 + h2) / ((1 + w2) * r2))
    lg += h2 * math.log(h2 * (1 + w2 + h2) / ((1 + h2) * r2))
    s += 0.25 * lg
    return s / (math.pi * ww)


# (function, arguments, tabulated value) from docs/known-answers.md §2, §3.
TABLE = [
    (parallel_rectangles, (0.5, 0.5, 1.0), 0.0685896),
    (parallel_rectangles, (1.0, 1.0, 1.0), 0.19982489570),
    (parallel_rectangles, (2.0, 2.0, 1.0), 0.4152533),
    (parallel_rectangles, (10.0, 10.0, 1.0), 0.8269945),
    (parallel_rectangles, (1.0, 2.0, 1.0), 0.2858754),
    (perpendicular_rectangles, (1.0, 1.0, 1.0), 0.20004377608),
    (perpendicular_rectangles, (0.5, 0.5, 1.0), 0.2406360),
    (perpendicular_rectangles, (2.0, 2.0, 1.0), 0.1492998),
    (perpendicular_rectangles, (1.0, 2.0, 1.0), 0.2328526),
    (perpendicular_rectangles, (2.0, 1.0, 1.0), 0.1164263),
]


def self_check() -> list[tuple[str, float, float, float]]:
    """Evaluate every tabulated case; raise if one is off by more than its printed digits."""
    rows = []
    for fn, args, want in TABLE:
        got = fn(*args)
        digits = len(repr(want).split(".")[1])
        tol = 0.6 * 10.0 ** (-digits)
        rows.append((f"{fn.__name__}{args}", got, want, abs(got - want)))
        if abs(got - want) > tol:
            raise AssertionError(f"{fn.__name__}{args} = {got:.10f}, table says {want} (tolerance {tol:g})")
    return rows


def cube_pairs() -> dict[tuple[str, str], float]:
    """Group-to-group factors of the unit cube, faces named x0 x1 y0 y1 z0 z1."""
    names = ["x0", "x1", "y0", "y1", "z0", "z1"]
    opp = parallel_rectangles(1, 1, 1)
    adj = perpendicular_rectangles(1, 1, 1)
    return {(a, b): (opp if a[0] == b[0] else adj) for a in names for b in names if a != b}


def plates_pairs(d: float) -> dict[tuple[str, str], float]:
    f = parallel_rectangles(1, 1, d)
    return {("bottom", "top"): f, ("top", "bottom"): f}


def perpendicular_pairs(h: float) -> dict[tuple[str, str], float]:
    # `bottom` is 1 (shared edge) x 1, `side` is 1 (shared edge) x h.
    return {
        ("bottom", "side"): perpendicular_rectangles(1.0, h, 1.0),
        ("side", "bottom"): perpendicular_rectangles(h, 1.0, 1.0),
    }
