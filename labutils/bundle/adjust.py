"""Bundle adjustment: refine cameras and 3D points by minimising the reprojection error.

The problem (H&Z Sec. 18.1; Triggs et al., "Bundle Adjustment — A Modern Synthesis", 2000) is

    minimise  0.5 · Σ_i Σ_{a=x,y} f_scale² ρ(r_ia² / f_scale²),   r_i = π(camera c_i, X_{p_i}) - x_i

over the camera parameters and the 3D points, where ``ρ`` is the identity (``loss='linear'``, plain
least squares) or a robust loss (``'huber'``, ``'cauchy'``, ``'soft_l1'``, ``'arctan'``, as in
:func:`scipy.optimize.least_squares`, applied to each pixel coordinate separately: :mod:`labutils.core.robust`).
The model, its Jacobian and the parametrisation are in :mod:`labutils.bundle.reprojection`; the gauge in
:mod:`labutils.bundle.gauge`.

Two solvers, the same objective:

- ``'lm-schur'``: ours, :mod:`labutils.bundle.schur` (Levenberg–Marquardt with the Schur complement);
- ``'scipy'``: :func:`scipy.optimize.least_squares` (trust-region reflective, ``x_scale='jac'``) with our
  analytic sparse Jacobian (``scipy_jac='analytic'``, default), or finite differences grouped by the
  sparsity mask (``'sparsity'``), or dense finite differences (``'dense'``; small problems only).

How fast each is: ``python -m labutils.bench ba`` measures them, and the README's results table holds its
numbers. Both solvers run with OpenBLAS on one thread (:func:`labutils.core.blas.single_threaded_blas`).

Command line: ``python -m labutils.bundle PROBLEM.txt --solver {lm-schur,scipy} --out SOLVED.txt
[--fix-intrinsics] [--json] [--verbose]`` solves a BAL file (see :mod:`labutils.data.bal`).
"""
import contextlib
import json
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from ..core import cli as _cli
from ..core.blas import single_threaded_blas
from ..core.geometry import rotation_from_angle_axis
from ..core.robust import LOSSES, SECOND_ORDER_AFTER, robust_cost, scipy_loss
from ..core.validation import as_points
from ..data.bal import BALProblem, format_bal, read_bal
from .gauge import apply_gauge, gauge_plan
from .reprojection import (
    Rt_from_camera_params,
    assemble_jacobian,
    camera_params_from_Rt,
    check_problem,
    jacobian_sparsity,
    jacobian_structure,
    project_observations,
)
from .schur import lm_schur


