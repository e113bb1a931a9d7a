"""Scalar kernels of Lambda Twist P3P (:mod:`labutils.pose.pnp`): the cubic of the conic pencil, its real roots, the
quadratic of a line, and the Gauss-Newton polish of the depths, in plain float arithmetic. They run once per RANSAC
sample on 3×3 quantities, where numpy's per-call overhead (``np.roots``, ``np.linalg.solve`` on 3×3) cost more than
the arithmetic. They trust their input (the public functions check it).
"""
import math

import numpy as np

_I3 = np.eye(3)


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
    return l1, l2, l3


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


def _sym_eig_singular(d00, d01, d02, d11, d12, d22):
    """The two eigenpairs of a singular symmetric 3×3 matrix that are not its null space: ``(σ1, e1), (σ2, e2)``
    with ``|σ1| >= |σ2|``, unit eigenvectors (the roots of ``σ² - tr σ + m``, ``m`` the sum of the principal 2×2
    minors; each eigenvector the longest cross product of two rows of ``D - σ I``)."""
    tr = d00 + d11 + d22
    m = (d00 * d11 - d01 * d01) + (d00 * d22 - d02 * d02) + (d11 * d22 - d12 * d12)
    sq = math.sqrt(max(tr * tr / 4 - m, 0.0))
    sa, sb = tr / 2 + sq, tr / 2 - sq
    if abs(sb) > abs(sa):
        sa, sb = sb, sa
    out = []
    for s in (sa, sb):
        r0, r1, r2 = (d00 - s, d01, d02), (d01, d11 - s, d12), (d02, d12, d22 - s)
        best, nb = None, -1.0
        for a, b in ((r0, r1), (r0, r2), (r1, r2)):
            c = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
            n = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
            if n > nb:
                best, nb = c, n
        nb = math.sqrt(nb)
        out.append((s, (best[0] / nb, best[1] / nb, best[2] / nb) if nb > 0 else (0.0, 0.0, 0.0)))
    return out


