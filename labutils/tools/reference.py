"""The references the benchmarks time ours against, in the same run: Ceres, the reference bundle adjuster, through
pycolmap (an optional extra: ``pip install -e .[bench]``), and OpenCV's ``solvePnPRansac`` for PnP-RANSAC.

Only the benchmarks use Ceres (:mod:`labutils.tools.bench`): it runs COLMAP's Ceres bundle adjuster on the same
problem our solver gets, with the same cost (plain least squares on the pixel residuals), the same frozen
parameters, one thread, and the stopping rule of ours (relative cost decrease ``tol``, step ``1e-2 tol``), so that
both times come from one run on one machine. Nothing of the workbook needs it; :func:`ceres_available` says
whether it is installed.

Models: the BAL camera (``p = -P[:2] / P[2]``, ``u = f (1 + k1‖p‖² + k2‖p‖⁴) p``, looking down -z) is COLMAP's
``RADIAL`` camera with the principal point at 0 after turning the camera by π about its y axis (a proper
rotation: ``P' = diag(-1, 1, -1) P``) and mirroring the observed x coordinate; the pinhole camera (no skew) is
COLMAP's ``PINHOLE`` with the intrinsics held.
"""
import importlib.util
import time

import cv2
import numpy as np

from ..bundle.adjust import bundle_adjust_params
from ..bundle.reprojection import reprojection_residuals
from ..core.geometry import angle_axis_from_rotation, rotation_from_angle_axis
from ..pose.pnp import pnp_ransac

_FLIP = np.diag([-1.0, 1.0, -1.0])      # BAL camera frame -> COLMAP's (z forward)


def ceres_available() -> bool:
    """True when pycolmap (with its Ceres bundle adjuster) is importable.

    >>> isinstance(ceres_available(), bool)
    True
    """
    return importlib.util.find_spec("pycolmap") is not None