@dataclass
class BundleResult:
    """What :func:`bundle_adjust` returns.

    Attributes
    ----------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (M, 3) ndarray
        The refined cameras (``x_cam = R @ X + t``) and points, in the gauge described by ``gauge``.
    camera_params : (V, k) ndarray
        The same cameras packed as ``[ω, t(, f, k1, k2)]``.
    cost_initial, cost_final : float
        ``0.5 · Σ r²`` in px² (plain squared error, whatever the loss).
    loss_cost_initial, loss_cost_final : float
        The objective actually minimised, ``0.5 · Σ f_scale² ρ(r²/f_scale²)`` (equal to the above for
        ``loss='linear'``).
    n_iter : int
        Iterations (Jacobian evaluations).
    n_eval : int
        Residual evaluations.
    seconds : float
        Wall time of the solve (set-up and checks included).
    success : bool
        True if a convergence test was met (not the iteration limit) and every observed point ends in front of
        its camera (pinhole model).
    message : str
    residuals : (n_obs, 2) ndarray
        Predicted minus observed pixels at the solution.
    solver : str
    free : (k · V + 3 · M,) bool ndarray
        Which columns of :func:`reprojection_jacobian` are free parameters in the gauge of the result
        (False: the anchor camera's pose, one translation coordinate of the scale camera, and whatever
        ``fixed_cameras``, ``fixed_points`` or fixed intrinsics held). ``J[:, free]`` has full rank at a
        regular solution and ``σ² (J[:, free]ᵀ J[:, free])⁻¹`` is a gauge-fixed covariance; quantities
        that do not depend on the gauge (relative poses, ratios of lengths) get the same covariance in
        every gauge.
    gauge : dict
        ``anchor`` (camera whose pose is held), ``scale_camera`` and ``baseline`` (the distance from the
        anchor's centre kept fixed), or empty when no gauge was imposed.
    n_behind : int
        Observations whose point ends behind its camera (pinhole model; 0 at a valid solution).
    """

    R: np.ndarray
    t: np.ndarray
    X: np.ndarray
    camera_params: np.ndarray
    cost_initial: float
    cost_final: float
    loss_cost_initial: float
    loss_cost_final: float
    n_iter: int
    n_eval: int
    seconds: float
    success: bool
    message: str
    residuals: np.ndarray
    solver: str
    free: np.ndarray = field(repr=False)
    gauge: dict = field(default_factory=dict)
    n_behind: int = 0

    @property
    def n_free(self):
        """Number of free parameters ``d`` (after the gauge)."""
        return int(self.free.sum())

    def cost_text(self):
        """``'a -> b px² in n iterations'`` for a log line. With a robust loss: the robust cost the solver lowered,
        and in brackets the plain ``½ Σ r²``, which a robust solve may raise."""
        it = f"in {self.n_iter} iterations"
        if self.loss_cost_initial == self.cost_initial and self.loss_cost_final == self.cost_final:
            return f"{self.cost_initial:.4g} -> {self.cost_final:.4g} px² {it}"
        return (f"robust cost {self.loss_cost_initial:.4g} -> {self.loss_cost_final:.4g} "
                f"(½Σr² {self.cost_initial:.4g} -> {self.cost_final:.4g} px²) {it}")

    def summary(self):
        """A JSON-friendly dict of the scalar results."""
        return dict(solver=self.solver, cost_initial=self.cost_initial, cost_final=self.cost_final,
                    loss_cost_initial=self.loss_cost_initial, loss_cost_final=self.loss_cost_final,
                    iterations=self.n_iter, evaluations=self.n_eval, seconds=self.seconds,
                    success=bool(self.success), message=self.message,
                    n_observations=int(self.residuals.shape[0]), n_free_parameters=self.n_free)


def _scipy(cp0, X0, ci, pi, x, Ks, free_cam, free_pt, loss, f_scale, max_iter, tol, verbose, scipy_jac,
           scipy_options):
    V, k = cp0.shape
    M = X0.shape[0]
    free = np.concatenate([free_cam.ravel(), np.repeat(free_pt, 3)])
    full0 = np.concatenate([cp0.ravel(), X0.ravel()])
    colmap = np.cumsum(free) - 1
    cols = jacobian_structure(ci, pi, V, M, k)
    keep = free[cols.ravel()]
    n_free = int(free.sum())

    def unpack(z):
        full = full0.copy()
        full[free] = z
        return full[:V * k].reshape(V, k), full[V * k:].reshape(M, 3)

    def fun(z):
        cp, X = unpack(z)
        return (project_observations(cp, X, ci, pi, Ks) - x).ravel()

    def jac(z):
        cp, X = unpack(z)
        _, Jc, Jp = project_observations(cp, X, ci, pi, Ks, jac=True)
        return assemble_jacobian(Jc, Jp, cols, n_free, keep, colmap)

    kw = dict(x_scale="jac", f_scale=f_scale, ftol=tol, xtol=1e-2 * tol, gtol=1e-2 * tol, method="trf",
              verbose=2 if verbose else 0)
    if scipy_jac == "analytic":
        kw.update(jac=jac, tr_solver="lsmr")
    elif scipy_jac == "sparsity":
        mask = jacobian_sparsity(V, M, ci, pi, k)[:, free]
        kw.update(jac="2-point", jac_sparsity=mask, tr_solver="lsmr")
    elif scipy_jac == "dense":
        kw.update(jac="2-point", tr_solver="exact")
    else:
        raise ValueError(f"scipy_jac must be 'analytic', 'sparsity' or 'dense'; got {scipy_jac!r}")
    kw.update(scipy_options or {})
    z, n_iter, n_eval = full0[free], 0, 0
    # a robust loss in two phases, as LM-Schur: IRLS until the relative decrease is below 1e-3, then the
    # second-order curvature (unless the caller chose scipy's loss in scipy_options)
    phases = [("linear", tol)] if loss == "linear" else [(scipy_loss(loss, False), SECOND_ORDER_AFTER),
                                                         (scipy_loss(loss, True), tol)]
    if "loss" in (scipy_options or {}):
        phases = [(scipy_options["loss"], tol)]
    for lossfn, ftol in phases:
        opts = dict(kw, loss=lossfn, ftol=max(ftol, tol), max_nfev=max(max_iter - n_eval, 1))
        res = least_squares(fun, z, **opts)
        z, n_iter, n_eval = res.x, n_iter + int(res.njev or res.nfev), n_eval + int(res.nfev)
        if n_eval >= max_iter:
            break
    cp, X = unpack(z)
    return dict(cp=cp, X=X, n_iter=n_iter, n_eval=n_eval, success=res.status > 0, message=res.message)


