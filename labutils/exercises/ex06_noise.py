"""Self-checks of notebook 06 (pose error against noise): the Cramér–Rao prediction for one camera, and the normalised
estimation error squared (NEES) that tests it.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (σ not squared, the information not inverted, the translation
block instead of the rotation block, radians, Σ instead of Σ⁻¹, the diagonal only ...).
"""
import numpy as np

from ..core.geometry import rotation_from_angle_axis
from ..pose.pnp import pose_jacobian
from ..sfm.noise_study import pose_covariance
from .runner import run_checks

# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the Cramér–Rao prediction for one camera
# ---------------------------------------------------------------------------------------------------------------


def cramer_rao_reference(J, sigma):
    """The reference answer: ``cov = σ² (JᵀJ)⁻¹`` and the RMS rotation error ``sqrt(tr cov[:3, :3])`` in degrees."""
    cov = sigma ** 2 * np.linalg.inv(J.T @ J)
    return cov, float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))


def _camera(seed, n=40, spread=1.0):
    """A camera ``(K, R, t)``, points in front of it and the Jacobian of its pixels w.r.t. ``(φ, δt)`` at the truth."""
    rng = np.random.default_rng(seed)
    K = np.array([[900.0, 0.0, 320.0], [0.0, 900.0, 240.0], [0.0, 0.0, 1.0]])
    R = rotation_from_angle_axis(rng.normal(scale=0.8, size=3))
    t = np.array([0.1, -0.2, 5.0])
    Xc = np.column_stack([spread * rng.uniform(-1.2, 1.2, n), spread * rng.uniform(-0.9, 0.9, n),
                          spread * rng.uniform(-1.0, 1.0, n) + 5.0])
    X = (Xc - t) @ R                                      # world points: R X + t = Xc
    J = pose_jacobian(np.concatenate([np.zeros(3), t]), X, np.zeros((n, 2)), K, R)
    return X, K, R, t, J


def _rot_variants(cov):
    """Wrong ways to read the RMS rotation error off a covariance, with the hint for each."""
    rot, tra = cov[:3, :3], cov[3:, 3:]
    return [
        (np.sqrt(np.trace(rot)), "the RMS rotation error is in radians: convert it with np.degrees"),
        (np.degrees(np.sqrt(np.trace(tra))), "you used the translation block cov[3:, 3:]; the rotation is cov[:3, :3] "
                                             "(the parameters are (φ, δt), rotation first)"),
        (np.degrees(np.trace(rot)), "tr Σ_φ is the mean *squared* error: take its square root (then degrees)"),
        (np.degrees(np.sqrt(np.diag(rot)).sum()), "the RMS of |φ| is sqrt(Σ_φ11 + Σ_φ22 + Σ_φ33) = sqrt(tr Σ_φ), not "
                                                  "the sum of the three standard deviations"),
        (np.degrees(np.sqrt(np.trace(rot) / 3)), "sqrt(tr Σ_φ / 3) is the RMS error per axis; the rotation error |φ| "
                                                 "has all three: sqrt(tr Σ_φ)"),
        (np.degrees(np.sqrt(np.linalg.eigvalsh(rot)[-1])), "the largest eigenvalue is the worst direction only; the "
                                                           "RMS of |φ| is sqrt(tr Σ_φ)"),
    ]


def _cov_variants(J, sigma):
    H = J.T @ J
    Hinv = np.linalg.inv(H)
    return [
        (Hinv, "the covariance scales with the noise: σ² (JᵀJ)⁻¹ (you left out σ²)"),
        (sigma * Hinv, "the covariance is σ² (JᵀJ)⁻¹: square σ (it is a variance)"),
        (Hinv / sigma ** 2, "the covariance is σ² (JᵀJ)⁻¹ (multiply by σ²; JᵀJ / σ² is the information)"),
        (sigma ** 2 * H, "σ² JᵀJ is not the covariance: invert the information, cov = σ² (JᵀJ)⁻¹"),
        (H / sigma ** 2, "JᵀJ / σ² is the *information*; the covariance is its inverse, σ² (JᵀJ)⁻¹"),
    ]


def _close(a, b, rtol=1e-6):
    return np.allclose(a, b, rtol=rtol, atol=rtol * np.abs(b).max())


def _diagnose_crb(out, J, sigma):
    if not (isinstance(out, tuple) and len(out) == 2):
        raise ValueError(f"cramer_rao_pose must return a tuple (cov, rot_rms_deg); it returned {type(out).__name__}")
    cov, rot = np.asarray(out[0], float), out[1]
    if cov.shape != (6, 6):
        if cov.shape == (len(J), len(J)):
            return "your cov is (2N, 2N): the information is Jᵀ J (6 × 6), not J Jᵀ"
        return f"cov must be the (6, 6) covariance of (φ, δt); it has shape {cov.shape}"
    if np.ndim(rot) != 0 or not np.isfinite(rot):
        return f"rot_rms_deg must be one finite number (degrees); got {rot!r}"
    ref_cov, ref_rot = cramer_rao_reference(J, sigma)
    if not _close(cov, ref_cov):
        for wrong, hint in _cov_variants(J, sigma):
            if _close(cov, wrong):
                return hint
        return (f"cov differs from σ² (JᵀJ)⁻¹ by up to {np.abs(cov - ref_cov).max() / np.abs(ref_cov).max():.2g} "
                "(relative): the information is JᵀJ (6 × 6), the covariance σ² times its inverse")
    if abs(rot - ref_rot) <= 1e-6 * ref_rot:
        return None
    for wrong, hint in _rot_variants(cov):
        if abs(rot - wrong) <= 1e-6 * abs(wrong):
            return hint
    return (f"cov is right, but rot_rms_deg = {rot:.4g} (expected {ref_rot:.4g}): the RMS rotation error is "
            "np.degrees(np.sqrt(np.trace(cov[:3, :3])))")


