"""Global structure from motion: every camera at once, from the pairs of views, then bundle adjustment.

Where incremental SfM (:mod:`labutils.sfm.incremental`) adds views one at a time, and each new pose inherits the errors
of the ones before it (drift), the global pipeline estimates all cameras together (Martinec & Pajdla, "Robust
rotation and translation estimation in multiview reconstruction", CVPR 2007; Moulon et al., "Global fusion of
relative motions", ICCV 2013; Wilson & Snavely, "Robust global translations with 1DSfM", ECCV 2014):

1. **The view graph** (:func:`view_graph`): for the pairs of views sharing the most tracks, the relative pose
   from the essential matrix (:func:`labutils.sfm.two_view_reconstruction`: F by RANSAC, E, cheirality,
   and a calibrated two-view BA), its inlier count as the edge's weight.
2. **Rotation averaging** (:mod:`labutils.pose.rotation_averaging`): the chordal start, then robust IRLS; edges
   that still disagree by more than ``max_residual_deg`` are dropped as wrong.
3. **Translations** (:mod:`labutils.pose.global_translations`): the centres and points from the known rotations,
   linearly (the points method: sound for forward motion too), reweighted to drop wrong observations.
4. **Bundle adjustment** (:func:`labutils.bundle.bundle_adjust`, robust): from the linear points on the
   observations within a coarse threshold, then every track triangulated from the adjusted cameras
   (:func:`labutils.twoview.triangulate_tracks`) and adjusted again.

The result is a :class:`labutils.sfm.Reconstruction`. The same last stage as the incremental
pipeline, :func:`labutils.sfm.bundle_from_cameras`, then takes it to the optimum; ``python -m labutils.sfm
TRACKS.txt K.txt --out RESULT.json --global`` runs both.
"""
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..bundle.adjust import bundle_adjust
from ..core.validation import as_calibration, as_count, as_positive, as_rng, as_tracks
from ..pose.global_translations import robust_centres_from_points
from ..pose.pnp import pnp_ransac
from ..pose.rotation_averaging import largest_component, rotation_averaging
from ..twoview.triangulation import triangulate_tracks
from .initial_pair import two_view_reconstruction
from .reconstruction import Reconstruction, masked_reprojection_errors
from .view_selection import covisibility


@dataclass
class ViewGraph:
    """The measured pairs of views: what global SfM starts from (:func:`view_graph`).

    Attributes
    ----------
    n_views : int
    pairs : (E, 2) int ndarray
        The edges ``(i, j)``, ``i < j``.
    R : (E, 3, 3) ndarray
    t : (E, 3) ndarray
        Relative pose of view j in view i's frame (``x_j = R x_i + t``, ``‖t‖ = 1``).
    n_inliers : (E,) int ndarray
        Correspondences kept by the two-view reconstruction (the edge's weight).
    median_angle : (E,) ndarray
        Median triangulation angle of the kept correspondences, degrees.
    tracks : list of (n_k,) int ndarray
        The tracks whose observations in views i and j are inliers of edge k.
    failed : list of dict
        Pairs tried without a result: ``i, j`` and ``reason``.
    seconds : float
    """

    n_views: int
    pairs: np.ndarray
    R: np.ndarray
    t: np.ndarray
    n_inliers: np.ndarray
    median_angle: np.ndarray
    tracks: list = field(repr=False)
    failed: list = field(default_factory=list)
    seconds: float = 0.0

    def inlier_mask(self, n_tracks, edges=None):
        """(V, T) bool: observations that are inliers of at least one of ``edges`` (default: all)."""
        mask = np.zeros((self.n_views, n_tracks), bool)
        for k in (range(len(self.pairs)) if edges is None else np.flatnonzero(edges)):
            i, j = self.pairs[k]
            mask[i, self.tracks[k]] = mask[j, self.tracks[k]] = True
        return mask


def candidate_pairs(tracks: ArrayLike, *, min_shared: int = 15, n_partners: int = None) -> np.ndarray:
    """The pairs of views to measure: each view's ``n_partners`` best (most shared tracks, at least ``min_shared``).

    ``n_partners=None`` takes every pair sharing ``min_shared`` tracks.

    Returns
    -------
    (E, 2) int ndarray
        ``i < j``, sorted.

    >>> x = np.full((3, 40, 2), np.nan); x[:2] = 1.0; x[2, :35] = 2.0
    >>> candidate_pairs(x, n_partners=1).tolist()
    [[0, 1], [0, 2]]
    """
    tracks = as_tracks(tracks, min_views=2)
    min_shared = as_count(min_shared, "min_shared", 1)
    cov = covisibility(tracks)
    V = len(cov)
    np.fill_diagonal(cov, -1)
    keep = np.zeros((V, V), bool)
    if n_partners is None:
        keep = cov >= min_shared
    else:
        n_partners = as_count(n_partners, "n_partners", 1)
        for v in range(V):
            best = np.argsort(-cov[v], kind="stable")[:n_partners]
            keep[v, best[cov[v, best] >= min_shared]] = True
    keep |= keep.T
    i, j = np.nonzero(np.triu(keep, 1))
    return np.stack([i, j], axis=1)