def _lambda_twist(X, y, a, d12, d13, c):
    """Lambda Twist P3P (LT Alg. 1) on one checked sample, in scalar arithmetic: the poses ``[(R, t), ...]``.

    ``X`` (3, 3) world points, ``y`` (3, 3) unit rays, ``a = (a12, a13, a23)`` squared distances, ``d12, d13``
    edges from the first point and ``c = d12 × d13`` (see :func:`labutils.pose.pnp.p3p_bearings`).
    """
    a12, a13, a23 = a
    (y00, y01, y02), (y10, y11, y12), (y20, y21, y22) = y.tolist()
    b12 = y00 * y10 + y01 * y11 + y02 * y12
    b13 = y00 * y20 + y01 * y21 + y02 * y22
    b23 = y10 * y20 + y11 * y21 + y12 * y22
    # Λᵀ D1 Λ = 0 and Λᵀ D2 Λ = 0 (a23 M12 - a12 M23 and a23 M13 - a13 M23), row order
    m1 = [a23, -a23 * b12, 0.0, -a23 * b12, a23 - a12, a12 * b23, 0.0, a12 * b23, -a12]
    m2 = [a23, 0.0, -a23 * b13, 0.0, -a13, a13 * b23, -a23 * b13, a13 * b23, a23 - a13]
    c1m, c2m = _cofactor_list(m1), _cofactor_list(m2)
    coeffs = [sum(c2m[i] * m2[i] for i in range(3)), sum(m1[i] * c2m[i] for i in range(9)),
              sum(m2[i] * c1m[i] for i in range(9)), sum(c1m[i] * m1[i] for i in range(3))]
    top = max(abs(v) for v in coeffs)
    if not top > 0:
        return []
    c3, c2, c1, c0 = (v / top for v in coeffs)
    best = None
    for g in _cubic_real_roots(c3, c2, c1, c0):
        for _ in range(2):                       # polish the root on the cubic
            f, df = ((c3 * g + c2) * g + c1) * g + c0, (3 * c3 * g + 2 * c2) * g + c1
            if df != 0:
                g = g - f / df
        d = [m1[i] + g * m2[i] for i in range(9)]
        (s1, e1), (s2, e2) = _sym_eig_singular(d[0], d[1], d[2], d[4], d[5], d[8])
        if s1 * s2 >= 0:                         # semidefinite: a pair of complex lines, skip
            continue
        quality = abs(s2 / s1)
        if best is None or quality > best[0]:
            best = (quality, g, s1, s2, e1, e2)
    if best is None:
        return []
    _, g, s1, s2, e1, e2 = best
    Q = m2 if abs(g) < 1 else m1                 # a conic of the pencil independent of D0
    asum = a12 + a13 + a23
    xm = [d12[0], d13[0], c[0], d12[1], d13[1], c[1], d12[2], d13[2], c[2]]     # [d12 d13 c] as columns
    cx = _cofactor_list(xm)
    det = xm[0] * cx[0] + xm[1] * cx[1] + xm[2] * cx[2]
    Xi = [cx[0] / det, cx[3] / det, cx[6] / det, cx[1] / det, cx[4] / det, cx[7] / det,
          cx[2] / det, cx[5] / det, cx[8] / det]                               # its inverse (adjugate / det)
    s = math.sqrt(-s2 / s1)
    sols = []
    for sign in (-1.0, 1.0):                     # σ1 (e1·Λ)² + σ2 (e2·Λ)² = 0  ⇒  (e1 ∓ s e2)·Λ = 0
        u = [e1[m] + sign * s * e2[m] for m in range(3)]
        k = max(range(3), key=lambda m: abs(u[m]))
        i, j = [m for m in range(3) if m != k]
        p, q = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]  # Λ ∝ p + τ q with τ = λj / λi
        p[i], p[k] = 1.0, -u[i] / u[k]
        q[j], q[k] = 1.0, -u[j] / u[k]
        Qp = [Q[3 * r] * p[0] + Q[3 * r + 1] * p[1] + Q[3 * r + 2] * p[2] for r in range(3)]
        Qq = [Q[3 * r] * q[0] + Q[3 * r + 1] * q[1] + Q[3 * r + 2] * q[2] for r in range(3)]
        A = q[0] * Qq[0] + q[1] * Qq[1] + q[2] * Qq[2]
        B = 2 * (p[0] * Qq[0] + p[1] * Qq[1] + p[2] * Qq[2])
        C = p[0] * Qp[0] + p[1] * Qp[1] + p[2] * Qp[2]
        for tau in _quadratic_roots(A, B, C):
            if tau <= 0:
                continue
            v0, v1, v2 = p[0] + tau * q[0], p[1] + tau * q[1], p[2] + tau * q[2]
            if (v0, v1, v2)[k] <= 0:
                continue
            vmv = 2 * (v0 * v0 + v1 * v1 + v2 * v2) - 2 * (b12 * v0 * v1 + b13 * v0 * v2 + b23 * v1 * v2)
            if not vmv > 0:
                continue
            sc = math.sqrt(asum / vmv)
            l1, l2, l3 = _refine_lambdas((v0 * sc, v1 * sc, v2 * sc), a, (b12, b13, b23))
            if not (math.isfinite(l1) and math.isfinite(l2) and math.isfinite(l3)) or min(l1, l2, l3) <= 0:
                continue
            w1 = (l1 * y00 - l2 * y10, l1 * y01 - l2 * y11, l1 * y02 - l2 * y12)
            w2 = (l1 * y00 - l3 * y20, l1 * y01 - l3 * y21, l1 * y02 - l3 * y22)
            w3 = (w1[1] * w2[2] - w1[2] * w2[1], w1[2] * w2[0] - w1[0] * w2[2], w1[0] * w2[1] - w1[1] * w2[0])
            R = np.array([[w1[r] * Xi[0] + w2[r] * Xi[3] + w3[r] * Xi[6],
                           w1[r] * Xi[1] + w2[r] * Xi[4] + w3[r] * Xi[7],
                           w1[r] * Xi[2] + w2[r] * Xi[5] + w3[r] * Xi[8]] for r in range(3)])
            RtR = R.T @ R
            if np.abs(RtR - _I3).max() < 1e-6:   # round-off only: two Newton-Schulz steps to the rotation
                R = R @ (1.5 * _I3 - 0.5 * RtR)
                R = R @ (1.5 * _I3 - 0.5 * (R.T @ R))
            else:                                # the nearest rotation (SVD)
                U, _, Vt = np.linalg.svd(R)
                R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
            t = l1 * np.array([y00, y01, y02]) - R @ X[0]
            if all(np.abs(R - R2).max() > 1e-9 or np.abs(t - t2).max() > 1e-9 * (1 + np.abs(t).max())
                   for R2, t2 in sols):
                sols.append((R, t))
    return sols
