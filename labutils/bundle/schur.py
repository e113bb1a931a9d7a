"""Our bundle-adjustment solver: Levenberg–Marquardt on the normal equations with the Schur complement.

The loop is the package's one (:mod:`labutils.core.lm`: Marquardt's diagonal scaling, Nielsen's damping update); the 3×3
point blocks are eliminated by the Schur complement (Triggs et al. 2000, Sec. 6.1; H&Z Sec. A6.3) and the
reduced camera system is solved by dense Cholesky, or, when it is large and its block pattern sparse (long
sequences, where a camera shares points with a few neighbours only), by a sparse ``L D Lᵀ`` factorisation with a
fill-reducing ordering. Everything per observation, per point and per camera is batched (no Python loop over them);
the index bookkeeping (sums by camera and point, the pairs of observations feeding each block of the reduced
system) is computed once per problem and reused by every iteration. Robust losses by iteratively reweighted least
squares, then the loss's second-order curvature near the optimum (:mod:`labutils.core.robust`). Called through
:func:`labutils.bundle.bundle_adjust` (``solver='lm-schur'``), which checks the input and fixes the gauge.
:func:`schur_step` computes one damped step of the same solver on its own (notebook 04 derives it in cells and
compares); :func:`schur_step_dense` and :func:`levenberg_marquardt` are the references of notebook 04's exercises
(the step on a dense ``J``, and the plain LM loop around the step).
"""
import sys
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg
from numpy.typing import ArrayLike

from ..core.lm import minimise
from ..core.robust import CURVATURE_FLOOR, SECOND_ORDER_AFTER, rho
from ..core.validation import as_array, as_count, as_positive
from .reprojection import check_problem, project_observations, reprojection_residuals


def _inv_sym3(A):
    """Inverse of a stack of symmetric 3×3 matrices, in closed form (adjugate / determinant)."""
    a, b, c = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    d, e, f = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    det = a * c00 + b * c01 + c * c02
    inv = np.stack([np.stack([c00, c01, c02], -1), np.stack([c01, c11, c12], -1),
                    np.stack([c02, c12, c22], -1)], axis=1)
    return inv / det[:, None, None]


class _Groups:
    """Sums of per-observation arrays by camera or by point: one sparse indicator matrix (groups × observations)
    built once per problem, applied to the flattened blocks (faster than ``np.add.reduceat`` or ``np.add.at``)."""

    def __init__(self, idx, n_groups):
        n = idx.shape[0]
        self.A = sp.csr_matrix((np.ones(n), (idx, np.arange(n))), shape=(n_groups, n))
        self.order = np.argsort(idx, kind="stable")

    def sum(self, a):
        """``(n, ...) -> (n_groups, ...)``: the rows of ``a`` summed by group."""
        return (self.A @ a.reshape(a.shape[0], -1)).reshape((-1,) + a.shape[1:])