def view_graph(tracks: ArrayLike, K: ArrayLike, *, rng: np.random.Generator, pairs: ArrayLike = None,
               min_shared: int = 15, n_partners: int = 5, min_inliers: int = 15, threshold_px: float = 4.0,
               confidence: float = 0.999, refine: bool = True) -> ViewGraph:
    """Measure the relative pose of each candidate pair of views (step 1 of the module docstring).

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels, NaN where unseen.
    K : (3, 3) or (V, 3, 3) array_like
    rng : numpy.random.Generator
    pairs : (E, 2) int array_like, optional
        The pairs to measure (default: :func:`candidate_pairs` with ``min_shared`` and ``n_partners``).
    min_inliers : int
        Fewest correspondences a two-view reconstruction must keep for the edge to count.
    threshold_px, confidence :
        Of the RANSAC for F (and of the two-view triangulation).
    refine : bool
        Finish each pair with a calibrated two-view BA (better rotations; most of the time is spent there).

    Returns
    -------
    ViewGraph
    """
    t0 = time.perf_counter()
    tracks = as_tracks(tracks, min_views=2)
    V = tracks.shape[0]
    Ks = as_calibration(K, "K", n_views=V, like_name="tracks")
    as_rng(rng)
    min_inliers = as_count(min_inliers, "min_inliers", 8)
    threshold_px = as_positive(threshold_px, "threshold_px")
    if pairs is None:
        pairs = candidate_pairs(tracks, min_shared=min_shared, n_partners=n_partners)
    seen = np.all(np.isfinite(tracks), axis=-1)
    rows, failed = [], []
    for i, j in np.asarray(pairs, int).reshape(-1, 2):
        idx = np.flatnonzero(seen[i] & seen[j])
        if idx.size < 8:
            failed.append(dict(i=int(i), j=int(j), reason=f"{idx.size} shared tracks"))
            continue
        try:
            R, t, X, med = two_view_reconstruction(tracks[i, idx], tracks[j, idx], Ks[i], Ks[j], rng=rng,
                                                   threshold_px=threshold_px, confidence=confidence, refine=refine)
        except ValueError as exc:                 # no baseline, too few inliers ...
            failed.append(dict(i=int(i), j=int(j), reason=str(exc)))
            continue
        ok = np.isfinite(X[:, 0])
        if ok.sum() < min_inliers:
            failed.append(dict(i=int(i), j=int(j), reason=f"{ok.sum()} inliers"))
            continue
        rows.append((int(i), int(j), R, t, int(ok.sum()), med, idx[ok]))
    if not rows:
        raise ValueError("no pair of views gave a two-view reconstruction"
                         + (f": {failed[0]['i']}-{failed[0]['j']}: {failed[0]['reason']}" if failed else ""))
    return ViewGraph(n_views=V, pairs=np.array([r[:2] for r in rows]), R=np.stack([r[2] for r in rows]),
                     t=np.stack([r[3] for r in rows]), n_inliers=np.array([r[4] for r in rows]),
                     median_angle=np.array([r[5] for r in rows]), tracks=[r[6] for r in rows], failed=failed,
                     seconds=time.perf_counter() - t0)


