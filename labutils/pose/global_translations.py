"""Camera positions from known rotations, all views at once: the translation step of global structure from motion.

With every rotation ``R_i`` known (from :mod:`labutils.pose.rotation_averaging`), what is left is linear.

- :func:`centres_from_points` — the **points** method (the "known-rotation problem": Martinec & Pajdla,
  "Robust rotation and translation estimation in multiview reconstruction", CVPR 2007, Sec. 4; Kahl & Hartley,
  "Multiple-view geometry under the L∞-norm", PAMI 2008, Sec. 5). An observation of point ``X_j`` by view ``i``
  along the world-frame ray ``d = R_iᵀ K⁻¹ x_h / ‖·‖`` says that ``X_j - C_i`` is parallel to ``d``:
  ``(I - d dᵀ)(X_j - C_i) = 0``, linear in the unknown centres and points (its length is the distance of
  ``X_j`` from the ray). The points are eliminated (a 3 × 3 solve per track: the Schur complement), and the
  centres are the eigenvector of the reduced matrix with the smallest eigenvalue once the translation gauge is
  lifted; the scale is free (fixed here by the RMS distance of the centres from their mean being 1), the sign
  by the points being in front. Because the points tie the views together, collinear centres (forward motion)
  are as well determined as any others. :func:`robust_centres_from_points` reweights it (IRLS) so that each
  equation measures a pixel error and wrong observations lose their weight.
- :func:`centres_from_directions` — the **pairwise-direction** method (Govindu, "Combining two-view
  constraints for motion estimation", CVPR 2001; Brand, Antone & Teller, ECCV 2004): each pair's translation
  direction turned into the world frame, ``d_ij ∝ C_j - C_i`` (:func:`pair_directions`), gives
  ``[d_ij]× (C_j - C_i) = 0``. It needs no points, but it cannot tell how far apart cameras on one line are:
  for collinear centres (forward motion) the solution is not determined, and the method refuses it.

Centres and translations convert by ``t_i = -R_i C_i``.
"""
import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from numpy.typing import ArrayLike

from ..core.validation import as_array, as_calibration, as_count, as_mask, as_positive, as_rotations, as_tracks
from .rotation_averaging import as_pairs, as_weights


def world_rays(tracks: ArrayLike, K: ArrayLike, R: ArrayLike) -> np.ndarray:
    """(V, T, 3) unit viewing rays in the world frame, ``R_iᵀ K_i⁻¹ x_h`` normalised (NaN where unseen).

    >>> world_rays(np.array([[[0.0, 0.0]]]), np.eye(3), np.eye(3)[None])
    array([[[0., 0., 1.]]])
    """
    tracks = as_tracks(tracks)
    V = tracks.shape[0]
    Ks = as_calibration(K, "K", n_views=V, like_name="tracks")
    R = as_rotations(R, "R", n=V, like_name="tracks")
    x_h = np.concatenate([tracks, np.ones(tracks.shape[:2] + (1,))], axis=2)
    d = np.einsum("vji,vjk,vtk->vti", R, np.linalg.inv(Ks), x_h)
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def _inputs(tracks, K, R, mask):
    """Checked tracks, K stack, R (NaN rows: views left out), and the observations to use."""
    tracks = as_tracks(tracks, min_views=2)
    V, T = tracks.shape[:2]
    Ks = as_calibration(K, "K", n_views=V, like_name="tracks")
    R = as_array(R, "R", f"({V}, 3, 3)")
    if R.shape != (V, 3, 3):
        raise ValueError(f"R must have shape ({V}, 3, 3) like tracks (NaN for views to leave out); got {R.shape}")
    have = np.isfinite(R).all((1, 2))
    if np.isinf(R).any() or (~have & np.isfinite(R).any((1, 2))).any():
        raise ValueError("R must be finite rotations, or rows entirely NaN for the views to leave out; got inf or "
                         "a partly NaN row")
    if have.sum() < 2:
        raise ValueError("R must hold at least two finite rotations (NaN rows leave views out)")
    R = R.copy()
    R[have] = as_rotations(R[have], "R")
    R[~have] = np.eye(3)
    seen = np.all(np.isfinite(tracks), axis=-1)
    if mask is None:
        use = seen.copy()
    else:
        use = as_mask(mask, "mask", (V, T), like="tracks") & seen
    use[~have] = False
    return tracks, Ks, R, have, use


