"""Self-checks of notebook 01 (the fundamental matrix): Hartley's normalisation, the normalised 8-point algorithm,
the Sampson distance and the residual vector of the gold standard's cost.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (mean distance 1 instead of √2, F left in normalised
coordinates, the squared distance, one image's error only ...).
"""
import numpy as np

from ..core.geometry import relative_pose
from ..core.metrics import up_to_sign_scale
from ..core.synthetic import make_scene
from ..twoview.epipolar import (
    design_matrix,
    fundamental_8point,
    hartley_normalisation,
    sampson_distance,
    transform_points,
)
from ..twoview.essential import fundamental_from_pose
from ..twoview.gold_standard import fundamental_gold_standard, gold_standard_residuals
from .runner import run_checks


def _pair(seed, noise_px, n=40, layout="general"):
    s = make_scene(n, 2, layout=layout, noise_px=noise_px, rng=np.random.default_rng(seed))
    which = "true" if noise_px == 0 else "meas"
    x1, x2, _ = s.pair(0, 1, which=which)
    return x1, x2


def _rank2(F):
    U, s, Vt = np.linalg.svd(F)
    return U @ np.diag([s[0], s[1], 0.0]) @ Vt


# ---------------------------------------------------------------------------------------------------------------
# exercise 1: Hartley's normalisation
# ---------------------------------------------------------------------------------------------------------------

