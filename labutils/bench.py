"""Benchmarks (printed, never asserted): ``python -m labutils.bench ba [--quick | --all]``.

``ba`` times the bundle-adjustment solvers of :mod:`labutils.bundle` on

(a) the real dinosaur problem of notebook 04: the 4,983 ``viff`` tracks, the 36 known cameras perturbed
    (about 1° and 2 % of the camera distance, seed 0) and the points re-triangulated from them, with a
    robust loss (``soft_l1``, the pseudo-Huber, f_scale = 2 px) because the tracks have outliers; see
    :func:`dino_problem`;
(b) the BAL ladybug problem ``bal/problem-49-7776-pre.txt`` (49 cameras, 7,776 points, 31,843
    observations; every BAL parameter refined, plain least squares, as the BAL benchmark does).

For each it prints JSON with the seconds (wall and CPU), iterations, and initial and final cost
``0.5·Σr²`` (and the robust objective) of LM-Schur and of scipy's ``least_squares`` with the sparsity
mask (finite differences), with our analytic sparse Jacobian, and with tighter LSMR tolerances
(``x_scale='jac'`` throughout). pyceres / pycolmap are not project dependencies; the bench only reports
whether ``pyceres`` is importable.

Measured on the 2-core workbook machine (shared with other jobs; ``OPENBLAS_NUM_THREADS=1``):

- dino: LM-Schur 13 iterations, 0.27 s, robust cost 5676.049; scipy with the mask 17 iterations, 3.2 s,
  7e-5 above; with tight LSMR 15 iterations, 14.6 s, the same cost (-5e-9).
- ladybug: LM-Schur 32 iterations, 1.9 s, cost 13344.29; scipy with the mask 410 iterations, 199 s
  wall (113 s CPU), 13388.25 (0.33 % above; with ``tol=1e-8`` and 2000 iterations, 439 s CPU and
  13394.48); with tight LSMR 72 iterations, 1322 s, 13352.11.
"""
import json
import os
import sys
import time

import numpy as np

from .bundle import bundle_adjust, solve_bal
from .data import find_data, load_scene, observations
from .geometry import P_from_KRt, rotation_from_angle_axis
from .metrics import pose_errors
from .triangulation import triangulate_multiview


def perturb_cameras(R, t, rng, rot_deg=1.0, rel_shift=0.02):
    """Rotate each camera by a random ~``rot_deg`` degrees and move its centre by ~``rel_shift`` of the
    mean distance of the centres from their centroid.

    Returns
    -------
    R0 : (V, 3, 3) ndarray
    t0 : (V, 3) ndarray

    >>> R0, t0 = perturb_cameras(np.stack([np.eye(3)] * 3), np.eye(3), np.random.default_rng(0))
    >>> R0.shape, t0.shape
    ((3, 3, 3), (3, 3))
    """
    R, t = np.asarray(R, float), np.asarray(t, float)
    C = -np.einsum("vji,vj->vi", R, t)
    scale = np.linalg.norm(C - C.mean(0), axis=1).mean()
    R0 = np.stack([rotation_from_angle_axis(rng.normal(size=3) * np.radians(rot_deg) / np.sqrt(3)) @ Ri for Ri in R])
    C0 = C + rng.normal(size=C.shape) * rel_shift * scale / np.sqrt(3)
    return R0, -np.einsum("vij,vj->vi", R0, C0)


def dino_problem(rng, scene=None):
    """The perturbed-camera problem on the dinosaur's real tracks (or the synthetic fallback's).

    Returns
    -------
    dict with ``scene``, ``R0``, ``t0``, ``X0`` (re-triangulated with the perturbed cameras),
    ``camera_indices``, ``point_indices``, ``points_2d`` (tracks seen in at least two views).
    """
    scene = load_scene(rng, verbose=False) if scene is None else scene
    tracks = scene.tracks
    tracks = tracks[:, np.isfinite(tracks[..., 0]).sum(0) >= 2]
    R0, t0 = perturb_cameras(scene.R, scene.t, rng)
    Ps = np.stack([P_from_KRt(scene.K, Ri, ti) for Ri, ti in zip(R0, t0)])
    X0 = triangulate_multiview(Ps, tracks)
    ci, pi, x = observations(tracks)
    return dict(scene=scene, R0=R0, t0=t0, X0=X0, camera_indices=ci, point_indices=pi, points_2d=x, tracks=tracks)


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    res = fn()
    return res, time.perf_counter() - w, time.process_time() - c


