"""Rotation averaging: every camera's orientation at once from the relative rotations of pairs of views.

A **view graph** has one node per view and one edge per pair ``(i, j)`` whose relative rotation ``R_ij`` was
measured (from an essential matrix, say), with ``R_j ≈ R_ij R_i`` in the workbook's convention (camera j relative
to camera i, as :func:`labutils.core.relative_pose` returns it). The rotations are found up to one global
rotation ``R_i -> R_i Q`` (a rotation of the world), fixed here by holding one view (``anchor``) at the identity.

1. :func:`chordal_rotation_averaging` — the linear (spectral) start (Martinec & Pajdla, "Robust rotation and
   translation estimation in multiview reconstruction", CVPR 2007; Arie-Nachimson et al., 3DIMPVT 2012;
   Hartley, Trumpf, Dai & Li, "Rotation averaging", IJCV 2013, Sec. 5.3): the stacked rotations
   ``M = [R_1; ...; R_V]`` satisfy ``G M = D M`` for the weighted matrix ``G`` of the relative rotations
   (blocks ``G_ji = w_ij R_ij``, ``G_ij = w_ij R_ijᵀ``) and the degrees ``D``; the three leading eigenvectors give
   ``M`` up to a 3×3 orthogonal matrix, and each block is projected onto SO(3) (:func:`project_to_so3`).
2. :func:`refine_rotations` — a robust refinement on the rotation manifold by iteratively reweighted least
   squares (Chatterjee & Govindu, "Efficient and robust large-scale rotation averaging", ICCV 2013): each edge's
   discrepancy ``E_ij = R_iᵀ R_ijᵀ R_j`` (the identity when consistent) is linearised as
   ``log E_ij + ω_j - ω_i`` for the updates ``R_k <- R_k exp([ω_k]×)``, and the weighted linear system is solved
   again and again with weights from an L1 or Cauchy loss on the residual angles, so that wrong edges
   (a wrong essential matrix) stop pulling.

:func:`rotation_averaging` runs both. The view graph must be connected (:func:`largest_component` picks the
part that is).
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from numpy.typing import ArrayLike

from ..core.geometry import angle_axis_from_rotation, rotation_from_angle_axis
from ..core.validation import as_array, as_count, as_positive, as_rotations

LOSSES = ("l2", "l1", "cauchy")


def as_pairs(pairs: ArrayLike, n_views: int, *, allow_empty: bool = False) -> np.ndarray:
    """Check the edges of a view graph: ``(E, 2)`` view indices in ``0..n_views-1``, two different views each.

    With ``allow_empty``, a graph without edges (``E = 0``, also written ``[]``) and a single view are accepted.

    >>> as_pairs([[0, 0]], 2)
    Traceback (most recent call last):
    ...
    ValueError: pairs[0] joins view 0 to itself: an edge needs two different views
    >>> as_pairs([], 3, allow_empty=True).shape
    (0, 2)
    """
    n_views = as_count(n_views, "n_views", 1 if allow_empty else 2)
    p = as_array(pairs, "pairs", "(E, 2)")
    if allow_empty and p.shape in ((0,), (0, 2)):
        return np.zeros((0, 2), int)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] == 0:
        at_least = 0 if allow_empty else 1
        raise ValueError(f"pairs must have shape (E, 2) with E >= {at_least} (one row (i, j) per edge); "
                         f"got shape {p.shape}")
    if not np.all(np.isfinite(p)) or np.any(p != np.round(p)) or p.min() < 0 or p.max() >= n_views:
        raise ValueError(f"pairs must hold view indices, integers in 0..{n_views - 1}; got values from "
                         f"{np.nanmin(p):g} to {np.nanmax(p):g}")
    p = p.astype(int)
    same = np.flatnonzero(p[:, 0] == p[:, 1])
    if same.size:
        raise ValueError(f"pairs[{same[0]}] joins view {p[same[0], 0]} to itself: an edge needs two different views")
    return p


def as_weights(weights: ArrayLike, n_edges: int) -> np.ndarray:
    """``(E,)`` positive finite edge weights (ones when ``weights`` is None).

    >>> as_weights(None, 2)
    array([1., 1.])
    """
    if weights is None:
        return np.ones(n_edges)
    w = as_array(weights, "weights", f"({n_edges},)")
    if w.shape != (n_edges,):
        raise ValueError(f"weights must have shape ({n_edges},), one per pair; got shape {w.shape}")
    if not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError("weights must be positive and finite (e.g. the inlier count of each pair)")
    return w


def as_view_graph(pairs: ArrayLike, R_rel: ArrayLike, n_views: int, weights: ArrayLike = None) -> tuple:
    """Check a view graph; returns ``pairs (E, 2) int``, ``R_rel (E, 3, 3)``, ``weights (E,)`` (ones by default).

    >>> p, R, w = as_view_graph([[0, 1]], [np.eye(3)], 2)
    >>> p.tolist(), w.tolist()
    ([[0, 1]], [1.0])
    """
    p = as_pairs(pairs, n_views)
    R_rel = as_rotations(R_rel, "R_rel", n=len(p), like_name="pairs")
    return p, R_rel, as_weights(weights, len(p))


def largest_component(pairs: ArrayLike, n_views: int) -> np.ndarray:
    """(V,) bool: the views of the largest connected part of the view graph (ties: the one with the lowest view).

    ``pairs`` is checked as by :func:`as_pairs` (view indices in ``0..n_views-1``), but may be empty: then every
    view is its own part and view 0 is returned.

    >>> largest_component([[0, 1], [1, 2], [3, 4]], 6).tolist()
    [True, True, True, False, False, False]
    """
    p = as_pairs(pairs, n_views, allow_empty=True)
    n_views = int(n_views)
    A = scipy.sparse.coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n_views, n_views))
    _, label = scipy.sparse.csgraph.connected_components(A, directed=False)
    sizes = np.bincount(label)
    return label == np.argmax(sizes)


def _check_connected(pairs, n_views):
    comp = largest_component(pairs, n_views)
    if not comp.all():
        out = np.flatnonzero(~comp)
        raise ValueError(f"the view graph is not connected: views {out[:10].tolist()}{' ...' if out.size > 10 else ''} "
                         "are not linked to the others by any pair (average each connected part on its own: "
                         "largest_component)")


def project_to_so3(M: ArrayLike) -> np.ndarray:
    """The rotation nearest to ``M`` in the Frobenius norm: ``U diag(1, 1, det(U Vᵀ)) Vᵀ`` from ``M = U S Vᵀ``.

    (Hartley et al. 2013, Sec. 5.3; H&Z Sec. A4.3.) Works on a stack ``(..., 3, 3)``.

    Raises
    ------
    ValueError
        Non-finite entries, or rank < 2 (the nearest rotation is not unique).

    >>> np.round(project_to_so3(2 * np.eye(3)), 12) + 0.0
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    >>> float(np.linalg.det(project_to_so3(np.diag([1.0, 2.0, -3.0]))))
    1.0
    """
    M = as_array(M, "M", "(3, 3) or (..., 3, 3)")
    if M.ndim < 2 or M.shape[-2:] != (3, 3):
        raise ValueError(f"M must have shape (3, 3) or (..., 3, 3); got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("M has non-finite entries (NaN or inf)")
    U, s, Vt = np.linalg.svd(M)
    if np.any(s[..., 1] <= 1e-12 * s[..., 0]):
        raise ValueError("M has rank < 2: its nearest rotation is not unique")
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def relative_rotation_errors_deg(R: ArrayLike, pairs: ArrayLike, R_rel: ArrayLike) -> np.ndarray:
    """(E,) angle in degrees between each measured ``R_ij`` and the one the absolute rotations imply, ``R_j R_iᵀ``.

    >>> relative_rotation_errors_deg(np.stack([np.eye(3)] * 2), [[0, 1]], [np.eye(3)])
    array([0.])
    """
    R = as_rotations(R, "R")
    pairs, R_rel, _ = as_view_graph(pairs, R_rel, len(R))
    return np.degrees(np.linalg.norm(_edge_logs(R, pairs, R_rel), axis=1))


def aligned_rotation_errors_deg(R_est: ArrayLike, R_true: ArrayLike) -> np.ndarray:
    """(V,) angle in degrees between ``R_est[i] Q`` and ``R_true[i]`` for the global rotation ``Q`` that fits best.

    Rotations from relative measurements are defined up to a rotation of the world, ``R_i -> R_i Q``; ``Q`` is the
    projection onto SO(3) of ``Σ R_est[i]ᵀ R_true[i]`` (the chordal fit). Views with a NaN estimate get NaN.

    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> R = rotation_from_angle_axis(np.random.default_rng(0).normal(size=(4, 3)))
    >>> Q = rotation_from_angle_axis([0.3, 0.0, 1.0])
    >>> bool(aligned_rotation_errors_deg(R @ Q, R).max() < 1e-6)
    True
    """
    R_true = as_rotations(R_true, "R_true")
    R_est = as_array(R_est, "R_est", f"({len(R_true)}, 3, 3)")
    if R_est.shape != R_true.shape:
        raise ValueError(f"R_est must have shape {R_true.shape} like R_true (NaN rows for views without an estimate); "
                         f"got {R_est.shape}")
    if np.isinf(R_est).any():
        raise ValueError("R_est has infinite entries (NaN rows mark views without an estimate)")
    ok = np.isfinite(R_est).all((1, 2))
    if not ok.any():
        raise ValueError("R_est has no finite rotation")
    Re = as_rotations(R_est[ok], "R_est")
    Q = project_to_so3(np.einsum("vji,vjk->ik", Re, R_true[ok]))
    err = np.full(len(R_true), np.nan)
    err[ok] = np.degrees(np.linalg.norm(angle_axis_from_rotation(project_to_so3(
        np.swapaxes(R_true[ok], 1, 2) @ Re @ Q)), axis=1))
    return err


def _edge_logs(R, pairs, R_rel):
    """(E, 3) ``log(R_iᵀ R_ijᵀ R_j)``: each edge's discrepancy as an angle-axis vector (zero when consistent)."""
    i, j = pairs[:, 0], pairs[:, 1]
    E = np.swapaxes(R[i], 1, 2) @ np.swapaxes(R_rel, 1, 2) @ R[j]
    return angle_axis_from_rotation(project_to_so3(E))


