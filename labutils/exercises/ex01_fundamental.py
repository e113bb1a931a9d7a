"""Self-checks of notebook 01 (the fundamental matrix): the normalised 8-point algorithm."""
import numpy as np

from ..epipolar import fundamental_8point, hartley_normalisation, sampson_distance
from ..synthetic import make_scene
from . import run_checks, up_to_sign_scale


def _pair(seed, noise_px, n=40, layout="general"):
    s = make_scene(n, 2, layout=layout, noise_px=noise_px, rng=np.random.default_rng(seed))
    which = "true" if noise_px == 0 else "meas"
    x1, x2, _ = s.pair(0, 1, which=which)
    return x1, x2


def _unnormalised_8point(x1, x2):
    """The 8-point on raw pixels (no Hartley normalisation), rank 2 enforced: a wrong answer's twin."""
    h1, h2 = np.hstack([x1, np.ones((len(x1), 1))]), np.hstack([x2, np.ones((len(x2), 1))])
    A = (h2[:, :, None] * h1[:, None, :]).reshape(-1, 9)
    U, s, Vt = np.linalg.svd(np.linalg.svd(A)[2][-1].reshape(3, 3))
    return U @ np.diag([s[0], s[1], 0.0]) @ Vt


def _as_F(F):
    F = np.asarray(F, float)
    if F.shape != (3, 3):
        raise ValueError(f"eight_point must return a (3, 3) array; it returned shape {F.shape}")
    if not np.all(np.isfinite(F)):
        raise ValueError("eight_point returned NaN or inf entries")
    return F


def _diagnose(F, x1, x2):
    """None if F is the normalised 8-point's answer, else the most likely mistake."""
    F = _as_F(F)
    s = np.linalg.svd(F, compute_uv=False)
    if s[2] > 1e-8 * s[0]:
        return (f"your F has rank 3 (singular values {np.round(s / s[0], 6).tolist()} after scaling): enforce rank 2 "
                "after the SVD — set the smallest singular value of F̂ to zero and rebuild it")
    ref = fundamental_8point(x1, x2, h_ratio=None)
    if up_to_sign_scale(F, ref) < 1e-6:
        return None
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    if up_to_sign_scale(F, np.linalg.inv(T2).T @ ref @ np.linalg.inv(T1)) < 1e-6:
        return "your F is still in normalised coordinates: undo the normalisation, F = T2ᵀ F̂ T1"
    if up_to_sign_scale(F, ref.T) < 1e-6:
        return "your F is transposed: the convention is x2ᵀ F x1 = 0 (rows kron(x2_h, x1_h)), not x1ᵀ F x2 = 0"
    if up_to_sign_scale(F, _unnormalised_8point(x1, x2)) < 1e-6:
        return "you skipped the normalisation: move each image's points to centroid 0, mean distance √2 (T1, T2)"
    d = sampson_distance(F, x1, x2)
    return (f"F differs from the normalised 8-point's (by {up_to_sign_scale(F, ref):.2g} after scaling both to unit "
            f"norm; median Sampson distance {np.median(d):.3g} px): check the design matrix (rows kron(x2_h, x1_h)) "
            "and that you take the right singular vector of the smallest singular value (the last row of Vᵀ)")


def check_eight_point(eight_point, verbose=True):
    """Self-check of the exercise ``eight_point(x1, x2) -> F`` (H&Z Alg. 11.1).

    Cases: noise-free correspondences (``x2ᵀ F x1 = 0`` to rounding), a noisy scene (equal to the normalised
    8-point up to scale and sign), and forward motion (the epipole inside the image).

    Examples
    --------
    >>> check_eight_point(lambda x1, x2: fundamental_8point(x1, x2, h_ratio=None), verbose=False).passed
    True
    """
    def exact(f):
        x1, x2 = _pair(0, 0.0)
        F = _as_F(f(x1, x2))
        d = sampson_distance(F, x1, x2).max()
        return None if d < 1e-6 else (_diagnose(F, x1, x2) or f"max Sampson distance {d:.2g} px on noise-free data")

    def noisy(f):
        x1, x2 = _pair(1, 1.0)
        return _diagnose(f(x1, x2), x1, x2)

    def forward(f):
        x1, x2 = _pair(2, 0.5, layout="forward")
        return _diagnose(f(x1, x2), x1, x2)

    return run_checks("eight_point", eight_point, [
        ("noise-free correspondences: x2ᵀ F x1 = 0 for every pair", exact),
        ("a noisy scene (σ = 1 px): the normalised 8-point's F, up to scale and sign", noisy),
        ("forward motion (the epipole inside the image)", forward),
    ], verbose=verbose)
