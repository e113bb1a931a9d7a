"""Incremental structure from motion: from point tracks and calibration to cameras and points.

The pipeline (H&Z Ch. 18 and Sec. 9.6, 12.2, 18.1; Snavely, Seitz & Szeliski, "Photo tourism", 2006;
Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016):

1. **Initial pair**: the pairs of views sharing the most tracks are each reconstructed (F by RANSAC, E,
   the pose by cheirality, a calibrated two-view BA, triangulation); among those whose median
   triangulation angle is large enough, the one with the largest ``points × median angle`` wins.
2. **Register views one at a time**: the next view is the one that sees the most already-triangulated
   points; its pose comes from robust PnP (P3P in RANSAC, then refinement).
3. **Triangulate** the tracks the new view shares with registered views, robustly: the largest
   consensus over all pairs of a track's observations, then multi-view DLT; a point is kept only if it
   lies in front of every camera, reprojects within the threshold in every view it keeps, and is seen
   under a large enough angle.
4. **Bundle adjustment**: a local BA around each new view, a global BA whenever the model has grown
   by a fixed factor, then **outlier removal** (large reprojection errors, too small angles).
5. **Final refinement**: every track triangulated afresh from the final cameras, a global robust BA,
   outlier removal and BA again until the inlier set is stable. :func:`bundle_from_cameras` runs this
   same last stage from given cameras (e.g. the ground truth): the bar the pipeline is judged against.

All thresholds are in pixels; every bundle adjustment is :func:`labutils.bundle.bundle_adjust` (LM with
the Schur complement) with a robust loss (Cauchy, scale 1 px, by default).

The result is a :class:`Reconstruction`. Run it from the command line with
``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json [--ply POINTS.ply] [--seed N]``.
"""
import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .bundle import bundle_adjust
from .epipolar import essential_from_fundamental, fundamental_ransac, pose_from_essential
from .metrics import align_cameras, apply_similarity, pose_errors
from .pnp import pnp_ransac
from .triangulation import triangulate_multiview

# ---------------------------------------------------------------------------------------------
# The record
# ---------------------------------------------------------------------------------------------


@dataclass
class Reconstruction:
    """Cameras, points and the observations that support them, as built by :func:`incremental_sfm`.

    Attributes
    ----------
    R : (V, 3, 3) ndarray
        Rotations, ``x_cam = R[i] @ X + t[i]``; NaN for views that were not registered.
    t : (V, 3) ndarray
        Translations; NaN for views that were not registered.
    registered : (V,) bool ndarray
    X : (T, 3) ndarray
        One world point per track; NaN for tracks that were not triangulated.
    inliers : (V, T) bool ndarray
        The observations the reconstruction uses (registered view, triangulated track, not rejected).
    order : list of int
        The views in the order they were added (the first two are the initial pair).
    K : (V, 3, 3) ndarray
        The calibration of each view.
    timings : dict
        Seconds spent per stage (``'total'`` included).
    log : list of str
        One line per step, for reading what happened.
    """

    R: np.ndarray
    t: np.ndarray
    registered: np.ndarray
    X: np.ndarray
    inliers: np.ndarray
    order: list
    K: np.ndarray
    timings: dict = field(default_factory=dict)
    log: list = field(default_factory=list, repr=False)

    @property
    def n_views(self):
        return self.R.shape[0]

    @property
    def n_tracks(self):
        return self.X.shape[0]

    @property
    def n_registered(self):
        return int(self.registered.sum())

    @property
    def n_points(self):
        """Triangulated tracks."""
        return int(np.isfinite(self.X[:, 0]).sum())

    @property
    def n_observations(self):
        return int(self.inliers.sum())

    @property
    def C(self):
        """(V, 3) camera centres (NaN for unregistered views)."""
        return -np.einsum("vji,vj->vi", self.R, self.t)

    @property
    def P(self):
        """(V, 3, 4) camera matrices ``K @ [R | t]`` (NaN for unregistered views)."""
        return np.einsum("vij,vjk->vik", self.K, np.concatenate([self.R, self.t[..., None]], axis=2))

    def reprojection_errors(self, tracks):
        """(V, T) reprojection errors in pixels of the inlier observations of ``tracks`` (NaN elsewhere)."""
        return reprojection_errors(self.K, self.R, self.t, self.X, tracks, self.inliers)

    def summary(self):
        """One line: what was reconstructed, and how long it took."""
        secs = self.timings.get("total")
        return (f"{self.n_registered} of {self.n_views} views registered, {self.n_points} of {self.n_tracks} "
                f"tracks triangulated, {self.n_observations} observations"
                + (f", {secs:.2f} s" if secs is not None else ""))

    def to_dict(self):
        """The result as plain JSON types (the format of the command line's RESULT.json).

        ``cameras`` has one entry per view in input order, ``{"R": 3x3, "t": [3]}`` or ``None`` for a
        view that was not registered; ``points`` lists ``{"track": index, "X": [3], "views": [...]}``
        for each triangulated track (``views``: the views whose observation supports it); ``order`` is
        the registration order. No timings: the same seed gives the same file.
        """
        cameras = [{"R": self.R[v].tolist(), "t": self.t[v].tolist()} if self.registered[v] else None
                   for v in range(self.n_views)]
        points = [{"track": int(k), "X": self.X[k].tolist(), "views": np.flatnonzero(self.inliers[:, k]).tolist()}
                  for k in np.flatnonzero(np.isfinite(self.X[:, 0]))]
        return {"cameras": cameras, "points": points, "order": [int(v) for v in self.order]}

    def to_json(self, path):
        """Write :meth:`to_dict` to ``path`` (JSON)."""
        Path(path).write_text(json.dumps(self.to_dict()) + "\n")

    def to_ply(self, path):
        """Write the triangulated points to ``path`` as an ASCII PLY point cloud."""
        Path(path).write_text(ply_text(self.X[np.isfinite(self.X[:, 0])]))


def ply_text(X):
    """An ASCII PLY file (as a string) holding the points ``X`` (N, 3).

    >>> print(ply_text(np.array([[1.0, 2.0, 3.5]])), end="")
    ply
    format ascii 1.0
    comment written by labutils.sfm
    element vertex 1
    property double x
    property double y
    property double z
    end_header
    1.0 2.0 3.5
    """
    X = np.asarray(X, float).reshape(-1, 3)
    head = ["ply", "format ascii 1.0", "comment written by labutils.sfm", f"element vertex {len(X)}",
            "property double x", "property double y", "property double z", "end_header"]
    return "\n".join(head + [" ".join(repr(float(c)) for c in p) for p in X]) + "\n"


def read_result_json(path):
    """Read a RESULT.json written by :meth:`Reconstruction.to_json` back into arrays.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for views that were not registered.
    X : (T', 3) ndarray
        The points, in the file's order.
    track : (T',) int ndarray
        Their track (row) indices.
    """
    d = json.loads(Path(path).read_text())
    V = len(d["cameras"])
    R, t = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan)
    for v, cam in enumerate(d["cameras"]):
        if cam is not None:
            R[v], t[v] = cam["R"], cam["t"]
    X = np.array([p["X"] for p in d["points"]], float).reshape(-1, 3)
    track = np.array([p["track"] for p in d["points"]], int)
    return R, t, X, track


# ---------------------------------------------------------------------------------------------
# Input checks and small geometric helpers
# ---------------------------------------------------------------------------------------------