def _fix_gauge(R, anchor):
    """Rotate the world so that view ``anchor`` is the identity: ``R_i <- R_i R_anchorᵀ``."""
    return project_to_so3(R @ R[anchor].T)


def chordal_rotation_averaging(pairs: ArrayLike, R_rel: ArrayLike, n_views: int, weights: ArrayLike = None, *,
                               anchor: int = 0) -> np.ndarray:
    """Absolute rotations from relative ones, linearly: the spectral (chordal) relaxation.

    With ``M = [R_1; ...; R_V]`` (3V × 3), the block matrix ``G`` (``G_ji = w_ij R_ij``, ``G_ij = w_ij R_ijᵀ``,
    zero elsewhere) and the degrees ``D = diag(d_i I)``, ``d_i = Σ_j w_ij``, noise-free data satisfy
    ``G M = D M``: the columns of ``M`` span the eigenvectors of ``D⁻¹ G`` for its largest eigenvalue, 1. The
    three leading eigenvectors of the symmetric ``D^-½ G D^-½`` give ``M Q`` for an unknown orthogonal ``Q``;
    a reflection (``det Q = -1``) is undone by flipping one column when most blocks have a negative
    determinant, each block is projected onto SO(3), and the world is rotated so that ``R_anchor = I``
    (Martinec & Pajdla 2007, Sec. 3; Arie-Nachimson et al. 2012; Hartley et al. 2013, Sec. 5.3).

    Parameters
    ----------
    pairs : (E, 2) int array_like
        Edge ``k`` joins views ``pairs[k, 0] = i`` and ``pairs[k, 1] = j``.
    R_rel : (E, 3, 3) array_like
        ``R_ij`` with ``R_j ≈ R_ij R_i`` (camera j relative to camera i).
    n_views : int
    weights : (E,) array_like, optional
        Confidence of each edge (e.g. its inlier count); equal by default.
    anchor : int
        The view held at the identity (the gauge).

    Returns
    -------
    R : (V, 3, 3) ndarray

    Raises
    ------
    ValueError
        A malformed graph, or one that is not connected.

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> R = rotation_from_angle_axis(np.random.default_rng(0).normal(size=(4, 3)))
    >>> pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
    >>> R_rel = R[pairs[:, 1]] @ np.swapaxes(R[pairs[:, 0]], 1, 2)
    >>> R_est = chordal_rotation_averaging(pairs, R_rel, 4)
    >>> bool(np.allclose(R_est, R @ R[0].T))
    True
    """
    pairs, R_rel, w = as_view_graph(pairs, R_rel, n_views, weights)
    anchor = _as_anchor(anchor, n_views)
    _check_connected(pairs, n_views)
    V = n_views
    G = np.zeros((V, 3, V, 3))
    i, j = pairs[:, 0], pairs[:, 1]
    np.add.at(G, (j, slice(None), i), w[:, None, None] * R_rel)
    np.add.at(G, (i, slice(None), j), w[:, None, None] * np.swapaxes(R_rel, 1, 2))
    d = np.bincount(i, w, V) + np.bincount(j, w, V)
    s = np.repeat(1 / np.sqrt(d), 3)
    A = G.reshape(3 * V, 3 * V) * s[:, None] * s[None, :]
    _, vec = np.linalg.eigh(A)
    M = (vec[:, -3:] * s[:, None]).reshape(V, 3, 3)
    if np.sum(np.sign(np.linalg.det(M))) < 0:        # the eigenvectors found M Q with det Q = -1
        M[:, :, 0] *= -1
    return _fix_gauge(project_to_so3(M), anchor)