class _SchurStructure:
    """The symbolic part of the normal equations and of the reduced camera system, computed once per problem and
    reused by every iteration: the sums by camera and by point, the pairs of observations of one point sorted by
    the camera block they feed, and the block pattern of the reduced camera matrix."""

    CHUNK = 4096          # pairs per batch of the reduced system's products (stays in cache)
    DENSE_MAX = 600       # reduced systems up to this size (V k) are factored dense

    def __init__(self, ci, pi, V, M, k=6, dense=None):
        n = ci.shape[0]
        obs = np.arange(n)
        self.cam, self.pt = _Groups(ci, V), _Groups(pi, M)
        # pairs of observations of the same point, o1 before o2 in its list
        order = self.pt.order
        counts = np.bincount(pi, minlength=M)
        starts = np.cumsum(counts) - counts
        pos = np.empty(n, np.int64)
        pos[order] = obs                                          # rank of each observation in the point order
        n_partners = counts[pi] - (pos - starts[pi]) - 1         # partners after itself
        o1 = np.repeat(obs, n_partners)
        first = np.repeat(pos + 1, n_partners)
        o2 = order[first + (np.arange(o1.size) - np.repeat(np.cumsum(n_partners) - n_partners, n_partners))]
        swap = ci[o1] > ci[o2]                                    # block (c1, c2) with c1 <= c2 (S is symmetric)
        o1, o2 = np.where(swap, o2, o1), np.where(swap, o1, o2)
        blk = ci[o1] * V + ci[o2]
        by_blk = np.argsort(blk, kind="stable")
        o1, o2, blk = o1[by_blk], o2[by_blk], blk[by_blk]
        bstart = np.flatnonzero(np.r_[True, blk[1:] != blk[:-1]]) if blk.size else np.zeros(0, np.int64)
        ublk = blk[bstart]
        # batches of about CHUNK pairs, cut at block boundaries: (o1, o2, block starts in the batch, blocks)
        self.chunks = []
        at = np.searchsorted(bstart, np.arange(0, blk.size, self.CHUNK))    # first block starting at or after
        cuts = np.unique(np.r_[bstart[np.minimum(at, bstart.size - 1)][at < bstart.size], blk.size])
        for a, b in zip(cuts[:-1], cuts[1:]):
            u0, u1 = np.searchsorted(bstart, [a, b])
            ind = sp.csr_matrix((np.ones(b - a), np.searchsorted(bstart[u0:u1], np.arange(a, b), "right") - 1,
                                 np.arange(b - a + 1)), shape=(b - a, u1 - u0)).T.tocsr()   # blocks × pairs
            self.chunks.append((o1[a:b], o2[a:b], ind, slice(u0, u1)))
        self.n_blocks = ublk.size
        r, c = ublk // V, ublk % V
        self.same = np.flatnonzero(r == c)                        # a point seen twice by one camera
        self.same_cam = r[self.same]
        off = np.flatnonzero(r != c)
        self.off, self.off_r, self.off_c = off, r[off], c[off]
        self.V, self.k, self.n_pairs = V, k, o1.size
        self.dense = V * k <= self.DENSE_MAX or 2 * off.size + V > 0.3 * V * V if dense is None else dense
        if not self.dense:                                        # the block pattern of S, rows then columns
            rows = np.r_[np.arange(V), self.off_r, self.off_c]
            cols = np.r_[np.arange(V), self.off_c, self.off_r]
            self.bsr_order = np.lexsort((cols, rows))
            self.bsr_indices = cols[self.bsr_order]
            self.bsr_indptr = np.searchsorted(rows[self.bsr_order], np.arange(V + 1))


def lm_schur(cp0, X0, ci, pi, x, Ks, free_cam, free_pt, loss, f_scale, max_iter, tol, verbose):
    """Levenberg–Marquardt with the Schur complement; see :func:`bundle_adjust`. Returns a dict.

    The loop is the package's one (:func:`labutils.core.lm.minimise`); what is particular to bundle adjustment is
    the local model, :class:`_SchurModel`: the normal equations' blocks, robust weights, frozen parameters, and the
    damped step by the Schur complement.
    """
    V, k = cp0.shape
    M = X0.shape[0]
    by_cam = np.argsort(ci, kind="stable")                        # observations by camera: sums by camera in place
    ci, pi, x = ci[by_cam], pi[by_cam], x[by_cam]
    st = _SchurStructure(ci, pi, V, M, k)
    mask_c = free_cam[ci].astype(float)[:, None, :]                 # zero the frozen columns
    mask_p = free_pt[pi].astype(float)[:, None, None]
    frozen_c, frozen_p = ~free_cam, ~free_pt
    state = {"second_order": False}

    def cost(p):
        cp, X = p
        r = project_observations(cp, X, ci, pi, Ks) - x
        return 0.5 * f_scale ** 2 * rho((r / f_scale) ** 2, loss)[0].sum()

    def linearise(p):
        cp, X = p
        u, Jc, Jp = project_observations(cp, X, ci, pi, Ks, jac=True)
        r = u - x
        Jc, Jp = Jc * mask_c, Jp * mask_p
        if loss != "linear":
            # Robust loss: the gradient of 0.5 f² ρ(r²/f²) is ρ' r J. Far from the optimum we weight the rows by
            # sqrt(ρ') (IRLS: curvature ρ' JᵀJ, a convex model whatever the residuals). IRLS overestimates the
            # curvature of residuals beyond the scale, so its steps there are too short and it converges only
            # linearly; once the cost decrease slows (below 1e-3 relative) we switch to the exact second-order
            # curvature of the loss, ρ' + 2 z ρ'' (Triggs et al. Sec. 4.3; what scipy uses from the start),
            # floored at 0.01 ρ' to keep the model convex.
            z = (r / f_scale) ** 2
            _, d1, d2 = rho(z, loss)
            hw = np.sqrt(np.maximum(d1 + 2 * z * d2, CURVATURE_FLOOR * d1) if state["second_order"] else d1)
            r = r * d1 / hw
            Jc, Jp = Jc * hw[:, :, None], Jp * hw[:, :, None]
        return _SchurModel(st, Jc, Jp, r, ci, pi, frozen_c, frozen_p)

    def accepted(F_old, F_new):
        if F_old - F_new <= SECOND_ORDER_AFTER * F_new:
            state["second_order"] = True

    def log(n_iter, F, F_new, g_inf, h_norm, gain, mu, taken):
        if not state.get("header"):
            print(f"{'iter':>4} {'cost':>13} {'cost_change':>12} {'|gradient|':>11} {'|step|':>10} "
                  f"{'gain':>7} {'damping':>9}", file=sys.stderr)
            state["header"] = True
        print(f"{n_iter:4d} {F:13.6e} {F - F_new:12.4e} {g_inf:11.3e} {h_norm:10.3e} {gain:7.3f} {mu:9.2e}"
              + ("" if taken else "  (rejected)"), file=sys.stderr, flush=True)

    res = minimise(cost, linearise, (cp0.copy(), X0.copy()), retract=lambda p, h: (p[0] + h[0], p[1] + h[1]),
                   norm=lambda p: float(np.sqrt((p[0] ** 2).sum() + (p[1] ** 2).sum())), max_iter=max_iter,
                   ftol=tol, xtol=1e-2 * tol, gtol=1e-14, mu0=1e-4, accepted=accepted,   # Ceres: xtol 1e-8, ftol 1e-6
                   log=log if verbose else None)
    cp, X = res.p
    return dict(cp=cp, X=X, n_iter=res.n_iter, n_eval=res.n_eval, success=res.converged, message=res.message)


