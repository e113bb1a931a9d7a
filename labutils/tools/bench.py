"""Benchmarks (printed, never asserted): ``python -m labutils.bench ba [--quick | --all]`` and
``python -m labutils.bench notebooks [NOTEBOOK ...]``.

``notebooks`` runs each notebook top to bottom in a fresh kernel (as nbval does; nothing is saved) and prints its
seconds, its slowest cell, and whether it is within the suite's budget of 90 s per notebook; the README's run
times are what it prints.

``ba`` times the bundle-adjustment solvers of :mod:`labutils.bundle.adjust` on

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

The README's results table quotes what this prints on the 2-core workbook machine. Progress goes to stderr, one
JSON document to stdout (``python -m labutils.bench ba | python -m json.tool`` works).
"""
import importlib.util
import json
import os
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from ..bundle.adjust import bundle_adjust, solve_bal
from ..core import cli as _cli
from ..core.geometry import P_from_KRt
from ..core.metrics import pose_errors
from ..core.scene import observations
from ..core.synthetic import perturb_cameras
from ..core.validation import as_count
from ..data.bal import read_bal
from ..data.loaders import load_scene
from ..data.paths import find_data
from ..twoview.triangulation import triangulate_multiview


def dino_problem(*, rng, scene=None):
    """The perturbed-camera problem on the dinosaur's real tracks (or the synthetic fallback's).

    Returns
    -------
    dict with ``scene``, ``R0``, ``t0``, ``X0`` (re-triangulated with the perturbed cameras),
    ``camera_indices``, ``point_indices``, ``points_2d`` (tracks seen in at least two views).
    """
    scene = load_scene(rng=rng, verbose=False) if scene is None else scene
    tracks = scene.tracks
    tracks = tracks[:, np.isfinite(tracks[..., 0]).sum(0) >= 2]
    R0, t0 = perturb_cameras(scene.R, scene.t, rng=rng)
    Ps = np.stack([P_from_KRt(scene.K, Ri, ti) for Ri, ti in zip(R0, t0)])
    X0 = triangulate_multiview(Ps, tracks)
    ci, pi, x = observations(tracks)
    return dict(scene=scene, R0=R0, t0=t0, X0=X0, camera_indices=ci, point_indices=pi, points_2d=x, tracks=tracks)


def subproblem(R0: np.ndarray, t0: np.ndarray, tracks: np.ndarray, K: np.ndarray, n_views: int,
               max_tracks: int = None) -> tuple:
    """A smaller bundle-adjustment problem cut from a bigger one, for timing solvers at several sizes.

    Parameters
    ----------
    R0 : (V, 3, 3) ndarray
    t0 : (V, 3) ndarray
        Starting cameras (e.g. perturbed).
    tracks : (V, M, 2) ndarray
        Pixels, NaN where a point is not seen.
    K : (3, 3) ndarray
    n_views : int
        Keep the first ``n_views`` cameras ...
    max_tracks : int, optional
        ... and ``max_tracks`` of the tracks seen at least twice among them (evenly spread over their order).

    Returns
    -------
    tuple
        ``(R0, t0, X0, camera_indices, point_indices, points_2d, K)``, the positional arguments of
        :func:`labutils.bundle.bundle_adjust`, with ``X0`` triangulated (DLT) from the starting cameras.

    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(30, 4, noise_px=0.5, rng=np.random.default_rng(0))
    >>> pb = subproblem(s.R, s.t, s.x_meas, s.K, 3, max_tracks=10)
    >>> pb[2].shape, pb[5].shape
    ((10, 3), (30, 2))
    """
    n_views = as_count(n_views, "n_views", 2)
    if n_views > len(R0):
        raise ValueError(f"n_views must be at most the {len(R0)} cameras of R0; got {n_views}")
    sub = tracks[:n_views]
    sub = sub[:, np.isfinite(sub[..., 0]).sum(0) >= 2]
    if max_tracks is not None and sub.shape[1] > max_tracks:            # evenly spread over the tracks
        keep = np.linspace(0, sub.shape[1] - 1, as_count(max_tracks, "max_tracks")).round().astype(int)
        sub = sub[:, np.unique(keep)]
    if sub.shape[1] == 0:
        raise ValueError(f"no track is seen twice in the first {n_views} views")
    Ps = np.stack([P_from_KRt(K, R, t) for R, t in zip(R0[:n_views], t0[:n_views])])
    ci, pi, x = observations(sub)
    return R0[:n_views], t0[:n_views], triangulate_multiview(Ps, sub), ci, pi, x, K