def _as_anchor(anchor, n_views):
    if not (isinstance(anchor, (int, np.integer)) and 0 <= anchor < n_views):
        raise ValueError(f"anchor must be a view index in 0..{n_views - 1}; got {anchor!r}")
    return int(anchor)


@dataclass
class RotationAveragingResult:
    """What :func:`refine_rotations` (and :func:`rotation_averaging`) found.

    Attributes
    ----------
    R : (V, 3, 3) ndarray
        Absolute rotations, ``R[anchor] = I``.
    residuals_deg : (E,) ndarray
        Each edge's disagreement with them, in degrees.
    weights : (E,) ndarray
        The last IRLS weights (edge weight × robust weight, scaled to at most 1): small for edges judged wrong.
    n_iter : int
    converged : bool
        The last update moved no rotation by more than ``tol`` radians.
    """

    R: np.ndarray
    residuals_deg: np.ndarray
    weights: np.ndarray
    n_iter: int
    converged: bool


def _robust_weights(r, loss, scale):
    """IRLS weights ``ρ'(r) / r`` of the residual angles ``r`` (radians) for ``ρ`` = r²/2, r, or Cauchy."""
    if loss == "l2":
        return np.ones_like(r)
    if loss == "l1":
        return 1.0 / np.maximum(r, 1e-6 * scale)
    return 1.0 / (1.0 + (r / scale) ** 2)


