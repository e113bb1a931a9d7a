"""Incremental structure from motion: from point tracks and calibration to cameras and points.

The pipeline (H&Z Ch. 18 and Sec. 9.6, 12.2, 18.1; Snavely, Seitz & Szeliski, "Photo tourism", 2006;
Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016):

1. **Initial pair** (:func:`labutils.sfm.choose_initial_pair`): the pairs of views sharing
   the most tracks are each reconstructed (F by RANSAC, E, the pose by cheirality, a calibrated two-view
   BA, triangulation); among those whose median triangulation angle is large enough, the one with the
   largest ``points × median angle`` wins.
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
``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json [--ply POINTS.ply [--images DIR]] [--seed N] [--global]``;
``--global`` runs global SfM instead (:func:`labutils.sfm.global_sfm`: rotation averaging, translations,
BA), finished by the same last stage, :func:`bundle_from_cameras`.
"""
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..bundle.adjust import bundle_adjust
from ..core import cli as _cli
from ..core.geometry import camera_center
from ..core.scene import read_rgb
from ..core.validation import as_array, as_calibration, as_positive, as_rng, as_rotations, as_tracks
from ..data.formats import read_calibration, read_tracks
from ..model.pointcloud import cloud_from_reconstruction
from ..pose.pnp import pnp_ransac
from ..twoview.triangulation import ray_angles_deg, triangulate_tracks
from .global_sfm import global_sfm
from .initial_pair import two_view_reconstruction
from .reconstruction import Reconstruction, masked_reprojection_errors
from .view_selection import (  # noqa: F401 (covisibility, next_view: public here too)
    as_scores,
    as_strategy,
    choose_initial_pair,
    covisibility,
    next_view,
    shared_observations,
)

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
        return camera_center(np.where(self.reg[:, None, None], self.R, np.eye(3)),
                             np.where(self.reg[:, None], self.t, 0))


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
    """:meth:`BundleResult.cost_text`, or a note that there was nothing to adjust."""
    if res is None:
        return "nothing to adjust (no observations)"
    return res.cost_text()