# the solvers the notebook and the command line time, by name: keywords of bundle_adjust
TIGHT_LSMR = dict(tr_options=dict(atol=1e-10, btol=1e-10))
SOLVERS = {
    "LM-Schur": dict(solver="lm-schur"),
    "scipy, no mask": dict(solver="scipy", scipy_jac="dense"),
    "scipy, mask": dict(solver="scipy", scipy_jac="sparsity"),
    "scipy, mask, tight LSMR": dict(solver="scipy", scipy_jac="sparsity", scipy_options=TIGHT_LSMR),
    "scipy, analytic": dict(solver="scipy", scipy_jac="analytic"),
}


def time_solvers(problem: tuple, names, *, loss: str = "soft_l1", f_scale: float = 2.0, max_iter: int = 500,
                 progress=None, show_cost: bool = True) -> list:
    """Run :func:`labutils.bundle.bundle_adjust` with each named solver on one problem, timed (wall clock).

    Parameters
    ----------
    problem : tuple
        The positional arguments of ``bundle_adjust`` (e.g. from :func:`subproblem`).
    names : sequence of str
        Keys of :data:`SOLVERS`: ``'LM-Schur'``, ``'scipy, no mask'`` (dense finite differences; small problems
        only), ``'scipy, mask'`` (finite differences grouped by the sparsity mask, LSMR), ``'scipy, mask, tight
        LSMR'``, ``'scipy, analytic'``.
    loss, f_scale, max_iter
        As in ``bundle_adjust`` (the same for every solver).
    progress : callable, optional
        Called with one line of text per run.
    show_cost : bool
        Put the final cost in that line (not meaningful for runs cut short after a few iterations).

    Returns
    -------
    list of dict
        One per run: ``name``, ``iterations``, ``seconds``, ``seconds_per_iteration``, ``cost_final``
        (``0.5·Σr²``), ``loss_cost_final`` (the robust objective), ``n_params`` and ``result`` (the
        :class:`labutils.bundle.BundleResult`).

    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(20, 3, noise_px=0.5, rng=np.random.default_rng(0))
    >>> rows = time_solvers(subproblem(s.R, s.t, s.x_meas, s.K, 3), ["LM-Schur", "scipy, mask"], loss="linear")
    >>> [r["name"] for r in rows], bool(abs(rows[0]["cost_final"] / rows[1]["cost_final"] - 1) < 1e-3)
    (['LM-Schur', 'scipy, mask'], True)
    """
    unknown = [n for n in names if n not in SOLVERS]
    if unknown:
        raise ValueError(f"names must be keys of SOLVERS {list(SOLVERS)}; got {unknown}")
    n_params = 6 * len(problem[0]) + 3 * len(problem[2])
    rows = []
    for name in names:
        (res, wall, _) = _timed(lambda name=name: bundle_adjust(*problem, loss=loss, f_scale=f_scale,
                                                                max_iter=max_iter, **SOLVERS[name]))
        rows.append(dict(name=name, iterations=res.n_iter, seconds=wall, seconds_per_iteration=wall / res.n_iter,
                         cost_final=res.cost_final, loss_cost_final=res.loss_cost_final, n_params=n_params,
                         result=res))
        if progress is not None:
            progress(f"  {name:24s} {res.n_iter:4d} iterations {wall:8.2f} s  ({1e3 * wall / res.n_iter:7.1f} ms per "
                     "iteration)" + (f"  cost {res.loss_cost_final:.7g}" if show_cost else ""))
    return rows


