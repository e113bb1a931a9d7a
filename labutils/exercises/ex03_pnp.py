"""Self-checks of notebook 03 (camera pose from known points): the pose from two triangles (the last step of P3P)
and the adaptive RANSAC loop.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (R transposed, t with the wrong sign or the camera centre,
edges paired in the wrong order, a loop that is not adaptive, only the first P3P candidate scored ...).
"""
import numpy as np

from ..core.geometry import angle_axis_from_rotation, rotation_from_angle_axis
from ..core.ransac import ransac_iterations
from ..core.synthetic import DEFAULT_K, look_at, make_scene
from ..pose.pnp import bearings, p3p, p3p_bearings, reprojection_errors
from .runner import run_checks

# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the pose from two congruent triangles
# ---------------------------------------------------------------------------------------------------------------


def _triangle(seed, offset=(0.0, 0.0, 0.0), distance=4.0):
    """Three world points, a pose, and the unit rays and depths that the pose gives them."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(3, 3)) + np.asarray(offset)
    R = rotation_from_angle_axis(rng.normal(scale=0.8, size=3))
    t = -R @ X.mean(0) + np.array([0.2, -0.1, distance])          # the triangle in front of the camera
    Xc = X @ R.T + t
    lam = np.linalg.norm(Xc, axis=1)
    return X, Xc / lam[:, None], lam, R, t


def _symmetric_example():
    """The notebook's equilateral triangle seen from above its centre: four P3P poses."""
    X = 0.1 * np.array([[1, 0, 0], [-0.5, np.sqrt(3) / 2, 0], [-0.5, -np.sqrt(3) / 2, 0]])
    R, t = look_at(np.array([0.01, 0.004, 0.6]), np.zeros(3), up=(0, 1, 0))
    x = X @ R.T + t
    x = (x @ DEFAULT_K.T)[:, :2] / x[:, 2:]
    return X, bearings(x, DEFAULT_K), p3p(X, x, DEFAULT_K)


def _close(A, B, tol=1e-8):
    return float(np.abs(A - B).max()) <= tol * max(1.0, float(np.abs(B).max()))


def _build_R(X, y, lam):
    d1, d2 = X[0] - X[1], X[0] - X[2]
    v1, v2 = lam[0] * y[0] - lam[1] * y[1], lam[0] * y[0] - lam[2] * y[2]
    return np.column_stack([v1, v2, np.cross(v1, v2)]) @ np.linalg.inv(np.column_stack([d1, d2, np.cross(d1, d2)]))


def _diagnose_pose(out, X, y, lam, R_ref, t_ref):
    """None when ``out`` is ``(R_ref, t_ref)``, else the most likely mistake."""
    if not isinstance(out, tuple | list) or len(out) != 2:
        return "pose_from_depths must return a pair (R, t)"
    R, t = np.asarray(out[0], float), np.asarray(out[1], float)
    if R.shape != (3, 3):
        return f"R must be a (3, 3) array; it has shape {R.shape}"
    if t.shape != (3,):
        return f"t must have shape (3,); it has shape {t.shape}" + (" (use .ravel())" if t.size == 3 else "")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return "R or t has NaN or inf entries"
    if _close(R, R_ref) and _close(t, t_ref):
        return None
    orth = float(np.abs(R.T @ R - np.eye(3)).max())
    if orth > 1e-6:
        if _close(R, _build_R(X, y, np.ones(3)), 1e-6):
            return ("R is not a rotation: the rays must be scaled by their depths — the camera-frame points are "
                    "λi yi, so v1 = λ1 y1 - λ2 y2 and v2 = λ1 y1 - λ3 y3")
        return (f"R is not a rotation (largest entry of RᵀR - I: {orth:.2g}): R maps [d1, d2, d1 × d2] onto "
                "[v1, v2, v1 × v2], so R = [v1 v2 v1×v2] @ inv([d1 d2 d1×d2]) — the cross products as third columns "
                "make both matrices invertible")
    if np.linalg.det(R) < 0:
        return ("det R = -1 (a reflection): the third columns must be the cross products in the same order on both "
                "sides, d1 × d2 and v1 × v2")
    if _close(R, R_ref.T):
        return ("R is transposed: R maps the world triangle onto the camera one, R @ [d1 d2 d1×d2] = [v1 v2 v1×v2], "
                "so R = V @ inv(D), not D @ inv(V)")
    if _close(R, R_ref):
        C = -R_ref.T @ t_ref
        if _close(t, -t_ref):
            return "t has the wrong sign: λ1 y1 = R X1 + t, so t = λ1 y1 - R X1"
        if _close(t, C):
            return "you returned the camera centre C = -Rᵀt; the convention is x_cam = R X + t, so t = λ1 y1 - R X1"
        if any(_close(t, lam[k] * y[k] - R_ref @ X[j]) for k in range(3) for j in range(3) if j != k):
            return "t mixes two points: use the same one on both sides, t = λ1 y1 - R X1"
        return f"R is right but t is off by {np.linalg.norm(t - t_ref):.3g}: t = λ1 y1 - R X1 (x_cam = R X + t)"
    angle = float(np.degrees(np.linalg.norm(angle_axis_from_rotation(R @ R_ref.T))))
    if abs(angle - 180.0) < 1e-3:
        return ("R is off by a half turn: pair the edges in the same order on both sides — d1 = X1 - X2 goes with "
                "v1 = λ1 y1 - λ2 y2, d2 = X1 - X3 with v2 = λ1 y1 - λ3 y3")
    return (f"R is a rotation but {angle:.3g}° away from the right one: check that v1, v2 are the edges λ1 y1 - λ2 y2 "
            "and λ1 y1 - λ3 y3 and d1, d2 the world edges X1 - X2 and X1 - X3")