def bundle_adjust_params(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike,
                         point_indices: ArrayLike, points_2d: ArrayLike, K: ArrayLike = None, *,
                         solver: str = "lm-schur", loss: str = "linear", f_scale: float = 1.0,
                         gauge: str = "first-camera-and-scale", fixed_cameras: ArrayLike = None,
                         fixed_points: ArrayLike = None, fix_intrinsics: bool = False, max_iter: int = 100,
                         tol: float = 1e-6, verbose: bool = False, scipy_jac: str = "analytic",
                         scipy_options: dict = None) -> "BundleResult":
    """Bundle adjustment on packed camera parameters (the engine behind :func:`bundle_adjust` and the BAL CLI).

    Parameters
    ----------
    camera_params : (V, 6) or (V, 9) array_like
        Starting cameras, ``[ω, t]`` (pinhole, with ``K``) or ``[ω, t, f, k1, k2]`` (BAL, ``K=None``).
    points_3d, camera_indices, point_indices, points_2d, K
        As in :func:`reprojection_residuals`.
    fix_intrinsics : bool
        BAL model only: hold ``f, k1, k2`` of every camera (the camera block then has 6 free parameters).
    Others
        As in :func:`bundle_adjust`.

    Returns
    -------
    BundleResult
    """
    t0 = time.perf_counter()
    cp, X, ci, pi, x, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    V, k = cp.shape
    M = X.shape[0]
    if solver not in ("lm-schur", "scipy"):
        raise ValueError(f"solver must be 'lm-schur' or 'scipy'; got {solver!r}")
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")
    if not (np.isfinite(f_scale) and f_scale > 0):
        raise ValueError(f"f_scale must be a positive number (pixels); got {f_scale}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer; got {max_iter}")
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be positive; got {tol}")
    free_pt = np.ones(M, bool)
    if fixed_points is not None:
        fp = np.asarray(fixed_points, dtype=np.int64).ravel()
        if fp.size and (fp.min() < 0 or fp.max() >= M):
            raise ValueError(f"fixed_points must index existing points 0..{M - 1}")
        free_pt[fp] = False
    free_cam, info = gauge_plan(cp, fixed_cameras, None if fixed_points is None else ~free_pt, gauge)
    if fix_intrinsics:
        if k != 9:
            raise ValueError("fix_intrinsics applies to the BAL model (9 camera parameters) only")
        free_cam[:, 6:] = False
    n_cam_obs = np.bincount(ci, minlength=V)
    no_obs = np.flatnonzero((n_cam_obs == 0) & free_cam.any(1))
    if no_obs.size:
        raise ValueError(f"camera(s) {no_obs[:10].tolist()} have no observations: their parameters are "
                         "undetermined (drop them, or hold them with fixed_cameras)")
    n_pt_obs = np.bincount(pi, minlength=M)
    no_obs = np.flatnonzero((n_pt_obs == 0) & free_pt)
    if no_obs.size:
        raise ValueError(f"point(s) {no_obs[:10].tolist()} have no observations: drop them before adjusting")
    n_free = int(free_cam.sum() + 3 * free_pt.sum())
    if info:                                                     # the gauge will hold 7 (or, anchor fixed, 1)
        n_free -= 1 if not free_cam[info["anchor"], :6].any() else 7
    if 2 * ci.shape[0] < n_free:
        raise ValueError(f"fewer residuals ({2 * ci.shape[0]} from {ci.shape[0]} observations) than free "
                         f"parameters ({n_free}): the problem is underdetermined")
    r0 = project_observations(cp, X, ci, pi, Ks) - x
    if not np.all(np.isfinite(r0)):
        bad = np.flatnonzero(~np.all(np.isfinite(r0), axis=1))
        raise ValueError(f"the starting point projects to non-finite pixels for observation(s) {bad[:5].tolist()} "
                         "(a point at a camera's centre?)")
    if Ks is not None:                      # pinhole: every observed point must start in front of its camera
        depth = _depths(cp, X, ci, pi)            # at the centre to rounding (1e-9 of the scene's depths) counts
        behind = np.flatnonzero(depth <= 1e-9 * np.median(np.abs(depth)))
        if behind.size:
            raise ValueError(f"{behind.size} of {ci.size} observations start with the point behind (or at) the "
                             f"camera (observations {behind[:5].tolist()}, e.g. point {pi[behind[0]]} in camera "
                             f"{ci[behind[0]]}): bundle adjustment cannot move a point through a camera's "
                             "principal plane; triangulate with cheirality first (a mirrored frame?)")
    args = (cp, X, ci, pi, x, Ks, free_cam, free_pt, loss, float(f_scale), int(max_iter), float(tol), verbose)
    with single_threaded_blas():
        out = lm_schur(*args) if solver == "lm-schur" else _scipy(*args, scipy_jac, scipy_options)
    cp_f, X_f, free_cam = apply_gauge(out["cp"], out["X"], free_cam, info)
    info = {key: info[key] for key in ("anchor", "scale_camera", "baseline")} if info else {}
    r = project_observations(cp_f, X_f, ci, pi, Ks) - x
    n_behind = int(np.sum(_depths(cp_f, X_f, ci, pi) <= 0)) if Ks is not None else 0
    if n_behind:
        out["success"] = False
        out["message"] = f"{n_behind} observations ended with the point behind its camera: " + str(out["message"])
    R_f, t_f = Rt_from_camera_params(cp_f)
    free = np.concatenate([free_cam.ravel(), np.repeat(free_pt, 3)])
    return BundleResult(R=R_f, t=t_f, X=X_f, camera_params=cp_f, cost_initial=robust_cost(r0),
                        cost_final=robust_cost(r), loss_cost_initial=robust_cost(r0, loss, f_scale),
                        loss_cost_final=robust_cost(r, loss, f_scale), n_iter=out["n_iter"],
                        n_eval=out["n_eval"], seconds=time.perf_counter() - t0, success=bool(out["success"]),
                        message=str(out["message"]), residuals=r, solver=solver, free=free, gauge=info,
                        n_behind=n_behind)