def time_per_iteration(R0: np.ndarray, t0: np.ndarray, tracks: np.ndarray, K: np.ndarray, sizes, names, *,
                       n_iter: int = 3, progress=None) -> list:
    """Seconds per iteration of each solver on growing subproblems: what the sparsity mask and the Schur
    complement are worth as the problem grows.

    Each solver runs ``n_iter`` iterations (plain least squares) on :func:`subproblem` of each size; the time of a
    run divided by its iterations (Jacobian evaluations: scipy counts a rejected step as a residual evaluation
    only, so it may report fewer) is one point. A dense solver's iteration grows between the square (finite
    differences, one residual evaluation per parameter) and the cube (the dense factorisation) of the number of
    parameters, a sparse one's about linearly.

    Parameters
    ----------
    R0, t0, tracks, K
        As in :func:`subproblem`.
    sizes : sequence of (n_views, max_tracks)
    names : sequence of str
        Keys of :data:`SOLVERS`.
    n_iter : int
    progress : callable, optional

    Returns
    -------
    list of dict
        One per (size, solver), as :func:`time_solvers` returns, with ``n_views`` and ``n_points``.
    """
    rows = []
    for n_views, max_tracks in sizes:
        pb = subproblem(R0, t0, tracks, K, n_views, max_tracks)
        if progress is not None:
            progress(f"{n_views} views, {len(pb[2])} points ({6 * n_views + 3 * len(pb[2])} parameters):")
        for row in time_solvers(pb, names, loss="linear", max_iter=n_iter, progress=progress, show_cost=False):
            rows.append(dict(row, n_views=n_views, n_points=len(pb[2])))
    return rows


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    res = fn()
    return res, time.perf_counter() - w, time.process_time() - c


def _row(res, wall, cpu, **extra):
    return dict(solver=res.solver, seconds=round(wall, 3), cpu_seconds=round(cpu, 3), iterations=res.n_iter,
                evaluations=res.n_eval, cost_initial=res.cost_initial, cost_final=res.cost_final,
                loss_cost_initial=res.loss_cost_initial, loss_cost_final=res.loss_cost_final,
                success=res.success, **extra)


SCIPY_VARIANTS = {
    "scipy-mask": dict(scipy_jac="sparsity"),
    "scipy-mask-tight-lsmr": dict(scipy_jac="sparsity", scipy_options=TIGHT_LSMR),
    "scipy-analytic": dict(scipy_jac="analytic"),
    "scipy-analytic-tight-lsmr": dict(scipy_jac="analytic", scipy_options=TIGHT_LSMR),
}


def _say(msg):
    print(msg, file=sys.stderr, flush=True)


def bench_dino(max_iter_scipy=2000, variants=SCIPY_VARIANTS, loss="soft_l1", f_scale=2.0, progress=_say):
    """LM-Schur and each scipy variant on :func:`dino_problem` (seed 0): a dict with the problem and one row per
    run (seconds, iterations, costs, and how each compares with LM-Schur)."""
    rng = np.random.default_rng(0)
    pb = dino_problem(rng=rng)
    s = pb["scene"]
    args = (pb["R0"], pb["t0"], pb["X0"], pb["camera_indices"], pb["point_indices"], pb["points_2d"], s.K)
    rows = []
    progress("dino: lm-schur ...")
    res, w, c = _timed(lambda: bundle_adjust(*args, loss=loss, f_scale=f_scale, max_iter=500))
    rows.append(_row(res, w, c, variant="lm-schur", rot_err_deg=float(pose_errors(res.R, res.t, s.R, s.t)[0].mean())))
    progress(f"dino: lm-schur {w:.2f} s")
    for name, kw in variants.items():
        progress(f"dino: {name} ...")
        r, w, c = _timed(lambda kw=kw: bundle_adjust(*args, solver="scipy", loss=loss, f_scale=f_scale,
                                                     max_iter=max_iter_scipy, **kw))
        rows.append(_row(r, w, c, variant=name, rel_to_lm=r.loss_cost_final / res.loss_cost_final - 1,
                         speedup_of_lm=round(w / rows[0]["seconds"], 1)))
        progress(f"dino: {name} {w:.2f} s")
    return dict(problem=f"{s.source} dino: {s.n_views} cameras, {int(pb['X0'].shape[0])} points, "
                        f"{len(pb['points_2d'])} observations; cameras perturbed 1 deg / 2 %, {loss} f_scale={f_scale}",
                runs=rows)


