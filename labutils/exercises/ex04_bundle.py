"""Self-checks of notebook 04 (bundle adjustment): the projection Jacobian, the Jacobian's sparsity mask, one
damped Schur-complement step and the Levenberg–Marquardt loop around it.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (J_l(ω) left out, [X]× instead of [RX]×, K's skew dropped,
the point block missing from the mask, Levenberg's μI instead of Marquardt's μ·diag, V inverted as a diagonal ...).
"""
import numpy as np
import scipy.sparse as sp

from ..bundle.reprojection import (
    camera_params_from_Rt,
    jacobian_sparsity,
    project_observations,
    reprojection_jacobian,
    reprojection_residuals,
)
from ..bundle.schur import levenberg_marquardt as _library_lm
from ..bundle.schur import schur_step as _library_schur_step
from ..core.geometry import left_jacobian_so3, rotation_from_angle_axis, skew
from ..core.scene import observations
from ..core.synthetic import DEFAULT_K, make_scene, perturb_cameras
from .runner import run_checks

K_SKEW = np.array([[1500.0, -60.0, 350.0], [0.0, 1480.0, 300.0], [0.0, 0.0, 1.0]])


def _problem(seed, n_points=10, n_views=3, K=DEFAULT_K, rot_scale=None, spread=0.1):
    """A small scene away from its optimum; ``rot_scale`` sets |ω| of every camera (0: the identity rotation)."""
    rng = np.random.default_rng(seed)
    s = make_scene(n_points, n_views, noise_px=1.0, rng=rng, K=K)
    ci, pi, x = observations(s.x_meas)
    cp = camera_params_from_Rt(s.R, s.t) + spread * rng.normal(size=(n_views, 6))
    if rot_scale is not None:
        if rot_scale == 0:
            R = np.stack([np.eye(3)] * n_views)
            cp = np.hstack([np.zeros((n_views, 3)), -np.einsum("vij,j->vi", R, s.X.mean(0)) + [0, 0, 4]])
        else:
            w = rng.normal(size=(n_views, 3))
            cp[:, :3] = rot_scale * w / np.linalg.norm(w, axis=1, keepdims=True)
            Rs = rotation_from_angle_axis(cp[:, :3])
            cp[:, 3:] = -np.einsum("vij,j->vi", Rs, s.X.mean(0)) + [0, 0, 4]
    X = s.X + 0.02 * rng.normal(size=s.X.shape)
    return cp, X, ci, pi, x, s.K


# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the projection Jacobian
# ---------------------------------------------------------------------------------------------------------------


def _jacobian_parts(cp, X, ci, pi, K):
    """The pieces of the chain rule per observation: R, RX, P, du/dP (and its variants), J_l."""
    w = cp[ci, :3]
    R = rotation_from_angle_axis(w)
    RX = np.einsum("nij,nj->ni", R, X[pi])
    P = RX + cp[ci, 3:6]
    z = P[:, 2]
    dn = np.zeros((len(P), 2, 3))
    dn[:, 0, 0] = dn[:, 1, 1] = 1 / z
    dn[:, :, 2] = -P[:, :2] / z[:, None] ** 2
    return dict(R=R, RX=RX, P=P, dn=dn, du=K[:2, :2] @ dn, Jl=left_jacobian_so3(w), X=X[pi])


