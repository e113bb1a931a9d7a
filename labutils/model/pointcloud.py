"""Coloured, oriented point clouds: colours from the images, normals from local neighbourhoods, signs by visibility.

A point cloud from structure from motion (or from dense stereo) is a set of world points ``X (N, 3)``, the cameras
``K, R, t`` and a visibility mask ``visible (V, N)``: which views see each point (``Reconstruction.inliers``). Three
things turn it into what a surface reconstructor needs:

1. **Colour** (:func:`point_colors`): project each point into the views that see it, sample each image bilinearly,
   and take the per-channel median over those views (robust to a highlight or a mismatched view).
2. **Normals** (:func:`local_pca`, :func:`estimate_normals`): the normal of a surface sampled by points is the
   direction in which a small neighbourhood is thinnest — the eigenvector of the neighbourhood's covariance with the
   smallest eigenvalue (Hoppe, DeRose, Duchamp, McDonald & Stuetzle, "Surface reconstruction from unorganized
   points", SIGGRAPH 1992; Pauly, Gross & Kobbelt 2002 for the *surface variation* λ₀ / (λ₀ + λ₁ + λ₂)). The k
   nearest neighbours come from scipy's KD-tree.
3. **Orientation** (:func:`orient_normals`): PCA gives a line, not a direction. A camera that sees a point lies on
   the outside of the surface there, so the normal must face it: its sign is chosen so that the sum over the
   observing cameras of ``cos∠(n, C_v − X)`` is positive. Screened Poisson reconstruction (Kazhdan & Hoppe, ACM TOG
   2013) needs exactly this: normals that point out of the object.

:class:`PointCloud` holds the result and writes it as PLY (``x y z nx ny nz red green blue``) through
:mod:`labutils.data.ply`.

Conventions: ``x_cam = R @ X + t``, ``C = -R.T @ t``, pixels ``(x, y)`` with x right and y down, pixel
``image[r, c]`` centred on ``(c, r)``. Views whose ``R`` and ``t`` are NaN (not registered) are allowed; they must
see no point.
"""
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from ..core.geometry import camera_center, pixels_and_depths
from ..core.validation import as_cameras, as_count, as_image, as_points, as_visibility
from ..data.ply import write_points

__all__ = ["LocalPCA", "PointCloud", "local_pca", "estimate_normals", "orient_normals", "facing_fractions",
           "sample_image", "point_colors", "oriented_point_cloud", "cloud_from_reconstruction"]


# --------------------------------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------------------------------
# --------------------------------------------------------------------------------------------------------------
# Normals
# --------------------------------------------------------------------------------------------------------------
@dataclass
class LocalPCA:
    """The principal axes of each point's neighbourhood (what :func:`local_pca` returns).

    Attributes
    ----------
    normals : (N, 3) ndarray
        Unit eigenvectors of the smallest eigenvalue (sign arbitrary: orient them with :func:`orient_normals`).
    eigenvalues : (N, 3) ndarray
        Of the neighbourhood's covariance, ascending (λ₀ ≤ λ₁ ≤ λ₂).
    neighbours : (N, k) int ndarray
        The k nearest points of each point (itself first).
    """

    normals: np.ndarray
    eigenvalues: np.ndarray
    neighbours: np.ndarray

    @property
    def variation(self):
        """(N,) surface variation λ₀ / (λ₀ + λ₁ + λ₂): 0 on a plane, 1/3 for an isotropic blob (Pauly et al. 2002)."""
        total = self.eigenvalues.sum(axis=1)
        return np.divide(self.eigenvalues[:, 0], total, out=np.zeros_like(total), where=total > 0)