def bench_ladybug(max_iter_scipy=2000, variants=None, progress=_say):
    """LM-Schur and scipy on the BAL ladybug problem (every BAL parameter refined, plain least squares)."""
    if variants is None:                                   # the tight-LSMR runs take ~20 min each here
        variants = {"scipy-mask": SCIPY_VARIANTS["scipy-mask"]}
    p = read_bal(find_data("bal/problem-49-7776-pre.txt"))
    rows = []
    progress("ladybug: lm-schur ...")
    (_, res), w, c = _timed(lambda: solve_bal(p, max_iter=500))
    rows.append(_row(res, w, c, variant="lm-schur"))
    progress(f"ladybug: lm-schur {w:.2f} s")
    for name, kw in variants.items():
        progress(f"ladybug: {name} ... (minutes)")
        (_, r), w, c = _timed(lambda kw=kw: solve_bal(p, solver="scipy", max_iter=max_iter_scipy, **kw))
        rows.append(_row(r, w, c, variant=name, rel_to_lm=r.cost_final / res.cost_final - 1,
                         speedup_of_lm=round(w / rows[0]["seconds"], 1)))
        progress(f"ladybug: {name} {w:.2f} s")
    rows.append(dict(reference="pyceres", available=importlib.util.find_spec("pyceres") is not None,
                     note="not a project dependency; not run"))
    return dict(problem="BAL ladybug problem-49-7776-pre: 49 cameras, 7776 points, 31843 observations; "
                        "all parameters (pose, f, k1, k2, points)", runs=rows)


NOTEBOOK_BUDGET_S = 90.0          # each notebook under nbval, on the 2-core CI machine (the developers' guide)
NOTEBOOK_DIR = Path(__file__).resolve().parents[2] / "notebooks"


def _cell_seconds(cell):
    """Seconds a code cell took, from the timestamps nbclient records (None if missing)."""
    ex = cell.get("metadata", {}).get("execution", {})
    start, end = ex.get("iopub.execute_input"), ex.get("shell.execute_reply")
    if not (start and end):
        return None
    return (datetime.fromisoformat(end) - datetime.fromisoformat(start)).total_seconds()


def time_notebooks(paths, *, timeout=900, keep=None, progress=_say):
    """Run each notebook in a fresh ``python3`` kernel from its own folder; one row per notebook.

    With ``keep`` (a folder), the executed copy of each notebook, outputs included, is written there under its own
    name; the notebooks themselves are never written.

    Rows: ``notebook``, ``seconds`` (wall, kernel start included), ``slowest_cell`` (index, seconds, first line),
    ``budget_seconds`` and ``within_budget``. A cell that raises stops the run with a
    :class:`labutils.core.cli.CommandError` naming the notebook and the cell.
    """
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError

    rows = []
    for path in paths:
        path = Path(path)
        try:
            nb = nbformat.read(path, as_version=4)
        except (OSError, ValueError) as exc:
            raise _cli.CommandError(f"{path}: cannot read the notebook ({exc})") from None
        progress(f"{path.name} ...")
        client = NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                resources={"metadata": {"path": str(path.parent)}})
        wall = time.perf_counter()
        try:
            client.execute()
        except CellExecutionError:
            bad = next(((i, o) for i, c in enumerate(nb.cells) if c.cell_type == "code"
                        for o in c.get("outputs", []) if o.get("output_type") == "error"), (None, {}))
            i, err = bad
            raise _cli.CommandError(f"{path}: cell {i} raised {err.get('ename', 'an error')}: "
                                    f"{err.get('evalue', '')}") from None
        wall = time.perf_counter() - wall
        if keep is not None:
            _cli.write_atomically(Path(keep) / path.name, nbformat.writes(nb).encode())
        times = [(i, _cell_seconds(c)) for i, c in enumerate(nb.cells) if c.cell_type == "code"]
        times = [(i, t) for i, t in times if t is not None]
        i, t = max(times, key=lambda it: it[1]) if times else (None, 0.0)
        first = nb.cells[i].source.splitlines()[0][:80] if i is not None and nb.cells[i].source else ""
        rows.append(dict(notebook=path.name, seconds=round(wall, 1),
                         slowest_cell=dict(index=i, seconds=round(t, 1), first_line=first),
                         budget_seconds=NOTEBOOK_BUDGET_S, within_budget=bool(wall < NOTEBOOK_BUDGET_S)))
        progress(f"{path.name}: {wall:.1f} s")
    return rows