def _jacobian_variants(parts, K):
    """Typical wrong (Jc, Jp), each with its hint."""
    R, RX, P, dn, du, Jl = (parts[k] for k in ("R", "RX", "P", "dn", "du", "Jl"))
    rot = -du @ skew(RX)
    out = []

    def jc(rot_block, trans_block=du):
        return np.concatenate([rot_block, trans_block], axis=2)
    out.append((jc(rot), du @ R,
                "the rotation block is missing J_l(ω): -[RX]× is the derivative for a small rotation applied on the "
                "left, exp([δ]×) R; the parameters are ω itself, so ∂P/∂ω = -[RX]× J_l(ω) (the two agree only at "
                "ω = 0, notebook 03's case)"))
    out.append((jc(rot @ np.swapaxes(Jl, 1, 2)), du @ R,
                "you used the right Jacobian J_r(ω) = J_l(ω)ᵀ: changing ω rotates the camera on the left, "
                "∂P/∂ω = -[RX]× J_l(ω)"))
    out.append((jc(-rot @ Jl), du @ R, "the rotation block has the wrong sign: ∂(RX)/∂ω = -[RX]× J_l(ω)"))
    out.append((jc(-du @ skew(parts["X"]) @ Jl), du @ R,
                "the rotation block uses [X]×: it is [R X]× (the point rotated into the camera), -[RX]× J_l(ω)"))
    out.append((jc(-du @ skew(P) @ Jl), du @ R,
                "the rotation block uses [RX + t]×: t does not rotate, so it is -[R X]× J_l(ω)"))
    out.append((np.concatenate([du, -du @ skew(RX) @ Jl], axis=2), du @ R,
                "the camera columns are in the wrong order: ω first (columns 0-2), then t (columns 3-5)"))
    out.append((jc(rot @ Jl), du,
                "∂P/∂X = R: the point block is ∂u/∂P @ R, not ∂u/∂P"))
    out.append((jc(rot @ Jl), -du @ R, "the point block has the wrong sign: ∂u/∂X = ∂u/∂P @ R"))
    dn_only = jc(-dn @ skew(RX) @ Jl, dn), dn @ R
    out.append((*dn_only, "∂u/∂P is missing K: u = K[:2, :2] (P1/P3, P2/P3) + K[:2, 2], so ∂u/∂P = K[:2, :2] @ "
                          "[[1/z, 0, -x/z²], [0, 1/z, -y/z²]]"))
    Kd = np.diag(np.diag(K[:2, :2]))
    dud = Kd @ dn
    out.append((jc(-dud @ skew(RX) @ Jl, dud), dud @ R,
                "K's skew K[0, 1] is missing: use the full 2×2 block K[:2, :2], not only fx and fy"))
    dn1 = dn.copy()
    dn1[:, :, 2] = -P[:, :2] / P[:, 2:3]
    du1 = K[:2, :2] @ dn1
    out.append((jc(-du1 @ skew(RX) @ Jl, du1), du1 @ R,
                "the z column of ∂(x/z, y/z)/∂P is -x/z², -y/z² (you have -x/z, -y/z)"))
    return out


def _diagnose_jacobian(out, cp, X, ci, pi, K):
    if not isinstance(out, tuple | list) or len(out) != 2:
        return "projection_jacobian must return a pair (Jc, Jp): the camera and point blocks of every observation"
    Jc, Jp = (np.asarray(a, float) for a in out)
    n = len(ci)
    if Jc.shape != (n, 2, 6) or Jp.shape != (n, 2, 3):
        return (f"Jc must have shape ({n}, 2, 6) and Jp ({n}, 2, 3) (one 2×6 and one 2×3 block per observation); got "
                f"{Jc.shape} and {Jp.shape}")
    if not (np.all(np.isfinite(Jc)) and np.all(np.isfinite(Jp))):
        return "Jc or Jp has NaN or inf entries"
    _, Jc_ref, Jp_ref = project_observations(cp, X, ci, pi, np.broadcast_to(K, (len(cp), 3, 3)), jac=True)
    scale = max(np.abs(Jc_ref).max(), np.abs(Jp_ref).max())

    def close(A, B):
        return np.abs(A - B).max() <= 1e-7 * scale

    if close(Jc, Jc_ref) and close(Jp, Jp_ref):
        return None
    for Jc_w, Jp_w, hint in _jacobian_variants(_jacobian_parts(cp, X, ci, pi, K), K):
        if close(Jc, Jc_w) and close(Jp, Jp_w):
            return hint
    bad = [name for name, A, B in (("ω", Jc[:, :, :3], Jc_ref[:, :, :3]), ("t", Jc[:, :, 3:], Jc_ref[:, :, 3:]),
                                   ("X", Jp, Jp_ref)) if not close(A, B)]
    return (f"the {', '.join(bad)} block(s) differ from the derivative (finite differences agree with the library's): "
            "∂u/∂P = K[:2, :2] @ [[1/z, 0, -x/z²], [0, 1/z, -y/z²]], then ∂P/∂ω = -[RX]× J_l(ω), ∂P/∂t = I, "
            "∂P/∂X = R")


