"""Self-checks of notebook 05 (incremental structure from motion): choosing the next view, and the filter that
decides which triangulated tracks enter the model.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake: for the next
view, counting every track a view sees instead of the triangulated ones, proposing a view that is already registered,
forgetting the minimum; for the filter, each test track is built to fail one rule (behind a camera, one observation
far off while the mean is small, a narrow angle ...), so the track a wrong answer misjudges names the rule.
"""
import numpy as np

from ..bundle.reprojection import Rt_from_camera_params, camera_params_from_Rt
from ..bundle.schur import levenberg_marquardt
from ..core.geometry import camera_center
from ..core.ransac import ransac
from ..core.synthetic import look_at, make_scene
from ..pose.pnp import bearings, p3p_bearings, refine_pose, reprojection_errors
from ..sfm.reconstruction import masked_reprojection_errors
from ..sfm.view_selection import choose_initial_pair
from ..twoview.triangulation import ray_angles_deg, triangulate, triangulate_multiview
from . import yours
from .runner import run_checks

# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the next view
# ---------------------------------------------------------------------------------------------------------------


def next_view_reference(seen, X, registered, min_points=15):
    """The reference answer: the unregistered view seeing the most triangulated points, or None."""
    counts = (np.asarray(seen, bool) & np.isfinite(np.asarray(X, float)[:, 0])).sum(1)
    counts[np.asarray(registered, bool)] = -1
    v = int(np.argmax(counts))
    return v if counts[v] >= min_points else None


def _small_model():
    """5 views, 10 tracks, views 0 and 1 registered, tracks 0-5 triangulated (6-9 not yet)."""
    seen = np.zeros((5, 10), bool)
    seen[0] = True
    seen[1, :8] = True
    seen[2, [0, 1, 2, 6, 7, 8, 9]] = True      # 7 tracks, 3 of them triangulated
    seen[3, :5] = True                         # 5 tracks, all triangulated: the answer
    seen[4, 5:] = True                         # 5 tracks, 1 triangulated
    X = np.full((10, 3), np.nan)
    X[:6] = np.arange(18.0).reshape(6, 3)
    registered = np.array([True, True, False, False, False])
    return seen, X, registered


def _as_view(v, V, name="choose_next_view"):
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise ValueError(f"{name} must return a view index (an int) or None; it returned {v!r} "
                         f"({type(v).__name__})")
    return int(v)


def _diagnose_next(v, seen, X, registered, min_points):
    """None when ``v`` is a right answer (any of the tied best views, or None), else the likely mistake."""
    V = len(registered)
    v = _as_view(v, V)
    tri = np.isfinite(X[:, 0])
    counts = (seen & tri).sum(1)
    free = ~registered
    best = counts[free].max() if free.any() else -1
    right = [] if best < min_points else [int(w) for w in np.flatnonzero(free & (counts == best))]
    if (v is None and not right) or v in right:
        return None
    if v is None:
        if best == min_points:
            return (f"view {right[0]} sees exactly min_points = {min_points} triangulated points, which is enough: "
                    "return it (counts >= min_points)")
        return f"view {right[0]} sees {best} triangulated points (at least min_points = {min_points}): return it"
    if not 0 <= v < V:
        return (f"you returned {v}, which is not a view index (0..{V - 1}): return the view (np.argmax of the counts), "
                "not its count")
    if registered[v]:
        if not free.any():
            return "every view is registered: return None (nothing is left to add)"
        return f"view {v} is already registered: leave the registered views out before taking the largest count"
    if not right:
        return (f"no unregistered view sees min_points = {min_points} triangulated points (the best sees {best}): "
                "return None, and the pipeline stops adding views")
    all_counts = np.where(free, seen.sum(1), -1)
    if all_counts[v] == all_counts.max() and counts[v] < best:
        return (f"view {v} sees the most tracks ({seen[v].sum()}), but only {counts[v]} of them are triangulated: "
                "count only the tracks with a point already (finite X) — those give PnP its 2D–3D correspondences")
    if counts[v] == counts[free].min():
        return (f"view {v} sees the fewest triangulated points ({counts[v]}): take the largest count "
                "(argmax, not argmin)")
    return (f"view {v} sees {counts[v]} triangulated points, view {right[0]} sees {best}: count, per view, the tracks "
            "it sees whose point is triangulated ((seen & np.isfinite(X[:, 0])).sum(axis=1)) and take the largest "
            "among the unregistered views")