def _select(rays, use, min_angle_deg):
    """Tracks with two or more rays at least ``min_angle_deg`` apart (else the point is not located), and the
    views that keep two or more observations; repeated until stable."""
    use = use.copy()
    while True:
        d = np.where(use[..., None], np.nan_to_num(rays), 0.0)
        A = use.sum(0)[:, None, None] * np.eye(3) - np.einsum("vti,vtj->tij", d, d)
        lam_min = np.linalg.eigvalsh(A)[:, 0]                  # for two rays at angle θ: 1 - cos θ
        ok_t = (use.sum(0) >= 2) & (lam_min >= 1 - np.cos(np.radians(min_angle_deg)))
        ok_v = (use & ok_t[None]).sum(1) >= 2
        new = use & ok_t[None] & ok_v[:, None]
        if np.array_equal(new, use):
            return use
        use = new


def _connected_views(use):
    """(V,) bool: views of the largest group tied together by shared tracks."""
    V, T = use.shape
    cam, trk = np.nonzero(use)
    A = scipy.sparse.coo_matrix((np.ones(cam.size), (cam, V + trk)), shape=(V + T, V + T))
    _, label = scipy.sparse.csgraph.connected_components(A, directed=False)
    lv = label[:V][use.any(1)]
    if lv.size == 0:
        return np.zeros(V, bool)
    best = np.bincount(lv).argmax()
    return (label[:V] == best) & use.any(1)


def _solve(rays, use, w):
    """Weighted points method on the observations ``use`` (weights ``w`` (V, T)): C (V, 3), X (T, 3), eigenvalues."""
    V, T = use.shape
    cam, trk = np.nonzero(use)
    d = rays[cam, trk]
    P = w[cam, trk][:, None, None] * (np.eye(3) - d[:, :, None] * d[:, None, :])     # (n, 3, 3)
    A = np.zeros((T, 3, 3))
    np.add.at(A, trk, P)
    pts = np.flatnonzero(use.any(0))
    Ainv = np.zeros((T, 3, 3))
    Ainv[pts] = np.linalg.inv(A[pts])
    H = np.zeros((V, 3, V, 3))
    np.add.at(H, (cam, slice(None), cam), P)
    # Schur complement: S = H_cc - Σ_tracks H_ct A_t⁻¹ H_tc, where H_ct[i, t] = -Σ P of track t in view i
    r3 = np.arange(3)
    rows = np.broadcast_to(3 * cam[:, None, None] + r3[None, :, None], P.shape).ravel()
    cols = np.broadcast_to(3 * trk[:, None, None] + r3[None, None, :], P.shape).ravel()
    H_ct = scipy.sparse.csr_matrix((P.ravel(), (rows, cols)), shape=(3 * V, 3 * T))
    bi = np.broadcast_to(3 * np.arange(T)[:, None, None] + r3[None, :, None], (T, 3, 3)).ravel()
    bj = np.broadcast_to(3 * np.arange(T)[:, None, None] + r3[None, None, :], (T, 3, 3)).ravel()
    A_inv = scipy.sparse.csr_matrix((Ainv.ravel(), (bi, bj)), shape=(3 * T, 3 * T))
    S = H.reshape(3 * V, 3 * V) - (H_ct @ A_inv @ H_ct.T).toarray()
    S = 0.5 * (S + S.T)
    N = np.tile(np.eye(3), (V, 1)) / np.sqrt(V)                # moving every centre and point together
    lam, vec = np.linalg.eigh(S + (np.trace(S) + 1.0) * N @ N.T)
    C = vec[:, 0].reshape(V, 3)
    PC = np.zeros((T, 3))
    np.add.at(PC, trk, np.einsum("nij,nj->ni", P, C[cam]))
    X = np.einsum("tij,tj->ti", Ainv, PC)
    return C, X, lam