def pose_from_depths_reference(X, y, lam):
    """The reference of notebook 03's ``pose_from_depths(X, y, lam) -> (R, t)``: the pose putting each world point
    ``X[i]`` at ``lam[i] * y[i]`` in the camera (``x_cam = R X + t``), from the two congruent triangles,
    ``R [d1, d2, d1 × d2] = [v1, v2, v1 × v2]`` and ``t = λ1 y1 - R X1``.

    Examples
    --------
    >>> X, y, lam, R, t = _triangle(0)
    >>> R_, t_ = pose_from_depths_reference(X, y, lam)
    >>> bool(np.allclose(R_, R) and np.allclose(t_, t))
    True
    """
    X, y, lam = (np.asarray(a, float) for a in (X, y, lam))
    R = _build_R(X, y, lam)
    return R, lam[0] * y[0] - R @ X[0]


def check_pose_from_depths(pose_from_depths, verbose=True):
    """Self-check of ``pose_from_depths(X, y, lam) -> (R, t)``: the pose that puts each world point ``X[i]`` at
    ``lam[i] * y[i]`` in the camera frame (``x_cam = R X + t``), from two congruent triangles.

    Cases: a random triangle with exact depths, the four P3P solutions of the notebook's symmetric example (each
    set of depths gives its own pose), and a triangle far from the world origin (a large t).

    Examples
    --------
    >>> check_pose_from_depths(pose_from_depths_reference, verbose=False).passed
    True
    """
    def call(f, X, y, lam):
        return f(X.copy(), y.copy(), lam.copy())

    def random_triangle(f):
        X, y, lam, R, t = _triangle(0)
        return _diagnose_pose(call(f, X, y, lam), X, y, lam, R, t)

    def four(f):
        X, y, sols = _symmetric_example()
        for k, (R, t) in enumerate(sols):
            lam = np.linalg.norm(X @ R.T + t, axis=1)
            hint = _diagnose_pose(call(f, X, y, lam), X, y, lam, R, t)
            if hint is not None:
                return f"solution {k} of 4: {hint}"
        return None

    def far(f):
        X, y, lam, R, t = _triangle(2, offset=(40.0, -25.0, 12.0), distance=30.0)
        return _diagnose_pose(call(f, X, y, lam), X, y, lam, R, t)

    return run_checks("pose_from_depths", pose_from_depths, [
        ("a random triangle with exact depths: the true pose", random_triangle),
        ("the symmetric example: each of the four sets of depths gives its own pose", four),
        ("a triangle far from the world origin (a large t)", far),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: adaptive RANSAC
# ---------------------------------------------------------------------------------------------------------------


def _rng_used(rng, state):
    """Whether ``rng`` drew anything since its bit generator had ``state``."""
    return rng.bit_generator.state != state


def _line_data(seed, n=60, outlier_ratio=0.4):
    """Points on the line 0.5 x - y + 1 = 0 (exact) and outliers at least 0.5 away from it (threshold 0.1)."""
    rng = np.random.default_rng(seed)
    n_out = int(round(outlier_ratio * n))
    xs = rng.uniform(-5, 5, n)
    pts = np.column_stack([xs, 0.5 * xs + 1])
    off = rng.uniform(0.5, 3.0, n_out) * rng.choice([-1, 1], n_out)
    pts[:n_out, 1] += off / (2 / np.sqrt(5))          # vertical shift giving that distance from the line
    perm = rng.permutation(n)
    pts = pts[perm]
    inlier = perm >= n_out
    return pts, inlier


class _LineProblem:
    """fit / errors for lines through 2 points; records what the loop asked for."""

    def __init__(self, pts, decoy=False, degenerate=False):
        self.pts, self.decoy, self.degenerate = pts, decoy, degenerate
        self.samples, self.scored = [], []

    def fit(self, idx):
        idx = np.asarray(idx)
        self.samples.append(idx.copy())
        if idx.size != 2 or len(set(idx.tolist())) < 2:
            return []
        if self.degenerate and idx.min() % 2 == 0:
            return []                                  # a degenerate sample: no model
        p, q = self.pts[idx[0]], self.pts[idx[1]]
        n = np.array([q[1] - p[1], p[0] - q[0]])
        if np.linalg.norm(n) == 0:
            return []
        n = n / np.linalg.norm(n)
        line = ("line", n[0], n[1], -n @ p)
        if not self.decoy:
            return [line]
        m = np.array([n[1], -n[0]])                     # the perpendicular through p: a poor candidate first
        return [("decoy", m[0], m[1], -m @ p), line]

    def errors(self, model):
        self.scored.append(model[0])
        _, a, b, c = model
        return np.abs(self.pts @ [a, b] + c)


def _unpack(out, n):
    if not isinstance(out, tuple | list) or len(out) != 3:
        raise ValueError("adaptive_ransac must return a triple (model, inliers, n_iter)")
    model, inl, n_iter = out
    inl = np.asarray(inl)
    if inl.shape != (n,) or inl.dtype != bool:
        raise ValueError(f"inliers must be a boolean mask of shape ({n},), one entry per datum; got shape "
                         f"{inl.shape}, dtype {inl.dtype}")
    return model, inl, int(n_iter)


def _diagnose_line(out, pb, truth, rng, state):
    model, inl, n_iter = _unpack(out, len(truth))
    if not _rng_used(rng, state):
        return ("the rng argument was never used: draw every sample with it, e.g. rng.choice(n_data, sample_size, "
                "replace=False), so that a seed gives the same answer every run (no np.random.*)")
    if any(len(s) != 2 for s in pb.samples):
        return "a sample must have sample_size items (2 for a line, 3 for P3P)"
    if any(len(set(np.asarray(s).tolist())) < len(s) for s in pb.samples):
        return "a sample repeated a datum: draw without replacement, rng.choice(n_data, sample_size, replace=False)"
    if pb.decoy and "line" not in pb.scored:
        return ("only the first candidate of each sample was scored: fit returns a list of models (P3P gives up "
                "to four) — score every one of them")
    if np.array_equal(inl, truth):
        return None
    if inl.sum() <= 2:
        return (f"only {int(inl.sum())} inliers: an inlier is any datum whose error is below the threshold, "
                "np.asarray(errors(model)) < threshold, for the best model")
    if inl.sum() < truth.sum():
        return (f"{int(inl.sum())} inliers where the best line has {int(truth.sum())}: keep the candidate with the "
                "most inliers (compare counts, and replace the best model when a candidate beats it)")
    return (f"the inlier mask is not the best line's ({int((inl & ~truth).sum())} outliers in it, "
            f"{int((~inl & truth).sum())} inliers missing)")


def check_adaptive_ransac(adaptive_ransac, verbose=True):
    """Self-check of ``adaptive_ransac(n_data, sample_size, fit, errors, threshold, *, rng, confidence, max_iter)
    -> (model, inliers, n_iter)`` (H&Z Alg. 4.5).

    Cases: a line through 60 points with 40 % outliers (the line's inliers exactly), adaptive stopping
    (``N = log(1 - p) / log(1 - wˢ)`` lowered as the best model improves), several candidates per sample (all
    scored), degenerate samples (``fit`` returns an empty list), and P3P on a synthetic view with 30 % outliers.

    Examples
    --------
    >>> from labutils.core.ransac import ransac
    >>> check_adaptive_ransac(ransac, verbose=False).passed
    True
    """
    def line_case(decoy=False, degenerate=False, seed=0):
        def run(f):
            pts, truth = _line_data(seed)
            pb, rng = _LineProblem(pts, decoy=decoy, degenerate=degenerate), np.random.default_rng(seed + 100)
            state = rng.bit_generator.state
            try:
                out = f(len(pts), 2, pb.fit, pb.errors, 0.1, rng=rng, confidence=0.9999, max_iter=500)
            except IndexError as exc:
                if degenerate:
                    return (f"raised IndexError ({exc}): fit returns an empty list for a degenerate sample — loop "
                            "over its candidates (for model in fit(idx)) so that an empty list is skipped")
                raise
            return _diagnose_line(out, pb, truth, rng, state)
        return run

    def adaptive(f):
        pts, truth = _line_data(1)
        pb, rng = _LineProblem(pts), np.random.default_rng(7)
        state = rng.bit_generator.state
        out = f(len(pts), 2, pb.fit, pb.errors, 0.1, rng=rng, confidence=0.9999, max_iter=500)
        hint = _diagnose_line(out, pb, truth, rng, state)
        if hint is not None:
            return hint
        n_iter = _unpack(out, len(truth))[2]
        w = truth.mean()
        needed = ransac_iterations(w, 2, 0.9999)
        if n_iter != len(pb.samples):
            return f"n_iter = {n_iter} but {len(pb.samples)} samples were drawn: return the number of samples drawn"
        if n_iter >= 500:
            return ("the loop drew all max_iter = 500 samples: it is not adaptive — each time a better model is "
                    f"found set N = log(1 - p) / log(1 - wˢ) (w its inlier ratio; here N = {needed}) and stop once "
                    "that many samples are drawn")
        if n_iter < needed:
            if n_iter <= ransac_iterations(w, 1, 0.9999):
                return (f"stopped after {n_iter} samples, but {needed} are needed at w = {w:.2f}: a sample is all "
                        "inliers with probability wˢ (s = sample_size), not w")
            return (f"stopped after {n_iter} samples, but N = log(1 - p) / log(1 - wˢ) = {needed} at w = {w:.2f}, "
                    "p = confidence")
        if n_iter > 3 * needed + 20:
            return (f"{n_iter} samples where N = {needed} suffice at w = {w:.2f}: recompute N each time the best model "
                    "improves, and stop as soon as the count reaches it")
        return None

    def pnp(f):
        rng_scene = np.random.default_rng(3)
        s = make_scene(80, 2, noise_px=0.5, rng=rng_scene)
        X, x = s.X, s.x_meas[0].copy()
        out_mask = np.zeros(len(X), bool)
        out_mask[rng_scene.choice(len(X), 24, replace=False)] = True
        x[out_mask] = rng_scene.uniform([0, 0], s.image_size, size=(24, 2))
        y = bearings(x, s.K)

        def fit(idx):
            try:
                return p3p_bearings(X[idx], y[idx])
            except ValueError:
                return []

        res = f(len(X), 3, fit, lambda m: reprojection_errors(X, x, s.K, *m), 2.0, rng=np.random.default_rng(5),
                confidence=0.9999, max_iter=500)
        _, inl, _ = _unpack(res, len(X))
        recall = (inl & ~out_mask).sum() / (~out_mask).sum()
        if (inl & out_mask).any() or recall < 0.9:
            return (f"on a P3P problem the inliers hold {int((inl & out_mask).sum())} outliers and "
                    f"{recall:.0%} of the inliers: score every candidate pose by its inlier count and keep the best")
        return None

    return run_checks("adaptive_ransac", adaptive_ransac, [
        ("a line through 60 points, 40 % outliers: the line's inliers", line_case()),
        ("adaptive stopping: N = log(1 - p) / log(1 - wˢ), lowered as the best model improves", adaptive),
        ("several candidates per sample (P3P gives up to four): every one scored", line_case(decoy=True, seed=2)),
        ("degenerate samples: fit returns an empty list", line_case(degenerate=True, seed=3)),
        ("P3P on a synthetic view, 30 % outliers, 0.5 px noise", pnp),
    ], verbose=verbose)


def p3p_ransac_inliers(adaptive_ransac, X, x, K, threshold_px, *, seed=1):
    """The inliers that a student's ``adaptive_ransac`` finds with P3P on the correspondences ``X (N, 3)``, ``x (N,
    2)`` (calibration ``K``), drawing from a generator of its own (``seed``): for a hidden test on the notebook's
    data that leaves the notebook's random stream alone.

    Examples
    --------
    >>> from labutils.core.ransac import ransac
    >>> s = make_scene(40, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> bool(p3p_ransac_inliers(ransac, s.X, s.x_true[0], s.K, 2.0).all())
    True
    """
    y = bearings(x, K)

    def fit(idx):
        try:
            return p3p_bearings(X[idx], y[idx])
        except ValueError:
            return []

    _, inliers, _ = adaptive_ransac(len(X), 3, fit, lambda m: reprojection_errors(X, x, K, *m), threshold_px,
                                    rng=np.random.default_rng(seed), confidence=0.9999, max_iter=10000)
    return np.asarray(inliers, bool)