def _as_T(T):
    T = np.asarray(T, float)
    if T.shape != (3, 3):
        raise ValueError(f"normalisation_matrix must return a (3, 3) array; it returned shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("normalisation_matrix returned NaN or inf entries")
    return T


def _similarity(s, tx, ty, sy=None):
    return np.array([[s, 0.0, tx], [0.0, s if sy is None else sy, ty], [0.0, 0.0, 1.0]])


def _normalisation_variants(x):
    """Typical wrong normalisations of the points x, each with its hint."""
    c = x.mean(0)
    dist = np.linalg.norm(x - c, axis=1)
    s = np.sqrt(2) / dist.mean()
    ref = _similarity(s, -s * c[0], -s * c[1])
    s_rms = np.sqrt(2) / np.sqrt((dist ** 2).mean())
    s_origin = np.sqrt(2) / np.linalg.norm(x, axis=1).mean()
    sx, sy = np.sqrt(2) / np.abs(x - c).mean(0)
    return [
        (_similarity(1 / dist.mean(), -c[0] / dist.mean(), -c[1] / dist.mean()),
         "your points have mean distance 1 from the centroid: Hartley's target is √2 (H&Z Sec. 4.4.4), so that the "
         "average point is (1, 1, 1) in homogeneous coordinates"),
        (_similarity(s_rms, -s_rms * c[0], -s_rms * c[1]),
         "you scaled the RMS distance to √2: the normalisation scales the *mean* distance to the centroid to √2"),
        (_similarity(s, 0.0, 0.0),
         "T does not move the centroid to the origin: subtract the centroid c first, the last column of T is "
         "(-s cx, -s cy, 1)"),
        (_similarity(s, -c[0], -c[1]),
         "the translation must be scaled too: T subtracts the centroid and *then* scales, so its last column is "
         "(-s cx, -s cy, 1), not (-cx, -cy, 1)"),
        (_similarity(s_origin, -s_origin * c[0], -s_origin * c[1]),
         "you measured the distances from the origin of the pixel frame: measure them from the centroid"),
        (_similarity(sx, -sx * c[0], -sy * c[1], sy=sy),
         "x and y are scaled differently: T is a similarity, one scale s for both axes (s = √2 / mean distance)"),
        (np.linalg.inv(ref),
         "you returned T⁻¹, which maps normalised points back to pixels: T maps pixels to normalised points, "
         "x_n_h = T @ x_h"),
    ]


def _diagnose_T(T, x):
    """None if T is Hartley's normalisation of x (centroid 0, mean distance √2, a similarity), else the mistake."""
    T = _as_T(T)
    ref = hartley_normalisation(x)
    tol = 1e-9 * max(1.0, np.abs(ref).max())
    if np.abs(T - ref).max() > tol and np.abs(T.T - ref).max() < tol:
        return "T is transposed: the translation is the last *column*, T = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]]"
    if abs(T[2, 2]) < 1e-12 or np.abs(T[2, :2]).max() > 1e-9 * abs(T[2, 2]):
        return "the last row of T must be (0, 0, 1): T is a similarity (scale and translation), not a general matrix"
    T = T / T[2, 2]
    scale = max(1.0, np.abs(ref).max())
    y = transform_points(T, x)
    centroid = y.mean(0)
    mean_dist = np.linalg.norm(y - centroid, axis=1).mean()
    similar = abs(T[0, 1]) + abs(T[1, 0]) < 1e-12 * scale and abs(T[0, 0] - T[1, 1]) < 1e-9 * abs(T[0, 0])
    if similar and np.abs(centroid).max() < 1e-9 and abs(mean_dist - np.sqrt(2)) < 1e-9:
        return None
    for wrong, hint in _normalisation_variants(x):
        if np.abs(T - wrong).max() < 1e-9 * max(1.0, np.abs(wrong).max()):
            return hint
    return (f"after T the points have centroid {np.round(centroid, 6).tolist()} and mean distance {mean_dist:.6g} "
            "from it: T must move the centroid c to the origin and scale by s = √2 / (mean distance to c), "
            "T = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]]")


def check_normalisation_matrix(normalisation_matrix, verbose=True):
    """Self-check of ``normalisation_matrix(x) -> T`` (Hartley's normalisation, H&Z Sec. 4.4.4).

    Cases: pixels spread over an image, points that are normalised already (T is the identity), a small patch far
    from the pixel origin, and two points (the fewest that can be normalised). Each is checked against the
    definition — centroid 0, mean distance √2, one scale for both axes — not against the library.

    Examples
    --------
    >>> check_normalisation_matrix(hartley_normalisation, verbose=False).passed
    True
    """
    def run(x):
        def case(f):
            return _diagnose_T(f(x.copy()), x)
        return case

    rng = np.random.default_rng(1)
    spread = rng.uniform([0, 0], [720, 576], size=(60, 2))
    unit = rng.normal(size=(30, 2))
    unit -= unit.mean(0)
    unit *= np.sqrt(2) / np.linalg.norm(unit, axis=1).mean()
    patch = np.array([5000.0, 3000.0]) + rng.uniform(-5, 5, size=(25, 2)) * [1.0, 0.4]
    two = np.array([[100.0, 200.0], [300.0, 250.0]])
    return run_checks("normalisation_matrix", normalisation_matrix, [
        ("60 pixels over a 720×576 image: centroid 0, mean distance √2 after T", run(spread)),
        ("points normalised already: T is the identity", run(unit)),
        ("a 10×4 px patch around (5000, 3000)", run(patch)),
        ("two points", run(two)),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the normalised 8-point algorithm
# ---------------------------------------------------------------------------------------------------------------

def _unnormalised_8point(x1, x2):
    """The 8-point on raw pixels (no Hartley normalisation), rank 2 enforced: a wrong answer's twin."""
    return _rank2(np.linalg.svd(design_matrix(x1, x2))[2][-1].reshape(3, 3))


def _as_F(F):
    F = np.asarray(F, float)
    if F.shape != (3, 3):
        raise ValueError(f"eight_point must return a (3, 3) array; it returned shape {F.shape}")
    if not np.all(np.isfinite(F)):
        raise ValueError("eight_point returned NaN or inf entries")
    if not np.linalg.norm(F) > 0:
        raise ValueError("eight_point returned the zero matrix")
    return F


def _eight_point_variants(x1, x2):
    """Typical wrong 8-point answers for x1, x2, each with its hint (order: the most telling first)."""
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    Vt = np.linalg.svd(design_matrix(transform_points(T1, x1), transform_points(T2, x2)))[2]
    F_hat = Vt[-1].reshape(3, 3)
    ref = fundamental_8point(x1, x2, degeneracy=None)
    inv1, inv2 = np.linalg.inv(T1), np.linalg.inv(T2)
    v1, v2 = _normalisation_variants(x1), _normalisation_variants(x2)
    return [
        (_rank2(F_hat), "your F is still in normalised coordinates: undo the normalisation, F = T2ᵀ F̂ T1"),
        (ref.T, "your F is transposed: the convention is x2ᵀ F x1 = 0 (rows kron(x2_h, x1_h)), not x1ᵀ F x2 = 0"),
        (T1.T @ _rank2(F_hat) @ T2,
         "the denormalisation has T1 and T2 swapped: y2ᵀ F̂ y1 = x2ᵀ (T2ᵀ F̂ T1) x1, so F = T2ᵀ F̂ T1"),
        (inv2.T @ _rank2(F_hat) @ inv1,
         "you denormalised with T⁻¹: since y = T x, y2ᵀ F̂ y1 = x2ᵀ (T2ᵀ F̂ T1) x1 — use T itself, F = T2ᵀ F̂ T1"),
        (_unnormalised_8point(x1, x2),
         "you skipped the normalisation: move each image's points to centroid 0, mean distance √2 (T1, T2)"
         + (" (with exactly eight points, enforcing rank 2 after denormalising gives this same F: the cases with "
            "more points tell the two apart)" if len(x1) == 8 else "")),
        (_rank2(T2.T @ F_hat @ T1),
         "you enforced rank 2 after denormalising: set the smallest singular value of F̂ to zero in normalised "
         "coordinates, then denormalise (H&Z Alg. 11.1: the Frobenius norm is only meaningful there)"),
        (T2.T @ _rank2(Vt[0].reshape(3, 3)) @ T1,
         "you took the right singular vector of the *largest* singular value: f minimises ‖A f‖, the *last* row of "
         "Vᵀ (np.linalg.svd sorts the singular values in decreasing order)"),
        (T2.T @ _rank2(Vt[min(len(x1), 9) - 1].reshape(3, 3)) @ T1,
         "with exactly 8 points np.linalg.svd(A, full_matrices=False) returns only 8 rows of Vᵀ, and the null vector "
         "of A is the 9th: keep full_matrices=True (the default) so that Vᵀ is 9×9"),
    ] + [
        (_eight_point_T(x1, x2, v1[k][0], v2[k][0]),
         f"your F is the 8-point's with another normalisation of the points ({v1[k][1].split(':')[0]}): use "
         "hartley_normalisation, or your normalisation_matrix once its self-check passes")
        for k in (0, 2)        # mean distance 1; not centred
    ]


def _eight_point_T(x1, x2, T1, T2):
    """The normalised 8-point with the normalisations T1, T2 (right or wrong)."""
    F_hat = np.linalg.svd(design_matrix(transform_points(T1, x1), transform_points(T2, x2)))[2][-1].reshape(3, 3)
    return T2.T @ _rank2(F_hat) @ T1


def _diagnose(F, x1, x2):
    """None if F is the normalised 8-point's answer, else the most likely mistake."""
    F = _as_F(F)
    s = np.linalg.svd(F, compute_uv=False)
    if s[2] > 1e-8 * s[0]:
        values = ", ".join(f"{v:.1e}" for v in s / s[0])
        return (f"your F has rank 3 (singular values {values} after scaling to the largest): enforce rank 2 after "
                "the SVD — set the smallest singular value of F̂ to zero and rebuild it")
    ref = fundamental_8point(x1, x2, degeneracy=None)
    if up_to_sign_scale(F, ref) < 1e-6:
        return None
    for wrong, hint in _eight_point_variants(x1, x2):
        if up_to_sign_scale(F, wrong) < 1e-6:
            return hint
    d = sampson_distance(F, x1, x2)
    return (f"F differs from the normalised 8-point's (by {up_to_sign_scale(F, ref):.2g} after scaling both to unit "
            f"norm; median Sampson distance {np.median(d):.3g} px): check the design matrix (rows kron(x2_h, x1_h)) "
            "and that you take the right singular vector of the smallest singular value (the last row of Vᵀ)")


def check_eight_point(eight_point, verbose=True):
    """Self-check of the exercise ``eight_point(x1, x2) -> F`` (H&Z Alg. 11.1).

    Cases: noise-free correspondences (``x2ᵀ F x1 = 0`` to rounding), a noisy scene (equal to the normalised
    8-point up to scale and sign), forward motion (the epipole inside the image), and exactly eight points.

    Examples
    --------
    >>> check_eight_point(lambda x1, x2: fundamental_8point(x1, x2, degeneracy=None), verbose=False).passed
    True
    """
    def exact(f):
        x1, x2 = _pair(0, 0.0)
        F = _as_F(f(x1, x2))
        d = sampson_distance(F, x1, x2).max()
        return None if d < 1e-6 else (_diagnose(F, x1, x2) or f"max Sampson distance {d:.2g} px on noise-free data")

    def noisy(f):
        x1, x2 = _pair(1, 1.0)
        return _diagnose(f(x1.copy(), x2.copy()), x1, x2)

    def forward(f):
        x1, x2 = _pair(2, 0.5, layout="forward")
        return _diagnose(f(x1.copy(), x2.copy()), x1, x2)

    def minimal(f):
        x1, x2 = _pair(3, 0.5, n=8)
        return _diagnose(f(x1.copy(), x2.copy()), x1, x2)

    return run_checks("eight_point", eight_point, [
        ("noise-free correspondences: x2ᵀ F x1 = 0 for every pair", exact),
        ("a noisy scene (σ = 1 px): the normalised 8-point's F, up to scale and sign", noisy),
        ("forward motion (the epipole inside the image)", forward),
        ("exactly eight correspondences", minimal),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: the Sampson distance
# ---------------------------------------------------------------------------------------------------------------

def _sampson_parts(F, x1, x2):
    x1_h = np.hstack([x1, np.ones((len(x1), 1))])
    x2_h = np.hstack([x2, np.ones((len(x2), 1))])
    Fx1, Ftx2 = x1_h @ F.T, x2_h @ F
    return np.einsum("ni,ni->n", x2_h, Fx1), Fx1, Ftx2


def _sampson_variants(F, x1, x2):
    """Typical wrong Sampson distances, each with its hint."""
    alg, Fx1, Ftx2 = _sampson_parts(F, x1, x2)
    a, b = np.hypot(Fx1[:, 0], Fx1[:, 1]), np.hypot(Ftx2[:, 0], Ftx2[:, 1])
    den = np.sqrt(a ** 2 + b ** 2)
    return [
        ((alg / den) ** 2, "you returned the squared distance (H&Z eq. 11.9 is the square): return its square root, "
                           "in pixels"),
        (alg / den, "some distances are negative: take the absolute value of x2ᵀ F x1"),
        (np.abs(alg) / a,
         "you divided by the length of (F x1)₁,₂ only: that is the distance of x2 to its epipolar line in image 2. "
         "The Sampson distance counts the errors of both images: (F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²"),
        (np.abs(alg) / b,
         "you divided by the length of (Fᵀ x2)₁,₂ only: that is the distance of x1 to its epipolar line in image 1. "
         "The Sampson distance counts the errors of both images: (F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²"),
        (np.abs(alg) / np.sqrt((Fx1 ** 2).sum(1) + (Ftx2 ** 2).sum(1)),
         "only the first two components of F x1 and Fᵀ x2 enter the denominator: they are the derivatives of "
         "x2ᵀ F x1 with respect to the pixel coordinates; the third component is not"),
        (np.abs(alg) / a + np.abs(alg) / b,
         "you added the distances of each point to its epipolar line: the Sampson distance has one denominator, "
         "the square root of the sum of all four squares"),
        (np.sqrt((alg / a) ** 2 + (alg / b) ** 2),
         "that is the symmetric epipolar distance: the Sampson distance has one denominator, the square root of "
         "(F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²"),
        (np.abs(alg), "you returned the algebraic error |x2ᵀ F x1|, which depends on the scale of F: divide it by "
                      "the length of its gradient, sqrt((F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²)"),
        (sampson_distance(F.T, x1, x2),
         "F is transposed: the constraint is x2ᵀ F x1 = 0 (F x1 is the epipolar line of x1 in image 2)"),
    ]


def _diagnose_sampson(d, F, x1, x2):
    d = np.asarray(d, float)
    if d.shape != (len(x1),):
        return f"sampson must return shape ({len(x1)},), one distance per correspondence; it returned {d.shape}"
    ref = sampson_distance(F, x1, x2)
    tol = 1e-9 * max(1.0, np.abs(ref).max())
    if np.all(np.isfinite(d)) and np.abs(d - ref).max() < tol:
        return None
    for wrong, hint in _sampson_variants(F, x1, x2):
        if np.all(np.isfinite(d)) and np.abs(d - wrong).max() < 1e-9 * max(1.0, np.abs(wrong).max()):
            return hint
    if not np.all(np.isfinite(d)):
        return "sampson returned NaN or inf for correspondences that are not at an epipole"
    return (f"the distances differ from Sampson's by up to {np.abs(d - ref).max():.3g} px: "
            "d = |x2ᵀ F x1| / sqrt((F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²), with homogeneous x1, x2")


def check_sampson(sampson, verbose=True):
    """Self-check of ``sampson(F, x1, x2) -> d`` (the Sampson distance in pixels, H&Z eq. 11.9 without the square).

    Cases: an F whose epipolar lines are image rows (the distance is known by hand), a noisy scene, the same F
    scaled by -1000 (the distance does not depend on F's scale or sign), and noise-free correspondences (zero).

    Examples
    --------
    >>> check_sampson(sampson_distance, verbose=False).passed
    True
    """
    def rows(f):
        F = np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]])       # x2ᵀ F x1 = y1 - y2: the rows must agree
        x1 = np.array([[0.0, 0.0], [10.0, 3.0], [-4.0, 7.0]])
        x2 = np.array([[5.0, 2.0], [1.0, 3.0], [6.0, 4.0]])
        d = np.asarray(f(F.copy(), x1.copy(), x2.copy()), float)
        known = np.abs(x1[:, 1] - x2[:, 1]) / np.sqrt(2)           # y1 and y2 each move half way: |Δy| / √2
        if d.shape == known.shape and np.all(np.isfinite(d)) and np.abs(d - known).max() < 1e-12:
            return None
        return _diagnose_sampson(d, F, x1, x2) or f"expected {known.round(6).tolist()}, got {np.round(d, 6).tolist()}"

    def noisy(f):
        x1, x2 = _pair(4, 1.0)
        F = fundamental_8point(x1, x2, degeneracy=None)
        return _diagnose_sampson(f(F.copy(), x1.copy(), x2.copy()), F, x1, x2)

    def scaled(f):
        x1, x2 = _pair(5, 1.0)
        F = fundamental_8point(x1, x2, degeneracy=None)
        d = np.asarray(f(-1000.0 * F, x1.copy(), x2.copy()), float)
        return _diagnose_sampson(d, -1000.0 * F, x1, x2)

    def exact(f):
        s = make_scene(30, 2, noise_px=0.0, rng=np.random.default_rng(6))
        x1, x2, _ = s.pair(0, 1, which="true")
        F = fundamental_from_pose(s.K, s.K, *relative_pose(s.R[0], s.t[0], s.R[1], s.t[1]))
        d = np.asarray(f(F.copy(), x1.copy(), x2.copy()), float)
        if d.shape == (len(x1),) and np.all(np.isfinite(d)) and np.abs(d).max() < 1e-6:
            return None
        return _diagnose_sampson(d, F, x1, x2) or f"noise-free correspondences: largest distance {np.abs(d).max():.3g}"

    return run_checks("sampson", sampson, [
        ("epipolar lines along the image rows: d = |y1 - y2| / √2", rows),
        ("a noisy scene (σ = 1 px) and its 8-point F", noisy),
        ("F scaled by -1000: the same distances", scaled),
        ("noise-free correspondences and the true F: zero", exact),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 4: the gold standard's cost (H&Z Alg. 11.3)
# ---------------------------------------------------------------------------------------------------------------

def _gs_variants(P2, q, x1, x2):
    """Typical wrong residual vectors of the gold-standard cost, each with its hint."""
    X = np.column_stack([q[:, 0], q[:, 1], np.ones(len(q)), q[:, 2]])
    X_swapped = np.column_stack([q[:, 0], q[:, 1], q[:, 2], np.ones(len(q))])
    y, y_sw = X @ P2.T, X_swapped @ P2.T
    r1, r2 = q[:, :2] - x1, y[:, :2] / y[:, 2:] - x2
    return [
        (np.hstack([r1.ravel(), r2.ravel()]),
         "the residuals are grouped by image (all of view 1, then all of view 2): give them point by point, the four "
         "of point 0 (x̂1 - x1, x̂2 - x2), then point 1, ... — np.hstack([r1, r2]).ravel() — the LM's sparse "
         "Jacobian has one row block per point"),
        (-np.hstack([r1, r2]).ravel(),
         "the sign is reversed: the residual is predicted minus measured, x̂ - x (the cost is the same, but the "
         "Jacobian the LM uses is that of x̂ - x, so with -r its steps go uphill)"),
        (np.hstack([r2, r1]).ravel(),
         "view 2 comes first in your residuals: per point (x̂1 - x1, x̂2 - x2), view 1 first"),
        (np.hstack([r1, y_sw[:, :2] / y_sw[:, 2:] - x2]).ravel(),
         "point i is X_i = (u_i, v_i, 1, ρ_i): ρ is the 4th coordinate (it multiplies e', the last column of P2), "
         "the 3rd is 1"),
        (np.hstack([r1, y[:, :2] - x2]).ravel(),
         "x̂2 is P2 X divided by its third coordinate: y = P2 X, x̂2 = y[:2] / y[2]"),
        (np.hstack([r1, (X @ P2.T)[:, :2] / (X @ P2.T)[:, 2:] - x1]).ravel(),
         "the view-2 residual compares x̂2 with x2, the measured points of view 2 (not x1)"),
    ]


def _diagnose_gs(r, P2, q, x1, x2):
    n = len(q)
    r = np.asarray(r, float)
    if r.ndim == 0 or r.shape == (n,):
        return ("return the residual vector, 4 numbers per point, not the cost: Levenberg–Marquardt needs each "
                "residual (and its derivatives), the cost Σ r² is its own business")
    if r.shape == (n, 4):
        return "return a flat vector of shape (4N,): r.ravel() of the (N, 4) per-point residuals"
    if r.shape == (2 * n,):
        return ("only one image's residuals: the cost counts both views, (x̂1 - x1, x̂2 - x2) per point — 4N numbers "
                "(in view 1, x̂1 = (u, v) since P1 X = (u, v, 1))")
    if r.shape != (4 * n,):
        return f"gold_standard_residuals must return shape ({4 * n},), 4 per point; it returned {r.shape}"
    if not np.all(np.isfinite(r)):
        return "gold_standard_residuals returned NaN or inf"
    ref = gold_standard_residuals(P2, q, x1, x2)
    if np.abs(r - ref).max() < 1e-9 * max(1.0, np.abs(ref).max()):
        return None
    for wrong, hint in _gs_variants(P2, q, x1, x2):
        if np.abs(r - wrong).max() < 1e-9 * max(1.0, np.abs(wrong).max()):
            return hint
    return (f"the residuals differ from the cost's by up to {np.abs(r - ref).max():.3g}: per point "
            "(u - x1, v - y1, x̂2 - x2, ŷ2 - y2) with (x̂2, ŷ2) = (P2 X)[:2] / (P2 X)[2], X = (u, v, 1, ρ)")


def _gs_random(seed, n):
    rng = np.random.default_rng(seed)
    P2 = rng.normal(size=(3, 4))
    P2[2] = [0.1, -0.2, 1.0, 0.3]                          # keeps the third coordinate away from 0
    q = np.column_stack([rng.uniform(-1, 1, size=(n, 2)), rng.uniform(-0.5, 0.5, size=n)])
    X = np.column_stack([q[:, 0], q[:, 1], np.ones(n), q[:, 2]]) @ P2.T
    x1, x2 = q[:, :2] + rng.normal(scale=0.05, size=(n, 2)), X[:, :2] / X[:, 2:] + rng.normal(scale=0.05, size=(n, 2))
    return P2, q, x1, x2


def check_gold_standard_residuals(gold_standard_residuals, verbose=True):
    """Self-check of ``gold_standard_residuals(P2, points, x1, x2) -> r`` (the cost of H&Z Alg. 11.3).

    Cases: one point worked by hand, measurements that are exactly the projections (r = 0), random cameras, points
    and noisy measurements (the residual vector, point by point), and the LM of :func:`fundamental_gold_standard`
    driven by the student's residuals on a noisy scene (the gold standard's F).

    Examples
    --------
    >>> check_gold_standard_residuals(gold_standard_residuals, verbose=False).passed
    True
    """
    def by_hand(f):
        P2 = np.hstack([np.eye(3), [[1.0], [0.0], [0.0]]])
        q, x1, x2 = np.array([[0.0, 0.0, 1.0]]), np.zeros((1, 2)), np.zeros((1, 2))
        r = np.asarray(f(P2, q, x1, x2), float)
        if r.shape == (4,) and np.allclose(r, [0, 0, 1, 0], atol=1e-12):
            return None
        return (_diagnose_gs(r, P2, q, x1, x2)
                or f"X = (0, 0, 1, 1), P2 X = (1, 0, 1): x̂2 = (1, 0), so r = (0, 0, 1, 0); you gave {r.round(6)}")

    def exact(f):
        P2, q, _, _ = _gs_random(7, 12)
        X = np.column_stack([q[:, 0], q[:, 1], np.ones(len(q)), q[:, 2]]) @ P2.T
        x1, x2 = q[:, :2].copy(), X[:, :2] / X[:, 2:]
        r = np.asarray(f(P2.copy(), q.copy(), x1, x2.copy()), float)
        if r.shape == (4 * len(q),) and np.abs(r).max() < 1e-12:
            return None
        return _diagnose_gs(r, P2, q, x1, x2) or "the measurements are the projections: every residual must be 0"

    def noisy(f):
        P2, q, x1, x2 = _gs_random(8, 15)
        return _diagnose_gs(f(P2.copy(), q.copy(), x1.copy(), x2.copy()), P2, q, x1, x2)

    def driven(f):
        x1, x2 = _pair(9, 1.0, n=20)
        F0 = fundamental_8point(x1, x2, degeneracy=None)
        ref = fundamental_gold_standard(x1, x2, F0=F0, n_starts=0)
        ours = fundamental_gold_standard(x1, x2, F0=F0, n_starts=0, residuals=f)
        if up_to_sign_scale(ours.F, ref.F) < 1e-6:
            return None
        return (f"Levenberg–Marquardt driven by your residuals ends {up_to_sign_scale(ours.F, ref.F):.2g} away from "
                f"the gold standard's F (residual {ours.residual:.4f} px against {ref.residual:.4f} px)")

    return run_checks("gold_standard_residuals", gold_standard_residuals, [
        ("one point by hand: P2 = [I | (1, 0, 0)], X = (0, 0, 1, 1), x1 = x2 = 0: r = (0, 0, 1, 0)", by_hand),
        ("measurements equal to the projections: r = 0", exact),
        ("a random P2, 15 points, noisy measurements: the residual vector, point by point", noisy),
        ("the LM on a noisy scene (σ = 1 px), driven by your residuals: the gold standard's F", driven),
    ], verbose=verbose)
