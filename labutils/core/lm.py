"""A dense Levenberg–Marquardt for small least-squares problems (Madsen, Nielsen & Tingleff 2004, Alg. 3.16;
H&Z A6.2), used by camera calibration. Bundle adjustment, where the points make the problem large and sparse, has
its own solver with the Schur complement (:mod:`labutils.bundle.schur`)."""
import numpy as np
import scipy.sparse as sp

from .blas import single_threaded_blas


def levenberg_marquardt(fun_and_jac, p0, *, max_iter=100, tol=1e-12):
    """Levenberg–Marquardt with Marquardt's diagonal scaling and Nielsen's damping update.

    (Madsen, Nielsen & Tingleff, *Methods for non-linear least squares problems*, 2004, Alg. 3.16; H&Z A6.2.)
    Each step solves ``(JᵀJ + μ diag(JᵀJ)) h = -Jᵀr``; a step that lowers the cost is taken and μ shrinks,
    otherwise μ grows and the step is tried again.

    Parameters
    ----------
    fun_and_jac : callable
        ``p -> (r, J)``, residuals ``(m,)`` and Jacobian ``(m, n)`` (dense, or ``scipy.sparse``: JᵀJ is formed
        sparse, then solved dense — n is small here).
    p0 : (n,) array_like
    max_iter : int
    tol : float
        Stop when the relative cost decrease of an accepted step, or the relative step length, is below ``tol``,
        or the gradient is zero to rounding.

    Returns
    -------
    p : (n,) ndarray
    info : dict
        ``cost`` (0.5·Σr²), ``costs`` (per accepted step, starting with the initial cost), ``n_iter``, ``r``, ``J``
        (at ``p``), ``converged`` (False only when ``max_iter`` ran out; when no step lowers the cost any more, even
        with a huge damping, we are at the minimum to rounding and that counts as converged).

    Examples
    --------
    >>> f = lambda p: (np.array([p[0] - 1, 10 * (p[1] - p[0] ** 2)]), np.array([[1, 0], [-20 * p[0], 10]]))
    >>> p, info = levenberg_marquardt(f, [-1.2, 1.0])
    >>> np.round(p, 8) + 0.0, info["converged"]
    (array([1., 1.]), True)
    """
    with single_threaded_blas():           # small dense solves: BLAS threads only wait on each other (see bundle)
        return _lm(fun_and_jac, p0, max_iter, tol)


def _lm(fun_and_jac, p0, max_iter, tol):
    p = np.asarray(p0, float).copy()
    r, J = fun_and_jac(p)
    cost = 0.5 * r @ r
    costs = [cost]
    mu, nu = None, 2.0
    converged = False
    n_iter = 0
    for n_iter in range(1, max_iter + 1):
        A, g = J.T @ J, J.T @ r
        A = A.toarray() if sp.issparse(A) else A
        D = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(), 1e-300))
        if np.abs(g).max() <= 1e-15 * max(1.0, np.sqrt(2 * cost)) * np.sqrt(np.diag(A).max()):
            converged = True
            break
        if mu is None:
            mu = 1e-3
        while True:
            try:
                h = np.linalg.solve(A + mu * np.diag(D), -g)
            except np.linalg.LinAlgError:
                h = None
            if h is not None:
                try:
                    r_new, J_new = fun_and_jac(p + h)
                    cost_new = 0.5 * r_new @ r_new
                except ValueError:             # e.g. a board behind the camera: reject the step
                    cost_new = np.inf
                pred = 0.5 * h @ (mu * D * h - g)
                rho = (cost - cost_new) / pred if pred > 0 else -1.0
                if rho > 0:
                    break
            mu *= nu
            nu *= 2
            if mu > 1e20:
                return p, dict(cost=cost, costs=costs, n_iter=n_iter, r=r, J=J, converged=True)
        small_step = np.linalg.norm(h) <= tol * (np.linalg.norm(p) + tol)
        rel_decrease = (cost - cost_new) / max(cost, 1e-300)
        p, r, J, cost = p + h, r_new, J_new, cost_new
        costs.append(cost)
        mu *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
        nu = 2.0
        if small_step or rel_decrease < tol:
            converged = True
            break
    return p, dict(cost=cost, costs=costs, n_iter=n_iter, r=r, J=J, converged=converged)
