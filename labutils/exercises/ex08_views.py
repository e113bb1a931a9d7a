"""Self-checks of notebook 08 (next-best-view): the visibility-pyramid score and the pose covariance of PnP.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (points counted instead of cells, levels off by one, the
weights squared, x and y swapped; the information matrix instead of its inverse, σ instead of σ², the rotation
perturbed on the wrong side ...).
"""
import numpy as np

from ..core.geometry import rotation_from_angle_axis
from ..pose.pnp import pose_jacobian
from ..sfm.view_selection import pose_covariance, pyramid_score
from .runner import run_checks

# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the visibility-pyramid score
# ---------------------------------------------------------------------------------------------------------------


def _cells(x, size, levels, swap=False, clip=True):
    """Cell indices (cx, cy) at the finest level; ``swap`` scales x by the height and y by the width."""
    w, h = (size[1], size[0]) if swap else size
    n = 2 ** levels
    cx, cy = np.floor(n * x[:, 0] / w).astype(int), np.floor(n * x[:, 1] / h).astype(int)
    if clip:
        cx, cy = np.clip(cx, 0, n - 1), np.clip(cy, 0, n - 1)
    return cx, cy


def _variant(x, size, levels, *, weight="K", count_points=False, first=1, swap=False):
    """A pyramid score computed the right way, or one of the typical wrong ways."""
    cx, cy = _cells(x, size, levels, swap)
    score = 0.0
    for level in range(first, first + levels):
        shift = levels - level
        cells = (cy >> shift) * 2 ** level + (cx >> shift)
        full = len(cells) if count_points else np.unique(cells).size
        score += {"K": 2 ** level, "K2": 4 ** level, "1": 1}[weight] * full
    return score


def _pyramid_variants(x, size, levels):
    return [
        (_variant(x, size, levels, count_points=True),
         "you count the points in each level, not the full cells: a cell is full once, however many points fall in "
         "it (np.unique of the cell indices) — that is what rewards spread-out points"),
        (_variant(x, size, levels, first=0),
         "your levels run l = 0 … L-1 (K = 1, 2, … cells per side): the pyramid starts at l = 1 with K_1 = 2 "
         "cells per side and ends at l = L with K_L = 2^L"),
        (_variant(x, size, levels, weight="K2"),
         "you weighted each full cell by K_l² (as COLMAP's code does); the paper's weight, used here, is "
         "w_l = K_l = 2^l"),
        (_variant(x, size, levels, weight="1"),
         "every full cell counts the same: weight the full cells of level l by w_l = K_l = 2^l"),
        (_variant(x, size, levels, swap=True),
         "x and y are swapped: the column of a point is ⌊K_l x / width⌋, its row ⌊K_l y / height⌋"),
    ]


def _diagnose_pyramid(score, x, size, levels):
    try:
        score = float(score)
    except (TypeError, ValueError):
        return f"pyramid_score must return one number; it returned {type(score).__name__}"
    if not np.isfinite(score):
        return "pyramid_score returned NaN or inf"
    ref = pyramid_score(x, size, levels)
    if abs(score - ref) < 1e-9 * max(ref, 1):
        return None
    for wrong, hint in _pyramid_variants(x, size, levels):
        if abs(score - wrong) < 1e-9 * max(wrong, 1):
            return hint
    return (f"the score is {score:g}, expected {ref:g}: for l = 1 … L, K_l = 2^l cells per side; a point falls in "
            "column ⌊K_l x / width⌋ and row ⌊K_l y / height⌋ (clipped to K_l - 1); score = Σ_l K_l × (number of "
            "distinct cells holding a point)")