class _SchurModel:
    """The local model of bundle adjustment at one point: the blocks of ``JᵀJ`` and ``Jᵀr``, Marquardt's scaling,
    and the damped step by the Schur complement (what :func:`labutils.core.lm.minimise` asks of a model)."""

    def __init__(self, st, Jc, Jp, r, ci, pi, frozen_c, frozen_p):
        U, Vp, W, gc, gp = _normal_blocks(st, Jc, Jp, r)
        # frozen parameters: identity rows, zero gradient (their step is exactly 0)
        ic = np.nonzero(frozen_c)
        U[ic[0], ic[1], ic[1]] = 1.0
        Vp[frozen_p] = np.eye(3)
        self.Dc = np.clip(np.diagonal(U, axis1=1, axis2=2), 1e-6, 1e32)      # Marquardt scaling
        self.Dp = np.clip(np.diagonal(Vp, axis1=1, axis2=2), 1e-6, 1e32)
        self.blocks = (U, Vp, W, gc, gp)
        self.st, self.ci, self.pi, self.frozen_c, self.frozen_p = st, ci, pi, frozen_c, frozen_p
        self.gradient_max = max(np.abs(gc).max(initial=0.0), np.abs(gp).max(initial=0.0))

    def step(self, mu):
        U, Vp, W, gc, gp = self.blocks
        dc, dp, _, _ = _damped_step(self.st, U, Vp, W, gc, gp, self.Dc, self.Dp, mu, self.ci, self.pi,
                                    self.frozen_c, self.frozen_p)
        h_norm = float(np.sqrt((dc ** 2).sum() + (dp ** 2).sum()))
        predicted = 0.5 * (mu * ((self.Dc * dc ** 2).sum() + (self.Dp * dp ** 2).sum())
                           - (gc * dc).sum() - (gp * dp).sum())
        return (dc, dp), h_norm, float(predicted)


