"""Self-checks of notebook 13 (camera calibration): Zhang's closed-form K, the distortion model, rectification.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (rows of H instead of columns, K⁻¹ instead of K, p1 and p2
swapped, the baseline pointing the wrong way ...).
"""
import numpy as np

from ..calibrate.lens import distort
from ..calibrate.rectification import rectify_fusiello
from ..calibrate.zhang import intrinsics_from_homographies
from ..core.geometry import rotation_from_angle_axis
from .runner import run_checks

K_SKEW = np.array([[820.0, 1.5, 330.0], [0.0, 800.0, 250.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------------------------------------------------
# exercise 1: K from homographies
# ---------------------------------------------------------------------------------------------------------------

def _homographies(seed, n_views=5, K=K_SKEW, noise=0.0, unit=True):
    rng = np.random.default_rng(seed)
    Hs = []
    for _ in range(n_views):
        w = rng.normal(size=3) * [0.5, 0.5, 0.3]
        R = rotation_from_angle_axis(w)
        t = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.5, 1.0)])
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        H = H * (1 + noise * rng.normal(size=(3, 3)))
        Hs.append(H / np.linalg.norm(H) if unit else H)
    return np.stack(Hs)


def _as_K(K, name="zhang_intrinsics"):
    K = np.asarray(K, float)
    if K.shape != (3, 3):
        raise ValueError(f"{name} must return a (3, 3) array; it returned shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError(f"{name} returned NaN or inf entries")
    return K


def _rel(A, B):
    """Largest entry of |A - B| relative to B's largest entry, both scaled to [2, 2] = 1 (K is defined up to scale)."""
    An, Bn = A / A[2, 2], B / B[2, 2]
    return float(np.abs(An - Bn).max() / np.abs(Bn).max())


def _diagnose_K(K, K_ref, Hs, tol=1e-6):
    """None when K is the closed-form answer for Hs (K_ref, to ``tol``), else the most likely mistake."""
    K = _as_K(K)
    if abs(K[2, 2]) < 1e-12 * max(np.abs(K).max(), 1e-300):
        return "K[2, 2] is 0: K = inv(L.T) for the Cholesky factor L of B, then divide by K[2, 2]"
    if _rel(K, K_ref) < tol:
        return None if abs(K[2, 2] - 1) < 1e-9 else (
            f"K is right up to scale but K[2, 2] = {K[2, 2]:.4g}: divide by K[2, 2] so that it is 1")
    if _rel(K.T, K_ref) < tol:
        return "your K is transposed: K is upper triangular (fx, s, cx in its first row)"
    Kinv = np.linalg.inv(K_ref)
    if _rel(K, Kinv) < tol:
        return "you returned K⁻¹ (= Lᵀ): B = K⁻ᵀK⁻¹ = L Lᵀ, so K⁻¹ = Lᵀ and K = inv(L.T)"
    if _rel(K, Kinv.T) < tol:
        return "you returned the Cholesky factor L = K⁻ᵀ itself: K⁻¹ = Lᵀ, so K = inv(L.T)"
    if np.abs(np.tril(K / K[2, 2], -1)).max() > 1e-9 * np.abs(K / K[2, 2]).max():
        return ("your K is not upper triangular: B = L Lᵀ with L lower triangular (np.linalg.cholesky) means "
                "L = K⁻ᵀ, so K = inv(L.T), then divide by K[2, 2]")
    try:
        if _rel(K, intrinsics_from_homographies(np.swapaxes(Hs, 1, 2))) < tol:
            return "you used the rows of H: h_i is the i-th *column*, H[:, i] (H = λ K [r1 r2 t])"
    except ValueError:
        pass
    return (f"K differs from Zhang's closed form by {_rel(K, K_ref):.2g} (relative): check v_ij — with "
            "b = (B11, B12, B22, B13, B23, B33), v_ij = (hi1 hj1, hi1 hj2 + hi2 hj1, hi2 hj2, hi3 hj1 + hi1 hj3, "
            "hi3 hj2 + hi2 hj3, hi3 hj3), hik = H[k-1, i-1] — and the two rows per view: v12 and v11 - v22")


SIGN_HINT = ("the Cholesky factorisation failed: b (and so B) is only defined up to sign — if B[0, 0] < 0 use -B "
             "before np.linalg.cholesky")


def _call_K(f, Hs, hint=SIGN_HINT):
    try:
        return f(Hs.copy())
    except np.linalg.LinAlgError as exc:
        raise ValueError(f"{exc}: {hint}") from None


def check_zhang_intrinsics(zhang_intrinsics, verbose=True):
    """Self-check of ``zhang_intrinsics(Hs) -> K`` (Zhang Sec. 3.1, with skew).

    Cases: five noise-free views (exact K, with skew), three views (the minimum: both equations of each view are
    needed), homographies with arbitrary scale and sign (B is found up to sign), and noisy homographies (Zhang's
    linear answer, within 1 % of the focal length of the library's).

    Examples
    --------
    >>> check_zhang_intrinsics(intrinsics_from_homographies, verbose=False).passed
    True
    """
    def exact(f):
        Hs = _homographies(0)
        return _diagnose_K(_call_K(f, Hs), K_SKEW, Hs)

    def minimal(f):
        Hs = _homographies(1, n_views=3)
        K = _call_K(f, Hs, "with 3 views: is B's sign handled (-B if B[0, 0] < 0), and does each view give *two* "
                           "equations (v12ᵀ b = 0 and (v11 - v22)ᵀ b = 0)?")
        d = _diagnose_K(K, K_SKEW, Hs)
        if d is None or any(w in d for w in ("column", "transposed", "K⁻¹", "L = K⁻ᵀ", "K[2, 2]", "upper")):
            return d
        return ("with 3 views K is wrong although more views may work: each view gives *two* equations, v12ᵀ b = 0 "
                "and (v11 - v22)ᵀ b = 0 — stack both (6 rows for 3 views; b has 5 unknowns up to scale)")

    def scaled(f):
        Hs = _homographies(2) * np.array([-3.0, 0.5, -0.01, 7.0, -1.0])[:, None, None]
        return _diagnose_K(_call_K(f, Hs), K_SKEW, Hs)

    def noisy(f):
        Hs = _homographies(3, n_views=8, noise=1e-3)
        # Zhang's linear answer depends on how each H is scaled (rows of V are weighted by it): 1 % allows for that
        return _diagnose_K(_call_K(f, Hs), intrinsics_from_homographies(Hs), Hs, tol=1e-2)

    return run_checks("zhang_intrinsics", zhang_intrinsics, [
        ("five noise-free views: the true K (with skew)", exact),
        ("three views, the minimum: two equations per view", minimal),
        ("homographies with arbitrary scale and sign: B up to sign", scaled),
        ("eight noisy homographies: Zhang's linear answer", noisy),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the distortion model
# ---------------------------------------------------------------------------------------------------------------

def _variants(xn, d):
    """Typical wrong versions of the distortion model, with the hint for each."""
    x, y = xn[:, 0], xn[:, 1]
    k1, k2, p1, p2, k3 = d
    r2 = x * x + y * y
    r = np.sqrt(r2)
    rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3

    def model(radial, tx, ty):
        return np.column_stack([x * radial + tx, y * radial + ty])
    tan_x = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    tan_y = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return [
        (model(rad, 2 * p2 * x * y + p1 * (r2 + 2 * x * x), p2 * (r2 + 2 * y * y) + 2 * p1 * x * y),
         "p1 and p2 are swapped: x gets 2 p1 x y + p2 (r² + 2x²), y gets p1 (r² + 2y²) + 2 p2 x y (OpenCV's order)"),
        (model(1 + k1 * r + k2 * r2 + k3 * r ** 3, tan_x, tan_y),
         "the radial factor uses r instead of r²: 1 + k1 r² + k2 r⁴ + k3 r⁶, with r² = x² + y²"),
        (model(1 + k1 * r2 + k2 * r2 ** 2, tan_x, tan_y),
         "k3 is missing: the radial factor is 1 + k1 r² + k2 r⁴ + k3 r⁶"),
        (model(1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 2, tan_x, tan_y),
         "k3 multiplies r⁶ (= r2**3), not r⁴"),
        (model(rad, p1 * x * y + p2 * (r2 + 2 * x * x), p1 * (r2 + 2 * y * y) + p2 * x * y),
         "the tangential cross terms are 2 p1 x y (in x) and 2 p2 x y (in y): the factor 2 is missing"),
        (model(rad, 2 * p1 * x * y + p2 * (r2 + x * x), p1 * (r2 + y * y) + 2 * p2 * x * y),
         "the tangential terms are p2 (r² + 2x²) and p1 (r² + 2y²): the factor 2 on x², y² is missing"),
        (model(rad, 0 * x, 0 * y), "the tangential terms (p1, p2) are missing"),
        (model(rad, tan_x, tan_y) * 540.0 + 320.0,
         "xd looks like pixels: the model works on normalised coordinates, without K (no fx, cx)"),
    ]


def _diagnose_dist(xd, xn, d):
    xd = np.asarray(xd, float)
    if xd.shape != xn.shape:
        return f"distort_points must return shape {xn.shape} (N, 2), like xn; it returned {xd.shape}"
    if not np.all(np.isfinite(xd)):
        return "distort_points returned NaN or inf"
    ref = distort(xn, d)
    err = np.abs(xd - ref).max()
    if err < 1e-9:                  # float64 rounding, in any order of operations; every wrong variant is >= 5e-4 off
        return None
    if err < 1e-5:
        return (f"xd agrees with the model only to {err:.1g}, float32 precision: compute in float64 (no "
                "np.float32 arrays or dtype=np.float32)")
    for wrong, hint in _variants(xn, d):
        if np.abs(xd - wrong).max() < 1e-5:
            return hint
    if np.abs(xd - xn).max() < 1e-15:
        return "xd equals xn: the distortion is not applied"
    return (f"xd differs from OpenCV's model by up to {np.abs(xd - ref).max():.2g}: "
            "x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²), y_d = y (...) + p1 (r² + 2y²) "
            "+ 2 p2 x y, with dist = (k1, k2, p1, p2, k3)")


def check_distort_points(distort_points, verbose=True):
    """Self-check of ``distort_points(xn, dist) -> xd`` (OpenCV's model, ``dist = (k1, k2, p1, p2, k3)``).

    Cases: no distortion (identity), radial terms only, the full model on random points, and the optical centre
    (``(0, 0)`` does not move).

    Examples
    --------
    >>> check_distort_points(distort, verbose=False).passed
    True
    """
    rng = np.random.default_rng(13)
    xn = rng.uniform(-0.6, 0.6, size=(50, 2))

    def identity(f):
        xd = f(xn.copy(), np.zeros(5))
        return _diagnose_dist(xd, xn, np.zeros(5))

    def radial(f):
        d = np.array([-0.28, 0.09, 0.0, 0.0, -0.02])
        return _diagnose_dist(f(xn.copy(), d.copy()), xn, d)

    def full(f):
        d = np.array([-0.26, 0.05, 0.0019, -0.0011, 0.2])
        return _diagnose_dist(f(xn.copy(), d.copy()), xn, d)

    def centre(f):
        d = np.array([-0.26, 0.05, 0.0019, -0.0011, 0.2])
        z = np.zeros((1, 2))
        return _diagnose_dist(f(z.copy(), d.copy()), z, d)

    return run_checks("distort_points", distort_points, [
        ("no distortion: xd = xn", identity),
        ("radial terms only (k1, k2, k3)", radial),
        ("the full model with tangential terms", full),
        ("the optical centre stays put", centre),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: the rectifying rotation
# ---------------------------------------------------------------------------------------------------------------

def _stereo(seed, t=None):
    rng = np.random.default_rng(seed)
    R = rotation_from_angle_axis(rng.normal(scale=0.05, size=3))
    t = np.array([-0.1, 0.004, 0.006]) + rng.normal(scale=0.003, size=3) if t is None else np.asarray(t, float)
    return R, t


def _diagnose_rect(R_rect, R, t):
    R_rect = np.asarray(R_rect, float)
    if R_rect.shape != (3, 3):
        return f"rectifying_rotation must return a (3, 3) matrix; it returned shape {R_rect.shape}"
    if not np.all(np.isfinite(R_rect)):
        return "rectifying_rotation returned NaN or inf"
    K = np.eye(3)
    ref = rectify_fusiello(K, K, R, t).R_rect
    if np.abs(R_rect - ref).max() < 1e-9:
        return None
    if np.abs(R_rect @ R_rect.T - np.eye(3)).max() > 1e-6:
        return "R_rect is not orthonormal: normalise each axis (x, y and z have unit length)"
    if np.linalg.det(R_rect) < 0:
        return "det R_rect = -1 (a mirror): z = x × y, in this order"
    C2 = -R.T @ t
    x = C2 / np.linalg.norm(C2)
    if np.abs(R_rect[0] + x).max() < 1e-9:
        return ("the x axis points from camera 2 to camera 1: the baseline is C2 - C1 with C2 = -Rᵀt (the centre of "
                "camera 2 in camera 1's frame), so that camera 2 ends up on the right")
    t_dir = t / np.linalg.norm(t)
    if np.abs(R_rect[0] - t_dir).max() < 1e-9 or np.abs(R_rect[0] + t_dir).max() < 1e-9:
        return "the x axis is t/|t|, but t is not the baseline in camera 1's frame: the centre of camera 2 is C2 = -Rᵀt"
    if np.abs(R_rect[0] - x).max() < 1e-9 and np.abs(R_rect[1] + ref[1]).max() < 1e-9:
        return "y points up: y = z1 × x (z1 = (0, 0, 1), camera 1's optical axis), not x × z1"
    if np.abs(R_rect.T - ref).max() < 1e-9:
        return "the axes x, y, z are the *rows* of R_rect (x_rect = R_rect @ x_cam1), not its columns"
    return ("R_rect differs from Fusiello's: rows x = (C2 - C1)/|C2 - C1| with C2 = -Rᵀt, y = z1 × x normalised "
            "(z1 = (0, 0, 1)), z = x × y")


def check_rectifying_rotation(rectifying_rotation, verbose=True):
    """Self-check of ``rectifying_rotation(R, t) -> R_rect`` (Fusiello et al. 2000; ``x_cam2 = R x_cam1 + t``).

    Cases: a side-by-side rig like the OpenCV sample's, a rig with a vertical component in the baseline, and a
    rig whose second camera is on the *left* (t pointing the other way).

    Examples
    --------
    >>> check_rectifying_rotation(lambda R, t: rectify_fusiello(np.eye(3), np.eye(3), R, t).R_rect,
    ...                           verbose=False).passed
    True
    """
    def case(seed, t=None):
        def run(f):
            R, t_ = _stereo(seed, t)
            return _diagnose_rect(f(R.copy(), t_.copy()), R, t_)
        return run

    return run_checks("rectifying_rotation", rectifying_rotation, [
        ("a side-by-side rig (camera 2 on the right)", case(0)),
        ("a baseline that also rises and moves forward", case(1, [-0.1, 0.03, 0.02])),
        ("camera 2 on the left", case(2, [0.12, -0.002, 0.004])),
    ], verbose=verbose)
