"""Self-checks of notebook 02 (the essential matrix and the relative pose): the four poses of E, the cheirality
choice, and linear (DLT) triangulation.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (a reflection instead of a rotation, t from V instead of U,
only camera 1 checked for depth, the homogeneous point not divided by its last coordinate ...).
"""
import numpy as np

from ..core.geometry import relative_pose, rotation_from_angle_axis, skew
from ..core.synthetic import make_scene
from ..twoview.essential import decompose_essential
from ..twoview.triangulation import triangulate
from .runner import run_checks

W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the four poses of E
# ---------------------------------------------------------------------------------------------------------------

def _as_poses(poses):
    """The student's answer as a list of (R (3, 3), t (3,)) or a ValueError saying what is wrong with its form."""
    try:
        poses = list(poses)
    except TypeError:
        raise ValueError("four_poses must return a list of four (R, t) pairs") from None
    if len(poses) != 4:
        raise ValueError(f"four_poses must return four (R, t) pairs; it returned {len(poses)}")
    out = []
    for k, pose in enumerate(poses):
        if len(pose) != 2:
            raise ValueError(f"pose {k} must be a pair (R, t)")
        R, t = np.asarray(pose[0], float), np.asarray(pose[1], float)
        if R.shape != (3, 3):
            raise ValueError(f"R of pose {k} must have shape (3, 3); it has {R.shape}")
        if t.shape != (3,):
            raise ValueError(f"t of pose {k} must have shape (3,); it has {t.shape} (use U[:, 2], not U[:, 2:])")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise ValueError(f"pose {k} has NaN or inf entries")
        out.append((R, t))
    return out


def _same_set(poses, ref, tol=1e-8):
    """Whether two lists of poses hold the same four (R, t), in any order."""
    return all(any(np.abs(R - Rr).max() < tol and np.abs(t - tr).max() < tol for R, t in poses) for Rr, tr in ref)


def _svd_variants(E):
    """Typical wrong decompositions of E, each with its hint."""
    U, _, Vt = np.linalg.svd(E)
    Up = U * np.sign(np.linalg.det(U))
    Vtp = Vt * np.sign(np.linalg.det(Vt))
    u3 = Up[:, 2]
    v3 = Vtp[2]
    return [
        ([(Up @ W @ Vtp.T, u3), (Up @ W @ Vtp.T, -u3), (Up @ W.T @ Vtp.T, u3), (Up @ W.T @ Vtp.T, -u3)],
         "R = U W Vᵀ, and np.linalg.svd already returns Vᵀ (Vt): use U @ W @ Vt, without transposing Vt again"),
        ([(Up @ W @ Vtp, v3), (Up @ W @ Vtp, -v3), (Up @ W.T @ Vtp, v3), (Up @ W.T @ Vtp, -v3)],
         "t is ±u3, the last column of U: tᵀ E = tᵀ [t]× R = 0, so t is E's *left* null vector; you used the last "
         "row of Vᵀ, the right null vector"),
        ([(Up @ W @ Vtp, u3), (Up @ W @ Vtp, -u3), (Up @ W @ Vtp, u3), (Up @ W @ Vtp, -u3)],
         "the two rotations are U W Vᵀ and U Wᵀ Vᵀ (the twisted pair): you have the same rotation twice"),
        ([(Up @ W @ Vtp, u3), (Up @ W @ Vtp, u3), (Up @ W.T @ Vtp, u3), (Up @ W.T @ Vtp, u3)],
         "each rotation goes with both signs of t: (R, u3) and (R, -u3)"),
    ]


def _diagnose_poses(poses, E):
    poses = _as_poses(poses)
    ref = decompose_essential(E)
    if _same_set(poses, ref):
        return None
    for R, _ in poses:
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-6:
            return ("R is not a rotation (Rᵀ R ≠ I): R = U W Vᵀ with W = [[0, -1, 0], [1, 0, 0], [0, 0, 1]] and no "
                    "singular values in it")
    for R, _ in poses:
        if np.linalg.det(R) < 0:
            return ("some R has det -1 (a reflection, not a rotation): U and Vᵀ from the SVD can have det -1 — flip "
                    "the sign of U (or of Vᵀ) when its determinant is negative; E is defined up to sign anyway")
    for _, t in poses:
        if abs(np.linalg.norm(t) - 1) > 1e-6:
            return f"t must be a unit vector (±u3, the last column of U); yours has length {np.linalg.norm(t):.4g}"
    for wrong, hint in _svd_variants(E):
        if _same_set(poses, wrong):
            return hint
    E_pose = [skew(t) @ R for R, t in poses]
    off = max(min(np.abs(Ep / np.linalg.norm(Ep) - s * E / np.linalg.norm(E)).max() for s in (1, -1)) for Ep in E_pose)
    return (f"your poses do not reproduce E ([t]× R differs from E by up to {off:.2g} after scaling): with "
            "E = U diag(1, 1, 0) Vᵀ (U, Vᵀ with det +1), R ∈ {U W Vᵀ, U Wᵀ Vᵀ} and t = ±u3")