def _parser():
    ap = _cli.Parser(prog="python -m labutils.bench",
                                 description="Benchmarks, printed as one JSON document (never asserted).")
    sub = ap.add_subparsers(dest="what", required=True)
    ba = sub.add_parser("ba", help="bundle adjustment: LM-Schur against scipy's least_squares",
                        description="Time LM-Schur against scipy on the dinosaur (default: four scipy variants, "
                                    "~40 s) and the BAL ladybug problem (LM-Schur and scipy with the mask, ~4 min).")
    size = ba.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="LM-Schur and scipy-analytic only, <= 200 scipy evaluations")
    size.add_argument("--all", action="store_true", help="also the tight-LSMR scipy variants on ladybug (~20 min each)")
    nbs = sub.add_parser("notebooks", help="run each notebook in a fresh kernel and time it against the 90 s budget",
                         description="Run notebooks top to bottom (nothing is saved) and print their seconds, "
                                     "slowest cell and whether each is within the 90 s budget.")
    nbs.add_argument("paths", nargs="*", metavar="NOTEBOOK",
                     help="notebooks to run (default: every notebooks/NN_*.ipynb of the workbook)")
    nbs.add_argument("--keep", type=Path, metavar="DIR",
                     help="also write each executed notebook, with its outputs, into DIR (not the notebooks' folder)")
    return ap


def main(argv=None):
    """``python -m labutils.bench ba [--quick | --all]`` or ``notebooks [NOTEBOOK ...]``: progress on stderr, one
    JSON document on stdout."""
    args = _parser().parse_args(argv)
    machine = dict(cpus=os.cpu_count(), OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS"),
                   load_average=os.getloadavg())
    if args.what == "notebooks":
        paths = [Path(p) for p in args.paths] or sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))
        for p in paths:
            if not p.is_file():
                raise _cli.CommandError(f"{p}: no such notebook")
        if args.keep is not None:
            if not args.keep.is_dir():
                raise _cli.CommandError(f"{args.keep}: no such folder (--keep)")
            if any(args.keep.resolve() == p.resolve().parent for p in paths):
                raise _cli.CommandError(f"{args.keep}: --keep must not be the notebooks' own folder")
            _cli.check_distinct([(args.keep / p.name, f"--keep (for {p})") for p in paths],
                                [(p, "a notebook to run") for p in paths])
        rows = time_notebooks(paths, keep=args.keep)
        print(json.dumps(dict(machine=machine, notebooks=rows,
                              total_seconds=round(sum(r["seconds"] for r in rows), 1)), indent=1))
        return 0
    variants = {"scipy-analytic": SCIPY_VARIANTS["scipy-analytic"]} if args.quick else SCIPY_VARIANTS
    n = 200 if args.quick else 2000
    out = dict(machine=machine, dino=bench_dino(n, variants))
    try:
        out["ladybug"] = bench_ladybug(n, variants if (args.quick or args.all) else None)
    except FileNotFoundError as exc:
        out["ladybug"] = dict(skipped=str(exc).splitlines()[0])
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
