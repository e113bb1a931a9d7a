"""Zhang's closed form: a homography per view of a planar board, K from the image of the absolute conic, and each
view's pose (Z. Zhang, "A flexible new technique for camera calibration", IEEE PAMI 22(11), 2000, Sec. 3.1;
H&Z Sec. 8.5 and 8.8)."""
import numpy as np

from ..core.validation import as_array, as_calibration, as_matrix, as_points
from ..twoview.epipolar import homography_dlt

# ---------------------------------------------------------------------------------------------------------------
# Zhang's closed form
# ---------------------------------------------------------------------------------------------------------------

def as_board_points(X, name):
    X = as_points(X, name, dim=3, min_n=4)
    if np.abs(X[:, 2]).max() > 1e-9 * max(1.0, np.abs(X[:, :2]).max()):
        raise ValueError(f"{name} must lie on the board plane Z = 0 (a planar target); "
                         f"largest |Z| is {np.abs(X[:, 2]).max():.3g}")
    return X


def board_homography(X, x):
    """Homography from the board plane to the image, ``x_h ≃ H @ (X, Y, 1)`` (normalised DLT, H&Z Alg. 4.2).

    Parameters
    ----------
    X : (N, 3) array_like
        Board points with Z = 0 (N >= 4, not all on a line).
    x : (N, 2) array_like
        Their pixels.

    Returns
    -------
    H : (3, 3) ndarray
        Scaled so that ``H[2, 2] = 1``... unless that entry is 0; then unit Frobenius norm.

    Examples
    --------
    >>> X = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    >>> board_homography(X, 100 * X[:, :2] + 5).round(9) + 0.0
    array([[100.,   0.,   5.],
           [  0., 100.,   5.],
           [  0.,   0.,   1.]])
    """
    X = as_board_points(X, "X")
    x = as_points(x, "x", min_n=4, like=X)
    H, _ = homography_dlt(X[:, :2], x)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


def _v(H, i, j):
    """Zhang's eq. (8): ``h_iᵀ B h_j = v_ijᵀ b`` with ``b = (B11, B12, B22, B13, B23, B33)``, columns h_i of H."""
    hi, hj = H[..., :, i], H[..., :, j]
    return np.stack([hi[..., 0] * hj[..., 0],
                     hi[..., 0] * hj[..., 1] + hi[..., 1] * hj[..., 0],
                     hi[..., 1] * hj[..., 1],
                     hi[..., 2] * hj[..., 0] + hi[..., 0] * hj[..., 2],
                     hi[..., 2] * hj[..., 1] + hi[..., 1] * hj[..., 2],
                     hi[..., 2] * hj[..., 2]], axis=-1)