def _depths(rays, use, C, X):
    """(V, T) distance along each used ray from the centre to the point's foot on it (NaN elsewhere)."""
    dep = np.full(use.shape, np.nan)
    cam, trk = np.nonzero(use)
    dep[cam, trk] = np.einsum("ni,ni->n", rays[cam, trk], X[trk] - C[cam])
    return dep


def _normalise(C, X, rays, use, w):
    """Sign (points in front, weighted majority) and scale (RMS centre spread 1), about the centres' mean."""
    dep = _depths(rays, use, C, X)
    if np.nansum(np.where(use, w * np.sign(dep), 0.0)) < 0:
        C, X = -C, -X
    m = C.mean(0)
    s = np.sqrt(((C - m) ** 2).sum(1).mean())
    if not s > 0:
        raise ValueError("every centre came out at the same place: no baseline, the positions are not determined")
    return (C - m) / s, (X - m) / s


def centres_from_points(tracks: ArrayLike, K: ArrayLike, R: ArrayLike, mask: ArrayLike = None, *,
                        min_angle_deg: float = 1.0) -> tuple:
    """Camera centres (and points) from known rotations, linearly, by the points method (module docstring).

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels, NaN where unseen.
    K : (3, 3) or (V, 3, 3) array_like
    R : (V, 3, 3) array_like
        The known rotations (NaN rows: views to leave out).
    mask : (V, T) bool array_like, optional
        The observations to use (default: all seen).
    min_angle_deg : float
        A track is used only if two of its rays (directions, known from the rotations) are this far apart:
        otherwise its point, and the baseline it would measure, are not determined.

    Returns
    -------
    C : (V, 3) ndarray
        Centres, mean 0 and RMS distance 1 from it; NaN for views left out (no rotation, fewer than two usable
        observations, or no shared track linking them to the largest group of views).
    X : (T, 3) ndarray
        The points in the same frame (NaN for tracks not used).

    Raises
    ------
    ValueError
        Bad shapes or values; fewer than two views tied together by usable tracks; no baseline.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(40, 5, noise_px=0.0, layout="forward", rng=np.random.default_rng(0))
    >>> C, X = centres_from_points(s.x_true, s.K, s.R)
    >>> from labutils.core.metrics import align_similarity
    >>> sc, Rs, ts = align_similarity(C, s.C)
    >>> bool(np.allclose(sc * C @ Rs.T + ts, s.C, atol=1e-9))
    True
    """
    tracks, Ks, R, have, use = _inputs(tracks, K, R, mask)
    min_angle_deg = as_positive(min_angle_deg, "min_angle_deg", allow_zero=True)
    rays = np.nan_to_num(world_rays(tracks, Ks, R))
    C, X, use, _ = _points_method(rays, use, np.ones(use.shape), min_angle_deg)
    return C, X


def _points_method(rays, use, w, min_angle_deg):
    use = _select(rays, use, min_angle_deg)
    views = _connected_views(use)
    use &= views[:, None]
    use = _select(rays, use, min_angle_deg)
    views = use.any(1)
    if views.sum() < 2:
        raise ValueError("fewer than two views share tracks whose rays meet at an angle: the camera positions "
                         "cannot be tied together")
    V, T = use.shape
    sub = np.flatnonzero(views)
    C_s, X, lam = _solve(rays[sub], use[sub], w[sub])
    C = np.full((V, 3), np.nan)
    C[sub] = C_s
    pts = use.any(0)
    X[~pts] = np.nan
    C[sub], X[pts] = _normalise(C[sub], X[pts], rays[sub][:, pts], use[sub][:, pts], w[sub][:, pts])
    return C, X, use, lam