def check_choose_next_view(choose_next_view, verbose=True):
    """Self-check of ``choose_next_view(seen, X, registered, min_points) -> int or None``.

    Cases: a small model built so that each typical mistake picks another view, the minimum (exactly
    ``min_points`` is enough, fewer is not), every view registered, and a turntable model half way through.

    Examples
    --------
    >>> check_choose_next_view(next_view_reference, verbose=False).passed
    True
    """
    def small(f):
        seen, X, reg = _small_model()
        return _diagnose_next(f(seen.copy(), X.copy(), reg.copy(), 3), seen, X, reg, 3)

    def minimum(f):
        seen, X, reg = _small_model()
        for m in (5, 6):                                   # the best unregistered view sees exactly 5
            hint = _diagnose_next(f(seen.copy(), X.copy(), reg.copy(), m), seen, X, reg, m)
            if hint:
                return hint
        return None

    def all_registered(f):
        seen, X, reg = _small_model()
        reg[:] = True
        return _diagnose_next(f(seen.copy(), X.copy(), reg.copy(), 3), seen, X, reg, 3)

    def turntable(f):
        s = make_scene(150, 16, layout="turntable", noise_px=0.0, rng=np.random.default_rng(5))
        seen = s.visible
        reg = np.zeros(16, bool)
        reg[3:9] = True
        X = np.where((seen[reg].sum(0) >= 2)[:, None], s.X, np.nan)
        return _diagnose_next(f(seen.copy(), X.copy(), reg.copy(), 15), seen, X, reg, 15)

    return run_checks("choose_next_view", choose_next_view, [
        ("a small model: the unregistered view that sees the most triangulated points", small),
        ("the minimum: exactly min_points is enough, fewer is not (None)", minimum),
        ("every view registered: None", all_registered),
        ("a turntable model half way through (ties: any of the best views)", turntable),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: which triangulated tracks enter the model
# ---------------------------------------------------------------------------------------------------------------


def accept_points_reference(X, K, R, t, tracks, mask, threshold_px, min_angle_deg):
    """The reference answer, from the library's pieces (``masked_reprojection_errors``, ``ray_angles_deg``)."""
    X, R, t = np.asarray(X, float), np.asarray(R, float), np.asarray(t, float)
    mask = np.asarray(mask, bool)
    V = len(R)
    Ks = np.repeat(np.asarray(K, float)[None], V, axis=0)
    finite = np.isfinite(X).all(1)
    Xf = np.where(finite[:, None], X, 0.0)
    m = mask & finite[None]
    err = masked_reprojection_errors(Ks, R, t, Xf, tracks, m)        # inf behind a camera, NaN outside m
    within = np.all(~m | (err <= threshold_px), axis=0)
    C = np.full((V, 3), np.nan)
    used = m.any(1)
    C[used] = camera_center(R[used], t[used])
    angle = ray_angles_deg(np.nan_to_num(C), Xf, m)
    return finite & (m.sum(0) >= 2) & within & (angle >= min_angle_deg)


# The test rig of the labelled tracks: five cameras on a circle of radius 1 around the origin, looking at it, at
# azimuths 0, 1, 2, 10 and 30 degrees (so two rays meet at about the azimuth difference); view 4 is not registered.
_AZIMUTHS = np.radians([0.0, 1.0, 2.0, 10.0, 30.0])
_K = np.array([[1500.0, 0.0, 360.0], [0.0, 1500.0, 288.0], [0.0, 0.0, 1.0]])
THRESHOLD, MIN_ANGLE = 4.0, 1.5


def _rig():
    poses = [look_at(np.array([np.cos(a), np.sin(a), 0.02]), np.zeros(3)) for a in _AZIMUTHS]
    R, t = np.stack([p[0] for p in poses]), np.stack([p[1] for p in poses])
    R[4], t[4] = np.nan, np.nan                                     # not registered
    return R, t


def _project(R, t, X):
    q = (R @ X + t) @ _K.T
    return q[:2] / q[2]


def _labelled_tracks():
    """(X, tracks, mask, expected, hints): each track built to test one rule, with the hint for misjudging it."""
    R, t = _rig()
    R4, t4 = look_at(np.array([np.cos(_AZIMUTHS[4]), np.sin(_AZIMUTHS[4]), 0.02]), np.zeros(3))
    rows = []       # (X, {view: pixel offset}, views in mask, expected, hint when misjudged)
    P0 = np.array([0.01, -0.02, 0.03])
    behind = 3.0 * np.array([np.cos(np.radians(5)), np.sin(np.radians(5)), 0.02])     # beyond the cameras
    rows.append((P0, {0: 0, 3: 0}, [0, 3], True,
                 "a clean point (exact observations in views 0 and 3, seen under about 10°) was rejected: check the "
                 "projection — K @ (R X + t), divided by its third coordinate — and that the angle is in degrees "
                 "(np.degrees) when you compare it with min_angle_deg"))
    rows.append((behind, {0: 0, 3: 0}, [0, 3], False,
                 "a point behind the cameras was accepted (it reprojects exactly: the projection cannot tell): check "
                 "the depth, (R X + t)[2] > 0, in every view that observes the point (cheirality)"))
    rows.append((P0, {0: 0, 1: 0, 2: 0, 3: [0.0, 14.0]}, [0, 1, 2, 3], False,
                 "a point with one observation 14 px off (and three exact ones) was accepted: *every* observation "
                 "must reproject within threshold_px — not the mean error of the track"))
    rows.append((P0, {0: [3.0, 0.0], 3: [0.0, -3.0]}, [0, 3], True,
                 "a point whose observations are 3 px off (threshold 4 px) was rejected: compare the distance "
                 "‖x − π(X)‖ itself with threshold_px, not its square"))
    rows.append((P0, {0: 0, 1: 0}, [0, 1], False,
                 "a point seen under only about 1° (views 0 and 1; min_angle_deg = 1.5) was accepted: reject a point "
                 "whose widest angle between two viewing rays is below min_angle_deg (its depth is poorly determined)"))
    rows.append((P0, {0: 0, 1: 0, 2: 0}, [0, 1, 2], True,
                 "a point seen by views 0, 1 and 2 (rays 1°, 1° and 2° apart) was rejected: the triangulation angle "
                 "is the *widest* angle between any two of its rays (here views 0 and 2), not the first pair's or the "
                 "smallest"))
    rows.append((P0, {3: 0}, [3], False,
                 "a point with a single observation was accepted: a point needs at least two observations (and its "
                 "angle is undefined)"))
    rows.append((P0, {0: 0, 2: [40.0, 25.0], 3: 0}, [0, 3], True,
                 "a point was rejected because of an observation that is not in mask (view 2, 47 px off): use only "
                 "the observations in mask[:, k]; the others are not part of the point"))
    rows.append((P0, {0: 0, 3: 0, 4: [5.0, 5.0]}, [0, 3], True,
                 "a point was rejected because of view 4, which is not registered (its R and t are NaN) and not in "
                 "mask: use only the observations in mask[:, k]"))
    N = len(rows)
    X = np.stack([r[0] for r in rows])
    tracks = np.full((5, N, 2), np.nan)
    mask = np.zeros((5, N), bool)
    for k, (Xk, obs, views, _, _) in enumerate(rows):
        for v, off in obs.items():
            Rv, tv = (R4, t4) if v == 4 else (R[v], t[v])
            tracks[v, k] = _project(Rv, tv, Xk) + np.broadcast_to(np.asarray(off, float), 2)
        mask[views, k] = True
    expected = np.array([r[3] for r in rows])
    hints = [r[4] for r in rows]
    return X, R, t, tracks, mask, expected, hints


def _as_ok(ok, N):
    ok = np.asarray(ok)
    if ok.shape != (N,):
        raise ValueError(f"accept_points must return a boolean array of shape ({N},), one entry per track; it returned "
                         f"shape {ok.shape}")
    if ok.dtype != bool:
        if not np.all(np.isin(ok, [0, 1])):
            raise ValueError("accept_points must return booleans (True: keep the point)")
        ok = ok.astype(bool)
    return ok


def _diagnose_accept(ok, X, R, t, tracks, mask):
    ref = accept_points_reference(X, _K, R, t, tracks, mask, THRESHOLD, MIN_ANGLE)
    ok = _as_ok(ok, len(X))
    if np.array_equal(ok, ref):
        return None
    wrong = np.flatnonzero(ok != ref)
    return (f"{wrong.size} of {len(X)} tracks judged differently from the reference ({int(ok[wrong].sum())} accepted "
            f"that should be rejected, {int((~ok[wrong]).sum())} the other way): a point is kept when it has ≥ 2 "
            "observations in mask, is in front of every camera that observes it, reprojects within threshold_px in "
            "each, and its widest ray angle is ≥ min_angle_deg")


def check_accept_points(accept_points, verbose=True):
    """Self-check of ``accept_points(X, K, R, t, tracks, mask, threshold_px, min_angle_deg) -> (N,) bool``.

    Cases: nine tracks, each built to test one rule (a clean point, one behind the cameras, one observation far off,
    errors below the threshold, a narrow angle, a wide angle between the outer rays only, a single observation, an
    observation outside the mask, an unregistered view); a noisy turntable scene with outliers against the reference.

    Examples
    --------
    >>> check_accept_points(accept_points_reference, verbose=False).passed
    True
    """
    def labelled(f):
        X, R, t, tracks, mask, expected, hints = _labelled_tracks()
        ok = _as_ok(f(X.copy(), _K.copy(), R.copy(), t.copy(), tracks.copy(), mask.copy(), THRESHOLD, MIN_ANGLE),
                    len(X))
        wrong = np.flatnonzero(ok != expected)
        return None if wrong.size == 0 else hints[wrong[0]]

    def scene(f):
        rng = np.random.default_rng(7)
        s = make_scene(120, 8, layout="turntable", noise_px=1.0, outlier_ratio=0.1, rng=rng, K=_K)
        R, t = s.R.copy(), s.t.copy()
        R[6:], t[6:] = np.nan, np.nan                               # views 6, 7 not registered yet
        x = s.x_meas
        mask = np.all(np.isfinite(x), axis=-1)
        mask[6:] = False
        Ps = np.einsum("ij,vjk->vik", _K, np.concatenate([s.R, s.t[:, :, None]], axis=2))
        X = triangulate_multiview(Ps[:6], np.where(mask[:6, :, None], x[:6], np.nan))
        keep = np.isfinite(X[:, 0])
        X, x, mask = X[keep], x[:, keep], mask[:, keep]
        ok = f(X.copy(), _K.copy(), R.copy(), t.copy(), x.copy(), mask.copy(), THRESHOLD, MIN_ANGLE)
        return _diagnose_accept(ok, X, R, t, x, mask)

    return run_checks("accept_points", accept_points, [
        ("nine tracks, each testing one rule (cheirality, every observation, the widest angle, the mask ...)",
         labelled),
        ("a turntable scene, σ = 1 px and 10 % outliers, 2 views not registered", scene),
    ], verbose=verbose)


__all__ = ["accept_points_reference", "check_accept_points", "check_choose_next_view", "next_view_reference"]


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: the incremental loop
# ---------------------------------------------------------------------------------------------------------------


def _piece(name, given):
    """The function given, else the student's from its notebook (``yours.load``), else the library's."""
    return given if given is not None else yours.load(name, quiet=True)


def register_view(X, x, K, threshold_px, *, rng, ransac_loop=None):
    """A new view's pose: P3P in adaptive RANSAC, refined on the inliers (notebook 03).

    Parameters
    ----------
    X : (N, 3) ndarray
        The model's points the view sees.
    x : (N, 2) ndarray
        Their pixels in the view.
    K : (3, 3) ndarray
    threshold_px : float
    rng : numpy.random.Generator
    ransac_loop : callable, optional
        ``adaptive_ransac``-like loop; by default the student's ``adaptive_ransac`` of notebook 03 as saved in the
        working folder (``yours.load``), the library's ``ransac`` where it is not written.

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray
    inliers : (N,) bool ndarray
        The correspondences reprojecting within ``threshold_px`` at the refined pose.
    """
    ransac_loop, y = _piece("adaptive_ransac", ransac_loop), bearings(x, K)

    def fit(idx):
        try:
            return p3p_bearings(X[idx], y[idx])
        except ValueError:                              # a collinear sample
            return []

    (R, t), inl, _ = ransac_loop(len(X), 3, fit, lambda pose: reprojection_errors(X, x, K, *pose), threshold_px,
                                 rng=rng, confidence=0.9999, max_iter=10000)
    R, t = refine_pose(X[inl], x[inl], K, R, t)
    return R, t, reprojection_errors(X, x, K, R, t) < threshold_px


def triangulate_new(tracks, K, R, t, v, new, registered, *, dlt=None):
    """The tracks ``new`` triangulated from view ``v`` and, per track, the registered view that sees it with the
    widest baseline (the camera centre farthest from ``v``'s), by two-view DLT.

    Parameters
    ----------
    tracks : (V, T, 2) ndarray
    K : (3, 3) ndarray
    R, t : (V, 3, 3), (V, 3) ndarray
        Poses, NaN for views not registered.
    v : int
        The new view.
    new : (n,) int ndarray
        The tracks to triangulate (each seen by ``v`` and another registered view).
    registered : (V,) bool ndarray
    dlt : callable, optional
        ``triangulate_linear(P1, P2, x1, x2)``; by default the student's of notebook 02 (``yours.load``), the
        library's ``triangulate`` where it is not written.

    Returns
    -------
    X_new : (n, 3) ndarray
    """
    dlt = _piece("triangulate_linear", dlt)
    C = -np.einsum("vji,vj->vi", np.nan_to_num(R), np.nan_to_num(t))
    seen = np.isfinite(tracks[:, new, 0]) & registered[:, None]
    seen[v] = False
    partner = np.argmax(np.where(seen, np.linalg.norm(C - C[v], axis=1)[:, None], -1.0), axis=0)
    X_new = np.full((len(new), 3), np.nan)
    for u in np.unique(partner):
        k = partner == u
        X_new[k] = dlt(K @ np.c_[R[v], t[v]], K @ np.c_[R[u], t[u]], tracks[v, new[k]], tracks[u, new[k]])
    return X_new


def adjust(R, t, X, inliers, tracks, K, max_iter, *, lm=None):
    """Bundle adjustment of the registered views and the model's points over the ``inliers`` observations.

    Parameters
    ----------
    R, t : (V, 3, 3), (V, 3) ndarray
        Poses, NaN for views not registered.
    X : (T, 3) ndarray
        Points, NaN for tracks not in the model.
    inliers : (V, T) bool ndarray
        The observations to use.
    tracks : (V, T, 2) ndarray
    K : (3, 3) ndarray
    max_iter : int
    lm : callable, optional
        ``levenberg_marquardt``; by default the student's of notebook 04 (``yours.load``), the library's where it is
        not written.

    Returns
    -------
    R, t, X : ndarray
        Adjusted copies.
    """
    lm = _piece("levenberg_marquardt", lm)
    views, points = np.flatnonzero(np.isfinite(R[:, 0, 0])), np.flatnonzero(np.isfinite(X[:, 0]))
    ci, pi = np.nonzero(inliers[np.ix_(views, points)])
    cp, Xp, _ = lm(camera_params_from_Rt(R[views], t[views]), X[points], ci, pi, tracks[views[ci], points[pi]], K,
                   max_iter=max_iter)
    R, t, X = R.copy(), t.copy(), X.copy()
    (R[views], t[views]), X[points] = Rt_from_camera_params(cp), Xp
    return R, t, X


def incremental_loop_reference(tracks, K, init, *, rng, threshold_px=4.0, min_angle_deg=1.5, min_points=15,
                               growth=1.3, ba_iter=10):
    """The reference of notebook 05's ``incremental_loop``, from the library's pieces: ``(R, t, X, order)``.

    From the initial pair ``init`` (``choose_initial_pair``'s dict), repeat: the next view (the most triangulated
    points), its pose by P3P-RANSAC and refinement, the new tracks triangulated from it and the registered view with
    the widest baseline and filtered by :func:`accept_points_reference`; plain Levenberg–Marquardt over everything
    whenever the number of views has grown by ``growth`` (and at the end), then the observations reprojecting
    farther than ``threshold_px`` removed and the points left with fewer than two dropped.
    """
    V, T = tracks.shape[:2]
    seen = np.isfinite(tracks[..., 0])
    R, t, X = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan), np.full((T, 3), np.nan)
    i, j = init["i"], init["j"]
    R[i], t[i], R[j], t[j] = np.eye(3), np.zeros(3), init["R"], init["t"]
    X[init["track"]] = init["X"]
    registered, inliers = np.zeros(V, bool), seen.copy()
    registered[[i, j]] = True
    order, n_adjusted = [i, j], 2
    K_all = np.repeat(np.asarray(K, float)[None], V, axis=0)
    while True:
        v = next_view_reference(seen & inliers, X, registered, min_points)
        if v is not None:
            have = np.flatnonzero(seen[v] & np.isfinite(X[:, 0]))
            R[v], t[v], inl = register_view(X[have], tracks[v, have], K, threshold_px, rng=rng, ransac_loop=ransac)
            inliers[v, have[~inl]] = False
            registered[v] = True
            order.append(v)
            new = np.flatnonzero(np.isnan(X[:, 0]) & seen[v] & (seen[registered].sum(0) >= 2))
            X_new = triangulate_new(tracks, K, R, t, v, new, registered, dlt=triangulate)
            ok = accept_points_reference(X_new, K, R, t, tracks[:, new], seen[:, new] & registered[:, None],
                                         threshold_px, min_angle_deg)
            X[new[ok]] = X_new[ok]
        if v is None or registered.sum() >= growth * n_adjusted:
            R, t, X = adjust(R, t, X, inliers & registered[:, None], tracks, K, ba_iter, lm=levenberg_marquardt)
            err = masked_reprojection_errors(K_all, R, t, np.nan_to_num(X), tracks, seen & registered[:, None])
            inliers &= ~(err > threshold_px)
            X[(inliers & registered[:, None]).sum(0) < 2] = np.nan
            n_adjusted = registered.sum()
        if v is None:
            return R, t, X, order


def _loop_scene(seed, n_points=120, n_views=10, outliers=0):
    rng = np.random.default_rng(seed)
    s = make_scene(n_points, n_views, layout="turntable", noise_px=0.5, rng=rng)
    tracks = np.where(s.visible[..., None], s.x_meas, np.nan)
    if outliers:
        v, k = np.nonzero(s.visible)
        pick = rng.choice(len(v), outliers, replace=False)
        tracks[v[pick], k[pick]] += rng.choice([-1, 1], (outliers, 2)) * rng.uniform(20, 60, (outliers, 2))
    init, _ = choose_initial_pair(tracks, s.K, rng=np.random.default_rng(seed), threshold_px=4.0)
    return s, tracks, init


def _diagnose_loop(out, s, tracks, init):
    if not isinstance(out, tuple | list) or len(out) != 4:
        return "incremental_loop must return (R, t, X, order)"
    R, t, X, order = out
    R, t, X = np.asarray(R, float), np.asarray(t, float), np.asarray(X, float)
    V, T = tracks.shape[:2]
    if R.shape != (V, 3, 3) or t.shape != (V, 3) or X.shape != (T, 3):
        return f"R, t, X must have shapes ({V}, 3, 3), ({V}, 3), ({T}, 3); got {R.shape}, {t.shape}, {X.shape}"
    order = [int(v) for v in order]
    if order[:2] != [init["i"], init["j"]]:
        return "order must start with the initial pair, init['i'] then init['j']"
    reg = np.isfinite(R[:, 0, 0])
    if reg.sum() <= 2:
        return "only the initial pair is in the model: repeat until choose_next_view returns None"
    if sorted(order) != sorted(np.flatnonzero(reg).tolist()):
        return "order must list every registered view once, in the order they were registered"
    ref = incremental_loop_reference(tracks, s.K, init, rng=np.random.default_rng(0))
    ref_reg = np.isfinite(ref[0][:, 0, 0])
    if reg.sum() < ref_reg.sum():
        return (f"{int(reg.sum())} views registered where the reference registers {int(ref_reg.sum())}: triangulate "
                "the new tracks of each registered view, so the next views see enough points")
    if not np.all(np.isfinite(X) | np.isnan(X)):
        return "X has inf entries: a track not in the model is a NaN row"
    rig = (R[reg], t[reg], s.R[reg], s.t[reg])
    Cs, Ct = -np.einsum("vji,vj->vi", rig[0], rig[1]), -np.einsum("vji,vj->vi", rig[2], rig[3])
    A, B = Cs - Cs.mean(0), Ct - Ct.mean(0)
    U, S, Wt = np.linalg.svd(B.T @ A)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Wt))])
    Q = U @ D @ Wt                                                # rotation taking our frame to the truth
    rot = [np.degrees(np.arccos(np.clip((np.trace(Rt @ (Re @ Q.T).T) - 1) / 2, -1, 1)))
           for Re, Rt in zip(rig[0], rig[2])]
    if np.mean(rot) > 0.5:
        return (f"the cameras are {np.mean(rot):.2f}° off on average (after alignment): bundle-adjust when the model "
                "has grown, and remove the observations reprojecting farther than threshold_px after each adjustment")
    if (np.isfinite(X[:, 0])).sum() < 0.5 * np.isfinite(ref[2][:, 0]).sum():
        return ("far fewer points than the reference: add every new track that accept_points accepts, "
                "X[new[ok]] = X_new[ok]")
    return None


def check_incremental_loop(incremental_loop, verbose=True):
    """Self-check of ``incremental_loop(tracks, K, init, *, rng, ...) -> (R, t, X, order)``: register, triangulate,
    bundle-adjust and remove outliers until no view is left.

    Cases: a synthetic turntable of 10 views (every view registered, the cameras within 0.5° after alignment), and the
    same with wrong observations among the tracks (the outlier removal keeps them out of the cameras).

    Examples
    --------
    >>> check_incremental_loop(incremental_loop_reference, verbose=False).passed
    True
    """
    def case(seed, outliers=0):
        def run(f):
            s, tracks, init = _loop_scene(seed, outliers=outliers)
            return _diagnose_loop(f(tracks.copy(), s.K, init, rng=np.random.default_rng(1)), s, tracks, init)
        return run

    return run_checks("incremental_loop", incremental_loop, [
        ("a synthetic turntable, 10 views, 0.5 px noise: every view, the cameras right", case(0)),
        ("the same with 40 wrong observations: removed after each bundle adjustment", case(1, outliers=40)),
    ], verbose=verbose)