def check_pyramid_score(pyramid_score_fn, verbose=True):
    """Self-check of ``pyramid_score(x, image_size, levels) -> float`` (Schönberger & Frahm 2016, Sec. 4.2).

    Cases: a small hand-made example, points spread over a non-square image, points on the right and bottom
    edges (they belong to the last cell), and random points with the default six levels.

    Examples
    --------
    >>> check_pyramid_score(pyramid_score, verbose=False).passed
    True
    """
    rng = np.random.default_rng(8)

    def case(x, size, levels):
        def run(f):
            return _diagnose_pyramid(f(x.copy(), size, levels), x, size, levels)
        return run

    def edges(f):
        x = np.array([[640.0, 480.0], [640.0, 0.0], [0.0, 480.0], [320.0, 240.0]])
        try:
            score = f(x.copy(), (640, 480), 3)
        except IndexError as exc:
            return (f"raised IndexError ({exc}): a point on the right or bottom edge (x = width or y = height) "
                    "belongs to the last cell: clip the cell index to K_l - 1")
        d = _diagnose_pyramid(score, x, (640, 480), 3)
        if d is not None and "expected" in d:
            return d + " — and a point on the edge x = width goes in the last column (clip the index to K_l - 1)"
        return d

    return run_checks("pyramid_score", pyramid_score_fn, [
        ("three points, 100 × 100 image, two levels", case(np.array([[10.0, 10], [20, 15], [90, 60]]),
                                                           (100, 100), 2)),
        ("points over a 720 × 360 image, four levels", case(rng.uniform([0, 0], [720, 360], (40, 2)), (720, 360), 4)),
        ("points on the right and bottom edges", edges),
        ("300 random points, six levels", case(rng.uniform([0, 0], [720, 576], (300, 2)), (720, 576), 6)),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the pose covariance of PnP
# ---------------------------------------------------------------------------------------------------------------


def _view(seed, n=30, spread=1.0):
    rng = np.random.default_rng(seed)
    K = np.array([[900.0, 1.5, 330.0], [0.0, 880.0, 250.0], [0.0, 0.0, 1.0]])
    R = rotation_from_angle_axis(rng.normal(scale=0.4, size=3))
    X = rng.uniform(-spread, spread, (n, 3)) + [0.0, 0.0, 6.0]      # in front, in the camera frame
    t = np.array([0.2, -0.1, 0.3])
    return R.T @ (X - t).T, K, R, t                                    # world points with R X_w + t = X


def _cov_variants(X, K, R, t, sigma):
    J = pose_jacobian(np.r_[0.0, 0.0, 0.0, t], X, np.zeros((len(X), 2)), K, R)
    H = J.T @ J
    cov = sigma ** 2 * np.linalg.inv(H)
    S = np.diag([-1.0, -1, -1, 1, 1, 1])
    P = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
    B = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3)]])      # ω_left = R ω_right
    Jn = pose_jacobian(np.r_[0.0, 0.0, 0.0, t], X, np.zeros((len(X), 2)), np.eye(3), R)   # normalised coordinates
    return [
        (sigma ** 2 * H, "you returned σ² JᵀJ, the information matrix: the covariance is its inverse, σ² (JᵀJ)⁻¹"),
        (H, "you returned JᵀJ, the information matrix: the covariance is σ² (JᵀJ)⁻¹"),
        (sigma * np.linalg.inv(H),
         "σ is the pixel noise's standard deviation: the covariance is σ² (JᵀJ)⁻¹, not σ (JᵀJ)⁻¹"),
        (np.linalg.inv(H), "the noise level is missing: the covariance is σ² (JᵀJ)⁻¹"),
        (S @ cov @ S, "the rotation–translation blocks have the wrong sign: ∂(R X)/∂ω = -[R X]× (the derivative of "
                      "exp([ω]×) R X at ω = 0 is [ω]× R X = -[R X]× ω)"),
        (P @ cov @ P, "rotation and translation are swapped: the parameters are (ω, t), rotation first"),
        (B.T @ cov @ B, "your ω perturbs R on the right (R exp([ω]×)); here it perturbs on the left, exp([ω]×) R, "
                        "so ∂(R X)/∂ω = -[R X]×, not -R [X]×"),
        (sigma ** 2 * np.linalg.inv(Jn.T @ Jn),
         "your covariance is in normalised image units: the Jacobian must go through K "
         "(∂u/∂p = (K[:2] - ũ K[2]) / u₃), since the noise is in pixels"),
    ]


def _diagnose_cov(C, X, K, R, t, sigma):
    C = np.asarray(C, float)
    if C.shape != (6, 6):
        return f"pose_covariance must return a (6, 6) matrix; it returned shape {C.shape}"
    if not np.all(np.isfinite(C)):
        return "pose_covariance returned NaN or inf"
    ref = pose_covariance(X, K, R, t, sigma)
    scale = np.abs(ref).max()
    if np.abs(C - ref).max() < 1e-6 * scale:
        return None
    for wrong, hint in _cov_variants(X, K, R, t, sigma):
        if np.abs(C - wrong).max() < 1e-6 * np.abs(wrong).max():
            return hint
    if np.abs(C - C.T).max() > 1e-6 * scale:
        return "a covariance is symmetric: yours is not (JᵀJ, then its inverse)"
    return (f"differs from σ² (JᵀJ)⁻¹ by up to {np.abs(C - ref).max() / scale:.2g} (relative): J has two rows per "
            "point, ∂u/∂(ω, t) = A [-[R X]×, I] with p = R X + t, u = K p, A = (K[:2] - ũ K[2]) / u₃ (ũ: the pixel)")


def check_pose_covariance(pose_covariance_fn, verbose=True):
    """Self-check of ``pose_covariance(X, K, R, t, sigma) -> (6, 6)``: ``σ² (JᵀJ)⁻¹`` for ``(ω, t)``, R <- exp([ω]×) R.

    Cases: a rotated camera with skewed K, a different noise level, and few clustered points (a large
    covariance).

    Examples
    --------
    >>> check_pose_covariance(pose_covariance, verbose=False).passed
    True
    """
    def case(seed, sigma, **kw):
        def run(f):
            Xw, K, R, t = _view(seed, **kw)
            X = Xw.T
            return _diagnose_cov(f(X.copy(), K.copy(), R.copy(), t.copy(), sigma), X, K, R, t, sigma)
        return run

    return run_checks("pose_covariance", pose_covariance_fn, [
        ("a rotated camera, skewed K, σ = 1 px", case(0, 1.0)),
        ("σ = 0.5 px", case(1, 0.5)),
        ("eight clustered points", case(2, 1.0, n=8, spread=0.2)),
    ], verbose=verbose)