def _normal_blocks(st, Jc, Jp, r):
    """The blocks of ``JᵀJ`` and ``Jᵀr`` from per-observation Jacobian blocks ``Jc (n, 2, k)``, ``Jp (n, 2, 3)``.

    Returns ``U (V, k, k)`` (camera blocks), ``Vp (M, 3, 3)`` (point blocks), ``W (n, k, 3)`` (one camera-point
    block per observation), ``gc (V, k)`` and ``gp (M, 3)`` (the gradient ``Jᵀr``).
    """
    JcT = np.swapaxes(Jc, 1, 2)
    U = st.cam.sum(JcT @ Jc)                                     # camera blocks
    Vp = st.pt.sum(np.swapaxes(Jp, 1, 2) @ Jp)                   # point blocks
    W = JcT @ Jp                                                 # (n, k, 3) camera-point blocks
    gc = st.cam.sum(np.einsum("nai,na->ni", Jc, r))              # (V, k)
    gp = st.pt.sum(np.einsum("nai,na->ni", Jp, r))               # (M, 3)
    return U, Vp, W, gc, gp


def _damped_step(st, U, Vp, W, gc, gp, Dc, Dp, mu, ci, pi, frozen_c=None, frozen_p=None, dense=None):
    """One damped Gauss–Newton step by the Schur complement: ``(dc (V, k), dp (M, 3), S, rhs)``.

    Solves ``(JᵀJ + μ D) δ = -Jᵀr`` with ``D = diag(Dc, Dp)``: the 3×3 point blocks inverted in closed form,
    the reduced camera system ``S δc = rhs`` by Cholesky — dense, or sparse (a symmetric sparse LU without
    pivoting, which is Cholesky's ``L D Lᵀ``) when the system is large and its block pattern sparse (``st.dense``,
    or ``dense``) — then back-substitution ``δp = V⁻¹(-gp - Wᵀ δc)``. Raises ``LinAlgError`` when ``S`` is not
    positive definite. Frozen parameters get a zero step.
    """
    V, k = gc.shape
    dense = st.dense if dense is None else dense
    Ua = U.copy()
    Ua[:, np.arange(k), np.arange(k)] += mu * Dc
    Va = Vp.copy()
    Va[:, np.arange(3), np.arange(3)] += mu * Dp
    Vinv = _inv_sym3(Va)
    Y = W @ Vinv[pi]                                             # W V⁻¹ per observation, (n, k, 3)
    diag, off = _reduced_camera_blocks(st, Y, W)
    diag = Ua - diag
    off = -off
    if dense:
        S = np.zeros((V, k, V, k))
        S[np.arange(V), :, np.arange(V), :] = diag
        S[st.off_r, :, st.off_c, :] = off
        S[st.off_c, :, st.off_r, :] = np.swapaxes(off, 1, 2)
        S = S.reshape(V * k, V * k)
    else:
        data = np.concatenate([diag, off, np.swapaxes(off, 1, 2)])[st.bsr_order]
        S = sp.bsr_matrix((data, st.bsr_indices, st.bsr_indptr), shape=(V * k, V * k))
    rhs = -(gc - st.cam.sum(np.einsum("nij,nj->ni", Y, gp[pi]))).ravel()
    dc = (_cholesky_solve(S, rhs) if dense else _sparse_spd_solve(S, rhs)).reshape(V, k)
    if frozen_c is not None:
        dc[frozen_c] = 0.0
    dp = np.einsum("mij,mj->mi", Vinv, -gp - st.pt.sum(np.einsum("nij,ni->nj", W, dc[ci])))
    if frozen_p is not None:
        dp[frozen_p] = 0.0
    return dc, dp, S, rhs


def _cholesky_solve(S, rhs):
    return scipy.linalg.cho_solve(scipy.linalg.cho_factor(S, lower=True, check_finite=False), rhs,
                                  check_finite=False)


def _sparse_spd_solve(S, rhs):
    """``S⁻¹ rhs`` for a sparse symmetric ``S``, or ``LinAlgError`` when it is not positive definite: SuperLU with a
    symmetric fill-reducing ordering and no pivoting factors ``S = L D Lᵀ`` (pivots ``D`` on ``U``'s diagonal)."""
    try:
        lu = scipy.sparse.linalg.splu(S.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                      options=dict(SymmetricMode=True))
    except RuntimeError as exc:                                  # an exactly singular pivot
        raise np.linalg.LinAlgError(str(exc)) from None
    if not (np.all(lu.perm_r == lu.perm_c) and np.all(lu.U.diagonal() > 0)):
        raise np.linalg.LinAlgError("the reduced camera matrix is not positive definite")
    return lu.solve(rhs)