def _filter(st, threshold_px, min_angle_deg, readmit=False):
    """Reject observations reprojecting beyond the threshold; drop points left with < 2 views or a small angle.

    With ``readmit``, every observation of a triangulated point in a registered view is judged afresh
    (earlier rejections are forgotten). Returns (observations rejected, points dropped).
    """
    if readmit:
        st.rejected[:] = False
    cand = st.used()
    err = masked_reprojection_errors(st.K, st.R, st.t, st.X, st.tracks, cand)
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
                                 threshold_px=threshold_px, min_angle_deg=min_angle_deg)
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

    ``threshold_px`` judges the fresh triangulations, which decide the inlier set, not the points the BA then
    returns: a kept observation may reproject a little beyond it at the end, because the BA moved its point (on
    the dinosaur's real tracks, 10 of 16,246 observations, up to 5.5 px against 4 px).

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


def incremental_sfm(tracks: ArrayLike, K: ArrayLike, *, rng: np.random.Generator, init_pair=None, threshold_px=4.0,
                    min_angle_deg=1.5, init_min_angle_deg=3.0,
                    n_init_candidates=6, min_inliers=15, local_ba_views=4, global_ba_growth=1.4, loss="cauchy",
                    f_scale=1.0, ba_max_iter=5, final_max_iter=100, confidence=0.9999, verbose=False,
                    view_selection="most_points", on_register=None):
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
    view_selection : str or callable
        How the next view is chosen among those that see ``min_inliers`` triangulated points:
        ``'most_points'`` (the most points), ``'pyramid'`` (the best-spread points) or ``'sequential'`` (the
        input order), or a function ``scores(tracks, visible, registered, order) -> (V,)``
        (:mod:`labutils.sfm.view_selection`).
    on_register : callable, optional
        Called after each view is registered (and its points triangulated and adjusted) with a snapshot of the
        model as a :class:`Reconstruction` (e.g. to follow the pose errors as views are added).

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
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(200, 12, layout="turntable", noise_px=0.0, rng=np.random.default_rng(1))
    >>> rec = incremental_sfm(s.tracks, s.K, rng=np.random.default_rng(0))
    >>> rec.n_registered, rec.R.shape, rec.X.shape, rec.n_points == s.n_points
    (12, (12, 3, 3), (186, 3), True)
    """
    t_start = time.perf_counter()
    tracks = as_tracks(tracks, min_views=2)
    V, T = tracks.shape[:2]
    Ks = as_calibration(K, "K", n_views=V)
    as_rng(rng)
    threshold_px = as_positive(threshold_px, "threshold_px")
    min_angle_deg = as_positive(min_angle_deg, "min_angle_deg", allow_zero=True)
    score = as_strategy(view_selection)
    if on_register is not None and not callable(on_register):
        raise ValueError(f"on_register must be a function of the model (a Reconstruction); got {on_register!r}")
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
        best, table = choose_initial_pair(tracks, Ks, rng=rng, n_candidates=n_init_candidates,
                                          min_angle_deg=init_min_angle_deg,
                                          threshold_px=threshold_px, confidence=confidence)
    else:
        i, j = (int(v) for v in init_pair)
        if not (0 <= i < V and 0 <= j < V and i != j):
            raise ValueError(f"init_pair must be two different views in 0..{V - 1}; got {init_pair}")
        x1, x2, idx = shared_observations(tracks, i, j)
        if len(idx) < 8:
            raise ValueError(f"views {i} and {j} share {len(idx)} tracks; at least 8 are needed to start")
        R, t, X, med = two_view_reconstruction(x1, x2, Ks[i], Ks[j], rng=rng, threshold_px=threshold_px,
                                               confidence=confidence)
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
        scores = as_scores(score(tracks, st.seen & ~st.rejected & st.triangulated[None], st.reg.copy(), list(order)),
                           V)
        v = next_view(vis, st.reg, skip=[w for w, n in failed.items() if vis[w] <= n], scores=scores,
                      min_points=min_inliers)
        if v is None:
            break
        t0 = time.perf_counter()
        idx = np.flatnonzero(st.seen[v] & ~st.rejected[v] & st.triangulated)
        try:
            pose = pnp_ransac(st.X[idx], tracks[v, idx], Ks[v], threshold_px=threshold_px, confidence=confidence,
                              rng=rng, refine=True)
            R, t, inl = pose.R, pose.t, pose.inliers
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
        stop = "" if pose.converged else ", RANSAC stopped at max_iter"
        note(f"view {v}: {inl.sum()} PnP inliers of {idx.size} (p_chance {pose.p_chance:.1g}{stop}), {n_new} new "
             f"points; {kind} BA {ba_note}; "
             f"{n_bad} observations rejected, {n_drop} points dropped; {int(st.triangulated.sum())} points")
        if on_register is not None:
            on_register(_result(st, order, timings, log))
    missing = np.flatnonzero(~st.reg)
    if missing.size:
        note(f"views not registered: {missing.tolist()}")

    # 3. final refinement
    _final_refinement(st, threshold_px=threshold_px, min_angle_deg=min_angle_deg, max_iter=final_max_iter,
                      note=note, timings=timings, **ba)
    timings["total"] = time.perf_counter() - t_start
    rec = _result(st, order, timings, log)
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
    tracks = as_tracks(tracks, min_views=2)
    V = tracks.shape[0]
    Ks = as_calibration(K, "K", n_views=V)
    R, t = as_array(R, "R", f"({V}, 3, 3)").copy(), as_array(t, "t", f"({V}, 3)").copy()
    if np.isinf(R).any() or np.isinf(t).any():
        raise ValueError("R and t must not hold inf (a NaN row leaves a camera out)")
    if R.shape != (V, 3, 3) or t.shape != (V, 3):
        raise ValueError(f"R and t must have shapes ({V}, 3, 3) and ({V}, 3) (NaN rows for cameras to leave out); "
                         f"got {R.shape} and {t.shape}" + (" — t transposed?" if t.shape == (3, V) else ""))
    threshold_px = as_positive(threshold_px, "threshold_px")
    st = _State(tracks, Ks)
    st.reg = np.isfinite(R).all((1, 2)) & np.isfinite(t).all(1)
    if st.reg.sum() < 2:
        raise ValueError("need at least two cameras with finite R and t")
    st.R[st.reg] = as_rotations(R[st.reg], "R")
    st.t[st.reg] = t[st.reg]
    log, timings = [], {}
    _final_refinement(st, threshold_px=threshold_px, min_angle_deg=min_angle_deg, loss=loss, f_scale=f_scale,
                      max_iter=max_iter, note=log.append, timings=timings)
    if not st.triangulated.any():
        raise ValueError("no track could be triangulated from the given cameras: they share one centre (no "
                         "baseline), or put the points behind them (a mirrored frame?), or do not fit the tracks")
    timings["total"] = time.perf_counter() - t_start
    return _result(st, [], timings, log)


def _parser():
    parser = _cli.Parser(
        prog="python -m labutils.sfm",
        description="Structure from motion from VGG-format tracks and known calibration: incremental, or global "
                    "with --global.")
    parser.add_argument("tracks", help="track file: one row per track, 'x y' per view, -1 -1 where unseen")
    parser.add_argument("K", help="calibration: one 3x3 matrix shared by all views, or one per view stacked (3V rows)")
    parser.add_argument("--out", required=True, help="the result, JSON: cameras (null if unregistered) and points")
    parser.add_argument("--ply", help="also write the points as a PLY file, with normals oriented to face the cameras "
                                      "that see them (and colours, with --images)")
    parser.add_argument("--images", metavar="DIR", help="the views' images (one per view, in sorted file-name order): "
                                                        "the PLY points get their colours from them")
    parser.add_argument("--ply-format", choices=["binary", "ascii"], default="binary",
                        help="PLY encoding (default binary little-endian)")
    parser.add_argument("--seed", type=_cli.seed_arg, default=0,
                        help="seed of the random generator, a non-negative integer (default 0)")
    parser.add_argument("--threshold", type=float, default=4.0, help="pixel threshold (default 4)")
    parser.add_argument("--quiet", action="store_true", help="no progress log, only the summary line")
    parser.add_argument("--global", dest="global_sfm", action="store_true",
                        help="global SfM (rotation averaging, translations from the points, BA) instead of adding "
                             "the views one at a time; the same last stage (bundle_from_cameras) finishes both")
    return parser


def _global_then_final(tracks, K, rng, threshold_px, verbose):
    """Global SfM (:func:`labutils.sfm.global_sfm`), then the incremental pipeline's last stage."""
    start = global_sfm(tracks, K, rng=rng, threshold_px=threshold_px, verbose=verbose)
    rec = bundle_from_cameras(tracks, K, start.R, start.t, threshold_px=threshold_px)
    rec.timings["total"] += start.timings["total"]
    return rec


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm")


def _read_image_folder(folder, n_views):
    """The RGB images of a folder in sorted file-name order, one per view; ``CommandError`` naming the folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise _cli.CommandError(f"{folder}: not a folder (--images takes the folder of the views' images)")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(paths) != n_views:
        raise _cli.CommandError(f"{folder}: {len(paths)} images ({', '.join(IMAGE_SUFFIXES)}) for {n_views} views: "
                                "one image per view, in sorted file-name order")
    return [read_rgb(p) for p in paths]


def main(argv=None):
    """``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json [--ply POINTS.ply [--images DIR]] [--seed N]
    [--global]``.

    ``--ply`` writes the triangulated points with normals (PCA over 12 neighbours, turned to face the cameras that
    see each point: :func:`labutils.model.cloud_from_reconstruction`) and, with ``--images``, their colours.

    The progress log goes to stderr, the summary to stdout. Exit status 0 on success; 2 for a bad input file or
    argument, an output that cannot be written or that is an input or the other output (checked before the
    reconstruction), or a reconstruction that fails — one line on stderr, and nothing is written.
    """
    args = _parser().parse_args(argv)
    images_in = []
    if args.images and Path(args.images).is_dir():
        images_in = [(p, "an input image (--images)") for p in sorted(Path(args.images).iterdir())
                     if p.suffix.lower() in IMAGE_SUFFIXES]
    _cli.check_distinct([(args.out, "--out"), (args.ply, "--ply")],
                        [(args.tracks, "the input TRACKS file"), (args.K, "the input K file")] + images_in)
    tracks = read_tracks(args.tracks)
    K = read_calibration(args.K, tracks.shape[0])
    outs = [_cli.check_output_path(args.out)] + ([_cli.check_output_path(args.ply)] if args.ply else [])
    if not (np.isfinite(args.threshold) and args.threshold > 0):
        raise _cli.CommandError(f"--threshold must be a positive number of pixels; got {args.threshold}")
    if args.images and not args.ply:
        raise _cli.CommandError(f"{args.images}: --images colours the PLY points: give --ply too")
    images = _read_image_folder(args.images, tracks.shape[0]) if args.images else None
    try:
        with contextlib.redirect_stdout(sys.stderr):
            if args.global_sfm:
                rec = _global_then_final(tracks, K, np.random.default_rng(args.seed), args.threshold, not args.quiet)
            else:
                rec = incremental_sfm(tracks, K, rng=np.random.default_rng(args.seed), threshold_px=args.threshold,
                                      verbose=not args.quiet)
    except ValueError as exc:
        raise _cli.CommandError(f"{args.tracks}: the reconstruction failed: {exc}") from None
    if args.ply:
        try:
            cloud = cloud_from_reconstruction(rec, images=images, k=min(12, max(rec.n_points, 3)))
        except ValueError as exc:
            raise _cli.CommandError(f"{args.ply}: cannot orient the points: {exc}") from None
        cloud.write_ply(outs[1], format="ascii" if args.ply_format == "ascii" else "binary_little_endian",
                        comments=["written by python -m labutils.sfm: normals face the cameras that see each point"])
    _cli.write_atomically(outs[0], json.dumps(rec.to_dict()) + "\n")
    print(rec.summary())
    print(f"wrote {args.out}" + (f" and {args.ply}" if args.ply else ""))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