def _depths(cp, X, ci, pi):
    """Depth of each observed point in its camera, ``(R X + t)_z``."""
    R = rotation_from_angle_axis(cp[:, :3])
    return np.einsum("nj,nj->n", R[ci, 2], X[pi]) + cp[ci, 5]


def bundle_adjust(R: ArrayLike, t: ArrayLike, X: ArrayLike, camera_indices: ArrayLike, point_indices: ArrayLike,
                  points_2d: ArrayLike, K: ArrayLike, *, solver: str = "lm-schur", loss: str = "linear",
                  f_scale: float = 1.0, gauge: str = "first-camera-and-scale", fixed_cameras: ArrayLike = None,
                  fixed_points: ArrayLike = None, max_iter: int = 100, tol: float = 1e-6, verbose: bool = False,
                  scipy_jac: str = "analytic", scipy_options: dict = None) -> "BundleResult":
    """Refine calibrated cameras and 3D points by minimising the reprojection error (H&Z Sec. 18.1, A6.3).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Starting poses, ``x_cam = R @ X + t``.
    X : (M, 3) array_like
        Starting points.
    camera_indices, point_indices : (n_obs,) int array_like
    points_2d : (n_obs, 2) array_like
        Observation ``i`` is point ``point_indices[i]`` seen at pixel ``points_2d[i]`` by camera
        ``camera_indices[i]`` (e.g. from :func:`labutils.data.loaders.observations`).
    K : (3, 3) or (V, 3, 3) array_like
        Known calibration, shared or per camera (held fixed).
    solver : {'lm-schur', 'scipy'}
        Our Levenberg–Marquardt with the Schur complement, or :func:`scipy.optimize.least_squares`
        (``x_scale='jac'``, our analytic sparse Jacobian; ``scipy_jac='sparsity'`` uses finite
        differences with :func:`jacobian_sparsity`, ``'dense'`` dense finite differences).
    loss : {'linear', 'huber', 'cauchy', 'soft_l1', 'arctan'}
        Robust loss on each pixel coordinate, with inlier scale ``f_scale`` pixels (scipy's definition).
        LM-Schur minimises the same objective, by iteratively reweighted least squares (weights ``ρ'``)
        while far from the optimum, then with the exact second-order curvature of the loss
        ``ρ' + 2zρ''`` (floored at ``0.01 ρ'``) once the cost decrease slows below 1e-3 relative: IRLS
        alone converges only linearly near the optimum (several times the iterations on the dinosaur), the exact
        curvature alone stalls from a far start. scipy gets
        the same two phases (two calls of ``least_squares`` with the loss as a callable), unless
        ``scipy_options`` names a ``loss`` of its own.
    f_scale : float
    gauge : {'first-camera-and-scale', None}
        How the 7-dof similarity ambiguity is fixed. The default holds the pose of the first camera at
        its starting value (6 dof) and the distance between the centres of the first two cameras
        (1 dof): without this, ``JᵀJ`` has a 7-dimensional null space, the optimum is a valley rather
        than a point, and covariances or comparisons between runs are meaningless. Both solvers iterate
        on all parameters (the damping keeps the steps finite along the valley, and this converges much
        faster than freezing parameters: on the dinosaur, 8 instead of 58 LM iterations, because a
        frozen perturbed first camera forces the whole scene through a slow, nonlinear rigid motion); the
        solution is then moved by the similarity that restores the gauge exactly (it changes no
        residual). With ``fixed_cameras`` the first fixed camera is the anchor, and with two or more
        fixed cameras, or three or more fixed points, nothing more is imposed. ``None`` imposes nothing.
    fixed_cameras : sequence of int, optional
        Cameras whose pose is held (e.g. the already registered cameras of an incremental SfM).
    fixed_points : sequence of int, optional
        Points held fixed (e.g. all of them for a PnP pose refinement).
    max_iter : int
        Iteration limit (LM: Jacobian evaluations; scipy: ``max_nfev``).
    tol : float
        Stop when an accepted step lowers the cost by less than ``tol`` times the cost, or the step is
        shorter than ``0.01 tol · ‖x‖`` (scipy: ``ftol = tol``, ``xtol = gtol = 0.01 tol``). The default 1e-6
        is Ceres's ``function_tolerance`` (and 1e-8 its ``parameter_tolerance``); use 1e-10 or less to
        converge to machine precision (noise-free data).
    scipy_jac : {'analytic', 'sparsity', 'dense'}
        For ``solver='scipy'``: the Jacobian it uses (see ``solver``).
    scipy_options : dict, optional
        Extra keywords for :func:`scipy.optimize.least_squares`, e.g. ``dict(tr_options=dict(atol=1e-10,
        btol=1e-10))``: tighter LSMR tolerances make each step dearer and change how many steps are needed
        (``python -m labutils.bench ba`` compares both).
    verbose : bool
        Print one line per iteration (cost, step, damping), the way Ceres reports.

    Returns
    -------
    BundleResult
        See :class:`BundleResult`; ``cost_*`` are ``0.5 · Σ r²`` in px².

    Raises
    ------
    ValueError
        Wrong shapes (``t`` must be ``(V, 3)``: a ``(3, V)`` array is refused), non-finite values, a singular K,
        indices of missing cameras or points, a free camera or a point without observations, fewer residuals
        than free parameters, an observed point behind (or at the centre of) its camera at the start, or an
        unknown option.

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.core.scene import observations
    >>> s = make_scene(60, 4, noise_px=0.0, rng=np.random.default_rng(0))
    >>> ci, pi, x = observations(s.x_true)
    >>> res = bundle_adjust(s.R, s.t, s.X + 0.01, ci, pi, x, s.K, tol=1e-12)
    >>> res.X.shape, res.cost_final < 1e-12, res.n_free == 4 * 6 - 7 + 3 * 60
    ((60, 3), True, True)
    """
    cp = camera_params_from_Rt(R, t)
    X = as_points(X, "X", dim=3)
    return bundle_adjust_params(cp, X, camera_indices, point_indices, points_2d, K, solver=solver, loss=loss,
                                f_scale=f_scale,
                 gauge=gauge, fixed_cameras=fixed_cameras, fixed_points=fixed_points, max_iter=max_iter,
                 tol=tol, verbose=verbose, scipy_jac=scipy_jac, scipy_options=scipy_options)