@dataclass
class SchurStep:
    """One damped step of LM-Schur, with the blocks it was made of (what :func:`schur_step` returns).

    Attributes
    ----------
    U : (V, k, k) ndarray
        Camera blocks of ``JᵀJ`` (undamped).
    V : (M, 3, 3) ndarray
        Point blocks of ``JᵀJ`` (undamped).
    W : (n_obs, k, 3) ndarray
        The camera-point blocks ``Jcᵀ Jp``, one per observation (block ``(c, p)`` of ``JᵀJ`` sums those of the
        observations of point ``p`` by camera ``c``).
    g_c : (V, k) ndarray
    g_p : (M, 3) ndarray
        The gradient ``Jᵀr`` split into its camera and point parts.
    S : (V k, V k) ndarray
        The damped reduced camera matrix ``U* - W V*⁻¹ Wᵀ`` (``*``: with ``μ D`` added to the diagonal).
    rhs : (V k,) ndarray
        ``-(g_c - W V*⁻¹ g_p)``.
    delta_c : (V, k) ndarray
    delta_p : (M, 3) ndarray
        The step: ``S δc = rhs``, then ``δp = V*⁻¹ (-g_p - Wᵀ δc)``.
    mu : float
    """

    U: np.ndarray = field(repr=False)
    V: np.ndarray = field(repr=False)
    W: np.ndarray = field(repr=False)
    g_c: np.ndarray = field(repr=False)
    g_p: np.ndarray = field(repr=False)
    S: np.ndarray = field(repr=False)
    rhs: np.ndarray = field(repr=False)
    delta_c: np.ndarray = field(repr=False)
    delta_p: np.ndarray = field(repr=False)
    mu: float


def schur_step(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike, point_indices: ArrayLike,
               points_2d: ArrayLike, K: ArrayLike, *, mu: float) -> SchurStep:
    """One damped Gauss–Newton step of :func:`lm_schur`, by the Schur complement (H&Z Sec. A6.3, Alg. A6.4).

    The step solves ``(JᵀJ + μ D) δ = -Jᵀr`` for the plain squared error, with Marquardt's scaling
    ``D = diag(JᵀJ)`` (each entry clipped to ``[1e-6, 1e32]``), exactly as an iteration of the solver behind
    ``bundle_adjust(..., solver='lm-schur')`` does (every parameter free, no gauge: the damping keeps ``S``
    positive definite). It exists to show, and to test, one step of the solver on its own.

    Parameters
    ----------
    camera_params, points_3d, camera_indices, point_indices, points_2d, K
        As in :func:`labutils.bundle.reprojection_residuals`.
    mu : float
        The damping, > 0.

    Returns
    -------
    SchurStep
        The blocks ``U, V, W``, the gradient, ``S``, the right-hand side and the step ``delta_c (V, k)``,
        ``delta_p (M, 3)``.

    Raises
    ------
    ValueError
        Bad input (see :func:`labutils.bundle.reprojection_residuals`), ``mu`` not positive, or a reduced
        camera matrix that is not positive definite.

    Examples
    --------
    The step equals the direct solution of the damped normal equations:

    >>> from labutils.bundle.reprojection import reprojection_jacobian, reprojection_residuals
    >>> cp = np.array([[0., 0, 0, 0, 0, 5], [0, 0.1, 0, -1, 0, 5]]); X = np.random.default_rng(0).normal(size=(6, 3))
    >>> ci, pi = np.repeat([0, 1], 6), np.tile(np.arange(6), 2); K = np.diag([500., 500, 1])
    >>> x = np.random.default_rng(1).normal(size=(12, 2))
    >>> step = schur_step(cp, X, ci, pi, x, K, mu=1e-3)
    >>> J = reprojection_jacobian(cp, X, ci, pi, K).toarray(); A = J.T @ J
    >>> g = J.T @ reprojection_residuals(cp, X, ci, pi, x, K)
    >>> delta = np.linalg.solve(A + 1e-3 * np.diag(np.diag(A)), -g)
    >>> bool(np.allclose(np.r_[step.delta_c.ravel(), step.delta_p.ravel()], delta, rtol=1e-8, atol=1e-10))
    True
    """
    cp, X, ci, pi, x, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    mu = as_positive(mu, "mu")
    V, M = cp.shape[0], X.shape[0]
    st = _SchurStructure(ci, pi, V, M, cp.shape[1], dense=True)
    u, Jc, Jp = project_observations(cp, X, ci, pi, Ks, jac=True)
    U, Vp, W, gc, gp = _normal_blocks(st, Jc, Jp, u - x)
    Dc = np.clip(np.diagonal(U, axis1=1, axis2=2), 1e-6, 1e32)
    Dp = np.clip(np.diagonal(Vp, axis1=1, axis2=2), 1e-6, 1e32)
    try:
        dc, dp, S, rhs = _damped_step(st, U, Vp, W, gc, gp, Dc, Dp, mu, ci, pi)
    except np.linalg.LinAlgError:
        raise ValueError(f"the damped reduced camera matrix is not positive definite at mu = {mu:g} "
                         "(a camera or point without enough observations?)") from None
    return SchurStep(U=U, V=Vp, W=W, g_c=gc, g_p=gp, S=S, rhs=rhs, delta_c=dc, delta_p=dp, mu=mu)


