"""The maximum-likelihood ("gold standard") fundamental matrix (H&Z Alg. 11.3).

Minimise the reprojection error over a camera ``P2`` and the points (:class:`GoldStandardProblem`), by our own
sparse Levenberg–Marquardt with an analytic Jacobian; started from the 8-point and from a global search over the
epipole (:func:`epipole_search`), which keeps it out of the wrong basin when the camera moves forward.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike

from ..core.geometry import skew
from ..core.lm import minimise
from ..core.validation import as_camera_matrix, as_count, as_fundamental, as_points, as_positive
from .epipolar import (
    _canonical_sign,
    _transform_points,
    check_pair,
    epipole_search,
    fundamental_8point,
    hartley_normalisation,
)
from .triangulation import triangulate_optimal


def gold_standard_residuals(P2: ArrayLike, points: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
    """The residual vector of the gold-standard cost (H&Z Alg. 11.3, eq. 11.6) for ``P1 = [I | 0]`` and ``P2``.

    Point i is ``X_i = (u_i, v_i, 1, ρ_i)``: ``P1 X_i = (u_i, v_i, 1)``, so its image in view 1 is ``(u_i, v_i)``;
    its image in view 2 is ``P2 X_i`` divided by its third coordinate.

    Parameters
    ----------
    P2 : (3, 4) ndarray
        The second camera ``[M | e']``.
    points : (N, 3) ndarray
        Rows ``(u_i, v_i, ρ_i)``.
    x1, x2 : (N, 2) ndarray
        The measured points, in the coordinates of the cameras.

    Returns
    -------
    r : (4N,) ndarray
        Per point ``(x̂1 - x1, x̂2 - x2)`` (4 numbers), point after point: the cost is ``Σ r²``.

    Examples
    --------
    >>> P2 = np.hstack([np.eye(3), [[1.0], [0.0], [0.0]]])
    >>> gold_standard_residuals(P2, np.array([[0.0, 0.0, 1.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    array([0., 0., 1., 0.])
    """
    P2 = as_camera_matrix(P2, "P2")
    points = as_points(points, "points", dim=3)
    x1 = as_points(x1, "x1")
    if len(x1) != len(points):
        raise ValueError(f"x1 has {len(x1)} rows for the {len(points)} rows of points: one per correspondence")
    x2 = as_points(x2, "x2", like=x1)
    X = np.column_stack([points[:, 0], points[:, 1], np.ones(len(points)), points[:, 2]])
    if np.any(np.abs((X @ P2.T)[:, 2]) < 1e-12 * np.abs(X @ P2.T).max(axis=1)):
        raise ValueError("points has a point that P2 maps to infinity in view 2 (third coordinate 0)")
    return _gold_standard_residuals(P2, points, x1, x2)


def _gold_standard_residuals(P2, points, x1, x2):
    """:func:`gold_standard_residuals` without the checks: the cost inside the LM loop."""
    X = np.column_stack([points[:, 0], points[:, 1], np.ones(len(points)), points[:, 2]])
    y = X @ P2.T
    return np.hstack([points[:, :2] - x1, y[:, :2] / y[:, 2:] - x2]).ravel()


class GoldStandardProblem:
    """The maximum-likelihood F problem of H&Z Alg. 11.3, as residuals and a sparse Jacobian.

    Cameras ``P1 = [I | 0]`` and ``P2`` (12 free entries); point i is ``X_i = (u_i, v_i, 1, ρ_i)``: its
    (corrected) image in view 1 and a projective inverse depth, so ``P1 X_i = (u_i, v_i, 1)`` exactly and
    ``P2 X_i`` its image in view 2 (this covers every point not at infinity in image 1, including points
    on the plane at infinity of the projective frame, with 3 parameters each). Everything is computed
    in Hartley-normalised coordinates (one similarity per image) and the residuals are scaled back to
    pixels, so the cost is the reprojection error in pixels (H&Z eq. 11.6). The parameter vector is
    ``[P2.ravel() (12), u_0, v_0, ρ_0, u_1, ...]``; the residuals are ``[x1 residual (2), x2 residual (2)]``
    per point. Gauge freedom (5: the scale of P2 and ``P2 -> P2 + e' vᵀ`` with λ) is left to the damping.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Measured correspondences, pixels.
    F0 : (3, 3) array_like
        Initial F (rank 2). The initial points are its optimal correction (H&Z Alg. 12.1), so the
        initial cost is exactly ``4 N fundamental_residual(F0, x1, x2)²``.
    residuals : callable, optional
        ``residuals(P2, points, y1, y2) -> (4N,)``, the residual vector of the cost in the normalised coordinates
        (:func:`gold_standard_residuals`, the default; notebook 01 passes the student's). The Jacobian stays the
        analytic one of :func:`gold_standard_residuals`.
    """

    def __init__(self, x1, x2, F0, residuals=None):
        x1, x2 = check_pair(x1, x2, 8)
        F0 = as_fundamental(F0, "F0")[0]
        if residuals is not None and not callable(residuals):
            raise ValueError("residuals must be a function (P2, points, y1, y2) -> (4N,), "
                             f"got {type(residuals).__name__}")
        self._residuals = _gold_standard_residuals if residuals is None else residuals
        self.x1, self.x2, self.n = x1, x2, len(x1)
        self.T1, self.T2 = hartley_normalisation(x1), hartley_normalisation(x2)
        self.s1, self.s2 = self.T1[0, 0], self.T2[0, 0]
        self.y1, self.y2 = _transform_points(self.T1, x1), _transform_points(self.T2, x2)
        Fn = np.linalg.inv(self.T2).T @ F0 @ np.linalg.inv(self.T1)
        Fn /= np.linalg.norm(Fn)
        e2 = np.linalg.svd(Fn)[0][:, 2]                      # left epipole: e2ᵀ F = 0
        P2 = np.hstack([skew(e2) @ Fn, e2[:, None]])         # H&Z Result 9.14
        x1_hat, x2_hat = triangulate_optimal(F0, x1, x2)
        u = _transform_points(self.T1, x1_hat)
        z2 = np.hstack([_transform_points(self.T2, x2_hat), np.ones((self.n, 1))])
        # rho from z2 ~ M u_h + rho e: least squares on z2 × (M u_h + rho e) = 0
        Mu = np.hstack([u, np.ones((self.n, 1))]) @ P2[:, :3].T
        a, b = np.cross(z2, P2[:, 3]), np.cross(z2, Mu)
        rho = -np.einsum("ni,ni->n", a, b) / np.maximum(np.einsum("ni,ni->n", a, a), 1e-300)
        self.p0 = np.concatenate([P2.ravel(), np.column_stack([u, rho]).ravel()])
        if residuals is not None:                  # a student's cost: its shape checked once, here, not in the loop
            r = np.asarray(residuals(P2, self.unpack(self.p0)[1], self.y1, self.y2))
            if r.shape != (4 * self.n,) or r.dtype.kind not in "fi":
                raise ValueError(f"residuals must return {4 * self.n} real numbers (shape ({4 * self.n},)), 4 per "
                                 f"point; it returned {r.dtype} shape {r.shape}")

    @property
    def n_params(self):
        return 12 + 3 * self.n

    def unpack(self, p):
        """``P2 (3, 4)`` and the point parameters ``(N, 3)`` (u, v, ρ) in normalised coordinates."""
        return p[:12].reshape(3, 4), p[12:].reshape(self.n, 3)

    def _project(self, p):
        P2, q = self.unpack(p)
        X = np.column_stack([q[:, 0], q[:, 1], np.ones(self.n), q[:, 2]])
        return P2, q, X, X @ P2.T

    def residuals(self, p):
        """``(4N,)`` residuals in pixels: per point ``(x1_hat - x1, x2_hat - x2)``."""
        P2, q = self.unpack(p)
        r = np.asarray(self._residuals(P2, q, self.y1, self.y2), float)
        r = r.reshape(self.n, 4) / [self.s1, self.s1, self.s2, self.s2]     # back to pixels
        return r.ravel()

    def _blocks(self, p):
        """Dense per-point Jacobian blocks: ``A (N, 2, 12)`` = ∂r2/∂P2, ``B (N, 4, 3)`` = ∂r/∂(u, v, ρ)."""
        P2, q, X, y = self._project(p)
        w = 1.0 / y[:, 2]
        D = np.zeros((self.n, 2, 3))                         # ∂π/∂y, π(y) = y[:2] / y[2]
        D[:, 0, 0] = D[:, 1, 1] = w
        D[:, :, 2] = -y[:, :2] * (w ** 2)[:, None]
        D /= self.s2
        A = (D[:, :, :, None] * X[:, None, None, :]).reshape(self.n, 2, 12)
        B = np.zeros((self.n, 4, 3))
        B[:, 0, 0] = B[:, 1, 1] = 1.0 / self.s1
        B[:, 2:, :] = D @ P2[:, [0, 1, 3]]
        return A, B

    def jacobian(self, p):
        """Analytic Jacobian as a ``scipy.sparse.csr_matrix`` of shape ``(4N, 12 + 3N)``."""
        A, B = self._blocks(p)
        rows, cols = self._pattern()
        full = np.zeros((self.n, 4, 15))
        full[:, 2:, :12] = A
        full[:, :, 12:] = B
        keep = self._mask15()
        return scipy.sparse.csr_matrix((full[:, keep].ravel(), (rows, cols)), shape=(4 * self.n, self.n_params))

    def _mask15(self):
        keep = np.zeros((4, 15), bool)
        keep[2:, :12] = True
        keep[:2, 12:14] = True
        keep[2:, 12:] = True
        return keep

    def _pattern(self):
        keep = self._mask15()
        r, c = np.nonzero(keep)
        i = np.arange(self.n)[:, None]
        rows = 4 * i + r[None]
        cols = np.where(c[None] < 12, c[None], 12 + 3 * i + (c[None] - 12))
        return rows.ravel(), cols.ravel()

    def sparsity(self):
        """Which Jacobian entries can be non-zero: a ``scipy.sparse`` 0/1 matrix (for ``jac_sparsity``)."""
        rows, cols = self._pattern()
        return scipy.sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(4 * self.n, self.n_params))

    def F(self, p):
        """The F of these parameters in pixels: ``F = T2ᵀ [e']× M T1`` with ``P2 = [M | e']`` (H&Z Result 9.9)."""
        P2 = p[:12].reshape(3, 4)
        return _canonical_sign(self.T2.T @ skew(P2[:, 3]) @ P2[:, :3] @ self.T1)

    def points(self, p):
        """Corrected pixels ``x1_hat, x2_hat`` (N, 2): the reprojections of the current points."""
        _, q, _, y = self._project(p)
        return (_transform_points(np.linalg.inv(self.T1), q[:, :2]),
                _transform_points(np.linalg.inv(self.T2), y[:, :2] / y[:, 2:]))

    def solve(self, p=None, max_iter=100, tol=1e-10):
        """Levenberg–Marquardt (the package's loop, :func:`labutils.core.lm.minimise`) with the Schur complement on
        the 3×3 point blocks (H&Z Sec. A6.3-A6.4).

        The normal equations ``[U W; Wᵀ V] [δa; δb] = -[g_a; g_b]`` (a: the 12 camera entries, b: the points,
        V block diagonal) are reduced to the 12×12 system ``(U - W V⁻¹ Wᵀ) δa = -g_a + W V⁻¹ g_b``; each point
        step is then ``δb_i = -V_i⁻¹ (g_b_i + W_iᵀ δa)`` (:class:`_GoldStandardModel`). Marquardt's scaling plus a
        tiny absolute term also fixes the gauge. A step is kept only if it lowers the cost, so the cost never rises
        above the initial one.

        Returns
        -------
        p : (12 + 3N,) ndarray
        info : dict
            ``cost`` (history of 0.5 Σ r², per accepted step), ``n_iter``, ``converged``.
        """
        p0 = self.p0.copy() if p is None else np.array(p, float)

        def cost(q):
            r = self.residuals(q)
            return 0.5 * r @ r

        def retract(q, h):
            q = q + h
            q[:12] /= np.linalg.norm(q[:12])                 # a pure gauge move (P2 up to scale)
            return q

        res = minimise(cost, lambda q: _GoldStandardModel(self, q), p0, retract=retract, max_iter=max_iter,
                       ftol=tol, xtol=0.0, gtol=0.0, mu0=1e-3)
        return res.p, dict(cost=np.array(res.costs), n_iter=res.n_iter, converged=res.converged)


class _GoldStandardModel:
    """The gold standard's local model: the blocks of ``JᵀJ`` and ``Jᵀr`` (12 camera entries, 3 per point) and the
    damped step by the Schur complement on the point blocks."""

    def __init__(self, problem, p):
        A, B = problem._blocks(p)
        rr = problem.residuals(p).reshape(problem.n, 4)
        A2 = A.reshape(-1, 12)
        self.U = A2.T @ A2
        self.V = B.transpose(0, 2, 1) @ B
        self.W = A.transpose(0, 2, 1) @ B[:, 2:, :]                 # (N, 12, 3)
        self.ga = A2.T @ rr[:, 2:].ravel()
        self.gb = (B.transpose(0, 2, 1) @ rr[:, :, None])[:, :, 0]
        self.Da = np.diag(self.U) + 1e-12 * np.trace(self.U) / 12
        dV = np.einsum("nii->ni", self.V)
        self.Db = dV + 1e-12 * dV.sum(1, keepdims=True) / 3
        self.gradient_max = float(max(np.abs(self.ga).max(), np.abs(self.gb).max()))

    def step(self, mu):
        Ud = self.U + mu * np.diag(self.Da)
        Vd = self.V + mu * self.Db[:, :, None] * np.eye(3)
        Vinv = np.linalg.inv(Vd)
        WVinv = (self.W @ Vinv).transpose(1, 0, 2).reshape(12, -1)
        S = Ud - WVinv @ self.W.transpose(1, 0, 2).reshape(12, -1).T
        da = np.linalg.solve(S, -self.ga + WVinv @ self.gb.ravel())
        db = -(Vinv @ (self.gb + (self.W.transpose(0, 2, 1) @ da))[:, :, None])[:, :, 0]
        h = np.concatenate([da, db.ravel()])
        g = np.concatenate([self.ga, self.gb.ravel()])
        D = np.concatenate([self.Da, self.Db.ravel()])
        return h, float(np.linalg.norm(h)), 0.5 * float(h @ (mu * D * h - g))


@dataclass
class GoldStandardResult:
    """What :func:`fundamental_gold_standard` returns.

    Attributes
    ----------
    F : (3, 3) ndarray
        The maximum-likelihood F: rank 2, unit Frobenius norm.
    x1_hat, x2_hat : (N, 2) ndarray
        The corrected pixels: the reprojections of the ML points, which satisfy ``x2_hatᵀ F x1_hat = 0``.
    residual : float
        RMS geometric residual over the 4N coordinates, ``sqrt(2 cost / (4 N))`` in pixels (the quantity
        :func:`labutils.twoview.fundamental_residual` computes for any F).
    cost : (n,) ndarray
        History of ``0.5 Σ r²`` (px²) of the winning run, per accepted step.
    n_iter : int
    converged : bool
    start : int
        Which start won: 0 for F0, then the epipole-search starts.
    start_costs : (n_starts + 1,) ndarray
        Final ``0.5 Σ r²`` of each start.
    """

    F: np.ndarray
    x1_hat: np.ndarray = field(repr=False)
    x2_hat: np.ndarray = field(repr=False)
    residual: float
    cost: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    start: int
    start_costs: np.ndarray


def fundamental_gold_standard(x1: ArrayLike, x2: ArrayLike, F0: ArrayLike = None, *, n_starts: int = 1,
                              max_iter: int = 100, tol: float = 1e-10, residuals=None) -> GoldStandardResult:
    """Maximum-likelihood ("gold standard") F (H&Z Alg. 11.3).

    Minimises the reprojection error ``Σ |x1 - P1 X|² + |x2 - P2 X|²`` over the camera ``P2`` (12
    entries, with ``P1 = [I | 0]``) and the N points (:class:`GoldStandardProblem`), starting from ``F0``
    (the normalised 8-point if None): ``P2 = [[e']× F0 | e']`` and the points from the optimal correction.
    The solver is our own sparse Levenberg–Marquardt with an analytic Jacobian
    (:meth:`GoldStandardProblem.solve`): the Schur complement leaves a 12×12 system per iteration.
    (``scipy.optimize.least_squares`` with ``jac=problem.jacobian`` or ``jac_sparsity=problem.sparsity()``
    solves the same problem, slower.)

    One addition makes it reliable when the epipole is inside the image (forward motion): there the
    cost has several local minima, the 8-point often starts in the wrong one, and LM can also stall
    where a corrected point reaches the epipole of image 2 (its 3D point would have to pass through
    the centre of camera 1, ρ through infinity). So besides F0 we also start from the ``n_starts`` best F
    of a global search over the epipole (:func:`epipole_search`) and keep the lowest final cost: the
    result is never worse than the textbook run from F0.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels, N >= 8 (inliers only: the cost is not robust).
    F0 : (3, 3) array_like, optional
        Initial F of rank 2.
    n_starts : int
        Extra starts from :func:`epipole_search` (0: only F0, the textbook algorithm).
    max_iter : int
        Levenberg–Marquardt iterations at most, per run.
    tol : float
        Stop when an iteration lowers the cost by less than ``tol`` times the cost.
    residuals : callable, optional
        The cost's residual vector, as :class:`GoldStandardProblem` takes it (notebook 01: the student's).

    Returns
    -------
    GoldStandardResult
        ``.F``, the corrected points ``.x1_hat, .x2_hat``, the ``.residual`` in pixels, and how it got there.

    Raises
    ------
    ValueError
        Bad input as for :func:`fundamental_8point` (including degenerate data when F0 is None).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.twoview.triangulation import fundamental_residual
    >>> s = make_scene(30, 2, noise_px=1.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1)
    >>> gs = fundamental_gold_standard(x1, x2)
    >>> gs.F.shape, bool(gs.residual <= fundamental_residual(fundamental_8point(x1, x2), x1, x2))
    ((3, 3), True)
    >>> bool(abs(gs.residual - fundamental_residual(gs.F, x1, x2)) < 1e-6)
    True
    """
    x1, x2 = check_pair(x1, x2, 8)
    n_starts = as_count(n_starts, "n_starts", 0)
    max_iter = as_count(max_iter, "max_iter", 1)
    tol = as_positive(tol, "tol")
    F0 = fundamental_8point(x1, x2) if F0 is None else as_fundamental(F0, "F0")[0]
    starts = [F0] + (epipole_search(x1, x2, n_best=n_starts) if n_starts > 0 else [])
    runs = []
    for F in starts:
        problem = GoldStandardProblem(x1, x2, F, residuals=residuals)
        p, info = problem.solve(max_iter=max_iter, tol=tol)
        runs.append((problem, p, info))
    costs = np.array([run[2]["cost"][-1] for run in runs])
    best = int(np.argmin(costs))
    problem, p, info = runs[best]
    x1_hat, x2_hat = problem.points(p)
    return GoldStandardResult(F=problem.F(p), x1_hat=x1_hat, x2_hat=x2_hat,
                              residual=float(np.sqrt(2 * costs[best] / (4 * len(x1)))), cost=info["cost"],
                              n_iter=int(info["n_iter"]), converged=bool(info["converged"]), start=best,
                              start_costs=costs)