def solve_bal(problem: BALProblem, *, solver: str = "lm-schur", fix_intrinsics: bool = False, **kwargs) -> tuple:
    """Bundle-adjust a :class:`labutils.data.BALProblem`; returns ``(solved BALProblem, BundleResult)``.

    By default every BAL parameter is refined (pose, f, k1, k2 of each camera, and the points), as the
    BAL benchmark and Ceres's BAL example do; ``fix_intrinsics=True`` holds f, k1, k2.
    Other keywords go to :func:`bundle_adjust_params` (``loss``, ``gauge``, ``max_iter``, ``tol``, ``verbose``).
    """
    res = bundle_adjust_params(problem.camera_params, problem.points_3d, problem.camera_indices,
                               problem.point_indices, problem.points_2d, None, solver=solver,
                               fix_intrinsics=fix_intrinsics, **kwargs)
    solved = BALProblem(camera_params=res.camera_params, points_3d=res.X, camera_indices=problem.camera_indices,
                        point_indices=problem.point_indices, points_2d=problem.points_2d)
    return solved, res


def _parser():
    ap = _cli.Parser(prog="python -m labutils.bundle",
                                 description="Bundle-adjust a BAL ('Bundle Adjustment in the Large') problem file.")
    ap.add_argument("problem", help="BAL problem file (.txt or .txt.bz2)")
    ap.add_argument("--solver", choices=("lm-schur", "scipy"), default="lm-schur")
    ap.add_argument("--out", required=True, help="where to write the solved problem (BAL format)")
    ap.add_argument("--fix-intrinsics", action="store_true", help="hold f, k1, k2 of every camera")
    ap.add_argument("--loss", choices=LOSSES, default="linear")
    ap.add_argument("--f-scale", type=float, default=1.0, help="inlier scale of the robust loss, pixels")
    ap.add_argument("--gauge", choices=("first-camera-and-scale", "none"), default="first-camera-and-scale")
    ap.add_argument("--max-iter", type=int, default=100)
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--verbose", action="store_true", help="one line per iteration (cost, step, damping) on stderr")
    return ap