def _reduced_camera_blocks(st, Y, W):
    """``Σ_p W_p V_p⁻¹ W_pᵀ`` by blocks, from per-observation ``Y = W V⁻¹`` and ``W``: ``(diag (V, k, k), off
    (n_off, k, k))``, the diagonal blocks and the blocks ``(off_r, off_c)`` above the diagonal.

    Block (c1, c2), c1 <= c2, sums ``Y_o1 W_o2ᵀ`` over the pairs of observations (o1 by c1, o2 by c2) of one point,
    the pairs sorted by block once (:class:`_SchurStructure`), so that a batch of products is summed into its
    blocks by one sparse indicator product; the diagonal blocks also get each observation's ``Y_o W_oᵀ``.
    """
    k = W.shape[1]
    B = np.empty((st.n_blocks, k, k))
    Wt = np.ascontiguousarray(np.swapaxes(W, 1, 2))
    for o1, o2, ind, blocks in st.chunks:
        T = np.take(Y, o1, axis=0) @ np.take(Wt, o2, axis=0)
        B[blocks] = (ind @ T.reshape(-1, k * k)).reshape(-1, k, k)
    diag = st.cam.sum(Y @ Wt)
    if st.same.size:                                              # pairs within one camera: both orders
        same = B[st.same]
        np.add.at(diag, st.same_cam, same + np.swapaxes(same, 1, 2))
    return diag, B[st.off]


def schur_step_dense(J: ArrayLike, r: ArrayLike, n_cam_cols: int, mu: float) -> tuple:
    """One damped Gauss–Newton step ``(JᵀJ + μ diag(JᵀJ)) δ = -Jᵀr`` by the Schur complement, on a dense ``J``.

    The reference of notebook 04's exercise ``schur_step`` (same arguments, same return): the ``3×3`` point
    blocks of ``V`` are inverted one by one, the reduced camera system ``S δc = -(gc - W V⁻¹ gp)`` is solved and
    ``δp = -V⁻¹ (gp + Wᵀ δc)`` back-substituted (H&Z Alg. A6.4).

    Parameters
    ----------
    J : (N, n_cam_cols + 3 M) array_like
        Jacobian, camera columns first, then 3 columns per point.
    r : (N,) array_like
        Residuals.
    n_cam_cols : int
        Number of camera columns (6 V).
    mu : float
        Damping, > 0.

    Returns
    -------
    delta_c : (n_cam_cols,) ndarray
    delta_p : (3 M,) ndarray

    Examples
    --------
    Each row touches one point (rows 0–9 point 0, rows 10–19 point 1), so ``V`` is block diagonal:

    >>> J = np.random.default_rng(0).normal(size=(20, 12)); J[:10, 9:] = J[10:, 6:9] = 0; r = np.ones(20)
    >>> dc, dp = schur_step_dense(J, r, 6, 1e-3)
    >>> A = J.T @ J; delta = np.linalg.solve(A + 1e-3 * np.diag(np.diag(A)), -J.T @ r)
    >>> bool(np.allclose(np.r_[dc, dp], delta))
    True
    """
    J = as_array(J.toarray() if sp.issparse(J) else J, "J", "(N, n)")
    r = as_array(r, "r", "(N,)")
    if J.ndim != 2 or J.size == 0 or r.shape != (J.shape[0],):
        raise ValueError(f"J must be (N, n) and r (N,); got J {J.shape} and r {r.shape}")
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
        raise ValueError("J and r must be finite (a NaN or inf entry)")
    c = as_count(n_cam_cols, "n_cam_cols", 0)
    if not 0 <= c <= J.shape[1] or (J.shape[1] - c) % 3:
        raise ValueError(f"n_cam_cols must leave a multiple of 3 point columns of J's {J.shape[1]}; got {n_cam_cols}")
    mu = as_positive(mu, "mu")
    A, g = J.T @ J, J.T @ r
    A = A + mu * np.diag(np.diag(A))
    U, W, Vb = A[:c, :c], A[:c, c:], A[c:, c:]
    M = Vb.shape[0] // 3
    blocks = Vb.reshape(M, 3, M, 3)[np.arange(M), :, np.arange(M), :]          # (M, 3, 3) diagonal blocks
    V_inv = scipy.linalg.block_diag(*np.linalg.inv(blocks)) if M else np.zeros((0, 0))
    S = U - W @ V_inv @ W.T
    delta_c = np.linalg.solve(S, -(g[:c] - W @ V_inv @ g[c:])) if c else np.zeros(0)
    return delta_c, -V_inv @ (g[c:] + W.T @ delta_c)