def refine_rotations(R0: ArrayLike, pairs: ArrayLike, R_rel: ArrayLike, weights: ArrayLike = None, *,
                     loss: str = "l1", scale_deg: float = 2.0, anchor: int = 0, max_iter: int = 50,
                     tol: float = 1e-9) -> RotationAveragingResult:
    """Robust rotation averaging by IRLS on the rotation manifold (Chatterjee & Govindu, ICCV 2013).

    Minimises ``Σ w_ij ρ(‖log(R_iᵀ R_ijᵀ R_j)‖)`` over the rotations. Each iteration linearises every edge's
    discrepancy ``e_ij = log(R_iᵀ R_ijᵀ R_j)`` in the updates ``R_k <- R_k exp([ω_k]×)`` as
    ``e_ij + ω_j - ω_i``, solves the weighted linear least-squares problem with ``ω_anchor = 0`` (weights
    ``w_ij ρ'(r)/r`` of the current residual angles ``r``) and applies the update.

    Parameters
    ----------
    R0 : (V, 3, 3) array_like
        The start (e.g. :func:`chordal_rotation_averaging`).
    pairs, R_rel, weights :
        The view graph, as in :func:`chordal_rotation_averaging`.
    loss : {'l1', 'cauchy', 'l2'}
        ``ρ(r) = r`` (L1: the median of the rotations, robust to a minority of wrong edges),
        ``scale² log(1 + r²/scale²)`` (Cauchy: wrong edges get almost no weight), or ``r²`` (least squares).
    scale_deg : float
        Residual angle where the Cauchy loss starts to discount an edge (L1: the smallest residual it
        divides by is ``1e-6 scale``).
    anchor : int
        The view held at the identity.
    max_iter : int
    tol : float
        Stop when no rotation moves by more than ``tol`` radians.

    Returns
    -------
    RotationAveragingResult

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> rng = np.random.default_rng(1)
    >>> R = rotation_from_angle_axis(rng.normal(size=(5, 3)))
    >>> pairs = np.array([[i, j] for i in range(5) for j in range(i + 1, 5)])
    >>> R_rel = R[pairs[:, 1]] @ np.swapaxes(R[pairs[:, 0]], 1, 2)
    >>> R_rel[0] = rotation_from_angle_axis([0.0, 0.0, 1.0]) @ R_rel[0]        # one wrong edge, 57 degrees off
    >>> res = refine_rotations(np.stack([np.eye(3)] * 5), pairs, R_rel)
    >>> bool(np.allclose(res.R, R @ R[0].T, atol=1e-6)), int(np.argmax(res.residuals_deg))
    (True, 0)
    """
    R = as_rotations(R0, "R0").copy()
    V = len(R)
    if V < 2:
        raise ValueError(f"R0 must hold the rotations of at least two views; got {V}")
    pairs, R_rel, w = as_view_graph(pairs, R_rel, V, weights)
    anchor = _as_anchor(anchor, V)
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")
    scale = np.radians(as_positive(scale_deg, "scale_deg"))
    max_iter = as_count(max_iter, "max_iter", 1)
    tol = as_positive(tol, "tol")
    _check_connected(pairs, V)
    w = w / w.max()
    i, j = pairs[:, 0], pairs[:, 1]
    free = np.ones(V, bool)
    free[anchor] = False
    converged, n_iter = False, 0
    R = _fix_gauge(R, anchor)
    while n_iter < max_iter:
        n_iter += 1
        e = _edge_logs(R, pairs, R_rel)
        wk = w * _robust_weights(np.linalg.norm(e, axis=1), loss, scale)
        # normal equations of Σ wk ‖ω_j - ω_i + e‖²: one 3×3 identity block pattern per edge
        H = np.zeros((V, V))
        np.add.at(H, (i, i), wk)
        np.add.at(H, (j, j), wk)
        np.add.at(H, (i, j), -wk)
        np.add.at(H, (j, i), -wk)
        g = np.zeros((V, 3))
        np.add.at(g, j, -wk[:, None] * e)
        np.add.at(g, i, wk[:, None] * e)
        omega = np.zeros((V, 3))
        omega[free] = np.linalg.solve(H[np.ix_(free, free)], g[free])
        R = project_to_so3(R @ rotation_from_angle_axis(omega))
        if np.linalg.norm(omega, axis=1).max() < tol:
            converged = True
            break
    e = _edge_logs(R, pairs, R_rel)
    r = np.linalg.norm(e, axis=1)
    wk = w * _robust_weights(r, loss, scale)
    return RotationAveragingResult(R=R, residuals_deg=np.degrees(r), weights=wk / wk.max(), n_iter=n_iter,
                                   converged=converged)


def rotation_averaging(pairs: ArrayLike, R_rel: ArrayLike, n_views: int, weights: ArrayLike = None, *,
                       loss: str = "l1", scale_deg: float = 2.0, anchor: int = 0,
                       max_iter: int = 50) -> RotationAveragingResult:
    """The chordal start (:func:`chordal_rotation_averaging`), then the robust IRLS (:func:`refine_rotations`).

    Returns
    -------
    RotationAveragingResult

    Examples
    --------
    >>> res = rotation_averaging([[0, 1], [1, 2]], np.stack([np.eye(3)] * 2), 3)
    >>> res.R.shape, float(res.residuals_deg.max())
    ((3, 3, 3), 0.0)
    """
    R0 = chordal_rotation_averaging(pairs, R_rel, n_views, weights, anchor=anchor)
    return refine_rotations(R0, pairs, R_rel, weights, loss=loss, scale_deg=scale_deg, anchor=anchor,
                            max_iter=max_iter)