def _row(res, wall, cpu, **extra):
    return dict(solver=res.solver, seconds=round(wall, 3), cpu_seconds=round(cpu, 3), iterations=res.n_iter,
                evaluations=res.n_eval, cost_initial=res.cost_initial, cost_final=res.cost_final,
                loss_cost_initial=res.loss_cost_initial, loss_cost_final=res.loss_cost_final,
                success=res.success, **extra)


TIGHT_LSMR = dict(tr_options=dict(atol=1e-10, btol=1e-10))
SCIPY_VARIANTS = {
    "scipy-mask": dict(scipy_jac="sparsity"),
    "scipy-mask-tight-lsmr": dict(scipy_jac="sparsity", scipy_options=TIGHT_LSMR),
    "scipy-analytic": dict(scipy_jac="analytic"),
    "scipy-analytic-tight-lsmr": dict(scipy_jac="analytic", scipy_options=TIGHT_LSMR),
}


def bench_dino(max_iter_scipy=2000, variants=SCIPY_VARIANTS, loss="soft_l1", f_scale=2.0):
    rng = np.random.default_rng(0)
    pb = dino_problem(rng)
    s = pb["scene"]
    args = (pb["R0"], pb["t0"], pb["X0"], pb["camera_indices"], pb["point_indices"], pb["points_2d"], s.K)
    rows = []
    res, w, c = _timed(lambda: bundle_adjust(*args, loss=loss, f_scale=f_scale, max_iter=500))
    rows.append(_row(res, w, c, variant="lm-schur", rot_err_deg=float(pose_errors(res.R, res.t, s.R, s.t)[0].mean())))
    for name, kw in variants.items():
        r, w, c = _timed(lambda: bundle_adjust(*args, solver="scipy", loss=loss, f_scale=f_scale,
                                               max_iter=max_iter_scipy, **kw))
        rows.append(_row(r, w, c, variant=name, rel_to_lm=r.loss_cost_final / res.loss_cost_final - 1,
                         speedup_of_lm=round(w / rows[0]["seconds"], 1)))
    return dict(problem=f"{s.source} dino: {s.n_views} cameras, {int(pb['X0'].shape[0])} points, "
                        f"{len(pb['points_2d'])} observations; cameras perturbed 1 deg / 2 %, {loss} f_scale={f_scale}",
                runs=rows)


def bench_ladybug(max_iter_scipy=2000, variants=None):
    from .bal import read_bal

    if variants is None:                                   # the tight-LSMR runs take ~20 min each here
        variants = {"scipy-mask": SCIPY_VARIANTS["scipy-mask"]}
    p = read_bal(find_data("bal/problem-49-7776-pre.txt"))
    rows = []
    (_, res), w, c = _timed(lambda: solve_bal(p, max_iter=500))
    rows.append(_row(res, w, c, variant="lm-schur"))
    for name, kw in variants.items():
        (_, r), w, c = _timed(lambda: solve_bal(p, solver="scipy", max_iter=max_iter_scipy, **kw))
        rows.append(_row(r, w, c, variant=name, rel_to_lm=r.cost_final / res.cost_final - 1,
                         speedup_of_lm=round(w / rows[0]["seconds"], 1)))
    rows.append(dict(reference="pyceres", available=_importable("pyceres"),
                     note="not a project dependency; not run"))
    return dict(problem="BAL ladybug problem-49-7776-pre: 49 cameras, 7776 points, 31843 observations; "
                        "all parameters (pose, f, k1, k2, points)", runs=rows)


def _importable(name):
    import importlib.util

    return importlib.util.find_spec(name) is not None


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] != "ba":
        print("usage: python -m labutils.bench ba [--quick | --all]\n"
              "  default: dino with LM-Schur and four scipy variants (~40 s), ladybug with LM-Schur and scipy\n"
              "           with the mask (~4 min)\n"
              "  --quick: LM-Schur and scipy-analytic only, at most 200 scipy evaluations\n"
              "  --all:   also the tight-LSMR scipy variants on ladybug (~20 min each)", file=sys.stderr)
        return 2
    quick, everything = "--quick" in argv, "--all" in argv
    variants = {"scipy-analytic": SCIPY_VARIANTS["scipy-analytic"]} if quick else SCIPY_VARIANTS
    n = 200 if quick else 2000
    out = dict(machine=dict(cpus=os.cpu_count(), OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS"),
                            load_average=os.getloadavg()),
               dino=bench_dino(n, variants))
    print(json.dumps(out["dino"], indent=1), flush=True)
    try:
        out["ladybug"] = bench_ladybug(n, variants if (quick or everything) else None)
    except FileNotFoundError as exc:
        out["ladybug"] = dict(skipped=str(exc).splitlines()[0])
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