def robust_centres_from_points(tracks: ArrayLike, K: ArrayLike, R: ArrayLike, mask: ArrayLike = None, *,
                               threshold_px: float = 4.0, n_iter: int = 8, min_angle_deg: float = 1.0) -> tuple:
    """The points method reweighted (IRLS) into pixel errors, with a robust (Cauchy) loss.

    Each equation of :func:`centres_from_points` is the distance of the point from the ray, about
    ``depth × error / f``; the weights ``(f / depth)²`` of the previous solution turn it into a pixel error, and a
    Cauchy weight ``1 / (1 + (e / threshold_px)²)`` of the pixel error ``e`` takes the pull of wrong observations
    away. Observations with ``e > threshold_px``, or behind their camera, are the outliers.

    Parameters
    ----------
    tracks, K, R, mask, min_angle_deg :
        As in :func:`centres_from_points`.
    threshold_px : float
    n_iter : int
        Reweightings after the plain solution.

    Returns
    -------
    C : (V, 3) ndarray
    X : (T, 3) ndarray
        As in :func:`centres_from_points`.
    inliers : (V, T) bool ndarray
        The observations that end within ``threshold_px``, in front of their camera, of tracks keeping two or more
        of them.
    """
    tracks, Ks, R, have, use = _inputs(tracks, K, R, mask)
    threshold_px = as_positive(threshold_px, "threshold_px")
    min_angle_deg = as_positive(min_angle_deg, "min_angle_deg", allow_zero=True)
    n_iter = as_count(n_iter, "n_iter", 0)
    rays = np.nan_to_num(world_rays(tracks, Ks, R))
    f = np.sqrt(np.abs(Ks[:, 0, 0] * Ks[:, 1, 1]))[:, None]
    w = np.ones(use.shape)
    C, X, used, _ = _points_method(rays, use, w, min_angle_deg)
    for _ in range(n_iter):
        err, dep = _pixel_errors(tracks, Ks, R, C, X, used)
        w = np.where(used & (dep > 0), (f / np.where(dep > 0, dep, 1.0)) ** 2 / (1 + (err / threshold_px) ** 2), 0.0)
        w = np.where(used, np.maximum(w, 1e-12 * np.nanmax(w)), 1.0)
        C, X, used, _ = _points_method(rays, used, w, min_angle_deg)
    err, dep = _pixel_errors(tracks, Ks, R, C, X, used)
    inliers = used & (dep > 0) & (err <= threshold_px)
    return C, X, inliers & (inliers.sum(0) >= 2)[None]          # one good ray alone does not confirm a point


def _pixel_errors(tracks, Ks, R, C, X, use):
    """(V, T) reprojection errors (px) and depths of the used observations (NaN elsewhere)."""
    err, dep = np.full(use.shape, np.nan), np.full(use.shape, np.nan)
    cam, trk = np.nonzero(use)
    Xc = np.einsum("nij,nj->ni", R[cam], X[trk] - C[cam])
    q = np.einsum("nij,nj->ni", Ks[cam], Xc)
    with np.errstate(divide="ignore", invalid="ignore"):
        err[cam, trk] = np.linalg.norm(q[:, :2] / q[:, 2:] - tracks[cam, trk], axis=1)
    dep[cam, trk] = Xc[:, 2]
    return err, dep


def pair_directions(R: ArrayLike, pairs: ArrayLike, t_rel: ArrayLike) -> np.ndarray:
    """(E, 3) unit directions ``C_j - C_i`` in the world frame from each pair's relative translation.

    Camera j is ``[R_ij | t_ij]`` in camera i's frame, so its centre there is ``-R_ijᵀ t_ij``; in the world,
    with ``R_ij = R_j R_iᵀ``, ``C_j - C_i ∝ -R_iᵀ R_ijᵀ t_ij = -R_jᵀ t_ij``.

    >>> pair_directions(np.stack([np.eye(3)] * 2), [[0, 1]], [[-1.0, 0.0, 0.0]]) + 0.0
    array([[1., 0., 0.]])
    """
    R = as_rotations(R, "R")
    if len(R) < 2:
        raise ValueError(f"R must hold the rotations of at least two views; got {len(R)}")
    p = as_pairs(pairs, len(R))
    t = as_array(t_rel, "t_rel", f"({len(p)}, 3)")
    if t.shape != (len(p), 3) or not np.all(np.isfinite(t)):
        raise ValueError(f"t_rel must be a finite ({len(p)}, 3) array, one translation per row of pairs; got "
                         f"{t.shape}")
    n = np.linalg.norm(t, axis=1)
    if not np.all(n > 0):
        raise ValueError(f"t_rel[{np.flatnonzero(~(n > 0))[0]}] is zero: a pair without a baseline has no direction")
    d = -np.einsum("eji,ej->ei", R[p[:, 1]], t)
    return d / n[:, None]