def ceres_bundle_adjust(camera_params, points_3d, camera_indices, point_indices, points_2d, K=None, *,
                        fix_intrinsics=False, max_iter=500, tol=1e-6, threads=1) -> dict:
    """Solve a bundle-adjustment problem with COLMAP's Ceres bundle adjuster (needs pycolmap).

    Parameters
    ----------
    camera_params : (V, 6) or (V, 9) ndarray
        ``[ω, t]`` (pinhole, with ``K`` (3, 3) without skew; intrinsics held) or ``[ω, t, f, k1, k2]`` (BAL,
        ``K=None``; ``f, k1, k2`` refined unless ``fix_intrinsics``).
    points_3d : (M, 3) ndarray
    camera_indices, point_indices : (n,) int ndarray
    points_2d : (n, 2) ndarray
    K : (3, 3) ndarray or None
    fix_intrinsics : bool
    max_iter : int
    tol : float
        Ceres' ``function_tolerance``; ``parameter_tolerance`` is ``1e-2 tol`` (as ours).
    threads : int

    Returns
    -------
    dict
        ``camera_params`` and ``points_3d`` at the end (in the input's parametrisation), ``seconds`` and
        ``cpu_seconds`` (wall and CPU time of the solve, building the problem excluded), ``iterations`` (Ceres'
        successful plus unsuccessful steps),
        ``jacobian_evaluations``, ``ceres_cost_initial``, ``ceres_cost_final`` (Ceres' ``0.5·Σr²``), ``linear_solver``
        and ``termination``.
    """
    import pycolmap as pc

    cp = np.asarray(camera_params, float)
    X = np.asarray(points_3d, float)
    ci, pi = np.asarray(camera_indices, np.int64), np.asarray(point_indices, np.int64)
    x = np.asarray(points_2d, float)
    V, k = cp.shape
    bal = k == 9
    R = rotation_from_angle_axis(cp[:, :3])
    t = cp[:, 3:6].copy()
    if bal:
        R, t, x = _FLIP @ R, t @ _FLIP, x * [-1.0, 1.0]
    rec = pc.Reconstruction()
    order = np.argsort(ci, kind="stable")
    starts = np.searchsorted(ci[order], np.arange(V + 1))
    slot = np.empty(ci.size, np.int64)                   # index of each observation among its image's keypoints
    for c in range(V):
        obs = order[starts[c]:starts[c + 1]]
        slot[obs] = np.arange(obs.size)
        if bal:
            cam = pc.Camera(camera_id=c + 1, model="RADIAL", width=1, height=1,
                            params=[cp[c, 6], 0.0, 0.0, cp[c, 7], cp[c, 8]])
        else:
            cam = pc.Camera(camera_id=c + 1, model="PINHOLE", width=1, height=1,
                            params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
        rec.add_camera_with_trivial_rig(cam)
        im = pc.Image(name=str(c), keypoints=x[obs], camera_id=c + 1, image_id=c + 1)
        rec.add_image_with_trivial_frame(im, pc.Rigid3d(np.hstack([R[c], t[c][:, None]])))
    by_pt = np.argsort(pi, kind="stable")
    pstarts = np.searchsorted(pi[by_pt], np.arange(X.shape[0] + 1))
    ids = []
    for j in range(X.shape[0]):
        track = pc.Track()
        for o in by_pt[pstarts[j]:pstarts[j + 1]]:
            track.add_element(int(ci[o]) + 1, int(slot[o]))
        ids.append(rec.add_point3D(X[j], track))
    opts = pc.BundleAdjustmentOptions()
    opts.print_summary = False
    opts.refine_focal_length = opts.refine_extra_params = bal and not fix_intrinsics
    opts.refine_principal_point = False
    so = opts.ceres.solver_options
    so.num_threads = threads
    so.max_num_iterations = int(max_iter)
    so.function_tolerance, so.parameter_tolerance, so.gradient_tolerance = tol, 1e-2 * tol, 1e-12
    cfg = pc.BundleAdjustmentConfig()
    for c in range(V):
        cfg.add_image(c + 1)
    cfg.fix_gauge(pc.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    adjuster = pc.create_default_bundle_adjuster(opts, cfg, rec)
    wall, cpu = time.perf_counter(), time.process_time()
    summary = adjuster.solve().ceres_summary
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    cp_out = cp.copy()
    for c in range(V):
        pose = rec.images[c + 1].cam_from_world().matrix()
        Rc, tc = pose[:, :3], pose[:, 3]
        if bal:
            Rc, tc = _FLIP @ Rc, _FLIP @ tc
            cp_out[c, 6], _, _, cp_out[c, 7], cp_out[c, 8] = rec.cameras[c + 1].params
        cp_out[c, :3], cp_out[c, 3:6] = angle_axis_from_rotation(Rc[None])[0], tc
    X_out = np.stack([rec.points3D[i].xyz for i in ids])
    return dict(camera_params=cp_out, points_3d=X_out, seconds=wall, cpu_seconds=cpu,
                iterations=int(summary.num_successful_steps + summary.num_unsuccessful_steps),
                jacobian_evaluations=int(summary.num_jacobian_evaluations),
                ceres_cost_initial=float(summary.initial_cost), ceres_cost_final=float(summary.final_cost),
                linear_solver=str(summary.linear_solver_type_used).split(".")[-1],
                termination=str(summary.termination_type).split(".")[-1])


def synthetic_ba_problem(n_cameras: int, points_per_camera: int = 100, *, rng, noise_px: float = 0.5) -> tuple:
    """A synthetic bundle-adjustment problem with the visibility of a video sequence, for the scaling run.

    The cameras move along a circle of radius 20 looking outwards-forwards along the path (a walk around a
    building); each camera creates ``points_per_camera`` new points 5 to 15 units ahead of it, and each point is seen
    by the camera that created it and the next ``L - 1`` cameras (``L`` from 2 to 8, geometric with mean about 4, as
    tracks are in real sequences), with ``noise_px`` pixels of noise. The cameras start perturbed (about 0.5° and
    1 % of the step between cameras) and the points with 1 % of their depth.

    Returns
    -------
    tuple
        ``(camera_params (V, 6), points_3d (M, 3), camera_indices, point_indices, points_2d, K)``: the start,
        the observations and the shared calibration (focal length 500 px, principal point (320, 240)).

    >>> pb = synthetic_ba_problem(10, 20, rng=np.random.default_rng(0))
    >>> pb[0].shape, pb[1].shape, bool(len(pb[2]) >= 2 * len(pb[1]))
    ((10, 6), (180, 3), True)
    """
    V, n = int(n_cameras), int(points_per_camera)
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    ang = np.linspace(0, 2 * np.pi, V, endpoint=False) * min(1.0, V / 60)     # short sequences: an arc
    C = 20 * np.stack([np.cos(ang), np.zeros(V), np.sin(ang)], 1)
    fwd = np.stack([-np.sin(ang), np.zeros(V), np.cos(ang)], 1)               # along the path ...
    out = C / 20
    look = fwd + 0.5 * out                                                      # ... and a bit outwards
    look /= np.linalg.norm(look, axis=1, keepdims=True)
    down = np.array([0.0, 1.0, 0.0])
    right = np.cross(down, look)
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    R = np.stack([right, np.cross(look, right), look], 1)                       # rows: camera axes in the world
    t = -np.einsum("vij,vj->vi", R, C)
    # points: ahead of their camera, within its field of view
    ci0 = np.repeat(np.arange(V), n)
    depth = rng.uniform(5, 15, ci0.size)
    xy = rng.uniform([-0.5, -0.4], [0.5, 0.4], (ci0.size, 2)) * depth[:, None]
    Xc = np.column_stack([xy, depth])
    X = np.einsum("nji,nj->ni", R[ci0], Xc - t[ci0])                            # R^T (x_cam - t)
    L = np.minimum(2 + rng.geometric(0.4, ci0.size) - 1, 8)
    ci = np.concatenate([ci0 + s for s in range(8)])
    pi = np.tile(np.arange(ci0.size), 8)
    keep = (np.repeat(np.arange(8), ci0.size) < np.tile(L, 8)) & (ci < V)
    ci, pi = ci[keep], pi[keep]
    P = np.einsum("nij,nj->ni", R[ci], X[pi]) + t[ci]
    ok = P[:, 2] > 0.5
    ci, pi, P = ci[ok], pi[ok], P[ok]
    u = P[:, :2] / P[:, 2:] @ K[:2, :2].T + K[:2, 2] + noise_px * rng.normal(size=(ci.size, 2))
    seen = np.bincount(pi, minlength=X.shape[0]) >= 2                          # keep points seen twice
    new = np.cumsum(seen) - 1
    o = seen[pi]
    ci, pi, u = ci[o], new[pi[o]], u[o]
    X = X[seen]
    order = np.lexsort((ci, pi))
    ci, pi, u = ci[order], pi[order], u[order]
    step = 20 * (ang[1] - ang[0]) if V > 1 else 1.0
    w = angle_axis_from_rotation(R) + np.deg2rad(0.5) * rng.normal(size=(V, 3)) / np.sqrt(3)
    Rp = rotation_from_angle_axis(w)
    Cp = C + 0.01 * step * rng.normal(size=(V, 3))
    cp0 = np.hstack([w, -np.einsum("vij,vj->vi", Rp, Cp)])
    depth_pt = np.linalg.norm(X - C[ci0[seen]], axis=1)
    X0 = X + 0.01 * depth_pt[:, None] * rng.normal(size=X.shape) / np.sqrt(3)
    return cp0, X0, ci, pi, u, K


def _cost(cp, X, ci, pi, x, K):
    r = reprojection_residuals(cp, X, ci, pi, x, K)
    return 0.5 * float(r @ r)


def compare_with_ceres(problem: tuple, *, fix_intrinsics: bool = False, repeats: int = 3, tol: float = 1e-6,
                       max_iter: int = 500) -> dict:
    """Our LM-Schur and Ceres on one problem, in turn, ``repeats`` times: times, costs and their ratios.

    Both minimise ``0.5·Σr²`` (plain least squares) with the same frozen parameters, on one thread, stopping at a
    relative cost decrease below ``tol``. The cost of each result is evaluated by our own
    :func:`labutils.bundle.reprojection_residuals`. Without pycolmap, only ours runs and ``ceres`` says so.

    Parameters
    ----------
    problem : tuple
        ``(camera_params, points_3d, camera_indices, point_indices, points_2d, K)`` (``K=None``: BAL model).

    Returns
    -------
    dict
        ``ours`` and ``ceres`` (median ``seconds``, ``cpu_seconds``, ``steps`` tried, ``cost_final``), and
        ``ratio_cpu``/``ratio_wall`` (ours over Ceres, the median of the per-repeat ratios; above 1: we are
        slower) and ``cost_ratio`` (ours over Ceres; at most 1: we reach a cost no higher).
    """
    cp, X, ci, pi, x, K = problem
    ours, ceres = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        res = bundle_adjust_params(cp, X, ci, pi, x, K, fix_intrinsics=fix_intrinsics, max_iter=max_iter, tol=tol)
        ours.append(dict(seconds=time.perf_counter() - w, cpu_seconds=time.process_time() - c,
                         steps=res.n_eval - 1, iterations=res.n_iter, cost_final=res.cost_final))
        if ceres_available():
            out = ceres_bundle_adjust(cp, X, ci, pi, x, K, fix_intrinsics=fix_intrinsics, max_iter=max_iter,
                                      tol=tol)
            ceres.append(dict(seconds=out["seconds"], cpu_seconds=out["cpu_seconds"], steps=out["iterations"],
                              iterations=out["jacobian_evaluations"],
                              cost_final=_cost(out["camera_params"], out["points_3d"], ci, pi, x, K),
                              linear_solver=out["linear_solver"], termination=out["termination"]))

    def median(rows):
        return {key: (float(np.median([r[key] for r in rows])) if isinstance(rows[0][key], float | int)
                      else rows[0][key]) for key in rows[0]}

    row = dict(n_cameras=len(cp), n_points=len(X), n_observations=len(ci), ours=median(ours))
    if not ceres:
        row["ceres"] = "not installed (pip install -e .[bench])"
        return row
    row["ceres"] = median(ceres)
    row["ratio_cpu"] = round(float(np.median([a["cpu_seconds"] / b["cpu_seconds"] for a, b in zip(ours, ceres)])), 3)
    row["ratio_wall"] = round(float(np.median([a["seconds"] / b["seconds"] for a, b in zip(ours, ceres)])), 3)
    row["cost_ratio"] = row["ours"]["cost_final"] / row["ceres"]["cost_final"]
    return row


def scaling_run(sizes=(10, 30, 100, 300), *, points_per_camera: int = 100, repeats: int = 1, progress=None) -> dict:
    """CPU time per step against observations, ours and Ceres, on :func:`synthetic_ba_problem` of each size.

    A step is a damped linear solve tried (accepted or not): ours ``n_eval - 1``, Ceres' successful plus
    unsuccessful iterations. The slope is the least-squares fit of ``log(seconds per step)`` against
    ``log(observations)`` (1: linear).

    Returns
    -------
    dict
        ``runs`` (one :func:`compare_with_ceres` row per size, with ``ms_per_step`` of each solver) and
        ``slope`` (``ours``, ``ceres`` when installed).
    """
    runs = []
    for V in sizes:
        row = compare_with_ceres(synthetic_ba_problem(V, points_per_camera, rng=np.random.default_rng(V)),
                                 repeats=repeats)
        for who in ("ours", "ceres"):
            if isinstance(row[who], dict):
                row[who]["ms_per_step"] = round(1e3 * row[who]["cpu_seconds"] / max(row[who]["steps"], 1), 2)
        runs.append(row)
        if progress is not None:
            progress(f"scaling: {V} cameras, {row['n_observations']} observations: ours "
                     f"{row['ours']['ms_per_step']} ms/step" + (f", ceres {row['ceres']['ms_per_step']} ms/step"
                                                                 if isinstance(row["ceres"], dict) else ""))
    n = np.log([r["n_observations"] for r in runs])
    slope = {}
    for who in ("ours", "ceres"):
        if len(runs) >= 2 and all(isinstance(r[who], dict) for r in runs):
            slope[who] = round(float(np.polyfit(n, np.log([r[who]["ms_per_step"] for r in runs]), 1)[0]), 3)
    return dict(problem=f"synthetic sequences, {points_per_camera} new points per camera, tracks of 2-8 views, "
                        "plain least squares, 6 parameters per camera (K known)", runs=runs, slope=slope)


def compare_pnp_with_opencv(sizes=(40, 80, 120, 160, 200), *, per_size: int = 4, outlier_ratio: float = 0.3,
                            repeats: int = 3, threshold_px: float = 2.0, seed: int = 0) -> dict:
    """:func:`labutils.pose.pnp_ransac` against OpenCV's ``solvePnPRansac`` (AP3P, one thread) on the same problems.

    Each problem: ``n`` points 5 to 7 units in front of a camera (f = 800 px, 640 × 480), 0.5 px noise, a fraction
    ``outlier_ratio`` of the pixels replaced by uniform ones; both with the same threshold and confidence 0.9999.
    Times are CPU seconds per call (median over the problems, then over ``repeats`` passes, passes alternating).

    Returns
    -------
    dict
        ``ours`` and ``opencv``: ``ms_per_call``, ``median_rotation_error_deg``, ``inlier_recall`` (true inliers
        found), ``failures`` (no pose, or a rotation error above 1°); ``ratio`` (ours over OpenCV).
    """
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    problems = []
    for n in sizes:
        for _ in range(per_size):
            R = rotation_from_angle_axis(0.3 * rng.normal(size=3))
            t = 0.3 * rng.normal(size=3)
            Xc = rng.uniform(-1, 1, (n, 3)) + [0, 0, 6]
            x = Xc[:, :2] / Xc[:, 2:] * 800 + [320, 240] + 0.5 * rng.normal(size=(n, 2))
            out = rng.random(n) < outlier_ratio
            x[out] = rng.uniform([0, 0], [640, 480], (out.sum(), 2))
            problems.append(((Xc - t) @ R, x, R, ~out))
    cv2.setNumThreads(1)

    def rot_err(Ra, Rb):
        return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))

    def ours(i, X, x):
        res = pnp_ransac(X, x, K, rng=np.random.default_rng(i), threshold_px=threshold_px)
        return res.R, res.inliers

    def opencv(i, X, x):
        ok, rvec, tvec, inl = cv2.solvePnPRansac(X, x, K, None, reprojectionError=threshold_px, confidence=0.9999,
                                                 iterationsCount=10000, flags=cv2.SOLVEPNP_AP3P)
        mask = np.zeros(len(X), bool)
        if inl is not None:
            mask[inl.ravel()] = True
        return (cv2.Rodrigues(rvec)[0] if ok else None), mask

    out = {}
    passes = {"ours": [], "opencv": []}
    for _ in range(repeats):
        for name, fn in (("ours", ours), ("opencv", opencv)):
            times, errs, recall, fails = [], [], [], 0
            for i, (X, x, R, inl) in enumerate(problems):
                c = time.process_time()
                try:
                    R_est, mask = fn(i, X, x)
                except ValueError:
                    R_est, mask = None, np.zeros(len(X), bool)
                times.append(time.process_time() - c)
                e = rot_err(R_est, R) if R_est is not None else np.inf
                fails += not e < 1.0
                errs.append(e)
                recall.append(float((mask & inl).sum() / inl.sum()))
            passes[name].append(dict(ms_per_call=1e3 * float(np.median(times)),
                                     median_rotation_error_deg=float(np.median(errs)),
                                     inlier_recall=float(np.mean(recall)), failures=fails))
    for name, rows in passes.items():
        out[name] = dict(rows[0], ms_per_call=round(float(np.median([r["ms_per_call"] for r in rows])), 3))
    out["ratio"] = round(out["ours"]["ms_per_call"] / out["opencv"]["ms_per_call"], 2)
    out["problems"] = (f"{len(problems)} problems of {min(sizes)}-{max(sizes)} points, {outlier_ratio:.0%} outliers, "
                       f"threshold {threshold_px} px, confidence 0.9999, one thread")
    return out