def main(argv=None):
    """``python -m labutils.bundle PROBLEM.txt --solver {lm-schur,scipy} --out SOLVED.txt [--fix-intrinsics] [--json]``.

    Reads a BAL file, solves it, writes the solution in BAL format (atomically, mode 0644) and prints a
    summary (JSON with ``--json``). Any failure — a malformed file (naming the line), an unwritable output or
    one that is the problem file (checked before the solve), a bad problem, a solve whose cost is not finite — is
    one line ``error: ...`` on stderr, exit status 2, and nothing is written.
    """
    args = _parser().parse_args(argv)
    _cli.check_distinct([(args.out, "--out")], [(args.problem, "the input PROBLEM file")])
    out = _cli.check_output_path(args.out)
    problem = read_bal(args.problem)
    try:
        # scipy's verbose output goes to stdout: keep it clean; an overflow is not a warning here but the error below
        with contextlib.redirect_stdout(sys.stderr), np.errstate(over="ignore", invalid="ignore"):
            solved, res = solve_bal(problem, solver=args.solver, fix_intrinsics=args.fix_intrinsics, loss=args.loss,
                                    f_scale=args.f_scale, gauge=None if args.gauge == "none" else args.gauge,
                                    max_iter=args.max_iter, tol=args.tol, verbose=args.verbose)
    except ValueError as exc:
        raise _cli.CommandError(f"{args.problem}: {exc}") from None
    if not (np.isfinite(res.cost_initial) and np.isfinite(res.cost_final) and np.isfinite(solved.camera_params).all()
            and np.isfinite(solved.points_3d).all()):
        raise _cli.CommandError(f"{args.problem}: the solve failed: cost {res.cost_initial:.6g} -> "
                                f"{res.cost_final:.6g} is not finite (values too large for the model?); nothing "
                                "written")
    _cli.write_atomically(out, format_bal(solved))
    summary = dict(problem=str(args.problem), out=str(args.out), n_cameras=problem.n_cameras,
                   n_points=problem.n_points, **res.summary())
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{args.problem}: {problem.n_cameras} cameras, {problem.n_points} points, "
              f"{problem.n_observations} observations")
        print(f"{res.solver}: cost 0.5·Σr² {res.cost_initial:.6e} -> {res.cost_final:.6e} in {res.n_iter} "
              f"iterations, {res.seconds:.2f} s ({res.message}); wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