def _fd_check(Jc, Jp, cp, X, ci, pi, x, K):
    """Largest difference between the blocks and central differences of the residuals, relative."""
    V, M = len(cp), len(X)

    def res(p):
        return reprojection_residuals(p[:6 * V].reshape(V, 6), p[6 * V:].reshape(M, 3), ci, pi, x, K)
    p0 = np.concatenate([cp.ravel(), X.ravel()])
    fd = np.stack([(res(p0 + 1e-6 * e) - res(p0 - 1e-6 * e)) / 2e-6 for e in np.eye(p0.size)], axis=1)
    J = np.zeros_like(fd)
    rows = np.arange(len(ci))
    for a in range(2):
        for j in range(6):
            J[2 * rows + a, 6 * ci + j] = Jc[:, a, j]
        for j in range(3):
            J[2 * rows + a, 6 * V + 3 * pi + j] = Jp[:, a, j]
    return float(np.abs(J - fd).max() / np.abs(fd).max())


def check_projection_jacobian(projection_jacobian, verbose=True):
    """Self-check of ``projection_jacobian(camera_params, points_3d, camera_indices, point_indices, K) -> (Jc, Jp)``:
    the 2×6 camera block and the 2×3 point block of the reprojection residual's Jacobian, per observation.

    Cases: finite differences on a small scene with rotations of about 0.5 rad, cameras with ω = 0 (where
    ``J_l = I``, notebook 03's case), and a calibration with skew (like the dinosaur's).

    Examples
    --------
    >>> def library(cp, X, ci, pi, K):
    ...     return project_observations(cp, X, ci, pi, np.broadcast_to(K, (len(cp), 3, 3)), jac=True)[1:]
    >>> check_projection_jacobian(library, verbose=False).passed
    True
    """
    def case(seed, K=DEFAULT_K, rot_scale=None, fd=False):
        def run(f):
            cp, X, ci, pi, x, K_ = _problem(seed, K=K, rot_scale=rot_scale)
            out = f(cp.copy(), X.copy(), ci.copy(), pi.copy(), K_.copy())
            hint = _diagnose_jacobian(out, cp, X, ci, pi, K_)
            if hint is None and fd:
                err = _fd_check(*(np.asarray(a, float) for a in out), cp, X, ci, pi, x, K_)
                if err > 1e-6:
                    return f"the blocks differ from central differences by {err:.1e} (relative)"
            return hint
        return run

    return run_checks("projection_jacobian", projection_jacobian, [
        ("central differences, rotations of 0.5 rad", case(0, rot_scale=0.5, fd=True)),
        ("ω = 0 for every camera (J_l = I: notebook 03's case)", case(1, rot_scale=0.0)),
        ("a calibration with skew (like the dinosaur's K)", case(2, K=K_SKEW, rot_scale=1.0)),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the sparsity mask
# ---------------------------------------------------------------------------------------------------------------


def _as_dense_mask(A):
    if sp.issparse(A):
        A = A.toarray()
    A = np.asarray(A)
    if A.dtype.kind not in "biuf":
        raise ValueError(f"sparsity_mask must return a numeric or boolean array; got dtype {A.dtype}")
    return A != 0


def _diagnose_mask(A, V, M, ci, pi):
    ref = jacobian_sparsity(V, M, ci, pi).toarray() != 0
    n = len(ci)
    if A.shape != ref.shape:
        if A.shape == (n, ref.shape[1]):
            return "one row per observation: each observation has two residuals (x and y), rows 2i and 2i + 1"
        if A.shape[0] == ref.shape[0] and A.shape[1] == 6 * (ci.max() + 1) + 3 * (pi.max() + 1) != ref.shape[1]:
            return ("the shape comes from the indices: use n_cameras and n_points (a camera or point may have no "
                    "observation and still has its columns)")
        if A.shape[0] == ref.shape[0] and A.shape[1] == 3 * V + 3 * M:
            return "each camera has 6 columns (ω and t), each point 3"
        return f"the mask must have shape (2 n_obs, 6 n_cameras + 3 n_points) = {ref.shape}; got {A.shape}"
    if np.array_equal(A, ref):
        return None
    cam, pts = A[:, :6 * V], A[:, 6 * V:]
    ref_cam, ref_pts = ref[:, :6 * V], ref[:, 6 * V:]
    if np.array_equal(cam, ref_cam) and not pts.any():
        return ("the point columns are empty: each row also depends on its point's 3 columns, "
                "6·n_cameras + 3·p + (0, 1, 2)")
    if np.array_equal(pts, ref_pts) and not cam.any():
        return "the camera columns are empty: each row depends on its camera's 6 columns, 6·c + (0 … 5)"
    swapped = np.hstack([ref[:, 6 * V:6 * V + 3 * M], ref[:, :6 * V]])
    if A.shape[1] == swapped.shape[1] and np.array_equal(A, swapped):
        return "cameras come first: columns 6·c … 6·c + 5 for camera c, then 3 per point from column 6·n_cameras"
    if np.array_equal(A[0::2], ref[0::2]) != np.array_equal(A[1::2], ref[1::2]):
        return "both rows of an observation (2i for x, 2i + 1 for y) depend on the same camera and point"
    missing, extra = ~A & ref, A & ~ref
    if missing[:, :6 * V].sum() == 0 and missing.any() and extra.any() and not extra[:, 3 * M:].any():
        return ("the point columns are missing their offset: point p's columns come after all 6·n_cameras camera "
                "columns, 6·n_cameras + 3·p + (0, 1, 2), not 3·p + (0, 1, 2)")
    if (A & ~ref).any() and not (~A & ref).any():
        return (f"{int((A & ~ref).sum())} entries too many: a row has exactly 9 non-zeros (its camera's 6, its "
                "point's 3); a mask that is too full costs scipy extra finite differences")
    return (f"{int((A & ~ref).sum())} entries too many and {int((~A & ref).sum())} missing: row 2i and 2i + 1 "
            "(observation i) have ones in columns 6·c + (0 … 5) and 6·n_cameras + 3·p + (0, 1, 2), with c, p the "
            "camera and point of observation i")


def check_sparsity_mask(sparsity_mask, verbose=True):
    """Self-check of ``sparsity_mask(n_cameras, n_points, camera_indices, point_indices) -> A``: the
    ``(2 n_obs, 6 n_cameras + 3 n_points)`` mask of where the bundle-adjustment Jacobian can be non-zero (a
    boolean or 0/1 array, dense or scipy.sparse).

    Cases: two cameras and three points, a turntable scene, and a camera and a point without observations.

    Examples
    --------
    >>> check_sparsity_mask(jacobian_sparsity, verbose=False).passed
    True
    """
    def run_case(V, M, ci, pi):
        def run(f):
            A = _as_dense_mask(f(V, M, np.asarray(ci).copy(), np.asarray(pi).copy()))
            return _diagnose_mask(A, V, M, np.asarray(ci), np.asarray(pi))
        return run

    tt = make_scene(60, 6, layout="turntable", noise_px=0.0, rng=np.random.default_rng(4))
    ci_t, pi_t, _ = observations(tt.x_true)
    return run_checks("sparsity_mask", sparsity_mask, [
        ("two cameras, three points", run_case(2, 3, [0, 1, 1, 0], [0, 1, 2, 2])),
        ("a turntable scene (each point seen by a few views)", run_case(tt.n_views, tt.n_points, ci_t, pi_t)),
        ("a camera and a point without observations: the shape comes from n_cameras, n_points",
         run_case(4, 5, [0, 2, 2, 0, 1], [0, 0, 3, 1, 3])),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: one damped Schur-complement step
# ---------------------------------------------------------------------------------------------------------------


def _block_inv(V):
    out = np.zeros_like(V)
    for j in range(0, V.shape[0], 3):
        out[j:j + 3, j:j + 3] = np.linalg.inv(V[j:j + 3, j:j + 3])
    return out


def _schur_variants(J, r, c, mu):
    """Typical wrong steps (delta_c, delta_p), each with its hint."""
    A0, g = J.T @ J, J.T @ r
    D = np.diag(np.diag(A0))

    def step(A, S_sign=-1, rhs_sign=-1, back_sign=1, inv=_block_inv):
        U, W, V = A[:c, :c], A[:c, c:], A[c:, c:]
        Vi = inv(V)
        dc = np.linalg.solve(U + S_sign * W @ Vi @ W.T, rhs_sign * (g[:c] - W @ Vi @ g[c:]))
        dp = -Vi @ (g[c:] + back_sign * W.T @ dc)
        return dc, dp

    damp_U = A0.copy()
    damp_U[:c, :c] += mu * D[:c, :c]
    return [
        (step(A0 + mu * np.eye(len(A0))), "the damping is Levenberg's μI: Marquardt's is μ·diag(JᵀJ), which scales "
                                          "with each parameter's units (angles, translations, points)"),
        (step(damp_U), "only U is damped: add μ·diag(JᵀJ) to the whole diagonal, V's too, before eliminating the "
                       "points"),
        (step(A0 + mu * D, rhs_sign=1),
         "the step has the wrong sign: (JᵀJ + μD) δ = -Jᵀr, so S δc = -(g_c - W V⁻¹ g_p)"),
        (step(A0 + mu * D, back_sign=-1), "back-substitution: δp = -V⁻¹ (g_p + Wᵀ δc)"),
        (step(A0 + mu * D, S_sign=1), "the Schur complement is S = U - W V⁻¹ Wᵀ (a minus sign)"),
        (step(A0 + mu * D, inv=lambda V: np.diag(1 / np.diag(V))),
         "V is block diagonal in 3×3 blocks, not diagonal: invert each 3×3 block V[j:j+3, j:j+3]"),
    ]


def _diagnose_schur(out, J, r, c, mu):
    if not isinstance(out, tuple | list) or len(out) != 2:
        return "schur_step must return a pair (delta_c, delta_p)"
    dc, dp = (np.asarray(a, float).ravel() for a in out)
    n = J.shape[1]
    if dc.size != c or dp.size != n - c:
        return (f"delta_c must have n_cam_cols = {c} entries and delta_p the other {n - c}; got {dc.size} and "
                f"{dp.size}")
    if not (np.all(np.isfinite(dc)) and np.all(np.isfinite(dp))):
        return "the step has NaN or inf entries"
    A = J.T @ J
    ref = np.linalg.solve(A + mu * np.diag(np.diag(A)), -(J.T @ r))
    got = np.r_[dc, dp]
    tol = 1e-6 * np.abs(ref).max()
    if np.abs(got - ref).max() <= tol:
        return None
    for (vc, vp), hint in _schur_variants(J, r, c, mu):
        if np.abs(got - np.r_[vc, vp]).max() <= tol:
            return hint
    g = J.T @ r
    if np.linalg.norm(A @ got + g) <= 1e-6 * np.linalg.norm(g):        # solves the undamped equations
        return ("no damping: that is a Gauss–Newton step (JᵀJ is singular here: the gauge); LM adds μ·diag(JᵀJ) "
                "to JᵀJ before eliminating the points")
    if np.abs(dc - ref[:c]).max() <= tol:
        return "δc is right but δp is not: back-substitute, δp = -V⁻¹ (g_p + Wᵀ δc), with the damped V"
    return (f"the step differs from the solution of (JᵀJ + μ diag(JᵀJ)) δ = -Jᵀr by {np.abs(got - ref).max():.2g} "
            "(largest entry): U, W, V are blocks of the damped matrix; S = U - W V⁻¹ Wᵀ, S δc = -(g_c - W V⁻¹ g_p), "
            "δp = -V⁻¹ (g_p + Wᵀ δc)")


def check_schur_step(schur_step, verbose=True):
    """Self-check of ``schur_step(J, r, n_cam_cols, mu) -> (delta_c, delta_p)``: one damped Gauss–Newton step
    ``(JᵀJ + μ diag(JᵀJ)) δ = -Jᵀr`` by the Schur complement, on a dense J.

    Cases: a small scene with light damping (the library's :func:`labutils.bundle.schur_step` gives the same
    step), strong damping, and a scene where some points are seen by two cameras only.

    Examples
    --------
    >>> def direct(J, r, c, mu):
    ...     A = J.T @ J; d = np.linalg.solve(A + mu * np.diag(np.diag(A)), -J.T @ r); return d[:c], d[c:]
    >>> check_schur_step(direct, verbose=False).passed
    True
    """
    def case(seed, mu, n_views=3, n_points=10, library=False):
        def run(f):
            cp, X, ci, pi, x, K = _problem(seed, n_points=n_points, n_views=n_views)
            J = reprojection_jacobian(cp, X, ci, pi, K).toarray()
            r = reprojection_residuals(cp, X, ci, pi, x, K)
            out = f(J.copy(), r.copy(), 6 * n_views, mu)
            hint = _diagnose_schur(out, J, r, 6 * n_views, mu)
            if hint is None and library:
                lib = _library_schur_step(cp, X, ci, pi, x, K, mu=mu)
                dc = np.asarray(out[0], float).ravel()
                if np.abs(dc - lib.delta_c.ravel()).max() > 1e-6 * np.abs(lib.delta_c).max():
                    return "δc differs from labutils.bundle.schur.schur_step's"
            return hint
        return run

    def two_views(f):
        rng = np.random.default_rng(6)
        s = make_scene(12, 4, noise_px=1.0, rng=rng)
        seen = np.zeros((4, 12), bool)
        for j in range(12):
            seen[rng.choice(4, 2 + j % 3, replace=False), j] = True
        tracks = np.where(seen[..., None], s.x_meas, np.nan)
        ci, pi, x = observations(tracks)
        cp = camera_params_from_Rt(s.R, s.t) + 0.05 * rng.normal(size=(4, 6))
        J = reprojection_jacobian(cp, s.X, ci, pi, s.K).toarray()
        r = reprojection_residuals(cp, s.X, ci, pi, x, s.K)
        return _diagnose_schur(f(J.copy(), r.copy(), 24, 1e-2), J, r, 24, 1e-2)

    return run_checks("schur_step", schur_step, [
        ("a small scene, μ = 1e-3: the damped normal equations (and the library's step)", case(0, 1e-3, library=True)),
        ("strong damping, μ = 10", case(1, 10.0)),
        ("four cameras, points seen by two to four of them, μ = 1e-2", two_views),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 4: the Levenberg–Marquardt loop
# ---------------------------------------------------------------------------------------------------------------


def _lm_problem(seed, noise_px=1.0, rot_deg=1.0):
    """A small turntable from perturbed cameras: (camera_params, points, ci, pi, x, K)."""
    rng = np.random.default_rng(seed)
    s = make_scene(40, 5, layout="turntable", noise_px=noise_px, rng=rng)
    ci, pi, x = observations(s.x_meas)
    R0, t0 = perturb_cameras(s.R, s.t, rng=rng, rot_deg=rot_deg, rel_shift=0.02)
    X0 = s.X + 0.01 * rng.normal(size=s.X.shape)
    return camera_params_from_Rt(R0, t0), X0, ci, pi, x, s.K


def _unpack_lm(out, V, M):
    if not isinstance(out, tuple | list) or len(out) != 3:
        raise ValueError("levenberg_marquardt must return a triple (camera_params, points_3d, costs)")
    cp, X, costs = (np.asarray(a, float) for a in out)
    if cp.shape != (V, 6) or X.shape != (M, 3):
        raise ValueError(f"camera_params must come back as ({V}, 6) and points_3d as ({M}, 3); got {cp.shape} and "
                         f"{X.shape} (reshape delta_c to (V, 6) and delta_p to (M, 3))")
    if costs.ndim != 1 or costs.size < 1:
        raise ValueError("costs must be a 1-d array: the cost at the start, then one per iteration")
    return cp, X, costs


def _diagnose_lm(out, prob, mu, max_iter, tol):
    cp0, X0, ci, pi, x, K = prob
    cp, X, costs = _unpack_lm(out, len(cp0), len(X0))
    r0 = reprojection_residuals(cp0, X0, ci, pi, x, K)
    c0 = 0.5 * r0 @ r0
    if np.isclose(costs[0], 2 * c0, rtol=1e-9):
        return "costs[0] is Σ r²: the cost is ½ Σ r² (the factor ½ makes Jᵀr its gradient)"
    if not np.isclose(costs[0], c0, rtol=1e-9):
        return f"costs[0] = {costs[0]:.6g} is not the cost at the start, ½ Σ r² = {c0:.6g}"
    if costs.size > max_iter + 1:
        return f"{costs.size - 1} iterations where max_iter = {max_iter}: stop after max_iter"
    rise = np.flatnonzero(np.diff(costs) > 1e-12 * costs[0])
    if rise.size:
        return (f"the cost went up at iteration {rise[0] + 1}: a step that does not lower the cost is rejected — keep "
                "the old parameters (and the old cost) and damp more, μ ← 4μ")
    r = reprojection_residuals(cp, X, ci, pi, x, K)
    if not np.isclose(0.5 * r @ r, costs[-1], rtol=1e-9):
        return ("the parameters returned are not those of the last cost: return the parameters of the last accepted "
                "step")
    _, _, ref = _library_lm(cp0, X0, ci, pi, x, K, mu=mu, max_iter=max_iter, tol=tol)
    if np.allclose(costs, costs[0]):
        return ("no step was ever accepted: the step δ solves (JᵀJ + μD)δ = -Jᵀr, so add it — cp + δc.reshape(V, 6), "
                "X + δp.reshape(M, 3) — and check that J's columns are in the order schur_step expects (cameras first)")
    if costs[-1] > ref[-1] * (1 + 1e-6) + 1e-9:
        if costs.size == max_iter + 1:
            return (f"after {max_iter} iterations the cost is {costs[-1]:.6g} where the reference reaches "
                    f"{ref[-1]:.6g}: after an accepted step trust the linear model more, μ ← μ/3 (with μ only "
                    "growing, LM crawls like gradient descent)")
        return (f"stopped at cost {costs[-1]:.6g} where the reference reaches {ref[-1]:.6g}: stop only when an "
                "accepted step lowers the cost by less than tol · cost (a rejected step is no reason to stop)")
    if costs.size == max_iter + 1 and ref.size < max_iter / 2:
        return (f"the loop ran all {max_iter} iterations where {ref.size - 1} suffice: stop when an accepted step "
                "lowers the cost by less than tol · cost, or when μ has grown past ~1e12 (no step lowers the cost)")
    return None


def check_levenberg_marquardt(levenberg_marquardt, verbose=True):
    """Self-check of ``levenberg_marquardt(camera_params, points_3d, camera_indices, point_indices, points_2d, K, *,
    mu, max_iter, tol) -> (camera_params, points_3d, costs)``: the LM loop of bundle adjustment around a Schur step.

    Cases: a small turntable from perturbed cameras (the reference's cost after 30 iterations, the cost never rising),
    a start with heavy damping (μ must shrink after accepted steps), and the stopping rule (``tol = 1e-4``, which the
    reference meets after about 15 of the 60 iterations allowed). The student's loop calls their own
    ``projection_jacobian`` and ``schur_step``.

    Examples
    --------
    >>> check_levenberg_marquardt(_library_lm, verbose=False).passed
    True
    """
    def case(seed, mu, max_iter, tol=1e-10, **kw):
        def run(f):
            prob = _lm_problem(seed, **kw)
            out = f(*(a.copy() for a in prob), mu=mu, max_iter=max_iter, tol=tol)
            return _diagnose_lm(out, prob, mu, max_iter, tol)
        return run

    return run_checks("levenberg_marquardt", levenberg_marquardt, [
        ("a small turntable from perturbed cameras: the optimum, the cost never rising", case(0, 1e-4, 30)),
        ("heavy damping at the start (μ = 100): μ must shrink after each accepted step", case(1, 100.0, 30)),
        ("tol = 1e-4: the loop stops by itself, long before max_iter = 60", case(2, 1e-4, 60, tol=1e-4, rot_deg=0.05)),
    ], verbose=verbose)