def _essential(seed, scale=1.0):
    rng = np.random.default_rng(seed)
    R = rotation_from_angle_axis(rng.normal(scale=0.4, size=3))
    t = rng.normal(size=3)
    return scale * skew(t) @ R, R, t / np.linalg.norm(t)


def check_four_poses(four_poses, verbose=True):
    """Self-check of ``four_poses(E) -> [(R, t), ...]`` (H&Z Result 9.19).

    Cases: one E = [t]× R (the true pose is among the four), ten E of either sign (the SVD's U and V are often
    reflections: they must be made rotations), and an E of arbitrary scale (t still a unit vector). The order of
    the four poses does not matter.

    Examples
    --------
    >>> check_four_poses(decompose_essential, verbose=False).passed
    True
    """
    def one(f):
        E, R, t = _essential(0)
        poses = _as_poses(f(E.copy()))
        hint = _diagnose_poses(poses, E)
        if hint is None and not any(np.allclose(Rk, R, atol=1e-8) and np.allclose(tk, t, atol=1e-8)
                                    for Rk, tk in poses):
            hint = "the true pose (R, t / |t|) is not among your four"
        return hint

    def signs(f):
        for k in range(10):
            E = _essential(10 + k)[0] * (-1) ** k
            hint = _diagnose_poses(f(E.copy()), E)
            if hint is not None:
                return f"E number {k}: {hint}"
        return None

    def scaled(f):
        E = _essential(30, scale=37.0)[0]
        return _diagnose_poses(f(E.copy()), E)

    return run_checks("four_poses", four_poses, [
        ("E = [t]× R: the true pose is one of the four", one),
        ("ten E of either sign: every R a rotation (det +1)", signs),
        ("E scaled by 37: t still a unit vector", scaled),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the cheirality choice
# ---------------------------------------------------------------------------------------------------------------

P1 = np.hstack([np.eye(3), np.zeros((3, 1))])


def _depths(poses, y1, y2):
    """For each pose: the depths of the triangulated points in camera 1 and in camera 2 (and without t)."""
    out = []
    for R, t in poses:
        X = triangulate(P1, np.hstack([R, t[:, None]]), y1, y2)
        out.append((X[:, 2], X @ R[2] + t[2], X @ R[2]))
    return out


def _normalised_pair(seed, noise_px=0.0, layout="general", n=40, mismatched=0):
    s = make_scene(n, 2, layout=layout, noise_px=noise_px, rng=np.random.default_rng(seed))
    x1, x2, _ = s.pair(0, 1, which="true" if noise_px == 0 else "meas")
    if mismatched:
        x2 = x2.copy()
        x2[:mismatched] = x2[np.roll(np.arange(mismatched), 1)]
    Kinv = np.linalg.inv(s.K)
    y1 = x1 @ Kinv[:2, :2].T + Kinv[:2, 2]
    y2 = x2 @ Kinv[:2, :2].T + Kinv[:2, 2]
    R, t = relative_pose(s.R[0], s.t[0], s.R[1], s.t[1])
    return y1, y2, R, t / np.linalg.norm(t)


def _which(answer, poses):
    """Index of the student's (R, t) among the candidate poses, or a ValueError."""
    if answer is None or not hasattr(answer, "__len__") or len(answer) != 2:
        raise ValueError(f"choose_pose must return one pose, a pair (R, t); it returned {type(answer).__name__}")
    R, t = np.asarray(answer[0], float), np.asarray(answer[1], float)
    if R.shape != (3, 3) or t.shape != (3,):
        raise ValueError(f"choose_pose must return (R (3, 3), t (3,)); it returned shapes {R.shape} and {t.shape}")
    for k, (Rk, tk) in enumerate(poses):
        if np.abs(R - Rk).max() < 1e-9 and np.abs(t - tk).max() < 1e-9:
            return k
    raise ValueError("choose_pose must return one of the candidate poses it is given, unchanged")


def _diagnose_choice(k, poses, y1, y2):
    d = _depths(poses, y1, y2)
    both = [int(np.sum((z1 > 0) & (z2 > 0))) for z1, z2, _ in d]
    if k == int(np.argmax(both)):
        return None
    one = [int(np.sum(z1 > 0)) for z1, _, _ in d]
    no_t = [int(np.sum((z1 > 0) & (z2 > 0))) for z1, _, z2 in d]
    camera_1_only, without_t = one[k] == max(one), no_t[k] == max(no_t)
    if camera_1_only and without_t:
        return ("the points must be in front of camera 2 too, and its depth is the z of R X + t: check camera 2, "
                "with t (camera 1 alone, or camera 2's depth without t, lets the twisted pose win here)")
    if camera_1_only:
        return ("you only checked camera 1 (X_z > 0): the twisted pose can put the points in front of camera 1 too; "
                "the winner must also have them in front of camera 2, (R X + t)_z > 0")
    if without_t:
        return "the depth in camera 2 is the z of R X + t: you left out t"
    return (f"points in front of both cameras for each candidate: {both}; you chose candidate {k} "
            f"({both[k]} in front): choose the one with the most")


def check_choose_pose(choose_pose, verbose=True):
    """Self-check of ``choose_pose(poses, y1, y2) -> (R, t)`` (cheirality, H&Z Sec. 9.6.3).

    ``poses`` are the four candidates, ``y1, y2`` normalised image points ``K⁻¹ x``. Cases: noise-free points with
    the candidates in the order of :func:`decompose_essential`, the same with the order changed (a wrong test can
    be lucky with one order), forward motion (where the twisted candidate puts every point in front of camera 1),
    and noisy points with a few mismatched pairs (no candidate has *every* point in front: the one with the most
    wins).

    Examples
    --------
    >>> def reference(poses, y1, y2):
    ...     counts = [np.sum((z1 > 0) & (z2 > 0)) for z1, z2, _ in _depths(poses, y1, y2)]
    ...     return poses[int(np.argmax(counts))]
    >>> check_choose_pose(reference, verbose=False).passed
    True
    """
    def run(seed, layout="general", order=None, noise_px=0.0, mismatched=0):
        def case(f):
            y1, y2, R, t = _normalised_pair(seed, noise_px, layout, mismatched=mismatched)
            poses = decompose_essential(skew(t) @ R)
            if order == "camera 1 first":        # the candidates with as many points in front of camera 1 first
                d = _depths(poses, y1, y2)
                good = int(np.argmax([np.sum((a > 0) & (b > 0)) for a, b, _ in d]))
                ties = [k for k in range(4) if k != good and np.sum(d[k][0] > 0) >= np.sum(d[good][0] > 0)]
                poses = [poses[k] for k in ties + [k for k in range(4) if k not in ties and k != good] + [good]]
            if order == "reversed":
                poses = poses[::-1]
            try:
                answer = f([(R_.copy(), t_.copy()) for R_, t_ in poses], y1.copy(), y2.copy())
            except NotImplementedError:
                raise
            except Exception as exc:
                if not mismatched:
                    raise
                answer, failure = None, f" (your function raised {type(exc).__name__})"
            else:
                failure = " (your function returned None)"
            if answer is None and mismatched:
                return ("with noise or mismatched pairs no candidate may have *every* point in front of both cameras: "
                        "choose the candidate with the most points in front" + failure)
            return _diagnose_choice(_which(answer, poses), poses, y1, y2)
        return case

    return run_checks("choose_pose", choose_pose, [
        ("noise-free points, the candidates of decompose_essential", run(0)),
        ("another scene", run(3)),
        ("a third scene, the candidates in reverse order", run(4, order="reversed")),
        ("forward motion, the twisted candidate (in front of camera 1) listed first",
         run(2, "forward", order="camera 1 first")),
        ("forward motion, 1 px of noise and 4 mismatched pairs: not every point can be in front",
         run(0, "forward", noise_px=1.0, mismatched=4)),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: linear (DLT) triangulation
# ---------------------------------------------------------------------------------------------------------------

def _dlt(P1, P2, x1, x2, rows="right", unit_rows=True, vector=-1, dehom=True):
    """Linear triangulation and its typical wrong variants."""
    out = []
    for a, b in zip(x1, x2):
        if rows == "right":
            A = np.array([a[0] * P1[2] - P1[0], a[1] * P1[2] - P1[1], b[0] * P2[2] - P2[0], b[1] * P2[2] - P2[1]])
        elif rows == "swapped":
            A = np.array([a[0] * P1[2] - P1[1], a[1] * P1[2] - P1[0], b[0] * P2[2] - P2[1], b[1] * P2[2] - P2[0]])
        else:                                                    # camera 1 for both views
            A = np.array([a[0] * P1[2] - P1[0], a[1] * P1[2] - P1[1], b[0] * P1[2] - P1[0], b[1] * P1[2] - P1[1]])
        if unit_rows:
            A = A / np.linalg.norm(A, axis=1, keepdims=True)
        X_h = np.linalg.svd(A)[2][vector]
        out.append(X_h[:3] / X_h[3] if dehom else X_h[:3])
    return np.array(out)


def _diagnose_X(X, P1, P2, x1, x2, X_true=None):
    X = np.asarray(X, float)
    n = len(x1)
    if X.shape == (n, 4):
        return "X must have shape (N, 3): divide the homogeneous X_h by its 4th coordinate and drop it"
    if X.shape != (n, 3):
        return f"triangulate_linear must return shape ({n}, 3), one point per row; it returned {X.shape}"
    if not np.all(np.isfinite(X)):
        return "triangulate_linear returned NaN or inf"
    size = max(1.0, np.abs(triangulate(P1, P2, x1, x2)).max())

    def close(Y):
        return np.abs(X - Y).max() < 1e-6 * size

    if close(_dlt(P1, P2, x1, x2)) or close(_dlt(P1, P2, x1, x2, unit_rows=False)):
        return None
    variants = [
        (dict(dehom=False), "divide X_h by its 4th coordinate: X = X_h[:3] / X_h[3]"),
        (dict(rows="swapped"), "the rows are x·P[2] − P[0] and y·P[2] − P[1] (H&Z Sec. 12.2): x goes with the first "
                               "row of P, y with the second"),
        (dict(rows="camera 1"), "you used camera 1's P for both views: the last two rows come from P2 and x2"),
        (dict(vector=0), "X_h minimises ‖A X_h‖: the *last* row of Vᵀ, the singular vector of the smallest "
                         "singular value"),
    ]
    for kwargs, hint in variants:
        for unit_rows in (True, False):
            if close(_dlt(P1, P2, x1, x2, unit_rows=unit_rows, **kwargs)):
                return hint
    if X_true is not None:
        return (f"the points are off by up to {np.abs(X - X_true).max():.3g} on noise-free data: for each "
                "correspondence stack the four rows x1·P1[2] − P1[0], y1·P1[2] − P1[1], x2·P2[2] − P2[0], "
                "y2·P2[2] − P2[1], take the last row of Vᵀ, divide by its 4th entry")
    return "the points differ from the linear triangulation (DLT) of H&Z Sec. 12.2"


def check_triangulate_linear(triangulate_linear, verbose=True):
    """Self-check of ``triangulate_linear(P1, P2, x1, x2) -> X`` (H&Z Sec. 12.2).

    Cases: noise-free pixels (the true points), noisy pixels (the DLT's answer, with or without rows scaled to unit
    norm), normalised coordinates with ``[I | 0]`` and ``[R | t]`` (as the cheirality test uses it), and a single
    point.

    Examples
    --------
    >>> check_triangulate_linear(triangulate, verbose=False).passed
    True
    """
    def scene_case(seed, noise_px, n=30, normalised=False):
        def case(f):
            s = make_scene(n, 2, noise_px=noise_px, rng=np.random.default_rng(seed))
            x1, x2, idx = s.pair(0, 1, which="true" if noise_px == 0 else "meas")
            P1_, P2_ = s.P[0], s.P[1]
            X_true = s.X[idx]
            if normalised:
                Kinv = np.linalg.inv(s.K)
                x1 = x1 @ Kinv[:2, :2].T + Kinv[:2, 2]
                x2 = x2 @ Kinv[:2, :2].T + Kinv[:2, 2]
                P1_, P2_ = Kinv @ P1_, Kinv @ P2_
            X = f(P1_.copy(), P2_.copy(), x1.copy(), x2.copy())
            if noise_px == 0:
                Xa = np.asarray(X, float)
                if Xa.shape == X_true.shape and np.all(np.isfinite(Xa)) and np.abs(Xa - X_true).max() < 1e-8:
                    return None
                return _diagnose_X(X, P1_, P2_, x1, x2, X_true)
            return _diagnose_X(X, P1_, P2_, x1, x2)
        return case

    return run_checks("triangulate_linear", triangulate_linear, [
        ("noise-free pixels: the true points", scene_case(0, 0.0)),
        ("1 px of noise: the DLT's points", scene_case(1, 1.0)),
        ("normalised coordinates, cameras K⁻¹P", scene_case(2, 0.0, normalised=True)),
        ("a single point: shape (1, 3)", scene_case(3, 0.5, n=1)),
    ], verbose=verbose)