def _as_tracks(tracks):
    try:
        x = np.array(tracks, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"tracks must be a numeric array of shape (V, T, 2): {exc}") from None
    if x.ndim != 3 or x.shape[2] != 2:
        raise ValueError(f"tracks must have shape (V, T, 2) (views, tracks, pixel), NaN where unseen; got {x.shape}")
    if x.shape[0] < 2 or x.shape[1] < 1:
        raise ValueError(f"tracks needs at least 2 views and 1 track; got shape {x.shape}")
    if np.isinf(x).any():
        raise ValueError("tracks has infinite coordinates; mark an unseen observation with NaN")
    if np.any(np.isnan(x[..., 0]) != np.isnan(x[..., 1])):
        v, k = np.argwhere(np.isnan(x[..., 0]) != np.isnan(x[..., 1]))[0]
        raise ValueError(f"tracks[{v}, {k}] has one NaN coordinate: an unseen observation is NaN in both")
    return x


def _as_calibrations(K, n_views):
    try:
        K = np.array(K, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"K must be a numeric array of shape (3, 3) or (V, 3, 3): {exc}") from None
    if K.shape == (3, 3):
        K = np.repeat(K[None], n_views, axis=0)
    if K.shape != (n_views, 3, 3):
        raise ValueError(f"K must have shape (3, 3) (shared) or ({n_views}, 3, 3) (one per view); got {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError("K has non-finite entries (NaN or inf)")
    scale = np.abs(K).max(axis=(1, 2))
    bad = np.flatnonzero((np.abs(K[:, 2, :2]) > 1e-12 * scale[:, None]).any(1) | (K[:, 2, 2] == 0))
    if bad.size:
        raise ValueError(f"K of view {bad[0]} is not a calibration matrix: its last row must be (0, 0, k), k != 0")
    K = K / K[:, 2:, 2:]
    bad = np.flatnonzero(np.abs(np.linalg.det(K)) <= 1e-12 * np.abs(K).max(axis=(1, 2)) ** 3)
    if bad.size:
        raise ValueError(f"K of view {bad[0]} is singular: a calibration matrix must be invertible")
    return K


def covisibility(tracks):
    """(V, V) int: how many tracks each pair of views shares (the diagonal: tracks seen by each view).

    >>> x = np.full((3, 2, 2), np.nan); x[:, 0] = 1.0; x[:2, 1] = 2.0
    >>> covisibility(x)
    array([[2, 2, 1],
           [2, 2, 1],
           [1, 1, 1]])
    """
    seen = np.all(np.isfinite(np.asarray(tracks, float)), axis=-1).astype(np.int64)
    return seen @ seen.T


def reprojection_errors(K, R, t, X, tracks, mask):
    """Reprojection errors in pixels, ``‖x - π(K (R X + t))‖``, of the observations in ``mask``.

    Parameters
    ----------
    K : (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    X : (T, 3) array_like
    tracks : (V, T, 2) array_like
    mask : (V, T) bool array_like
        The observations to evaluate.

    Returns
    -------
    err : (V, T) ndarray
        NaN outside ``mask``; ``inf`` where the point is not in front of the camera (cheirality).

    >>> K = np.eye(3)[None]; R = np.eye(3)[None]; t = np.zeros((1, 3))
    >>> reprojection_errors(K, R, t, [[0.3, 0.4, 1.0], [0, 0, -1]], [[[0.0, 0.0], [0.0, 0.0]]], [[True, True]])
    array([[0.5, inf]])
    """
    K, R, t, X = (np.asarray(a, float) for a in (K, R, t, X))
    tracks, mask = np.asarray(tracks, float), np.asarray(mask, bool)
    err = np.full(mask.shape, np.nan)
    cam, pt = np.nonzero(mask)
    c = np.einsum("nij,nj->ni", R[cam], X[pt]) + t[cam]
    q = np.einsum("nij,nj->ni", K[cam], c)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.linalg.norm(q[:, :2] / q[:, 2:] - tracks[cam, pt], axis=1)
    e[~(c[:, 2] > 0)] = np.inf
    err[cam, pt] = e
    return err


def ray_angles_deg(C, X, mask):
    """Triangulation angle of each point: the largest angle between two of its viewing rays (degrees).

    Parameters
    ----------
    C : (V, 3) array_like
        Camera centres.
    X : (T, 3) array_like
        Points.
    mask : (V, T) bool array_like
        Which views observe which point.

    Returns
    -------
    angle : (T,) ndarray
        NaN for points with fewer than two observations.

    >>> C = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    >>> np.round(ray_angles_deg(C, [[1, 0, 1], [1, 0, 1]], [[1, 1], [0, 1], [1, 0]]), 6)
    array([90., 45.])
    """
    C, X, mask = np.asarray(C, float), np.asarray(X, float), np.asarray(mask, bool)
    n = mask.sum(0)
    angle = np.full(X.shape[0], np.nan)
    order = np.argsort(~mask, axis=0, kind="stable")                      # observing views first
    for L in np.unique(n[n >= 2]):                                         # tracks grouped by length
        cols = np.flatnonzero(n == L)
        rays = X[cols][None] - C[order[:L, cols]]                          # (L, m, 3)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        cos = np.einsum("imk,jmk->mij", rays, rays).min(axis=(1, 2))
        angle[cols] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angle


def _camera_matrices(K, R, t, views):
    return np.einsum("vij,vjk->vik", K[views], np.concatenate([R[views], t[views, :, None]], axis=2))


def _refine_points(Ps, xs, use, X, n_iter=3):
    """Each point moved to (near) its maximum-likelihood position in the views of ``use`` (H&Z Sec. 12.3, A6.2).

    ``n_iter`` Levenberg–Marquardt steps on each point's reprojection error, all points at once (3×3 normal
    equations per point); from the DLT, three reach the optimum to 1e-6 px on the dinosaur. The DLT
    minimises an algebraic error whose weights depend on the world frame: from cameras that differ only
    by a similarity it gives reprojection errors that differ by pixels, so decisions taken on them
    (inlier or not) would depend on the gauge. The reprojection error does not.

    Parameters
    ----------
    Ps : (V, 3, 4) ndarray
        Camera matrices, scaled so that the third coordinate of ``P X_h`` is the depth's sign.
    xs : (V, N, 2) ndarray
    use : (V, N) bool ndarray
        The observations each point is fitted to.
    X : (N, 3) ndarray
        Starting points (NaN rows, and points behind a camera of ``use``, are left as they are).

    Returns
    -------
    X : (N, 3) ndarray
        A step is kept only if it lowers the point's error and keeps it in front of its cameras.
    """
    X = np.array(X, float)
    cols = np.flatnonzero(np.all(np.isfinite(X), axis=1) & (use.sum(0) >= 2))
    if cols.size == 0:
        return X
    cam, j = np.nonzero(use[:, cols])
    N = cols.size
    P, x = Ps[cam], xs[cam, cols[j]]

    def evaluate(Xc):
        q = np.einsum("nij,nj->ni", P[:, :, :3], Xc[j]) + P[:, :, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = q[:, :2] / q[:, 2:]
        r = u - x
        cost = np.bincount(j, (r ** 2).sum(1), N)
        cost[(np.bincount(j, ~(q[:, 2] > 0), N) > 0) | ~np.isfinite(cost)] = np.inf
        return r, u, q, cost

    Xc = X[cols]
    r, u, q, cost = evaluate(Xc)
    lam = np.full(N, 1e-3)
    for _ in range(n_iter):
        J = (P[:, :2, :3] - u[:, :, None] * P[:, 2:3, :3]) / q[:, 2, None, None]          # (n, 2, 3)
        JtJ = np.stack([np.bincount(j, np.einsum("nk,nk->n", J[:, :, a], J[:, :, b]), N)
                        for a in range(3) for b in range(3)], axis=1).reshape(N, 3, 3)
        g = np.stack([np.bincount(j, np.einsum("nk,nk->n", J[:, :, a], r), N) for a in range(3)], axis=1)
        d = np.einsum("nii->ni", JtJ)
        A = JtJ + (lam[:, None] * d + 1e-12 * d.sum(1, keepdims=True))[:, :, None] * np.eye(3)
        ok = np.isfinite(cost) & np.all(np.isfinite(A), axis=(1, 2)) & (np.abs(np.linalg.det(A)) > 0)
        step = np.zeros((N, 3))
        step[ok] = np.linalg.solve(A[ok], -g[ok][:, :, None])[:, :, 0]
        better = ok & (evaluate(Xc + step)[3] < cost)
        Xc = np.where(better[:, None], Xc + step, Xc)
        lam = np.where(better, lam / 10, lam * 10)
        r, u, q, cost = evaluate(Xc)
    X[cols] = Xc
    return X


def triangulate_tracks(tracks, K, R, t, views, mask, *, max_error_px, min_angle_deg):
    """Robust triangulation of tracks from registered views (H&Z Sec. 12.2; the idea of COLMAP's RANSAC
    triangulation, with every pair of views tried).

    For each track, every pair of its observations is triangulated (midpoint of the two rays) and scored
    by how many of the track's observations then reproject within ``max_error_px`` in front of the camera
    (the consensus). The observations on which all the largest consensus sets agree are triangulated by
    multi-view DLT and the consensus taken again (twice); a track whose largest consensus sets share fewer
    than two observations is ambiguous (which observation is the outlier cannot be told) and is rejected.
    Then, while some kept observation reprojects too far, the worst one is dropped and the track
    triangulated again. A point is accepted when at least two observations remain and its triangulation
    angle is at least ``min_angle_deg``. Trying all pairs makes the result depend on the cameras only, not
    on the order in which views were added; every DLT point is moved to its maximum-likelihood position
    (:func:`_refine_points`) before it is judged, so the result does not depend on the world frame either
    (the DLT's algebraic error does: on the dinosaur, track 3255 triangulated from the true cameras in the
    world frame reprojects at most 3.1 px from its observations, from the same cameras in the frame of
    view 17 4.8 px, beyond a 4 px threshold).

    Parameters
    ----------
    tracks : (V, N, 2) array_like
        Pixels, NaN where unseen (the columns are the tracks to triangulate).
    K, R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Calibration and poses (used only for ``views``).
    views : (m,) int array_like
        The registered views to use.
    mask : (V, N) bool array_like
        Observations allowed (outside ``views`` they are ignored).
    max_error_px, min_angle_deg : float

    Returns
    -------
    X : (N, 3) ndarray
        NaN where the track was rejected.
    used : (V, N) bool ndarray
        The observations that support each accepted point (all False for a rejected one).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(20, 3, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x = s.x_true.copy(); x[2, 0] += 50                     # one gross outlier
    >>> X, used = triangulate_tracks(x, np.stack([s.K] * 3), s.R, s.t, [0, 1, 2], s.visible,
    ...                              max_error_px=1.0, min_angle_deg=1.0)
    >>> bool(np.allclose(X, s.X)), int(used.sum()), bool(used[2, 0])
    (True, 59, False)
    """
    tracks = np.asarray(tracks, float)
    K, R, t = np.asarray(K, float), np.asarray(R, float), np.asarray(t, float)
    views = np.asarray(views, int)
    V, N = tracks.shape[:2]
    use = np.zeros((V, N), bool)
    use[views] = np.asarray(mask, bool)[views] & np.all(np.isfinite(tracks[views]), axis=-1)
    X = np.full((N, 3), np.nan)
    if N == 0 or views.size < 2:
        return X, np.zeros((V, N), bool)
    Ps = np.zeros((V, 3, 4))
    Ps[views] = _camera_matrices(K / K[:, 2:, 2:], R, t, views)     # K33 > 0: q_z has the sign of the depth
    xs = np.where(use[..., None], tracks, 0.0)

    def errors(Xq, cam, col):
        """Reprojection errors of points ``Xq`` (n, 3) in views ``cam`` against ``xs[cam, col]``; inf behind."""
        q = np.einsum("nij,nj->ni", Ps[cam], np.hstack([Xq, np.ones((len(Xq), 1))]))
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.linalg.norm(q[:, :2] / q[:, 2:] - xs[cam, col], axis=1)
        e[~(q[:, 2] > 0)] = np.inf
        return e

    # 1. every pair of observations of every track, and its consensus in the whole track
    cand = np.flatnonzero(use.sum(0) >= 2)
    if cand.size == 0:
        return X, np.zeros((V, N), bool)
    n_obs = use[:, cand].sum(0)
    L = int(n_obs.max())
    vid = np.argsort(~use[:, cand], axis=0, kind="stable")[:L]           # (L, n): observing views first
    a, b = np.triu_indices(L, 1)
    pa, col = np.nonzero(b[:, None] < n_obs[None])                         # all pairs of each track
    va, vb, trk = vid[a[pa], col], vid[b[pa], col], cand[col]
    # the midpoint of the two viewing rays (H&Z Sec. 12.1): cheap, and only used to find the consensus
    Kinv = np.zeros((V, 3, 3))
    Kinv[views] = np.linalg.inv(K[views])
    C = np.zeros((V, 3))
    C[views] = -np.einsum("vji,vj->vi", R[views], t[views])
    Rt = np.swapaxes(np.where(use.any(1)[:, None, None], R, 0.0), 1, 2)
    xh = np.concatenate([xs, np.ones((V, N, 1))], axis=2)
    da = np.einsum("nij,nj->ni", Rt[va] @ Kinv[va], xh[va, trk])
    db = np.einsum("nij,nj->ni", Rt[vb] @ Kinv[vb], xh[vb, trk])
    w0 = C[va] - C[vb]
    aa, ab, bb = (da * da).sum(1), (da * db).sum(1), (db * db).sum(1)
    d, e = (da * w0).sum(1), (db * w0).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = aa * bb - ab ** 2
        sa, sb = (ab * e - bb * d) / den, (aa * e - ab * d) / den
        Xp = 0.5 * (C[va] + sa[:, None] * da + C[vb] + sb[:, None] * db)
    Xp[~(np.abs(den) > 1e-12 * aa * bb) | ~np.all(np.isfinite(Xp), axis=1)] = np.inf
    # each pair's point against every observation of its track
    n_po = n_obs[col]
    pair_of = np.repeat(np.arange(col.size), n_po)
    slot = np.arange(pair_of.size) - np.repeat(np.cumsum(n_po) - n_po, n_po)
    cam = vid[slot, col[pair_of]]
    e = errors(np.nan_to_num(Xp[pair_of], posinf=0.0), cam, trk[pair_of])
    e[~np.isfinite(Xp[pair_of, 0])] = np.inf
    inl = np.isfinite(e) & (e <= max_error_px)                            # inf: behind a camera
    count = np.bincount(pair_of, inl, col.size)
    most = np.zeros(N)
    np.maximum.at(most, trk, count)
    top = count == most[trk]                                               # the pairs with the largest consensus
    # the observations on which all the largest consensus sets agree (an ambiguous track keeps < 2)
    n_top = np.bincount(trk[top], minlength=N)
    votes = np.zeros((V, N), int)
    w = top[pair_of] & inl
    np.add.at(votes, (cam[w], trk[pair_of[w]]), 1)
    cons = (votes == n_top[None]) & (votes > 0)
    # 2. refit on the consensus set and take the consensus again
    for _ in range(2):
        todo = np.flatnonzero(cons.sum(0) >= 2)
        X[todo] = _refine_points(Ps, xs[:, todo], cons[:, todo],
                                 triangulate_multiview(Ps, np.where(cons[:, todo, None], xs[:, todo], np.nan)))
        cam, pt = np.nonzero(use[:, todo])
        cons[:, todo] = False
        e = errors(np.nan_to_num(X[todo[pt]]), cam, todo[pt])
        cons[cam, todo[pt]] = np.isfinite(e) & (e <= max_error_px)
    use &= cons
    # 3. drop the worst observation while one reprojects too far
    todo = np.flatnonzero(use.sum(0) >= 2)
    while todo.size:
        X[todo] = _refine_points(Ps, xs[:, todo], use[:, todo],
                                 triangulate_multiview(Ps, np.where(use[:, todo, None], xs[:, todo], np.nan)))
        cam, pt = np.nonzero(use[:, todo])
        err = np.full((V, todo.size), -1.0)
        err[cam, pt] = errors(np.nan_to_num(X[todo[pt]]), cam, todo[pt])
        worst = np.argmax(err, axis=0)
        e = err[worst, np.arange(todo.size)]
        bad = np.isinf(e) | (e > max_error_px)
        use[worst[bad], todo[bad]] = False
        todo = todo[bad & (use[:, todo].sum(0) >= 2)]
    ok = use.sum(0) >= 2
    angle = ray_angles_deg(C, np.where(ok[:, None], np.nan_to_num(X), 0.0), use & ok)
    ok &= angle >= min_angle_deg
    X[~ok] = np.nan
    use[:, ~ok] = False
    return X, use


# ---------------------------------------------------------------------------------------------
# Initial pair and next view
# ---------------------------------------------------------------------------------------------


def two_view_reconstruction(x1, x2, K1, K2, rng, *, threshold_px=4.0, confidence=0.999, min_angle_deg=1.0,
                            refine=True, loss="cauchy", f_scale=1.0):
    """Relative pose and points from two views, as in the two-view notebooks (H&Z Sec. 9.6, 11.6, 12.2, 18.1).

    F by RANSAC (Sampson distance below ``threshold_px``), ``E = K2ᵀ F K1``, the pose of the four
    decompositions that puts the points in front of both cameras, then DLT triangulation. A point is kept
    when it is an F inlier, in front of both cameras, reprojects within ``threshold_px`` in both views and
    is seen under at least ``min_angle_deg``. With ``refine`` the pose and the points are then
    bundle-adjusted (camera 1 and the baseline length held) and every correspondence is triangulated
    again with the refined pose: F ignores the calibration, and from a narrow field of view (the
    dinosaur's) its translation direction can be off by tens of degrees, which the calibrated BA repairs.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels, N >= 8.
    K1, K2 : (3, 3) array_like
    rng : numpy.random.Generator
    refine : bool
    loss, f_scale : str, float
        Loss of the refinement (see :func:`labutils.bundle.bundle_adjust`).

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray
        Camera 2 ``[R | t]`` with camera 1 ``[I | 0]`` and ``‖t‖ = 1``.
    X : (N, 3) ndarray
        NaN for the rejected correspondences.
    median_angle : float
        Median triangulation angle (degrees) of the kept points (0 when none is kept).
    """
    x1 = np.asarray(x1, float)
    x2 = np.asarray(x2, float)
    K1, K2 = np.asarray(K1, float), np.asarray(K2, float)
    F, inl = fundamental_ransac(x1, x2, threshold=threshold_px, rng=rng, confidence=confidence)
    inl = np.asarray(inl, bool)
    E = essential_from_fundamental(F, K1, K2)
    R, t = pose_from_essential(E, x1[inl], x2[inl], K1, K2)
    Ks = np.stack([K1, K2])
    Rs, ts = np.stack([np.eye(3), R]), np.stack([np.zeros(3), np.asarray(t, float).reshape(3)])
    xs = np.stack([x1, x2])
    mask = np.tile(inl, (2, 1))
    # E is F projected onto the essential matrices: when F is poorly conditioned the pose is rough and the
    # reprojection errors large, so before the refinement a point only has to be in front of both cameras
    X, used = triangulate_tracks(xs, Ks, Rs, ts, [0, 1], mask, max_error_px=np.inf if refine else threshold_px,
                                 min_angle_deg=min_angle_deg)
    ok = np.isfinite(X[:, 0])
    if refine and ok.sum() >= 8:
        ci, pi = np.nonzero(used[:, ok])
        res = bundle_adjust(Rs, ts, X[ok], ci, pi, xs[ci, np.flatnonzero(ok)[pi]], Ks, loss=loss, f_scale=f_scale,
                            fixed_cameras=[0], max_iter=30, tol=1e-6)     # a repair, not the last word
        s = np.linalg.norm(res.t[1])                              # keep ‖t‖ = 1 exactly
        Rs, ts = np.stack([np.eye(3), res.R[1]]), np.stack([np.zeros(3), res.t[1] / s])
        X, used = triangulate_tracks(xs, Ks, Rs, ts, [0, 1], np.ones_like(mask), max_error_px=threshold_px,
                                     min_angle_deg=min_angle_deg)
        ok = np.isfinite(X[:, 0])
    angle = ray_angles_deg(-np.einsum("vji,vj->vi", Rs, ts), np.where(ok[:, None], X, 0), used)
    return Rs[1], ts[1], X, float(np.median(angle[ok])) if ok.any() else 0.0


def choose_initial_pair(tracks, K, rng, *, n_candidates=6, min_tracks=30, min_angle_deg=3.0, threshold_px=4.0,
                        confidence=0.999):
    """Pick the initial pair: many shared tracks and a wide enough baseline.

    The ``n_candidates`` pairs sharing the most tracks (at least ``min_tracks``) are each reconstructed
    with :func:`two_view_reconstruction`. Among those whose median triangulation angle reaches
    ``min_angle_deg`` the pair with the largest ``points × median angle`` wins (more points, and each
    better determined: a point's depth error falls about as 1 / angle); if none reaches it, the pair with
    the widest median angle.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        NaN where unseen.
    K : (3, 3) or (V, 3, 3) array_like
    rng : numpy.random.Generator

    Returns
    -------
    best : dict
        ``i, j`` (views), ``R, t`` (view j relative to view i), ``track`` (indices of the accepted tracks),
        ``X`` (their points in view i's frame), ``median_angle``.
    table : list of dict
        One row per candidate, most shared tracks first: ``i, j, shared, points, median_angle`` (and
        ``failed``, the reason, when the two-view reconstruction failed).

    Raises
    ------
    ValueError
        If no pair of views shares ``min_tracks`` tracks.
    """
    tracks = _as_tracks(tracks)
    Ks = _as_calibrations(K, tracks.shape[0])
    cov = covisibility(tracks)
    i, j = np.triu_indices(len(cov), 1)
    keep = cov[i, j] >= max(min_tracks, 8)
    if not keep.any():
        raise ValueError(f"no pair of views shares {max(min_tracks, 8)} tracks: cannot start a reconstruction "
                         f"(the best pair shares {cov[i, j].max()})")
    i, j = i[keep], j[keep]
    order = np.argsort(-cov[i, j], kind="stable")[:n_candidates]
    table, results = [], []
    for a, b in zip(i[order], j[order]):
        x1, x2, idx = _pair(tracks, a, b)
        try:
            R, t, X, med = two_view_reconstruction(x1, x2, Ks[a], Ks[b], rng, threshold_px=threshold_px,
                                                   confidence=confidence)
        except ValueError as exc:          # e.g. no baseline: no pose puts the points in front
            table.append(dict(i=int(a), j=int(b), shared=int(len(idx)), points=0, median_angle=0.0, failed=str(exc)))
            results.append(None)
            continue
        ok = np.isfinite(X[:, 0])
        table.append(dict(i=int(a), j=int(b), shared=int(len(idx)), points=int(ok.sum()), median_angle=med))
        results.append(dict(i=int(a), j=int(b), R=R, t=t, track=idx[ok], X=X[ok], median_angle=med))
    usable = [k for k, r in enumerate(results) if r is not None and table[k]["points"] >= 8]
    if not usable:
        raise ValueError("no candidate pair gave a two-view reconstruction: "
                         + "; ".join(f"({r['i']}, {r['j']}): {r.get('failed', 'too few points')}" for r in table))
    wide = [k for k in usable if table[k]["median_angle"] >= min_angle_deg]
    if wide:
        best = max(wide, key=lambda k: (table[k]["points"] * table[k]["median_angle"], -k))
    else:
        best = max(usable, key=lambda k: (table[k]["median_angle"], -k))
    return results[best], table


def _pair(tracks, i, j):
    both = np.all(np.isfinite(tracks[i]), axis=-1) & np.all(np.isfinite(tracks[j]), axis=-1)
    idx = np.flatnonzero(both)
    return tracks[i, idx], tracks[j, idx], idx


def next_view(visible_points, registered, skip=()):
    """The unregistered view that sees the most triangulated points (the next to register).

    Parameters
    ----------
    visible_points : (V,) int array_like
        For each view, how many triangulated points it observes.
    registered : (V,) bool array_like
    skip : collection of int
        Views not to propose now (e.g. whose registration just failed).

    Returns
    -------
    int or None
        None when no candidate is left.

    >>> next_view([5, 9, 7, 3], [False, True, False, False])
    2
    """
    counts = np.asarray(visible_points, float).copy()
    counts[np.asarray(registered, bool)] = -1
    for v in skip:
        counts[v] = -1
    if counts.max() <= 0:
        return None
    return int(np.argmax(counts))


# ---------------------------------------------------------------------------------------------
# The incremental pipeline
# ---------------------------------------------------------------------------------------------


class _State:
    """The growing model: poses, points, and which observations were rejected."""

    def __init__(self, tracks, K):
        self.tracks, self.K = tracks, K
        V, T = tracks.shape[:2]
        self.seen = np.all(np.isfinite(tracks), axis=-1)
        self.R, self.t = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan)
        self.reg = np.zeros(V, bool)
        self.X = np.full((T, 3), np.nan)
        self.rejected = np.zeros((V, T), bool)

    @property
    def triangulated(self):
        return np.isfinite(self.X[:, 0])

    def used(self):
        """(V, T) the observations the model uses now."""
        return self.seen & ~self.rejected & self.reg[:, None] & self.triangulated[None]

    def visible_counts(self):
        """(V,) triangulated points each view observes (rejected observations excluded)."""
        return (self.seen & ~self.rejected & self.triangulated[None]).sum(1)

    def centres(self):
        return -np.einsum("vji,vj->vi", np.where(self.reg[:, None, None], self.R, 0), np.where(self.reg[:, None], self.t, 0))


def _bundle(st, cams, pts, fixed, *, loss, f_scale, max_iter, tol=1e-8):
    """Bundle-adjust cameras ``cams`` (global ids, those in ``fixed`` held) and points ``pts`` in place."""
    cams, pts = np.asarray(cams, int), np.asarray(pts, int)
    obs = st.used()[np.ix_(cams, pts)]
    ci, pi = np.nonzero(obs)
    if ci.size == 0:
        return None
    x = st.tracks[cams[ci], pts[pi]]
    Ks = st.K[cams]
    K = Ks[0] if np.all(Ks == Ks[:1]) else Ks
    fixed_local = np.flatnonzero(np.isin(cams, fixed)) if len(fixed) else None
    res = bundle_adjust(st.R[cams], st.t[cams], st.X[pts], ci, pi, x, K, loss=loss, f_scale=f_scale,
                        fixed_cameras=fixed_local, max_iter=max_iter, tol=tol)
    st.R[cams], st.t[cams], st.X[pts] = res.R, res.t, res.X
    return res


def _cost_text(res):
    """'a -> b px² in n iterations' for a BA result, or a note that there was nothing to adjust."""
    if res is None:
        return "nothing to adjust (no observations)"
    return f"{res.cost_initial:.4g} -> {res.cost_final:.4g} px² in {res.n_iter} iterations"


def _filter(st, threshold_px, min_angle_deg, readmit=False):
    """Reject observations reprojecting beyond the threshold; drop points left with < 2 views or a small angle.

    With ``readmit``, every observation of a triangulated point in a registered view is judged afresh
    (earlier rejections are forgotten). Returns (observations rejected, points dropped).
    """
    if readmit:
        st.rejected[:] = False
    cand = st.used()
    err = reprojection_errors(st.K, st.R, st.t, st.X, st.tracks, cand)
    bad = cand & ~(err <= threshold_px)
    st.rejected |= bad
    used = st.used()
    angle = ray_angles_deg(st.centres(), np.where(st.triangulated[:, None], st.X, 0), used)
    drop = st.triangulated & ~(angle >= min_angle_deg)
    st.X[drop] = np.nan
    return int(bad.sum()), int(drop.sum())


def _triangulate_new(st, candidates, threshold_px, min_angle_deg):
    """Triangulate the candidate tracks from the registered views; returns how many were accepted."""
    cand = np.asarray(candidates, int)
    if cand.size == 0:
        return 0
    views = np.flatnonzero(st.reg)
    allowed = st.seen[:, cand] & ~st.rejected[:, cand]
    X, used = triangulate_tracks(st.tracks[:, cand], st.K, st.R, st.t, views, allowed,
                                 max_error_px=threshold_px, min_angle_deg=min_angle_deg)
    ok = np.isfinite(X[:, 0])
    st.X[cand[ok]] = X[ok]
    # observations dropped while triangulating an accepted point are outliers of that point
    st.rejected[:, cand[ok]] |= allowed[:, ok] & ~used[:, ok] & st.reg[:, None]
    return int(ok.sum())


def _final_refinement(st, *, threshold_px, min_angle_deg, loss, f_scale, max_iter, note, timings, rounds=5,
                      tol=1e-8, l2_start=True):
    """Inlier set and cameras that agree: triangulate every track afresh from the cameras, BA, and again.

    Each round triangulates every track afresh from the current cameras (:func:`triangulate_tracks`: the
    inlier set is a function of the cameras alone, whatever the earlier decisions were), then runs a global
    BA on that set: least squares first (with ``l2_start``), then the robust loss from there. It stops when
    a round gives back the inlier set the last BA used (a fixed point: these cameras are the optimum of
    this set, and this set is what these cameras accept), or after ``rounds`` BAs (then the last BA's
    set and result are kept).

    Why each piece (measured on three-view subsets of the dinosaur's tracks and on forward-moving
    corridors, against :func:`bundle_from_cameras`, which runs this same function from the true cameras):

    - judging only the points kept so far (readmitting their observations) let the start decide: a track
      dropped once (too far from unconverged cameras) never came back, one kept once stayed though a fresh
      triangulation calls it ambiguous; 33 observations of 788 on views (15, 17, 19) made 72 % more
      rotation error;
    - the robust cost has several minima, and a robust BA ends in the one its start leads to: on views
      (0, 3, 6) the same inlier set gave 16.98 px² (rotation error 1.02°) from the pipeline's cameras and
      16.86 px² (1.00°) from the truth; on the forward corridor of seed 209 in the tests, 493.09 px²
      (0.129°) and 493.04 px² (0.159°). Least squares on the inlier set has one minimum, so the robust BA
      started from it ends in the same minimum whatever the cameras were (16.86 and 493.09 px² there):
      the result depends on the inlier set only, though not always in the lowest of the minima;
    - ``tol``: a relative cost change of 1e-6 stopped the BA up to 27 % (rotation error) short of the
      optimum on these weakly constrained problems; 1e-8 reaches it (within 0.4 %).
    """
    t0 = time.perf_counter()
    views = np.flatnonzero(st.reg)
    cand = np.flatnonzero(st.seen[views].sum(0) >= 2)

    def triangulate_afresh():
        st.rejected[:] = False
        st.X[:] = np.nan                # every track afresh: the result depends on the cameras only
        n_new = _triangulate_new(st, cand, threshold_px, min_angle_deg)
        return (n_new,) + _filter(st, threshold_px, min_angle_deg, readmit=False)

    n_new, n_bad, n_drop = triangulate_afresh()
    timings["final_triangulation"] = time.perf_counter() - t0
    note(f"final: {n_new} tracks triangulated, {n_bad} observations rejected, {n_drop} points dropped")
    t0 = time.perf_counter()
    for k in range(1, rounds + 1):
        pts = np.flatnonzero(st.triangulated)
        if l2_start and loss != "linear":
            _bundle(st, views, pts, [], loss="linear", f_scale=f_scale, max_iter=max_iter, tol=tol)
        res = _bundle(st, views, pts, [], loss=loss, f_scale=f_scale, max_iter=max_iter, tol=tol)
        note(f"final BA {k}: {_cost_text(res)}")
        before, X_ba, rejected_ba = st.used(), st.X.copy(), st.rejected.copy()
        n_new, n_bad, n_drop = triangulate_afresh()
        changed = int((before != st.used()).sum())
        if changed == 0 or k == rounds:
            st.X[:], st.rejected[:] = X_ba, rejected_ba     # keep the BA's points and the set it used
            note("final: triangulated afresh, the inlier set is the same" if changed == 0 else
                 f"final: {changed} observations would still change after {rounds} rounds; kept the last BA")
            break
        note(f"final: triangulated afresh, {changed} observations changed ({n_new} tracks)")
    timings["final_ba"] = time.perf_counter() - t0


def _result(st, order, timings, log):
    return Reconstruction(R=st.R.copy(), t=st.t.copy(), registered=st.reg.copy(), X=st.X.copy(),
                          inliers=st.used(), order=[int(v) for v in order], K=st.K.copy(),
                          timings=dict(timings), log=list(log))


def incremental_sfm(tracks, K, rng, *, init_pair=None, threshold_px=4.0, min_angle_deg=1.5, init_min_angle_deg=3.0,
                    n_init_candidates=6, min_inliers=15, local_ba_views=4, global_ba_growth=1.4, loss="cauchy",
                    f_scale=1.0, ba_max_iter=5, final_max_iter=100, confidence=0.9999, verbose=False):
    """Incremental structure from motion from calibrated tracks (module docstring; H&Z Ch. 18).

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels of T tracks in V views, NaN where a view does not see a track (like ``Scene.tracks``).
    K : (3, 3) or (V, 3, 3) array_like
        Calibration shared by all views, or one per view.
    rng : numpy.random.Generator
        The source of every random choice (RANSAC): the same seed gives the same result.
    init_pair : (int, int), optional
        Force the initial pair (default: :func:`choose_initial_pair`).
    threshold_px : float
        Pixel threshold of the RANSAC stages, of triangulation and of outlier removal (COLMAP's 4 px).
    min_angle_deg : float
        Smallest triangulation angle a point may have.
    init_min_angle_deg, n_init_candidates :
        Passed to :func:`choose_initial_pair`.
    min_inliers : int
        Fewest PnP inliers accepted to register a view.
    local_ba_views : int
        Views optimised by the local BA after each registration (the new one and its best-connected).
    global_ba_growth : float
        A global BA runs whenever the number of registered views has grown by this factor.
    loss, f_scale : str, float
        Robust loss of every bundle adjustment (``scipy.optimize.least_squares`` names; scale in px).
    ba_max_iter, final_max_iter : int
        Iteration caps of the incremental and the final BAs.
    confidence : float
        RANSAC confidence.
    verbose : bool
        Print the log as it is written.

    Returns
    -------
    Reconstruction
        In the frame of the first view of the initial pair, with the scale of its baseline (1); views
        that could not be registered have NaN poses.

    Raises
    ------
    ValueError
        Bad shapes or values of ``tracks``/``K``, no ``rng``, or no pair of views to start from.

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(200, 12, layout="turntable", noise_px=0.0, rng=np.random.default_rng(1))
    >>> rec = incremental_sfm(s.tracks, s.K, np.random.default_rng(0))
    >>> rec.n_registered, rec.R.shape, rec.X.shape, rec.n_points == s.n_points
    (12, (12, 3, 3), (186, 3), True)
    """
    t_start = time.perf_counter()
    tracks = _as_tracks(tracks)
    V, T = tracks.shape[:2]
    Ks = _as_calibrations(K, V)
    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    if not threshold_px > 0:
        raise ValueError(f"threshold_px must be positive; got {threshold_px}")
    st = _State(tracks, Ks)
    timings = {k: 0.0 for k in ("initial_pair", "pnp", "triangulation", "local_ba", "global_ba")}
    log = []

    def note(msg):
        log.append(msg)
        if verbose:
            print(msg)

    ba = dict(loss=loss, f_scale=f_scale)
    # 1. the initial pair
    t0 = time.perf_counter()
    if init_pair is None:
        best, table = choose_initial_pair(tracks, Ks, rng, n_candidates=n_init_candidates, min_angle_deg=init_min_angle_deg,
                                          threshold_px=threshold_px, confidence=confidence)
    else:
        i, j = (int(v) for v in init_pair)
        if not (0 <= i < V and 0 <= j < V and i != j):
            raise ValueError(f"init_pair must be two different views in 0..{V - 1}; got {init_pair}")
        x1, x2, idx = _pair(tracks, i, j)
        if len(idx) < 8:
            raise ValueError(f"views {i} and {j} share {len(idx)} tracks; at least 8 are needed to start")
        R, t, X, med = two_view_reconstruction(x1, x2, Ks[i], Ks[j], rng, threshold_px=threshold_px, confidence=confidence)
        ok = np.isfinite(X[:, 0])
        best = dict(i=i, j=j, R=R, t=t, track=idx[ok], X=X[ok], median_angle=med)
    i, j = best["i"], best["j"]
    st.R[i], st.t[i] = np.eye(3), np.zeros(3)
    st.R[j], st.t[j] = best["R"], best["t"]
    st.reg[[i, j]] = True
    st.X[best["track"]] = best["X"]
    order = [i, j]
    res = _bundle(st, [i, j], np.flatnonzero(st.triangulated), [i], max_iter=ba_max_iter, **ba)
    n_bad, n_drop = _filter(st, threshold_px, min_angle_deg)
    timings["initial_pair"] = time.perf_counter() - t0
    note(f"initial pair ({i}, {j}): {len(best['track'])} points, median angle {best['median_angle']:.1f} deg; "
         f"BA {_cost_text(res)}; {n_bad} observations rejected, {n_drop} points dropped")

    # 2. register the other views one at a time
    n_last_global, failed = 2, {}
    while True:
        vis = st.visible_counts()
        v = next_view(vis, st.reg, skip=[w for w, n in failed.items() if vis[w] <= n])
        if v is None or vis[v] < min_inliers:
            break
        t0 = time.perf_counter()
        idx = np.flatnonzero(st.seen[v] & ~st.rejected[v] & st.triangulated)
        try:
            R, t, inl = pnp_ransac(st.X[idx], tracks[v, idx], Ks[v], threshold=threshold_px, confidence=confidence,
                                   rng=rng, refine=True)
            inl = np.asarray(inl, bool)
            ok = inl.sum() >= min_inliers
        except ValueError as exc:
            ok, inl = False, np.zeros(idx.size, bool)
            note(f"view {v}: PnP failed ({exc})")
        timings["pnp"] += time.perf_counter() - t0
        if not ok:
            failed[v] = vis[v]
            note(f"view {v}: not registered ({inl.sum()} PnP inliers of {idx.size}); retry when it sees more points")
            continue
        st.R[v], st.t[v], st.reg[v] = R, t, True
        st.rejected[v, idx[~inl]] = True
        order.append(v)
        t0 = time.perf_counter()
        views = np.flatnonzero(st.reg)
        cand = np.flatnonzero(~st.triangulated & st.seen[v] & ~st.rejected[v]
                              & ((st.seen & ~st.rejected)[views].sum(0) >= 2))
        n_new = _triangulate_new(st, cand, threshold_px, min_angle_deg)
        timings["triangulation"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        if st.reg.sum() >= global_ba_growth * n_last_global:
            kind, n_last_global = "global", int(st.reg.sum())
            res = _bundle(st, views, np.flatnonzero(st.triangulated), [order[0]], max_iter=ba_max_iter, **ba)
        elif local_ba_views > 0:
            kind = "local"
            res = _local_bundle(st, v, local_ba_views, max_iter=ba_max_iter, **ba)
        else:
            kind, res = "no", None
        n_bad, n_drop = _filter(st, threshold_px, min_angle_deg)
        timings[f"{kind}_ba"] = timings.get(f"{kind}_ba", 0.0) + time.perf_counter() - t0
        ba_note = "" if res is None else (f"{res.cost_initial:.4g} -> {res.cost_final:.4g} px² ({res.n_iter} it, "
                                          f"{res.seconds:.2f} s, {res.residuals.shape[0]} obs)")
        note(f"view {v}: {inl.sum()} PnP inliers of {idx.size}, {n_new} new points; {kind} BA {ba_note}; "
             f"{n_bad} observations rejected, {n_drop} points dropped; {int(st.triangulated.sum())} points")
    missing = np.flatnonzero(~st.reg)
    if missing.size:
        note(f"views not registered: {missing.tolist()}")

    # 3. final refinement
    _final_refinement(st, threshold_px=threshold_px, min_angle_deg=min_angle_deg, max_iter=final_max_iter,
                      note=note, timings=timings, **ba)
    timings["total"] = time.perf_counter() - t_start
    rec = _result(st, order, timings, log)
    note(rec.summary())
    rec.log = log
    return rec


def _local_bundle(st, v, n_views, *, loss, f_scale, max_iter):
    """BA of view ``v``, its ``n_views - 1`` best-connected registered views and the points they see."""
    used = st.used()
    shared = (used & used[v]).sum(1)
    shared[~st.reg] = -1
    shared[v] = np.iinfo(shared.dtype).max
    window = np.argsort(-shared, kind="stable")[:n_views]
    window = window[shared[window] > 0]
    pts = np.flatnonzero(used[window].any(0))
    cams = np.flatnonzero(used[:, pts].any(1))
    fixed = np.setdiff1d(cams, window)
    if fixed.size == 0:                 # the window is the whole model: hold the first camera (gauge)
        fixed = cams[:1] if cams[0] != v else cams[1:2]
    return _bundle(st, cams, pts, fixed, loss=loss, f_scale=f_scale, max_iter=max_iter)


def bundle_from_cameras(tracks, K, R, t, *, threshold_px=4.0, min_angle_deg=1.5, loss="cauchy", f_scale=1.0,
                        max_iter=100):
    """Reference solution: triangulate every track from given cameras, then the pipeline's final refinement.

    This is the bar :func:`incremental_sfm` is judged against: with the ground-truth cameras it gives
    what bundle adjustment reaches on the same tracks when started from the truth (triangulate with the
    DLT, drop gross outliers, robust global BA, outlier removal, robust global BA: the very same steps and
    settings as the pipeline's last stage).

    Parameters
    ----------
    tracks : (V, T, 2) array_like
    K : (3, 3) or (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        The starting cameras (NaN rows are left out).

    Returns
    -------
    Reconstruction
        ``order`` is empty (nothing was registered incrementally).
    """
    t_start = time.perf_counter()
    tracks = _as_tracks(tracks)
    V = tracks.shape[0]
    Ks = _as_calibrations(K, V)
    R, t = np.array(R, float), np.array(t, float)
    if R.shape != (V, 3, 3) or t.shape != (V, 3):
        raise ValueError(f"R and t must have shapes ({V}, 3, 3) and ({V}, 3); got {R.shape} and {t.shape}")
    st = _State(tracks, Ks)
    st.reg = np.isfinite(R).all((1, 2)) & np.isfinite(t).all(1)
    if st.reg.sum() < 2:
        raise ValueError("need at least two cameras with finite R and t")
    st.R[st.reg], st.t[st.reg] = R[st.reg], t[st.reg]
    log, timings = [], {}
    _final_refinement(st, threshold_px=threshold_px, min_angle_deg=min_angle_deg, loss=loss, f_scale=f_scale,
                      max_iter=max_iter, note=log.append, timings=timings)
    timings["total"] = time.perf_counter() - t_start
    return _result(st, [], timings, log)


# ---------------------------------------------------------------------------------------------
# Evaluation
# ---------------------------------------------------------------------------------------------


def camera_errors(rec, R_true, t_true):
    """Per-camera errors against reference poses, after a similarity alignment of the centres (Umeyama).

    Parameters
    ----------
    rec : Reconstruction
    R_true : (V, 3, 3) array_like
    t_true : (V, 3) array_like

    Returns
    -------
    rot_deg : (V,) ndarray
        Rotation error in degrees (NaN for views that were not registered).
    centre_rel : (V,) ndarray
        Centre error divided by the scene size (RMS distance of the reference centres from their mean).
    """
    reg = np.asarray(rec.registered, bool)
    if reg.sum() < 3:
        raise ValueError(f"need at least 3 registered views to align; got {reg.sum()}")
    rot, cen = np.full(reg.shape, np.nan), np.full(reg.shape, np.nan)
    rot[reg], cen[reg] = pose_errors(rec.R[reg], rec.t[reg], np.asarray(R_true, float)[reg],
                                     np.asarray(t_true, float)[reg])
    return rot, cen


def align_reconstruction(rec, R_true, t_true):
    """The reconstruction moved into the frame (and scale) of reference poses, for plotting.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (T, 3) ndarray
        Poses and points after the similarity that best maps the registered centres onto the reference.
    """
    reg = np.asarray(rec.registered, bool)
    R, t = np.full_like(rec.R, np.nan), np.full_like(rec.t, np.nan)
    R[reg], t[reg], sim = align_cameras(rec.R[reg], rec.t[reg], np.asarray(R_true, float)[reg],
                                        np.asarray(t_true, float)[reg])
    return R, t, apply_similarity(sim, rec.X)


# ---------------------------------------------------------------------------------------------
# Files and the command line
# ---------------------------------------------------------------------------------------------


def _numeric_rows(path, what):
    """(line number, list of floats) for each non-blank line of ``path`` ('#' starts a comment)."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the {what} file ({exc})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        vals = []
        for col, tok in enumerate(tokens, 1):
            try:
                val = float(tok)
            except ValueError:
                raise ValueError(f"{path}, line {lineno}, column {col}: {tok!r} is not a number") from None
            if not np.isfinite(val):
                raise ValueError(f"{path}, line {lineno}, column {col}: {tok!r} is not a finite number")
            vals.append(val)
        rows.append((lineno, vals))
    if not rows:
        raise ValueError(f"{path}: the {what} file holds no numbers")
    return rows


def read_tracks(path):
    """Read a VGG track file: one row per track, ``x y`` for each view, ``-1 -1`` where unseen.

    (The format of the dinosaur's ``viff`` array, 4,983 rows × 72 columns.) Blank lines and text after
    ``#`` are ignored.

    Returns
    -------
    tracks : (V, T, 2) ndarray
        NaN where unseen, like ``Scene.tracks``.

    Raises
    ------
    ValueError
        Naming the file and line: a non-numeric or non-finite entry, an odd number of columns, a row
        whose length differs from the first, fewer than 2 views, or a half-missing observation.
    """
    rows = _numeric_rows(path, "tracks")
    first, n = rows[0][0], len(rows[0][1])
    if n % 2:
        raise ValueError(f"{path}, line {first}: {n} numbers, an odd count; a track row holds an x y pair per view")
    if n < 4:
        raise ValueError(f"{path}, line {first}: {n} numbers = {n // 2} view; at least 2 views (4 columns) are needed")
    for lineno, vals in rows:
        if len(vals) != n:
            raise ValueError(f"{path}, line {lineno}: {len(vals)} numbers, but line {first} has {n} "
                             f"(an x y pair for each of {n // 2} views)")
    a = np.array([vals for _, vals in rows]).reshape(len(rows), n // 2, 2)
    miss = a == -1
    half = miss[..., 0] != miss[..., 1]
    if half.any():
        k, v = np.argwhere(half)[0]
        raise ValueError(f"{path}, line {rows[k][0]}: view {v} has {a[k, v].tolist()}; an unseen observation "
                         "is '-1 -1'")
    a[miss.all(-1)] = np.nan
    return a.transpose(1, 0, 2)


def read_calibration(path, n_views):
    """Read K: one 3×3 matrix shared by all views (3 rows) or one per view stacked (3·V rows).

    Returns
    -------
    K : (V, 3, 3) ndarray
        Scaled so that ``K[2, 2] == 1``.

    Raises
    ------
    ValueError
        Naming the file and line: a row without exactly 3 numbers, a row count other than 3 or 3·V,
        a last row that is not ``0 0 k`` (k ≠ 0), or a singular matrix.
    """
    rows = _numeric_rows(path, "calibration")
    for lineno, vals in rows:
        if len(vals) != 3:
            raise ValueError(f"{path}, line {lineno}: {len(vals)} numbers; each row of K holds 3")
    if len(rows) not in (3, 3 * n_views):
        raise ValueError(f"{path}: {len(rows)} rows; expected 3 (one K shared by all views) or {3 * n_views} "
                         f"(one 3x3 K per view for the {n_views} views of the tracks file)")
    Ks = np.array([vals for _, vals in rows]).reshape(-1, 3, 3)
    for m, K in enumerate(Ks):
        lines = f"lines {rows[3 * m][0]}-{rows[3 * m + 2][0]}"
        who = f" (view {m})" if len(Ks) > 1 else ""
        if K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] == 0:
            raise ValueError(f"{path}, line {rows[3 * m + 2][0]}{who}: the last row of K must be '0 0 k' with k != 0; "
                             f"got {K[2].tolist()}")
        K = K / K[2, 2]
        if abs(np.linalg.det(K)) <= 1e-12 * np.abs(K).max() ** 3:
            raise ValueError(f"{path}, {lines}{who}: K is singular (det = {np.linalg.det(K):.3g})")
        Ks[m] = K
    return np.repeat(Ks, n_views, axis=0) if len(Ks) == 1 else Ks


def write_tracks(path, tracks):
    """Write ``tracks`` (V, T, 2), NaN where unseen, as a VGG track file (inverse of :func:`read_tracks`)."""
    a = np.asarray(tracks, float).transpose(1, 0, 2).reshape(np.shape(tracks)[1], -1)
    Path(path).write_text("".join(" ".join("-1" if np.isnan(v) else repr(float(v)) for v in row) + "\n" for row in a))


def _write_atomically(path, text):
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    return tmp


def main(argv=None):
    """``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json [--ply POINTS.ply] [--seed N]``.

    Exit status 0 on success, 2 for a bad input file or argument (nothing is written), 1 when the
    reconstruction itself fails.
    """
    parser = argparse.ArgumentParser(
        prog="python -m labutils.sfm",
        description="Incremental structure from motion from VGG-format tracks and known calibration.")
    parser.add_argument("tracks", help="track file: one row per track, 'x y' per view, -1 -1 where unseen")
    parser.add_argument("K", help="calibration: one 3x3 matrix shared by all views, or one per view stacked (3V rows)")
    parser.add_argument("--out", required=True, help="the result, JSON: cameras (null if unregistered) and points")
    parser.add_argument("--ply", help="also write the points as an ASCII PLY file")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random generator (default 0)")
    parser.add_argument("--threshold", type=float, default=4.0, help="pixel threshold (default 4)")
    parser.add_argument("--quiet", action="store_true", help="print only the summary line")
    args = parser.parse_args(argv)

    def fail(msg, code):
        print(f"error: {msg}", file=sys.stderr)
        return code

    try:
        tracks = read_tracks(args.tracks)
        K = read_calibration(args.K, tracks.shape[0])
    except ValueError as exc:
        return fail(exc, 2)
    for out in [args.out] + ([args.ply] if args.ply else []):
        if not Path(out).parent.resolve().is_dir():
            return fail(f"{out}: the folder {Path(out).parent} does not exist", 2)
    if not args.threshold > 0:
        return fail(f"--threshold must be positive; got {args.threshold}", 2)
    try:
        rec = incremental_sfm(tracks, K, np.random.default_rng(args.seed), threshold_px=args.threshold,
                              verbose=not args.quiet)
    except ValueError as exc:
        return fail(f"reconstruction failed: {exc}", 1)
    tmps = [(_write_atomically(args.out, json.dumps(rec.to_dict()) + "\n"), args.out)]
    if args.ply:
        tmps.append((_write_atomically(args.ply, ply_text(rec.X[np.isfinite(rec.X[:, 0])])), args.ply))
    for tmp, dst in tmps:
        os.replace(tmp, dst)
    print(rec.summary())
    print(f"wrote {args.out}" + (f" and {args.ply}" if args.ply else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