def check_cramer_rao_pose(cramer_rao_pose, verbose=True):
    """Self-check of ``cramer_rao_pose(J, sigma) -> (cov, rot_rms_deg)`` (H&Z Sec. 5.2.2, backward propagation).

    Cases: a camera at σ = 1 px against :func:`labutils.sfm.noise_study.pose_covariance`, the same at σ = 0.5 and 2 px
    (the covariance scales as σ²), and a camera seeing a small patch (strongly correlated rotation and translation).

    Examples
    --------
    >>> check_cramer_rao_pose(cramer_rao_reference, verbose=False).passed
    True
    """
    def library(f):
        X, K, R, t, J = _camera(0)
        out = f(J.copy(), 1.0)
        hint = _diagnose_crb(out, J, 1.0)
        if hint is None and not _close(np.asarray(out[0]), pose_covariance(X, K, R, t, 1.0)):
            return "cov differs from labutils.sfm.noise_study.pose_covariance on the same camera"
        return hint

    def scaling(f):
        X, K, R, t, J = _camera(1)
        for sigma in (0.5, 2.0):
            hint = _diagnose_crb(f(J.copy(), sigma), J, sigma)
            if hint:
                return f"σ = {sigma} px: {hint}"
        return None

    def patch(f):
        X, K, R, t, J = _camera(2, n=12, spread=0.15)
        return _diagnose_crb(f(J.copy(), 1.5), J, 1.5)

    return run_checks("cramer_rao_pose", cramer_rao_pose, [
        ("a camera seeing 40 points, σ = 1 px: the library's covariance", library),
        ("the same at σ = 0.5 and 2 px: the covariance scales as σ²", scaling),
        ("a camera seeing a small patch (rotation and translation correlated), σ = 1.5 px", patch),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the normalised estimation error squared
# ---------------------------------------------------------------------------------------------------------------


def nees_reference(errors, cov):
    """The reference answer: ``e_kᵀ Σ⁻¹ e_k`` for each row ``e_k`` of ``errors``."""
    return np.einsum("ki,ij,kj->k", errors, np.linalg.inv(cov), errors)


def _correlated_cov(seed, d=6):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(d, d)) * np.logspace(-3, 0, d)[:, None]
    return A @ A.T + 1e-8 * np.eye(d)


def _diagnose_nees(values, errors, cov):
    values = np.asarray(values, float)
    T = len(errors)
    if values.shape != (T,):
        if values.shape == ():
            return "return one value per trial, shape (T,) — not their mean or sum (the mean is taken afterwards)"
        return f"nees must return shape ({T},), one value per row of errors; it returned {values.shape}"
    ref = nees_reference(errors, cov)
    if np.allclose(values, ref, rtol=1e-6, atol=0):
        return None
    if np.allclose(values, np.sqrt(ref), rtol=1e-6, atol=0):
        return "you returned the Mahalanobis distance sqrt(eᵀ Σ⁻¹ e): the NEES is its square, eᵀ Σ⁻¹ e"
    if np.allclose(values, np.einsum("ki,ij,kj->k", errors, cov, errors), rtol=1e-6, atol=0):
        return "you used Σ; the NEES weighs the error by the *inverse* covariance, eᵀ Σ⁻¹ e"
    if np.allclose(values, np.sum(errors ** 2 / np.diag(cov), axis=1), rtol=1e-6, atol=0):
        return ("you used only the diagonal of Σ (each parameter on its own): the errors are correlated, use the "
                "whole Σ⁻¹ — eᵀ Σ⁻¹ e, e.g. np.einsum('ki,ij,kj->k', e, inv(Σ), e)")
    if np.allclose(values, np.sum(errors ** 2, axis=1), rtol=1e-6, atol=0):
        return "you returned |e|²: weigh it by the inverse covariance, eᵀ Σ⁻¹ e"
    return f"NEES differs from eᵀ Σ⁻¹ e by up to {np.abs(values - ref).max() / ref.max():.2g} (relative)"


def check_nees(nees_function, verbose=True):
    """Self-check of ``nees(errors, cov) -> (T,)``, the normalised estimation error squared.

    Cases: two hand-made errors with a diagonal covariance, errors drawn from a correlated 6 × 6 covariance (their
    mean NEES is near 6, the χ²₆ mean), and a single trial.

    Examples
    --------
    >>> check_nees(nees_reference, verbose=False).passed
    True
    """
    def by_hand(f):
        e = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
        cov = np.diag([1.0, 4.0])
        return _diagnose_nees(f(e.copy(), cov.copy()), e, cov)

    def correlated(f):
        cov = _correlated_cov(3)
        e = np.random.default_rng(4).multivariate_normal(np.zeros(6), cov, size=2000)
        return _diagnose_nees(f(e.copy(), cov.copy()), e, cov)

    def one_trial(f):
        cov = _correlated_cov(5)
        e = np.random.default_rng(6).multivariate_normal(np.zeros(6), cov, size=1)
        return _diagnose_nees(f(e.copy(), cov.copy()), e, cov)

    return run_checks("nees", nees_function, [
        ("two errors by hand, a diagonal covariance", by_hand),
        ("2000 errors drawn from a correlated 6 × 6 covariance (mean NEES ≈ 6)", correlated),
        ("a single trial", one_trial),
    ], verbose=verbose)


__all__ = ["check_cramer_rao_pose", "check_nees", "cramer_rao_reference", "nees_reference"]