def local_pca(X: ArrayLike, *, k: int = 12) -> LocalPCA:
    """PCA of each point's k-nearest-neighbour neighbourhood (Hoppe et al. 1992; scipy's KD-tree).

    For the neighbourhood ``N_i`` (the point and its k − 1 nearest others) with centroid ``m_i``, the covariance
    ``Σ_i = (1/k) Σ_{j ∈ N_i} (X_j − m_i)(X_j − m_i)ᵀ`` has eigenvalues ``λ₀ ≤ λ₁ ≤ λ₂``; the eigenvector of λ₀ is
    the direction in which the neighbourhood is thinnest: the surface normal, up to sign.

    Parameters
    ----------
    X : (N, 3) array_like
        Points, N >= k.
    k : int
        Neighbourhood size, 3 <= k <= N (the point itself included).

    Returns
    -------
    LocalPCA

    Raises
    ------
    ValueError
        Shape, NaN or inf, k out of range, or a neighbourhood whose points are all on one line or one point (no
        plane through them: the normal is undefined).

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    >>> plane = np.column_stack([g, 0.5 * g[:, 0]])                 # the plane z = x / 2
    >>> n = local_pca(plane, k=8).normals
    >>> np.allclose(np.abs(n @ [-0.5, 0, 1]) / np.linalg.norm([-0.5, 0, 1]), 1)
    True
    """
    X = as_points(X, "X", dim=3, min_n=3)
    k = as_count(k, "k", 3)
    if k > len(X):
        raise ValueError(f"k = {k} neighbours asked for, but X has only {len(X)} points")
    _, idx = cKDTree(X).query(X, k=k)
    idx = idx.reshape(len(X), k)
    Q = X[idx] - X[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", Q, Q) / k
    w, v = np.linalg.eigh(cov)
    scale = np.maximum(w[:, 2], np.finfo(float).tiny)
    flat = w[:, 1] <= 1e-12 * scale
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        raise ValueError(f"the {k} nearest points of X[{i}] lie on a line (or coincide): no plane fits them, the "
                         "normal is undefined (remove duplicates, or use a larger k)")
    return LocalPCA(v[:, :, 0].copy(), w, idx)


def estimate_normals(X: ArrayLike, *, k: int = 12) -> np.ndarray:
    """Unit normals by PCA over the k nearest neighbours (:func:`local_pca`), sign arbitrary.

    Returns
    -------
    (N, 3) ndarray

    >>> flat = np.random.default_rng(0).normal(size=(30, 3)) * [1, 1, 0.01]     # a thin slab: normals along z
    >>> bool(np.abs(estimate_normals(flat, k=10)[:, 2]).min() > 0.99)
    True
    """
    return local_pca(X, k=k).normals


def _view_directions(X, C, visible):
    """(N, V, 3) unit vectors from each point to each camera centre (0 where the view does not see the point)."""
    d = C[None, :, :] - X[:, None, :]
    with np.errstate(invalid="ignore"):
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.where(visible.T[:, :, None], d, 0.0)


def orient_normals(X: ArrayLike, normals: ArrayLike, R: ArrayLike, t: ArrayLike, visible: ArrayLike) -> np.ndarray:
    """Flip each normal to face the cameras that see its point (the orientation Poisson reconstruction needs).

    A view ``v`` that sees the point ``X_i`` has its centre ``C_v`` outside the surface, so the outward normal
    makes an acute angle with ``C_v − X_i``. PCA normals have an arbitrary sign; the sign kept is the one for which
    ``s_i = Σ_{v sees i} n_i · (C_v − X_i) / ‖C_v − X_i‖`` is positive (a vote of the observing cameras, each
    weighted by how squarely it looks at the surface; one camera is enough).

    Parameters
    ----------
    X : (N, 3) array_like
    normals : (N, 3) array_like
        Unit normals, any sign.
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Poses, ``x_cam = R @ X + t``; NaN for views that are not registered.
    visible : (V, N) bool array_like
        Which views see each point; every point must be seen by at least one view.

    Returns
    -------
    (N, 3) ndarray
        ``normals`` with some rows negated.

    Raises
    ------
    ValueError
        Shapes, NaN, normals that are not unit vectors, a point seen by no view, or a point that coincides with a
        camera centre.

    Examples
    --------
    >>> X = np.zeros((2, 3)); n = np.array([[0, 0, 1.0], [0, 0, 1.0]])
    >>> R = np.eye(3)[None]; t = np.array([[0, 0, 5.0]])        # the camera sits at (0, 0, -5)
    >>> orient_normals(X, n, R, t, np.ones((1, 2), bool))
    array([[-0., -0., -1.],
           [-0., -0., -1.]])
    """
    X = as_points(X, "X", dim=3)
    normals = as_points(normals, "normals", dim=3, like=(X, "X"))
    length = np.linalg.norm(normals, axis=1)
    if np.any(np.abs(length - 1) > 1e-6):
        i = int(np.flatnonzero(np.abs(length - 1) > 1e-6)[0])
        raise ValueError(f"normals must be unit vectors; normals[{i}] has length {length[i]:.6g}")
    _, R, t, registered = as_cameras(np.eye(3), R, t)
    visible = as_visibility(visible, len(R), len(X), registered)
    unseen = ~visible.any(axis=0)
    if unseen.any():
        raise ValueError(f"point {int(np.flatnonzero(unseen)[0])} is seen by no view ({int(unseen.sum())} such "
                         "points): visibility cannot orient its normal")
    C = camera_center(R, t)
    d = C[None, :, :] - X[:, None, :]
    dist = np.linalg.norm(np.where(visible.T[:, :, None], d, 1.0), axis=-1)
    if np.any(dist == 0):
        raise ValueError("a point coincides with the centre of a camera that sees it")
    score = np.einsum("nvi,ni->n", _view_directions(X, C, visible), normals)
    return np.where(score[:, None] < 0, -normals, normals)


def facing_fractions(X: ArrayLike, normals: ArrayLike, R: ArrayLike, t: ArrayLike, visible: ArrayLike) -> dict:
    """How well normals face the cameras that see their points: the checks of an orientation.

    Returns
    -------
    dict
        ``'any'``: the fraction of points whose normal faces at least one observing camera
        (``n · (C_v − X) > 0``); ``'all'``: faces every observing camera; ``'pairs'``: the fraction of
        (point, observing view) pairs in which the normal faces the camera.

    >>> X = np.zeros((1, 3)); R = np.stack([np.eye(3)] * 2); t = np.array([[0, 0, 5.0], [0, 0, -5.0]])
    >>> facing_fractions(X, [[0, 0, -1.0]], R, t, np.ones((2, 1), bool))
    {'any': 1.0, 'all': 0.0, 'pairs': 0.5}
    """
    X = as_points(X, "X", dim=3)
    normals = as_points(normals, "normals", dim=3, like=(X, "X"))
    _, R, t, registered = as_cameras(np.eye(3), R, t)
    visible = as_visibility(visible, len(R), len(X), registered)
    seen = visible.any(axis=0)
    if not seen.any():
        raise ValueError("no point is seen by any view")
    cos = np.einsum("nvi,ni->nv", _view_directions(X, camera_center(R, t), visible), normals)
    faces = (cos > 0) & visible.T
    return {"any": float(faces.any(axis=1)[seen].mean()),
            "all": float((faces | ~visible.T).all(axis=1)[seen].mean()),
            "pairs": float(faces.sum() / visible.sum())}


# --------------------------------------------------------------------------------------------------------------
# Colours
# --------------------------------------------------------------------------------------------------------------
def sample_image(image: ArrayLike, x: ArrayLike) -> np.ndarray:
    """Bilinear samples of an image at pixels ``x`` (x right, y down; pixel ``image[r, c]`` centred on ``(c, r)``).

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
    x : (N, 2) array_like

    Returns
    -------
    (N, C) float ndarray
        (N, 1) for a grey image; NaN rows where a pixel falls outside ``[0, W − 1] × [0, H − 1]`` (more than a
        hundredth of a pixel out).

    Examples
    --------
    >>> img = np.array([[0, 10], [20, 30]], np.uint8)
    >>> sample_image(img, [[0.5, 0.5], [1, 0], [2.5, 0]])
    array([[15.],
           [10.],
           [nan]])
    """
    img = as_image(image, "image")
    img = img[:, :, None] if img.ndim == 2 else img
    x = as_points(x, "x", min_n=0)
    h, w = img.shape[:2]
    eps = 1e-2
    inside = (x[:, 0] >= -eps) & (x[:, 0] <= w - 1 + eps) & (x[:, 1] >= -eps) & (x[:, 1] <= h - 1 + eps)
    u = np.clip(x[:, 0], 0, w - 1)
    v = np.clip(x[:, 1], 0, h - 1)
    c0 = np.minimum(np.floor(u).astype(np.int64), w - 2)
    r0 = np.minimum(np.floor(v).astype(np.int64), h - 2)
    fu, fv = (u - c0)[:, None], (v - r0)[:, None]
    f00, f01, f10, f11 = (img[r, c].astype(float) for r, c in ((r0, c0), (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1)))
    out = (1 - fv) * ((1 - fu) * f00 + fu * f01) + fv * ((1 - fu) * f10 + fu * f11)
    out[~inside] = np.nan
    return out


def point_colors(X: ArrayLike, images: Sequence, K: ArrayLike, R: ArrayLike, t: ArrayLike,
                 visible: ArrayLike) -> np.ndarray:
    """The colour of each point: the per-channel median of its bilinear samples in the views that see it.

    Parameters
    ----------
    X : (N, 3) array_like
    images : sequence of V images (H, W, 3) (or None for a view without an image)
        RGB, ``uint8`` (0..255).
    K : (3, 3) or (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        ``x_cam = R @ X + t``; NaN for views that are not registered.
    visible : (V, N) bool array_like

    Returns
    -------
    (N, 3) uint8 ndarray

    Raises
    ------
    ValueError
        Shapes; a visible point behind its camera; a point that gets no sample (seen by no view that has an image,
        or projecting outside every image that sees it).

    Examples
    --------
    >>> img = np.zeros((4, 4, 3), np.uint8); img[:, :, 0] = 200
    >>> point_colors([[0.0, 0, 1]], [img], np.array([[2.0, 0, 1.5], [0, 2, 1.5], [0, 0, 1]]), np.eye(3)[None],
    ...              np.zeros((1, 3)), np.ones((1, 1), bool))
    array([[200,   0,   0]], dtype=uint8)
    """
    X = as_points(X, "X", dim=3)
    Ks, R, t, registered = as_cameras(K, R, t)
    visible = as_visibility(visible, len(R), len(X), registered)
    images = list(images)
    if len(images) != len(R):
        raise ValueError(f"images has {len(images)} entries for {len(R)} views: give one per view (None to skip)")
    views, points, samples = [], [], []
    for v in np.flatnonzero(visible.any(axis=1)):
        if images[v] is None:
            continue
        img = as_image(images[v], f"images[{v}]")
        if img.ndim != 3 or img.shape[2] < 3:
            raise ValueError(f"images[{v}] must be an RGB image (H, W, 3); got shape {img.shape}")
        idx = np.flatnonzero(visible[v])
        x, depth = pixels_and_depths(Ks[v], R[v], t[v], X[idx])
        if np.any(depth <= 0):
            raise ValueError(f"point {int(idx[np.argmax(depth <= 0)])} is marked visible in view {v} but lies behind "
                             "its camera")
        c = sample_image(img[:, :, :3], x)
        ok = np.isfinite(c[:, 0])
        views.append(np.full(ok.sum(), v))
        points.append(idx[ok])
        samples.append(c[ok])
    pts = np.concatenate(points) if points else np.zeros(0, np.int64)
    counts = np.bincount(pts, minlength=len(X))
    if np.any(counts == 0):
        i = int(np.flatnonzero(counts == 0)[0])
        raise ValueError(f"point {i} gets no colour ({int(np.sum(counts == 0))} such points): no view that sees it "
                         "has an image, or it projects outside every such image")
    col = np.concatenate(samples)
    return np.stack([_grouped_median(pts, col[:, ch], len(X)) for ch in range(3)], axis=1).round().astype(np.uint8)


def _grouped_median(group, values, n):
    """Median of ``values`` within each group 0..n-1 (every group non-empty)."""
    order = np.lexsort((values, group))
    v = values[order]
    counts = np.bincount(group, minlength=n)
    start = np.cumsum(counts) - counts
    return 0.5 * (v[start + (counts - 1) // 2] + v[start + counts // 2])


# --------------------------------------------------------------------------------------------------------------
# The cloud
# --------------------------------------------------------------------------------------------------------------
@dataclass
class PointCloud:
    """A point cloud with (optional) colours and normals, and which views see each point.

    Attributes
    ----------
    X : (N, 3) ndarray
    normals : (N, 3) ndarray or None
        Unit, oriented to face the observing cameras.
    colors : (N, 3) uint8 ndarray or None
    visible : (V, N) bool ndarray
    index : (N,) int ndarray
        Where each point came from (the track index for a reconstruction).
    """

    X: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    visible: np.ndarray
    index: np.ndarray

    @property
    def n_points(self):
        return len(self.X)

    def write_ply(self, path: str | os.PathLike, *, format: str = "binary_little_endian",
                  comments: Sequence[str] = ()) -> None:
        """Write ``x y z`` (float), ``nx ny nz`` and ``red green blue`` (when present) with :func:`write_points`."""
        write_points(path, self.X, colors=self.colors, normals=self.normals, format=format, comments=comments)


def oriented_point_cloud(X: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike, visible: ArrayLike, *,
                         images: Sequence | None = None, k: int = 12) -> PointCloud:
    """Normals by PCA over k neighbours, oriented by visibility, and colours from the images when given.

    Parameters
    ----------
    X : (N, 3) array_like
    K : (3, 3) or (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    visible : (V, N) bool array_like
        Every point seen by at least one view.
    images : sequence of V RGB images (or None entries), optional
        Without it the cloud has no colours.
    k : int

    Returns
    -------
    PointCloud
        ``index`` is ``arange(N)``.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(300, 12, layout="turntable", noise_px=0, rng=np.random.default_rng(0))
    >>> cloud = oriented_point_cloud(s.X, s.K, s.R, s.t, s.visible)
    >>> cloud.normals.shape == s.X.shape, cloud.colors is None
    (True, True)
    """
    X = as_points(X, "X", dim=3)
    as_cameras(K, R, t)
    normals = orient_normals(X, estimate_normals(X, k=k), R, t, visible)
    colors = None if images is None else point_colors(X, images, K, R, t, visible)
    return PointCloud(X, normals, colors, np.asarray(visible, bool).copy(), np.arange(len(X)))


def cloud_from_reconstruction(rec, *, images: Sequence | None = None, k: int = 12) -> PointCloud:
    """:func:`oriented_point_cloud` of a :class:`labutils.sfm.Reconstruction`'s triangulated points.

    ``rec.inliers`` is the visibility; ``index`` holds each point's track number.
    """
    for name in ("X", "R", "t", "K", "inliers"):
        if not hasattr(rec, name):
            raise ValueError(f"rec must be a Reconstruction (with X, R, t, K, inliers); it has no {name!r}")
    ok = np.flatnonzero(np.isfinite(rec.X[:, 0]))
    if ok.size < 3:
        raise ValueError(f"the reconstruction has {ok.size} triangulated points; at least 3 are needed")
    cloud = oriented_point_cloud(rec.X[ok], rec.K, rec.R, rec.t, rec.inliers[:, ok], images=images, k=k)
    cloud.index = ok
    return cloud
