"""The benchmark helpers notebook 04 uses (subproblem, time_solvers, time_per_iteration) and the command line's
refusals, and ``bench notebooks`` on tiny notebooks. Timings are printed by the benchmark, never asserted here
(only that the slowest cell is the one that sleeps)."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from labutils.bundle.reprojection import reprojection_residuals
from labutils.core.synthetic import make_scene, perturb_cameras
from labutils.tools.bench import SOLVERS, subproblem, time_per_iteration, time_solvers

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def turntable():
    s = make_scene(80, 6, layout="turntable", noise_px=0.5, rng=np.random.default_rng(2))
    R0, t0 = perturb_cameras(s.R, s.t, rng=np.random.default_rng(3), rot_deg=0.5, rel_shift=0.01)
    return s, R0, t0


def test_subproblem_keeps_views_and_spread_tracks(turntable):
    s, R0, t0 = turntable
    R, t, X, ci, pi, x, K = subproblem(R0, t0, s.x_meas, s.K, 4, max_tracks=20)
    assert R.shape == (4, 3, 3) and t.shape == (4, 3) and X.shape == (20, 3)
    assert ci.max() < 4 and pi.max() == 19 and np.bincount(pi).min() >= 2     # every track seen twice
    assert np.all(np.isfinite(X))


def test_subproblem_refuses_bad_sizes(turntable):
    s, R0, t0 = turntable
    with pytest.raises(ValueError, match="n_views"):
        subproblem(R0, t0, s.x_meas, s.K, 7)
    with pytest.raises(ValueError, match="n_views"):
        subproblem(R0, t0, s.x_meas, s.K, 1)
    with pytest.raises(ValueError, match="max_tracks"):
        subproblem(R0, t0, s.x_meas, s.K, 3, max_tracks=0)


def test_time_solvers_rows_and_same_optimum(turntable):
    s, R0, t0 = turntable
    rows = time_solvers(subproblem(R0, t0, s.x_meas, s.K, 4), ["LM-Schur", "scipy, analytic"], loss="linear")
    assert [r["name"] for r in rows] == ["LM-Schur", "scipy, analytic"]
    for r in rows:
        assert r["iterations"] >= 1 and r["seconds"] > 0 and r["result"].success
        assert np.isclose(r["seconds_per_iteration"], r["seconds"] / r["iterations"])
    assert abs(rows[1]["cost_final"] / rows[0]["cost_final"] - 1) < 1e-4


def test_time_solvers_refuses_unknown_names(turntable):
    s, R0, t0 = turntable
    with pytest.raises(ValueError, match="SOLVERS"):
        time_solvers(subproblem(R0, t0, s.x_meas, s.K, 3), ["ceres"])
    assert {"LM-Schur", "scipy, no mask", "scipy, mask"} <= set(SOLVERS)


def test_time_per_iteration_one_row_per_size_and_solver(turntable, capsys):
    s, R0, t0 = turntable
    rows = time_per_iteration(R0, t0, s.x_meas, s.K, [(3, 15), (4, 30)], ["scipy, no mask", "LM-Schur"], n_iter=2,
                              progress=print)
    assert [(r["n_views"], r["name"]) for r in rows] == [(3, "scipy, no mask"), (3, "LM-Schur"),
                                                         (4, "scipy, no mask"), (4, "LM-Schur")]
    assert all(r["n_params"] == 6 * r["n_views"] + 3 * r["n_points"] for r in rows)
    assert "per iteration" in capsys.readouterr().out


def test_command_line_refuses_unknown_arguments():
    r = subprocess.run([sys.executable, "-m", "labutils.bench", "ba", "--fast"], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 2 and r.stdout == "" and "--fast" in r.stderr


def _notebook(path, *sources):
    import nbformat

    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(s) for s in sources]
    nbformat.write(nb, path)
    return path


def test_notebooks_prints_seconds_and_the_slowest_cell(tmp_path):
    nb = _notebook(tmp_path / "01_t.ipynb", "x = 1", "import time\ntime.sleep(0.3)", "y = x + 1")
    before = nb.read_bytes()
    r = subprocess.run([sys.executable, "-m", "labutils.bench", "notebooks", str(nb)], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    row, = json.loads(r.stdout)["notebooks"]
    assert row["notebook"] == "01_t.ipynb" and row["slowest_cell"]["index"] == 1
    assert row["slowest_cell"]["first_line"] == "import time" and row["slowest_cell"]["seconds"] >= 0.3
    assert row["seconds"] >= row["slowest_cell"]["seconds"] and row["within_budget"] is (row["seconds"] < 90)
    assert nb.read_bytes() == before                                          # nothing saved into the notebook
    (tmp_path / "out").mkdir()
    r = subprocess.run([sys.executable, "-m", "labutils.bench", "notebooks", str(nb), "--keep", "out"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    kept = json.loads((tmp_path / "out" / "01_t.ipynb").read_text())
    assert [c["execution_count"] for c in kept["cells"]] == [1, 2, 3] and nb.read_bytes() == before
    for keep in ("missing", "."):                                             # no folder; the notebook's own
        r = subprocess.run([sys.executable, "-m", "labutils.bench", "notebooks", str(nb), "--keep", keep],
                           capture_output=True, text=True, cwd=tmp_path)
        assert r.returncode == 2 and r.stdout == "" and r.stderr.startswith(f"error: {keep}: ")


def test_notebooks_names_the_cell_that_raises(tmp_path):
    nb = _notebook(tmp_path / "bad.ipynb", "x = 1", "1 / 0")
    r = subprocess.run([sys.executable, "-m", "labutils.bench", "notebooks", str(nb), str(tmp_path / "none.ipynb")],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert f"error: {tmp_path / 'none.ipynb'}: no such notebook" in r.stderr          # checked before any is run
    r = subprocess.run([sys.executable, "-m", "labutils.bench", "notebooks", str(nb)], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines()[-1] == f"error: {nb}: cell 1 raised ZeroDivisionError: division by zero"


def test_notebooks_default_to_the_workbook_s_notebooks():
    """Without paths, ``bench notebooks`` times the notebooks of this checkout (it timed none when the package's
    layout moved and the folder was looked for one level too high)."""
    from labutils.tools.bench import NOTEBOOK_DIR
    assert NOTEBOOK_DIR == Path(__file__).resolve().parents[1] / "notebooks"
    assert len(list(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))) >= 15


# ---------------------------------------------------------------- the references: Ceres (optional) and OpenCV

def test_compare_with_ceres_says_when_ceres_is_missing(monkeypatch):
    from labutils.tools import reference

    monkeypatch.setattr(reference, "ceres_available", lambda: False)
    pb = reference.synthetic_ba_problem(6, 15, rng=np.random.default_rng(0))
    row = reference.compare_with_ceres(pb, repeats=1)
    assert row["ceres"].startswith("not installed") and "ratio_cpu" not in row
    assert row["ours"]["cost_final"] > 0 and row["ours"]["steps"] >= 1
    run = reference.scaling_run((5, 8), points_per_camera=15)
    assert [r["n_cameras"] for r in run["runs"]] == [5, 8] and set(run["slope"]) == {"ours"}


@pytest.mark.skipif(not __import__("labutils.tools.reference", fromlist=["x"]).ceres_available(),
                    reason="pycolmap (the optional extra [bench]) is not installed")
@pytest.mark.parametrize("model", ["pinhole", "bal"])
def test_ceres_solves_the_same_problem(model):
    """Ceres through pycolmap minimises our cost: the BAL camera turned into COLMAP's frame and back, the pinhole
    camera with its intrinsics held; both reach the same minimum (our cost at Ceres' answer)."""
    from labutils.bundle.adjust import bundle_adjust_params
    from labutils.tools.reference import ceres_bundle_adjust, synthetic_ba_problem

    cp, X, ci, pi, x, K = synthetic_ba_problem(8, 20, rng=np.random.default_rng(3))
    if model == "bal":             # the same scene as a BAL problem: camera looking down -z, f, k1, k2
        F = np.diag([-1.0, 1.0, -1.0])
        from labutils.core.geometry import angle_axis_from_rotation, rotation_from_angle_axis
        R = F @ rotation_from_angle_axis(cp[:, :3])
        cp = np.hstack([angle_axis_from_rotation(R), cp[:, 3:6] @ F, np.tile([500.0, 0.01, -0.001], (len(cp), 1))])
        x, K = (x - [320, 240]) * [-1, 1], None
    ours = bundle_adjust_params(cp, X, ci, pi, x, K, max_iter=200)
    out = ceres_bundle_adjust(cp, X, ci, pi, x, K, max_iter=200)
    r = reprojection_residuals(out["camera_params"], out["points_3d"], ci, pi, x, K)
    assert np.isclose(out["ceres_cost_final"], 0.5 * r @ r, rtol=1e-6)
    assert abs(0.5 * r @ r / ours.cost_final - 1) < 1e-3


def test_pnp_against_opencv_rows():
    from labutils.tools.reference import compare_pnp_with_opencv

    out = compare_pnp_with_opencv((40,), per_size=2, repeats=1)
    for who in ("ours", "opencv"):
        assert out[who]["failures"] == 0 and out[who]["inlier_recall"] > 0.9 and out[who]["ms_per_call"] > 0
    assert out["ratio"] > 0
