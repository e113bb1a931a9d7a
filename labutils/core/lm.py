"""The one Levenberg–Marquardt loop of the workbook (Madsen, Nielsen & Tingleff 2004, Alg. 3.16; H&Z A6.2), with one
damping rule: Marquardt's diagonal scaling and Nielsen's update.

Every non-linear least-squares solver of the package runs this loop — the gold-standard F
(:mod:`labutils.twoview.gold_standard`), the Sampson F behind GRIC (:mod:`labutils.twoview.epipolar`), camera
calibration (:mod:`labutils.calibrate.camera`) and bundle adjustment (:mod:`labutils.bundle.schur`) — and differs
only in how it makes a damped step. A solver describes its problem by three functions and a step:

- ``cost(p)``: the cost ``F(p)`` (``½ Σ r²``, or a robust ``½ Σ ρ``); ``inf`` (or ``ValueError``) where it is
  undefined, which rejects the step;
- ``linearise(p)``: the local model at ``p`` — an object with ``gradient_max`` (``‖g‖∞``) and
  ``step(mu) -> (h, h_norm, predicted)``: the damped step ``(A + μ D) h = -g``, its length, and the decrease the
  model predicts, ``L(0) - L(h) = ½ hᵀ(μ D h - g)``. Dense problems use :class:`DenseLinearisation`; bundle
  adjustment its Schur complement (:mod:`labutils.bundle.schur`), the gold standard its 3×3 point blocks;
- ``retract(p, h)``: the new parameters (``p + h`` by default; a rotation is updated by its exponential).

The loop: a step is taken when the cost falls (gain ratio ``ρ = (F(p) - F(p + h)) / predicted > 0``), and μ shrinks
by ``max(1/3, 1 - (2ρ - 1)³)``; otherwise μ grows by ν, and ν doubles (Nielsen 1999). It stops when the gradient is
zero to rounding, the step is negligible, the relative decrease of an accepted step is below ``ftol``, or no step
lowers the cost even with a huge damping (the minimum to rounding: counted as converged), or after ``max_iter``
linearisations (not converged).
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .blas import single_threaded_blas

MU_MAX = 1e32          # beyond this damping the step is ~0: no reduction is possible any more


@dataclass
class LMResult:
    """What :func:`minimise` returns.

    Attributes
    ----------
    p : object
        The parameters at the end (whatever ``retract`` makes).
    cost : float
        ``cost(p)``.
    costs : list of float
        The cost before the first step and after each accepted one.
    n_iter : int
        Linearisations (Jacobian evaluations).
    n_eval : int
        Cost evaluations.
    converged : bool
        False only when ``max_iter`` ran out.
    message : str
        Why it stopped.
    """

    p: object = field(repr=False)
    cost: float
    costs: list = field(repr=False)
    n_iter: int
    n_eval: int
    converged: bool
    message: str


def minimise(cost, linearise, p0, *, retract=None, norm=None, max_iter=100, ftol=1e-12, xtol=1e-12, gtol=1e-15,
             mu0=1e-3, accepted=None, log=None) -> LMResult:
    """Minimise ``cost`` by Levenberg–Marquardt with Nielsen's damping (the one loop of the package).

    Parameters
    ----------
    cost : callable
        ``p -> float``; ``inf`` or ``ValueError`` rejects the step.
    linearise : callable
        ``p -> model`` with ``model.gradient_max`` and ``model.step(mu) -> (h, h_norm, predicted)``; ``step`` may
        raise ``numpy.linalg.LinAlgError`` (the damped system is singular), which counts as a rejected step.
    p0 : object
        The start.
    retract : callable, optional
        ``(p, h) -> p_new``; default ``p + h``.
    norm : callable, optional
        ``p -> float``, the size of ``p`` for the step test; default the Euclidean norm.
    max_iter : int
        Linearisations at most.
    ftol, xtol, gtol : float
        Stop when an accepted step lowers the cost by less than ``ftol`` times the new cost, when
        ``‖h‖ <= xtol (‖p‖ + xtol)``, or when ``‖g‖∞ <= gtol · max(1, F)``.
    mu0 : float
        The first damping (relative to Marquardt's diagonal scaling).
    accepted : callable, optional
        ``(F_old, F_new) -> None``, called after each accepted step (bundle adjustment switches to the loss's
        second-order curvature there).
    log : callable, optional
        ``(n_iter, F, F_new, gradient_max, h_norm, gain, mu, taken) -> None``, called after each tried step.

    Returns
    -------
    LMResult

    Examples
    --------
    Rosenbrock's function as least squares, ``r = (1 - p₀, 10 (p₁ - p₀²))``:

    >>> def lin(p):
    ...     r = np.array([1 - p[0], 10 * (p[1] - p[0] ** 2)]); J = np.array([[-1, 0], [-20 * p[0], 10]])
    ...     return DenseLinearisation(J, r)
    >>> res = minimise(lambda p: 0.5 * ((1 - p[0]) ** 2 + 100 * (p[1] - p[0] ** 2) ** 2), lin, np.array([-1.2, 1]))
    >>> np.round(res.p, 6) + 0.0, res.converged
    (array([1., 1.]), True)
    """
    retract = retract or (lambda p, h: p + h)
    norm = norm or (lambda p: float(np.linalg.norm(p)))
    p = p0
    F = _cost(cost, p)
    if not np.isfinite(F):
        raise ValueError(f"the cost at the start is not finite ({F})")
    costs, n_iter, n_eval = [F], 0, 1
    mu, nu = mu0, 2.0
    model, message, converged = None, "maximum number of iterations reached", False
    while True:
        if model is None:
            if n_iter >= max_iter:
                break
            model = linearise(p)
            n_iter += 1
            if not model.gradient_max > gtol * max(1.0, F):
                message, converged = "gradient is zero to machine precision", True
                break
        try:
            h, h_norm, predicted = model.step(mu)
        except np.linalg.LinAlgError:
            mu, nu = nielsen(mu, nu, -1.0)
            if mu > MU_MAX:
                message, converged = f"damping exceeded {MU_MAX:g}: no further reduction possible", True
                break
            continue
        if h_norm <= xtol * (norm(p) + xtol):
            message, converged = "step size below xtol", True
            break
        p_new = retract(p, h)
        F_new = _cost(cost, p_new)
        n_eval += 1
        gain = (F - F_new) / predicted if predicted > 0 and np.isfinite(F_new) else -1.0
        taken = gain > 0
        if log is not None:
            log(n_iter, F, F_new, model.gradient_max, h_norm, gain, mu, taken)
        mu, nu = nielsen(mu, nu, gain)
        if taken:
            F_old = F
            p, F = p_new, F_new
            costs.append(F)
            model = None
            if accepted is not None:
                accepted(F_old, F)
            if F_old - F <= ftol * F or F == 0.0:
                message, converged = "relative cost reduction below ftol", True
                break
        elif mu > MU_MAX:
            message, converged = f"damping exceeded {MU_MAX:g}: no further reduction possible", True
            break
    return LMResult(p=p, cost=F, costs=costs, n_iter=n_iter, n_eval=n_eval, converged=converged, message=message)


def nielsen(mu, nu, gain):
    """The damping rule of every LM in the package (Nielsen 1999; Madsen, Nielsen & Tingleff 2004, eq. 2.21).

    After a step with gain ratio ``gain`` (actual over predicted decrease): taken (``gain > 0``), the damping
    shrinks by ``max(1/3, 1 - (2 gain - 1)³)`` and ``ν`` resets to 2; rejected, it grows by ``ν`` and ``ν``
    doubles. Element-wise on arrays, so that a batch of small problems (one per point) shares the rule.

    >>> nielsen(1.0, 2.0, 1.0), nielsen(1.0, 2.0, -1.0), nielsen(1.0, 4.0, -1.0)
    ((0.3333333333333333, 2.0), (2.0, 4.0), (4.0, 8.0))
    """
    taken = np.asarray(gain) > 0
    shrink = np.maximum(1 / 3, 1 - (2 * np.asarray(gain, float) - 1) ** 3)
    mu_new, nu_new = np.where(taken, mu * shrink, mu * nu), np.where(taken, 2.0, nu * 2)
    if np.ndim(mu_new) == 0:
        return float(mu_new), float(nu_new)
    return mu_new, nu_new


def _cost(cost, p):
    try:
        F = float(cost(p))
    except ValueError:                  # e.g. a board behind the camera: the step is rejected
        return np.inf
    return F if np.isfinite(F) else np.inf


class DenseLinearisation:
    """The local model of a dense (or small sparse) least-squares problem: ``A = JᵀJ``, ``g = Jᵀr``, and the damped
    step ``(A + μ D) h = -g`` with Marquardt's ``D = diag(A)`` (floored at ``floor · max(diag(A))``, so that a
    parameter the data does not see gets a finite step).

    Parameters
    ----------
    J : (m, n) ndarray or scipy.sparse matrix
    r : (m,) ndarray
        Residuals; the cost is ``½ rᵀr``.
    floor : float
        Relative floor of the scaling ``D``.
    """

    def __init__(self, J, r, floor=1e-12):
        A = J.T @ J
        self.A = A.toarray() if sp.issparse(A) else np.asarray(A)
        self.g = np.asarray(J.T @ r).ravel()
        d = np.diag(self.A)
        self.D = np.maximum(d, floor * max(d.max(initial=0.0), 1e-300))
        self.gradient_max = float(np.abs(self.g).max(initial=0.0))

    def step(self, mu):
        h = np.linalg.solve(self.A + mu * np.diag(self.D), -self.g)
        return h, float(np.linalg.norm(h)), 0.5 * float(h @ (mu * self.D * h - self.g))


def levenberg_marquardt(fun_and_jac, p0, *, max_iter=100, tol=1e-12):
    """Dense least squares ``min ½ ‖r(p)‖²`` by :func:`minimise` (used by camera calibration).

    Parameters
    ----------
    fun_and_jac : callable
        ``p -> (r, J)``, residuals ``(m,)`` and Jacobian ``(m, n)`` (dense, or ``scipy.sparse``: JᵀJ is formed
        sparse, then solved dense — n is small here). A ``ValueError`` rejects the step.
    p0 : (n,) array_like
    max_iter : int
    tol : float
        ``ftol`` and ``xtol`` of :func:`minimise`.

    Returns
    -------
    p : (n,) ndarray
    info : dict
        ``cost`` (0.5·Σr²), ``costs`` (per accepted step, starting with the initial cost), ``n_iter``, ``r``, ``J``
        (at ``p``), ``converged`` (False only when ``max_iter`` ran out).

    Examples
    --------
    >>> f = lambda p: (np.array([p[0] - 1, 10 * (p[1] - p[0] ** 2)]), np.array([[1, 0], [-20 * p[0], 10]]))
    >>> p, info = levenberg_marquardt(f, [-1.2, 1.0])
    >>> np.round(p, 8) + 0.0, info["converged"]
    (array([1., 1.]), True)
    """
    cache = {}

    def evaluate(p):
        key = p.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = fun_and_jac(p)
        return cache[key]

    def cost(p):
        r, _ = evaluate(p)
        return 0.5 * float(r @ r)

    def linearise(p):
        r, J = evaluate(p)
        return DenseLinearisation(J, r)

    p0 = np.asarray(p0, float).copy()
    with single_threaded_blas():           # small dense solves: BLAS threads only wait on each other (see bundle)
        res = minimise(cost, linearise, p0, max_iter=max_iter, ftol=tol, xtol=tol, mu0=1e-3)
        r, J = evaluate(res.p) if res.p.tobytes() in cache else fun_and_jac(res.p)
    return res.p, dict(cost=res.cost, costs=res.costs, n_iter=res.n_iter, r=r, J=J, converged=res.converged)