def global_sfm(tracks: ArrayLike, K: ArrayLike, *, rng: np.random.Generator, threshold_px: float = 4.0,
               min_shared: int = 15, n_partners: int = 5, min_inliers: int = 15, refine_pairs: bool = True,
               loss: str = "cauchy", scale_deg: float = 2.0, max_residual_deg: float = 20.0,
               coarse_threshold_px: float = None, min_angle_deg: float = 1.5, ba_loss: str = "cauchy",
               f_scale: float = 1.0, max_iter: int = 50, confidence: float = 0.999, graph: ViewGraph = None,
               verbose: bool = False) -> Reconstruction:
    """Global SfM from calibrated tracks: the view graph, rotation averaging, translations, BA (module docstring).

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels of T tracks in V views, NaN where unseen.
    K : (3, 3) or (V, 3, 3) array_like
    rng : numpy.random.Generator
        The source of every random choice (the RANSAC of each pair).
    threshold_px : float
        Pixel threshold of the RANSAC stages, of triangulation and of the inliers at the end.
    min_shared, n_partners, refine_pairs :
        Which pairs are measured, and how (:func:`view_graph`).
    min_inliers : int
        Fewest inliers of a pair (:func:`view_graph`), and of the PnP that registers a view the pairs could not
        place (one that shares too few tracks with any single view).
    loss, scale_deg :
        The robust loss of the rotation averaging (:func:`labutils.pose.refine_rotations`).
    max_residual_deg : float
        Edges disagreeing with the averaged rotations by more are dropped (their inliers are not used).
    coarse_threshold_px : float, optional
        Inlier threshold of the linear translations and the first BA (default ``5 threshold_px``): the linear
        cameras are rough.
    min_angle_deg : float
        Smallest triangulation angle of a point.
    ba_loss, f_scale, max_iter :
        Of each bundle adjustment.
    confidence : float
        RANSAC confidence.
    graph : ViewGraph, optional
        A view graph measured before (skips step 1).
    verbose : bool
        Print the log as it is written.

    Returns
    -------
    Reconstruction
        In the frame of the averaged rotations (the first view of the largest connected part of the view graph
        at the identity), centres with RMS spread 1 before the BA; ``order`` is empty; views outside the largest
        connected part, or without usable observations, are not registered (NaN).

    Raises
    ------
    ValueError
        Bad input, or no two views that can be tied together.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(150, 8, layout="turntable", noise_px=0.0, rng=np.random.default_rng(1))
    >>> rec = global_sfm(s.tracks, s.K, rng=np.random.default_rng(0))
    >>> from labutils.sfm.reconstruction import camera_errors
    >>> rec.n_registered, bool(camera_errors(rec, s.R, s.t)[0].max() < 1e-4)
    (8, True)
    """
    t_start = time.perf_counter()
    tracks = as_tracks(tracks, min_views=2)
    V, T = tracks.shape[:2]
    Ks = as_calibration(K, "K", n_views=V, like_name="tracks")
    as_rng(rng)
    threshold_px = as_positive(threshold_px, "threshold_px")
    coarse = 5 * threshold_px if coarse_threshold_px is None else as_positive(coarse_threshold_px,
                                                                             "coarse_threshold_px")
    max_residual_deg = as_positive(max_residual_deg, "max_residual_deg")
    log, timings = [], {}

    def note(msg):
        log.append(msg)
        if verbose:
            print(msg)

    # 1. the view graph
    if graph is None:
        graph = view_graph(tracks, Ks, rng=rng, min_shared=min_shared, n_partners=n_partners, min_inliers=min_inliers,
                           threshold_px=threshold_px, confidence=confidence, refine=refine_pairs)
    timings["view_graph"] = graph.seconds
    note(f"view graph: {len(graph.pairs)} pairs measured ({len(graph.failed)} failed), "
         f"{int(np.median(graph.n_inliers))} inliers per pair (median), {graph.seconds:.2f} s")
    # 2. rotations, on the largest connected part
    t0 = time.perf_counter()
    comp = largest_component(graph.pairs, V)
    edges = comp[graph.pairs[:, 0]]
    views = np.flatnonzero(comp)
    if views.size < 2:
        raise ValueError("no two views are linked by a measured pair: nothing to reconstruct")
    local = np.cumsum(comp) - 1
    ra = rotation_averaging(local[graph.pairs[edges]], graph.R[edges], views.size, graph.n_inliers[edges],
                            loss=loss, scale_deg=scale_deg)
    R = np.full((V, 3, 3), np.nan)
    R[views] = ra.R
    good = np.zeros(len(graph.pairs), bool)
    good[np.flatnonzero(edges)] = ra.residuals_deg <= max_residual_deg
    timings["rotations"] = time.perf_counter() - t0
    note(f"rotation averaging: {views.size} of {V} views, {ra.n_iter} IRLS iterations; edge residuals median "
         f"{np.median(ra.residuals_deg):.2f}°, {int(edges.sum() - good.sum())} edges beyond {max_residual_deg:g}° "
         "dropped")
    # 3. translations from the inliers of the edges kept
    t0 = time.perf_counter()
    mask = graph.inlier_mask(T, good)
    C, X, inl = robust_centres_from_points(tracks, Ks, R, mask, threshold_px=coarse, min_angle_deg=min_angle_deg)
    reg = np.isfinite(C[:, 0]) & (inl.sum(1) >= 6)
    inl &= reg[:, None]
    R[~reg], C[~reg] = np.nan, np.nan
    t = -np.einsum("vij,vj->vi", np.nan_to_num(R), np.nan_to_num(C))
    t[~reg] = np.nan
    timings["translations"] = time.perf_counter() - t0
    note(f"translations: {int(reg.sum())} views placed, {int(inl.sum())} of {int(mask.sum())} observations "
         f"within {coarse:g} px")
    # 4. bundle adjustment: from the linear points, then from every track triangulated afresh
    t0 = time.perf_counter()
    ba = dict(loss=ba_loss, f_scale=f_scale, max_iter=max_iter)
    R, t, _, res = _adjust(tracks, Ks, R, t, X, inl, reg, **ba)
    note(f"BA from the linear start: {res.cost_text()}")
    X, used = _triangulate(tracks, Ks, R, t, reg, threshold_px, min_angle_deg)
    # views the pairs could not place (too few tracks shared with any one view): by PnP, as incremental SfM does
    why = {}                                      # view -> why PnP did not register it (the last attempt)
    for _ in range(V):
        added = _resection(tracks, Ks, R, t, X, reg, rng=rng, threshold_px=threshold_px, min_inliers=min_inliers,
                           confidence=confidence, why=why)
        if not added:
            break
        note(f"registered by PnP on the triangulated points: views {added}")
        X, used = _triangulate(tracks, Ks, R, t, reg, threshold_px, min_angle_deg)
    R, t, X, res = _adjust(tracks, Ks, R, t, X, used, reg, **ba)
    err = masked_reprojection_errors(Ks, np.nan_to_num(R), np.nan_to_num(t), np.nan_to_num(X), tracks, used)
    inliers = used & (err <= threshold_px)
    timings["bundle_adjustment"] = time.perf_counter() - t0
    note(f"BA after triangulating every track: {int(np.isfinite(X[:, 0]).sum())} points, {res.cost_text()}; "
         f"{int((used & ~inliers).sum())} observations beyond "
         f"{threshold_px:g} px")
    missing = np.flatnonzero(~reg)
    if missing.size:
        note(f"views not registered: {missing.tolist()}"
             + "".join(f"; {v}: {why[v]}" for v in missing.tolist() if v in why))
    timings["total"] = time.perf_counter() - t_start
    R[~reg], t[~reg] = np.nan, np.nan
    rec = Reconstruction(R=R, t=t, registered=reg.copy(), X=X, inliers=inliers, order=[], K=Ks, timings=timings,
                         log=log)
    note(f"global start, before the last stage: {rec.summary()}")
    return rec


