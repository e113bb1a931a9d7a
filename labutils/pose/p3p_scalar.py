"""Scalar kernels of Lambda Twist P3P (:mod:`labutils.pose.pnp`): the cubic of the conic pencil, its real roots, the
quadratic of a line, and the Gauss-Newton polish of the depths, in plain float arithmetic. They run once per RANSAC
sample on 3×3 quantities, where numpy's per-call overhead (``np.roots``, ``np.linalg.solve`` on 3×3) cost more than
the arithmetic. They trust their input (the public functions check it).
"""
import math

import numpy as np


def _cofactor_list(m):
    """Cofactors of a 3×3 matrix given as its 9 entries in row order (a list), in the same order."""
    a, b, c, d, e, f, g, h, i = m
    return [e * i - f * h, f * g - d * i, d * h - e * g,
            c * h - b * i, a * i - c * g, b * g - a * h,
            b * f - c * e, c * d - a * f, a * e - b * d]


def _cubic_real_roots(a, b, c, d):
    """Real roots of a x³ + b x² + c x + d (closed form: Cardano, or the trigonometric form for three real roots;
    the caller polishes them by Newton's method)."""
    scale = max(abs(b), abs(c), abs(d))
    if abs(a) <= 1e-12 * scale:                  # degenerate: a quadratic
        return _quadratic_roots(b, c, d)
    b, c, d = b / a, c / a, d / a
    p, q = c - b * b / 3, 2 * b ** 3 / 27 - b * c / 3 + d
    shift = -b / 3
    disc = (q / 2) ** 2 + (p / 3) ** 3
    if disc > 0:                                 # one real root
        sq = math.sqrt(disc)
        return [math.copysign(abs(-q / 2 + sq) ** (1 / 3), -q / 2 + sq)
                + math.copysign(abs(-q / 2 - sq) ** (1 / 3), -q / 2 - sq) + shift]
    if p == 0:
        return [shift]
    r = math.sqrt(-p / 3)
    phi = math.acos(max(-1.0, min(1.0, -q / (2 * r ** 3))))
    return [2 * r * math.cos((phi - 2 * math.pi * k) / 3) + shift for k in range(3)]


def _refine_lambdas(lam, a, b, iters=5):
    """Gauss-Newton on the three law-of-cosines equations (LT Sec. 3.5), in scalar arithmetic (3×3 by Cramer's
    rule: numpy's per-call overhead dominated the hypothesis loop of RANSAC).

    ``lam`` (3,), ``a = (a12, a13, a23)``, ``b = (b12, b13, b23)``.
    """
    l1, l2, l3 = (float(v) for v in lam)
    a12, a13, a23 = a
    b12, b13, b23 = b
    tol = 1e-15 * (a12 + a13 + a23)
    for _ in range(iters):
        r1 = l1 * l1 + l2 * l2 - 2 * b12 * l1 * l2 - a12
        r2 = l1 * l1 + l3 * l3 - 2 * b13 * l1 * l3 - a13
        r3 = l2 * l2 + l3 * l3 - 2 * b23 * l2 * l3 - a23
        if abs(r1) + abs(r2) + abs(r3) < tol:
            break
        # J = [[j11, j12, 0], [j21, 0, j23], [0, j32, j33]]
        j11, j12 = 2 * l1 - 2 * b12 * l2, 2 * l2 - 2 * b12 * l1
        j21, j23 = 2 * l1 - 2 * b13 * l3, 2 * l3 - 2 * b13 * l1
        j32, j33 = 2 * l2 - 2 * b23 * l3, 2 * l3 - 2 * b23 * l2
        det = -j11 * j23 * j32 - j12 * j21 * j33
        if det == 0 or not math.isfinite(det):
            break
        d1 = (-r1 * j23 * j32 - j12 * (r2 * j33 - j23 * r3)) / det
        d2 = (j11 * (r2 * j33 - j23 * r3) - r1 * j21 * j33) / det
        d3 = (-j11 * r2 * j32 - j12 * j21 * r3 + r1 * j21 * j32) / det
        l1, l2, l3 = l1 - d1, l2 - d2, l3 - d3
    return np.array([l1, l2, l3])


def _quadratic_roots(A, B, C):
    """Real roots of A τ² + B τ + C (numerically stable; a double root counted once)."""
    scale = max(abs(A), abs(B), abs(C))
    if scale == 0:
        return []
    A, B, C = A / scale, B / scale, C / scale
    if abs(A) < 1e-14:
        return [] if abs(B) < 1e-14 else [-C / B]
    disc = B * B - 4 * A * C
    if disc < -1e-12:
        return []
    sq = np.sqrt(max(disc, 0.0))
    r1 = (-B - sq) / (2 * A) if B >= 0 else (-B + sq) / (2 * A)
    if disc <= 1e-12:
        return [-B / (2 * A)]
    return [r1, C / (A * r1)] if r1 != 0 else [r1, -B / A]