def centres_from_directions(pairs: ArrayLike, directions: ArrayLike, n_views: int, weights: ArrayLike = None) -> \
        np.ndarray:
    """Camera centres from pairwise directions ``d_ij ∝ C_j - C_i``: ``[d_ij]× (C_j - C_i) = 0``, linearly.

    The stacked equations ``A c = 0`` (``c`` the 3V centres) are solved by the eigenvector of ``AᵀA`` with the
    smallest eigenvalue after lifting the translation gauge (all centres moved together); the sign makes
    ``Σ d_ij · (C_j - C_i) > 0`` and the scale the RMS distance from the mean 1 (Govindu 2001).

    Parameters
    ----------
    pairs : (E, 2) int array_like
    directions : (E, 3) array_like
        World-frame directions from ``C_i`` towards ``C_j`` (any length).
    n_views : int
    weights : (E,) array_like, optional

    Returns
    -------
    C : (V, 3) ndarray

    Raises
    ------
    ValueError
        Bad input; or a solution that is not unique: a view in no pair, or centres on one line (forward motion),
        where the directions cannot say how far apart the cameras are.

    Examples
    --------
    >>> C = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]])
    >>> pairs = np.array([[0, 1], [1, 2], [0, 2]])
    >>> C_est = centres_from_directions(pairs, C[pairs[:, 1]] - C[pairs[:, 0]], 3)
    >>> bool(np.allclose(C_est, (C - C.mean(0)) / np.sqrt(((C - C.mean(0)) ** 2).sum(1).mean())))
    True
    """
    p = as_pairs(pairs, n_views)
    w = as_weights(weights, len(p))
    d = as_array(directions, "directions", f"({len(p)}, 3)")
    if d.shape != (len(p), 3) or not np.all(np.isfinite(d)):
        raise ValueError(f"directions must be a finite ({len(p)}, 3) array, one per row of pairs; got {d.shape}")
    n = np.linalg.norm(d, axis=1)
    if not np.all(n > 0):
        raise ValueError(f"directions[{np.flatnonzero(~(n > 0))[0]}] is zero: it has no direction")
    d = d / n[:, None]
    V = n_views
    H = np.zeros((V, 3, V, 3))
    B = w[:, None, None] * (np.eye(3) - d[:, :, None] * d[:, None, :])     # ([d]×)ᵀ [d]× for a unit d
    i, j = p[:, 0], p[:, 1]
    for a, b, s in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
        np.add.at(H, (a, slice(None), b), s * B)
    H = H.reshape(3 * V, 3 * V)
    N = np.tile(np.eye(3), (V, 1)) / np.sqrt(V)
    lam, vec = np.linalg.eigh(H + (np.trace(H) + 1.0) * N @ N.T)
    if lam[1] <= 1e-9 * lam[-1]:
        raise ValueError("the centres are not determined by the directions (two or more independent solutions): a "
                         "view in no pair, or centres on one line (forward motion) — use the points method")
    C = vec[:, 0].reshape(V, 3)
    if np.sum(w * np.einsum("ei,ei->e", d, C[j] - C[i])) < 0:
        C = -C
    C -= C.mean(0)
    return C / np.sqrt((C ** 2).sum(1).mean())