def intrinsics_from_homographies(Hs, *, zero_skew=False, equal_focal=False, image_size=None):
    """Closed-form K from board homographies through the image of the absolute conic (Zhang Sec. 3.1; H&Z Sec. 8.8).

    With ``H = λ K [r1 r2 t]`` and orthonormal r1, r2, each view gives two equations linear in the
    symmetric ``B = K⁻ᵀK⁻¹``: ``h1ᵀ B h2 = 0`` and ``h1ᵀ B h1 = h2ᵀ B h2``, i.e. ``v12ᵀ b = 0`` and
    ``(v11 - v22)ᵀ b = 0``. Stacked for all views, ``V b = 0``; b is the right singular vector of V with
    the smallest singular value, B is positive definite up to sign, and K follows from the Cholesky factor
    ``B = L Lᵀ``: ``K = (Lᵀ)⁻¹``, scaled to ``K[2, 2] = 1``.

    Parameters
    ----------
    Hs : (V, 3, 3) array_like
        Homographies board → image, each up to scale and sign.
    zero_skew : bool
        Impose ``K[0, 1] = 0`` (B12 = 0): 2 views suffice.
    equal_focal : bool
        Also impose ``fx = fy`` (B11 = B22; needs ``zero_skew``).
    image_size : (w, h), optional
        When given, pixels are first mapped to about [-1, 1] (a similarity), which conditions V better.

    Returns
    -------
    K : (3, 3) ndarray
        Upper triangular, positive diagonal, ``K[2, 2] = 1``.

    Raises
    ------
    ValueError
        If there are too few views (3, or 2 with ``zero_skew``), or B is not positive definite (the views do
        not determine K: boards all parallel to each other, or nearly parallel to the image).

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> K0 = np.array([[800., 0.5, 320], [0, 780, 240], [0, 0, 1]])
    >>> Hs = [K0 @ np.column_stack([rotation_from_angle_axis(w)[:, :2], [0.1, 0, 2]])
    ...       for w in ([0.3, 0, 0], [0, 0.4, 0.1], [-0.2, 0.3, 0])]
    >>> np.allclose(intrinsics_from_homographies(Hs), K0)
    True
    """
    Hs = as_array(Hs, "Hs", "(V, 3, 3)")
    if Hs.ndim != 3 or Hs.shape[1:] != (3, 3):
        raise ValueError(f"Hs must have shape (V, 3, 3); got shape {Hs.shape}")
    if not np.all(np.isfinite(Hs)):
        raise ValueError("Hs has non-finite entries (NaN or inf)")
    if equal_focal and not zero_skew:
        raise ValueError("equal_focal=True needs zero_skew=True")
    need = 3 if not zero_skew else 2
    if len(Hs) < need:
        unknowns = 5 if not zero_skew else 4 if not equal_focal else 3
        raise ValueError(f"Hs has {len(Hs)} homographies; at least {need} views are needed "
                         f"({unknowns} unknowns in K, 2 equations a view)")
    T = np.eye(3)
    if image_size is not None:
        w, h = image_size
        s = 2.0 / max(w, h)
        T = np.array([[s, 0, -s * (w - 1) / 2], [0, s, -s * (h - 1) / 2], [0, 0, 1]])
    Hn = T @ Hs
    Hn = Hn / np.linalg.norm(Hn, axis=(1, 2), keepdims=True)
    V = np.concatenate([_v(Hn, 0, 1), _v(Hn, 0, 0) - _v(Hn, 1, 1)])
    # constraints on b as a basis N of the allowed subspace: b = N c
    N = np.eye(6)
    if zero_skew:
        N = N[:, [0, 2, 3, 4, 5]]
    if equal_focal:
        N = np.column_stack([[1, 0, 1, 0, 0, 0], np.eye(6)[:, 3:]])
    _, s, Vt = np.linalg.svd(V @ N)
    b = N @ Vt[-1]
    B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
    if B[0, 0] < 0:
        B = -B
    try:
        L = np.linalg.cholesky(B)
    except np.linalg.LinAlgError:
        raise ValueError("the homographies do not determine K: the estimated image of the absolute conic B is not "
                         "positive definite (too few views, boards all parallel to each other or to the image plane, "
                         "or too much noise)") from None
    K = np.linalg.inv(L.T)
    K = np.linalg.solve(T, K / K[2, 2])
    return K / K[2, 2]


def pose_from_homography(H, K):
    """Board pose from its homography and K (Zhang Sec. 3.1): ``[r1 r2 t] = λ K⁻¹ H``, ``r3 = r1 × r2``.

    The scale is ``λ = 2 / (|K⁻¹h1| + |K⁻¹h2|)``, its sign makes the board lie in front (t_z > 0); with noise
    ``[r1 r2 r3]`` is not exactly orthonormal and is replaced by the nearest rotation (Zhang Appendix C).

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray
        ``x_cam = R @ X + t`` for board points ``X = (X, Y, 0)``.

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> K = np.array([[800., 0, 320], [0, 800, 240], [0, 0, 1]]); R0 = rotation_from_angle_axis([0.3, -0.2, 0.1])
    >>> R, t = pose_from_homography(-3 * K @ np.column_stack([R0[:, :2], [0.1, 0.2, 2.0]]), K)
    >>> bool(np.allclose(R, R0)), t.round(12) + 0.0
    (True, array([0.1, 0.2, 2. ]))
    """
    H = as_matrix(H, "H", (3, 3))
    K = as_calibration(K, "K")
    M = np.linalg.solve(K, H)
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] < 0:
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return R, t
