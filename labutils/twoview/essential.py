"""The essential matrix and the relative pose of two calibrated views (H&Z Sec. 9.6).

Conventions: camera 1 is ``[I | 0]``, camera 2 ``[R | t]``; ``E = [t]× R``; ``F = K2⁻ᵀ E K1⁻¹``; E is defined up to
scale (and sign), t from E up to scale and sign.
"""
import numpy as np
from numpy.typing import ArrayLike

from ..core.geometry import skew
from ..core.validation import (
    as_calibration,
    as_essential,
    as_fundamental,
    as_matrix,
    as_points,
    as_rotation,
    as_vector3,
)
from .epipolar import _canonical_sign, _transform_points, check_pair, sampson_distance
from .triangulation import triangulate


def fundamental_from_pose(K1: ArrayLike, K2: ArrayLike, R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """``F = K2⁻ᵀ [t]× R K1⁻¹`` for camera 2 ``[R | t]`` relative to camera 1 ``[I | 0]`` (H&Z eq. 9.2).

    Returns F with unit norm and the package's sign convention.

    Examples
    --------
    >>> F = fundamental_from_pose(np.eye(3), np.eye(3), np.eye(3), [1., 0, 0])
    >>> (F * np.sqrt(2)).round(9) + 0.0
    array([[ 0.,  0.,  0.],
           [ 0.,  0.,  1.],
           [ 0., -1.,  0.]])
    """
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    R = as_rotation(R, "R")
    t = as_matrix(t, "t", (3,))
    if not np.linalg.norm(t) > 0:
        raise ValueError("t is zero: with no baseline the two views are related by a homography and F is not defined")
    return _canonical_sign(np.linalg.inv(K2).T @ skew(t) @ R @ np.linalg.inv(K1))


def essential_from_fundamental(F: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> np.ndarray:
    """``E = K2ᵀ F K1``, projected onto the essential manifold (H&Z eq. 9.12, Sec. 9.6.1).

    The projection keeps the singular vectors and sets the singular values to ``(1, 1, 0)``. The closest
    essential matrix in Frobenius norm has singular values ``((σ₁ + σ₂)/2, (σ₁ + σ₂)/2, 0)`` (H&Z Result 9.18
    and Sec. 11.7.3); since E is defined up to scale, this is the same matrix scaled to ``(1, 1, 0)``.

    Parameters
    ----------
    F : (3, 3) array_like
    K1, K2 : (3, 3) array_like
        Calibrations of views 1 and 2.

    Returns
    -------
    E : (3, 3) ndarray
        Singular values exactly (1, 1, 0) (to rounding).

    Examples
    --------
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> F = fundamental_from_pose(K, K, np.eye(3), [1., 0, 0])
    >>> np.linalg.svd(essential_from_fundamental(F, K, K))[1].round(9)
    array([1., 1., 0.])
    """
    F = as_matrix(F, "F", (3, 3))
    as_fundamental(F, "F")
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    U, s, Vt = np.linalg.svd(K2.T @ F @ K1)
    if s[1] <= 1e-12 * s[0]:
        raise ValueError(f"K2ᵀ F K1 has rank < 2 (singular values {s}): F is not a fundamental matrix")
    return U @ np.diag([1.0, 1.0, 0.0]) @ Vt


def decompose_essential(E: ArrayLike) -> list:
    """The four camera poses ``[R | t]`` compatible with E, camera 1 being ``[I | 0]`` (H&Z Result 9.19).

    With ``E = U diag(1, 1, 0) Vᵀ`` (U, V rotations) and ``W = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]``:
    ``R ∈ {U W Vᵀ, U Wᵀ Vᵀ}`` and ``t = ±u3``. Only one of the four puts the points in front of both
    cameras: see :func:`pose_from_essential`.

    Parameters
    ----------
    E : (3, 3) array_like
        Essential matrix (any scale): singular values (s, s, 0) within 1e-5 relative
        (:func:`labutils.core.validation.as_essential`).

    Returns
    -------
    list of 4 tuples (R, t)
        ``(U W Vᵀ, u3), (U W Vᵀ, -u3), (U Wᵀ Vᵀ, u3), (U Wᵀ Vᵀ, -u3)``; det R = +1, ``|t| = 1``.

    Raises
    ------
    ValueError
        If E is not finite, not 3×3, or not essential (``E = I``, rank < 2, unequal singular values).

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> R0, t0 = rotation_from_angle_axis([0.1, 0.2, 0.3]), np.array([0.6, 0.0, 0.8])
    >>> poses = decompose_essential(skew(t0) @ R0)
    >>> len(poses), any(np.allclose(R, R0) and np.allclose(t, t0) for R, t in poses)
    (4, True)
    """
    E = as_essential(E, "E")
    U, s, Vt = np.linalg.svd(E)
    if s[0] == 0 or s[1] <= 1e-12 * s[0]:
        raise ValueError(f"E has rank < 2 (singular values {s}): not an essential matrix")
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Ra, Rb, u3 = U @ W @ Vt, U @ W.T @ Vt, U[:, 2]
    return [(Ra, u3.copy()), (Ra, -u3), (Rb, u3.copy()), (Rb, -u3)]


def _cheirality_counts(poses, y1, y2):
    """Points in front of both cameras for each pose; y1, y2 are normalised image points."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    counts = []
    for R, t in poses:
        X = triangulate(P1, np.hstack([R, t[:, None]]), y1, y2)
        ok = np.isfinite(X).all(1) & (X[:, 2] > 0) & (X @ R[2] + t[2] > 0)
        counts.append(int(ok.sum()))
    return counts


def cheirality_choice(poses: list, y1: ArrayLike, y2: ArrayLike) -> tuple:
    """The candidate pose that puts the most points in front of both cameras (H&Z Sec. 9.6.3).

    The step of :func:`pose_from_essential` after :func:`decompose_essential`, on normalised points: each
    candidate triangulates the points (DLT with ``P1 = [I | 0]``, ``P2 = [R | t]``) and counts those with positive
    depth in camera 1 (``X_z``) and in camera 2 (``(R X + t)_z``); the first candidate with the most wins.

    Parameters
    ----------
    poses : list of (R (3, 3), t (3,))
        Candidate poses of camera 2, camera 1 being ``[I | 0]``.
    y1, y2 : (N, 2) array_like
        Corresponding normalised image points ``K⁻¹ x``.

    Returns
    -------
    (R, t)
        One of ``poses``, unchanged.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.core.geometry import relative_pose, skew
    >>> from labutils.twoview.epipolar import transform_points
    >>> s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> Kinv = np.linalg.inv(s.K)
    >>> R_true, t_true = relative_pose(s.R[0], s.t[0], s.R[1], s.t[1])
    >>> R, t = cheirality_choice(decompose_essential(skew(t_true) @ R_true), transform_points(Kinv, x1),
    ...                          transform_points(Kinv, x2))
    >>> bool(np.allclose(R, R_true))
    True
    """
    y1 = as_points(y1, "y1", min_n=5)              # a vote needs voters: five, the minimum that fixes E
    y2 = as_points(y2, "y2", like=y1)
    if isinstance(poses, np.ndarray | str) or not hasattr(poses, "__len__") or not len(poses):
        raise ValueError(f"poses must be a list of (R, t) candidates, at least one; got {type(poses).__name__}")
    for k, pose in enumerate(poses):
        if not isinstance(pose, tuple | list) or len(pose) != 2:
            raise ValueError(f"poses[{k}] must be a pair (R, t)")
        as_rotation(pose[0], f"poses[{k}] R")
        as_vector3(pose[1], f"poses[{k}] t")
    return poses[int(np.argmax(_cheirality_counts(list(poses), y1, y2)))]


def cheirality_counts(E: ArrayLike, x1: ArrayLike, x2: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> list:
    """How many correspondences each of the four poses of E puts in front of both cameras (H&Z Sec. 9.6.3).

    Parameters
    ----------
    E : (3, 3) array_like
    x1, x2 : (N, 2) array_like
        Corresponding pixels.
    K1, K2 : (3, 3) array_like

    Returns
    -------
    list of 4 int
        In the order of :func:`decompose_essential`; exactly one pose should win.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.twoview.epipolar import fundamental_8point
    >>> s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> E = essential_from_fundamental(fundamental_8point(x1, x2), s.K, s.K)
    >>> sorted(cheirality_counts(E, x1, x2, s.K, s.K))[-2:]
    [0, 20]
    """
    x1, x2 = check_pair(x1, x2, 1)
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    y1, y2 = _transform_points(np.linalg.inv(K1), x1), _transform_points(np.linalg.inv(K2), x2)
    return _cheirality_counts(decompose_essential(E), y1, y2)


def pure_rotation(x1: ArrayLike, x2: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> tuple:
    """The rotation that best maps the rays of x1 onto those of x2 (no baseline), and the Sampson distances to it.

    Without a baseline the views are related by the homography ``x2 ≃ K2 R K1⁻¹ x1`` (H&Z Sec. 8.4.2). R is the
    orthogonal Procrustes (Kabsch) rotation of the unit rays, ``argmin Σ ‖R y1ᵢ - y2ᵢ‖²``, fitted again (three
    times) to the correspondences within three times the median distance, so that a few outliers do not drag it;
    each correspondence's distance is the Sampson distance to that homography with both pixels noisy,
    ``rᵀ (J Jᵀ + I)⁻¹ r`` with ``r = π(H x1) - x2`` and ``J = ∂π(H x1)/∂x1``.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
    K1, K2 : (3, 3) array_like

    Returns
    -------
    R : (3, 3) ndarray
    d : (N,) ndarray
        Pixels, not squared.

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]]); R0 = rotation_from_angle_axis([0, 0.1, 0])
    >>> x1 = np.array([[100., 50], [300, 400], [500, 100], [320, 240]])
    >>> u = np.c_[x1, np.ones(4)] @ (K @ R0 @ np.linalg.inv(K)).T
    >>> R, d = pure_rotation(x1, u[:, :2] / u[:, 2:], K, K)
    >>> bool(np.allclose(R, R0)), bool(d.max() < 1e-9)
    (True, True)
    """
    x1, x2 = check_pair(x1, x2, 2)
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    n = len(x1)
    y1, y2 = (np.linalg.solve(K, np.c_[x, np.ones(n)].T).T for K, x in ((K1, x1), (K2, x2)))
    y1, y2 = y1 / np.linalg.norm(y1, axis=1, keepdims=True), y2 / np.linalg.norm(y2, axis=1, keepdims=True)
    use = np.ones(n, bool)
    for _ in range(4):
        U, _, Vt = np.linalg.svd(y2[use].T @ y1[use])
        R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
        H = K2 @ R @ np.linalg.inv(K1)
        u = np.c_[x1, np.ones(n)] @ H.T
        p = u[:, :2] / u[:, 2:]
        J = (H[None, :2, :2] - p[:, :, None] * H[None, 2:3, :2]) / u[:, 2, None, None]
        r = p - x2
        d = np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", r, np.linalg.inv(J @ J.transpose(0, 2, 1) + np.eye(2)), r),
                               0.0))
        use = d <= 3 * np.median(d)
        if use.sum() < 2:
            break
    return R, d


def check_parallax(F: ArrayLike, x1: ArrayLike, x2: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> tuple:
    """Refuse correspondences that a pure rotation explains as well as F: no baseline, the translation unknown.

    Torr's GRIC (Torr 1998; as in :func:`labutils.twoview.gric_model_selection`) of the rotation of
    :func:`pure_rotation` (a 2D variety, d = 2, k = 3 parameters) against F (d = 3, k = 7):
    ``GRIC = Σ ρ(eᵢ² / σ²) + log(4) d n + log(4n) k`` with ``eᵢ`` the Sampson distances, σ² the median of F's
    squared distances over 0.455 (the median of χ²(1); at least (10⁻⁶ px)²), and Torr's robust
    ``ρ(x) = min(x, 2 (4 - d))``, so that an outlier costs each model a constant (F's inliers may hold a few
    outliers that happen to lie near their epipolar lines, which a rotation cannot follow). With no baseline F
    over-fits the noise (1 residual degree of freedom per point against the rotation's 2) and the rotation wins
    by about ``0.39 n``; a real baseline leaves the rotation the parallax, capped at 4 per point against F's ~1.

    Parameters
    ----------
    F : (3, 3) array_like
        Fitted to the correspondences.
    x1, x2 : (N, 2) array_like
        Inliers, N >= 8.
    K1, K2 : (3, 3) array_like

    Returns
    -------
    gric_rotation, gric_F : float
        F wins (``gric_F < gric_rotation``).

    Raises
    ------
    ValueError
        Bad input, or the rotation wins (no parallax: x2 = x1, a pure rotation, or a baseline too short to see).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.twoview.epipolar import fundamental_8point
    >>> s = make_scene(30, 2, noise_px=0.5, rng=np.random.default_rng(0)); x1, x2, _ = s.pair(0, 1)
    >>> g_R, g_F = check_parallax(fundamental_8point(x1, x2), x1, x2, s.K, s.K); bool(g_F < g_R)
    True
    """
    F = as_matrix(F, "F", (3, 3))
    x1, x2 = check_pair(x1, x2, 8)
    n = len(x1)
    d_R, d_F = pure_rotation(x1, x2, K1, K2)[1], sampson_distance(F, x1, x2)
    s2, l1, l2 = max(np.median(d_F ** 2) / 0.455, 1e-12), np.log(4.0), np.log(4.0 * n)
    g_R = np.minimum(d_R ** 2 / s2, 4.0).sum() + 2 * l1 * n + 3 * l2
    g_F = np.minimum(d_F ** 2 / s2, 2.0).sum() + 3 * l1 * n + 7 * l2
    e_R, e_F = float(np.median(d_R ** 2)), float(np.median(d_F ** 2))
    if g_R <= g_F:
        raise ValueError(f"no parallax: a pure rotation explains the correspondences as well as F (GRIC {g_R:.1f} "
                         f"against {g_F:.1f}; median {np.sqrt(e_R):.3g} px against {np.sqrt(e_F):.3g} px, "
                         f"N = {n}): no baseline (x2 = x1, or a pure rotation), so the translation is not determined")
    return g_R, g_F


def pose_from_essential(E: ArrayLike, x1: ArrayLike, x2: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> tuple:
    """Relative pose of camera 2 (camera 1 = ``[I | 0]``) from E, chosen by cheirality (H&Z Sec. 9.6.3).

    Each of the four poses of :func:`decompose_essential` is used to triangulate the correspondences
    (linear DLT on ``K⁻¹ x``); the pose that puts the most points in front of both cameras wins
    (:func:`cheirality_counts` gives the four counts). Correspondences that a pure rotation maps exactly
    (:func:`pure_rotation`: x2 = x1, or no baseline, noise-free) are refused; with noise E itself cannot tell,
    as it may be rough (E from F): :func:`check_parallax` compares the rotation with F.

    Parameters
    ----------
    E : (3, 3) array_like
        Essential matrix, ``x2_nᵀ E x1_n = 0`` for normalised coordinates ``x_n = K⁻¹ x_h``.
    x1, x2 : (N, 2) array_like
        Corresponding pixels (inliers), N >= 1.
    K1, K2 : (3, 3) array_like

    Returns
    -------
    R : (3, 3) ndarray
        det +1.
    t : (3,) ndarray
        ``|t| = 1``: the translation direction (the scale is not observable).

    Raises
    ------
    ValueError
        Bad input, no pose puts more points in front than every other, or a rotation maps x1 onto x2 exactly
        (no parallax).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.twoview.epipolar import fundamental_8point
    >>> from labutils.core.geometry import relative_pose
    >>> s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> E = essential_from_fundamental(fundamental_8point(x1, x2), s.K, s.K)
    >>> R, t = pose_from_essential(E, x1, x2, s.K, s.K)
    >>> R_true, t_true = relative_pose(s.R[0], s.t[0], s.R[1], s.t[1])
    >>> bool(np.allclose(R, R_true) and np.allclose(t, t_true / np.linalg.norm(t_true)))
    True
    """
    counts = cheirality_counts(E, x1, x2, K1, K2)
    order = np.argsort(counts)[::-1]
    if counts[order[0]] == 0 or counts[order[0]] == counts[order[1]]:
        raise ValueError(f"cheirality cannot decide between the four poses (points in front: {counts}); "
                         "no baseline, or the correspondences do not fit E")
    if pure_rotation(x1, x2, K1, K2)[1].max() < 1e-6:
        raise ValueError("no parallax: a pure rotation maps x1 onto x2 exactly (x2 = x1, or no baseline), so the "
                         "translation is not determined")
    return decompose_essential(E)[order[0]]