def _triangulate(tracks, Ks, R, t, reg, threshold_px, min_angle_deg):
    """Every track triangulated robustly from the registered views: X (T, 3) and the observations used (V, T)."""
    Rf = np.where(reg[:, None, None], np.nan_to_num(R), np.eye(3))
    tf = np.where(reg[:, None], np.nan_to_num(t), 0.0)
    return triangulate_tracks(tracks, Ks, Rf, tf, np.flatnonzero(reg), np.all(np.isfinite(tracks), axis=-1),
                              threshold_px=threshold_px, min_angle_deg=min_angle_deg)


def _resection(tracks, Ks, R, t, X, reg, *, rng, threshold_px, min_inliers, confidence, why=None):
    """Register (in place) each unregistered view that sees ``min_inliers`` triangulated points and whose PnP-RANSAC
    keeps as many inliers; returns the views added, and writes why the others were not into ``why``."""
    why = {} if why is None else why
    seen = np.all(np.isfinite(tracks), axis=-1) & np.isfinite(X[:, 0])[None]
    added = []
    for v in np.flatnonzero(~reg & (seen.sum(1) >= min_inliers)):
        idx = np.flatnonzero(seen[v])
        try:
            pose = pnp_ransac(X[idx], tracks[v, idx], Ks[v], threshold_px=threshold_px, rng=rng,
                              confidence=confidence)
        except ValueError as exc:                 # degenerate, or no pose better than chance
            why[int(v)] = f"PnP refused ({exc})"
            continue
        if pose.inliers.sum() >= min_inliers:
            R[v], t[v], reg[v] = pose.R, pose.t, True
            added.append(int(v))
            why.pop(int(v), None)
        else:
            why[int(v)] = f"{pose.n_inliers} PnP inliers < {min_inliers}"
    return added


def _adjust(tracks, Ks, R, t, X, obs, reg, *, loss, f_scale, max_iter):
    """Robust BA of the registered cameras and the points of the tracks observed in ``obs`` (V, T), in place of
    ``X`` (T, 3); returns R, t, X and the BA result."""
    cams = np.flatnonzero(reg)
    pts = np.flatnonzero(obs[cams].sum(0) >= 2)
    ci, pi = np.nonzero(obs[np.ix_(cams, pts)])
    Kb = Ks[cams]
    res = bundle_adjust(R[cams], t[cams], X[pts], ci, pi, tracks[cams[ci], pts[pi]], Kb[0] if np.all(Kb == Kb[:1])
                        else Kb, loss=loss, f_scale=f_scale, max_iter=max_iter)
    R, t, X = R.copy(), t.copy(), X.copy()
    R[cams], t[cams], X[pts] = res.R, res.t, res.X
    return R, t, X, res