def levenberg_marquardt(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike,
                        point_indices: ArrayLike, points_2d: ArrayLike, K: ArrayLike, *, mu: float = 1e-4,
                        max_iter: int = 50, tol: float = 1e-10) -> tuple:
    """Plain Levenberg–Marquardt for bundle adjustment: one Schur step per iteration, accepted if it lowers the cost.

    The reference of notebook 04's exercise ``levenberg_marquardt`` (same arguments, same return). An accepted step
    trusts the linear model more (``μ ← μ/3``), a rejected one damps more (``μ ← 4μ``, the parameters unchanged).
    The loop stops after ``max_iter`` iterations, when an accepted step lowers the cost by less than
    ``tol · cost``, or when ``μ`` exceeds ``1e12`` (no step lowers the cost). No gauge is fixed (the damping keeps
    every step finite) and no loss other than least squares: :func:`labutils.bundle.bundle_adjust` does both.

    Parameters
    ----------
    camera_params, points_3d, camera_indices, point_indices, points_2d, K
        As in :func:`labutils.bundle.reprojection_residuals`.
    mu : float
        Initial damping, > 0.
    max_iter : int
        Most iterations (one step each, accepted or not).
    tol : float
        Relative decrease of the cost below which an accepted step ends the loop.

    Returns
    -------
    camera_params : (V, 6) ndarray
    points_3d : (M, 3) ndarray
    costs : (n_iter + 1,) ndarray
        ``½ Σ r²`` at the start and after each iteration (unchanged after a rejected step).

    Examples
    --------
    >>> cp = np.array([[0., 0, 0, 0, 0, 5], [0, 0.1, 0, -1, 0, 5]]); X = np.random.default_rng(0).normal(size=(6, 3))
    >>> ci, pi = np.repeat([0, 1], 6), np.tile(np.arange(6), 2); K = np.diag([500., 500, 1])
    >>> x = reprojection_residuals(cp, X, ci, pi, np.zeros((12, 2)), K).reshape(-1, 2)
    >>> cp1, X1, costs = levenberg_marquardt(cp + 0.01, X, ci, pi, x, K)
    >>> bool(costs[0] > 1 and costs[-1] < 1e-12 and np.all(np.diff(costs) <= 0))
    True
    """
    cp, X, ci, pi, x, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    mu = as_positive(mu, "mu")
    max_iter = as_count(max_iter, "max_iter")
    tol = as_positive(tol, "tol", allow_zero=True)
    cost = 0.5 * float(np.sum(reprojection_residuals(cp, X, ci, pi, x, K) ** 2))
    costs = [cost]
    for _ in range(int(max_iter)):
        step = schur_step(cp, X, ci, pi, x, K, mu=mu)
        cp_new, X_new = cp + step.delta_c, X + step.delta_p
        new = 0.5 * float(np.sum(reprojection_residuals(cp_new, X_new, ci, pi, x, K) ** 2))
        if new < cost:
            done = cost - new <= tol * cost
            cp, X, cost, mu = cp_new, X_new, new, mu / 3
        else:
            mu *= 4
            done = mu > 1e12
        costs.append(cost)
        if done:
            break
    return cp, X, np.array(costs)
