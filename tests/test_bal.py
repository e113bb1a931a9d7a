"""BAL files: reading, writing, errors that name the line, and the ``python -m labutils.bundle`` CLI."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from labutils.bundle.reprojection import reprojection_residuals
from labutils.core.robust import robust_cost
from labutils.data.bal import BALFormatError, BALProblem, format_bal, parse_bal, read_bal, write_bal

ROOT = Path(__file__).resolve().parents[1]


def small_problem(rng, noise_px=0.5, n_points=40, n_views=4):
    """A BAL problem whose cameras look down -z at points near the origin, with a perturbed start."""
    from labutils.bundle.reprojection import camera_params_from_Rt
    from labutils.core.scene import observations
    from labutils.core.synthetic import make_scene

    s = make_scene(n_points, n_views, noise_px=0.0, rng=rng)
    D = np.diag([1.0, -1.0, -1.0])
    cp = np.hstack([camera_params_from_Rt(D @ s.R, s.t @ D), np.tile([1500.0, 0.01, -0.001], (n_views, 1))])
    ci, pi, _ = observations(s.x_true)
    x = reprojection_residuals(cp, s.X, ci, pi, np.zeros((len(ci), 2)), None).reshape(-1, 2)
    x += rng.normal(scale=noise_px, size=x.shape)
    cp0 = cp + np.hstack([0.002 * rng.normal(size=(n_views, 6)), np.zeros((n_views, 3))])
    return BALProblem(cp0, s.X + 0.002 * rng.normal(size=s.X.shape), ci, pi, x)


def test_round_trip(rng, tmp_path):
    p = small_problem(rng)
    write_bal(tmp_path / "p.txt", p)
    q = read_bal(tmp_path / "p.txt")
    for name in ("camera_params", "points_3d", "camera_indices", "point_indices", "points_2d"):
        assert np.array_equal(getattr(p, name), getattr(q, name)), name
    assert not (tmp_path / "p.txt.tmp").exists()


def test_reads_the_ladybug_file():
    from labutils.data.paths import DataNotFoundError, find_data

    try:
        path = find_data("bal/problem-49-7776-pre.txt")
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")
    p = read_bal(path)
    assert (p.n_cameras, p.n_points, p.n_observations) == (49, 7776, 31843)
    r = reprojection_residuals(p.camera_params, p.points_3d, p.camera_indices, p.point_indices, p.points_2d, None)
    assert robust_cost(r) == pytest.approx(8.509125e5, rel=1e-6)       # the documented initial cost


GOOD = "2 2 3\n0 0 1 2\n1 0 3 4\n1 1 5 6\n" + "0.1\n" * 18 + "0\n0\n-5\n1\n0\n-5\n"


@pytest.mark.parametrize("text, line, pattern", [
    ("", 1, "empty"),
    ("2 2\n", 1, "header"),
    ("2 x 3\n", 1, "n_points must be an integer"),
    ("2 2 3\n0 0 1 2\n1 0 3 4\n", 4, "ends after 2 of 3 observation lines"),
    ("2 2 3\n0 0 1 2\n1 0 3 4 7\n1 1 5 6\n", 3, "4 fields"),
    ("2 2 3\n0 0 1 2\n1 0 3 abc\n1 1 5 6\n", 3, "finite numbers; got 'abc'"),
    ("2 2 3\n0 0 1 2\n1 0 3 nan\n1 1 5 6\n", 3, "finite numbers"),
    ("2 2 3\n0 0 1 2\n1 0.5 3 4\n1 1 5 6\n", 3, "indices must be integers"),
    ("2 2 3\n0 0 1 2\n2 0 3 4\n1 1 5 6\n", 3, "camera index 2 is out of range"),
    ("2 2 3\n0 0 1 2\n1 0 3 4\n1 -1 5 6\n", 4, "point index -1 is out of range"),
    (GOOD.replace("-5\n1\n0\n-5\n", "-5\n1\n0\n"), 28, "ends early"),
    (GOOD + "7\n", 29, "unexpected data"),
    (GOOD.replace("0.1\n" * 18, "0.1\n" * 17 + "1e400\n"), 22, "finite numbers"),
    (GOOD.replace("0.1\n" * 18, "0.1\n" * 10 + "x\n" + "0.1\n" * 7), 15, "got 'x'"),
])
def test_parse_errors_name_the_line(text, line, pattern):
    with pytest.raises(BALFormatError, match=rf"line {line}: .*{pattern}"):
        parse_bal(text)


def test_good_example_parses():
    p = parse_bal(GOOD)
    assert p.camera_params.shape == (2, 9) and p.points_3d.tolist() == [[0, 0, -5], [1, 0, -5]]
    assert isinstance(BALFormatError("x"), ValueError)
    assert parse_bal(format_bal(p)).points_2d.tolist() == p.points_2d.tolist()


# ------------------------------------------------------------------------------------------ the CLI
def run_cli(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "labutils.bundle", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=120)


@pytest.mark.parametrize("solver", ["lm-schur", "scipy"])
def test_cli_solves_a_bal_file(rng, tmp_path, solver):
    p = small_problem(rng)
    write_bal(tmp_path / "problem.txt", p)
    out = tmp_path / "solved.txt"
    proc = run_cli(tmp_path / "problem.txt", "--solver", solver, "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["solver"] == solver and summary["iterations"] >= 1 and summary["seconds"] > 0
    assert summary["cost_final"] < 0.5 * 0.5 ** 2 * 2 * p.n_observations < summary["cost_initial"]
    q = read_bal(out)
    r = reprojection_residuals(q.camera_params, q.points_3d, q.camera_indices, q.point_indices, q.points_2d, None)
    assert robust_cost(r) == pytest.approx(summary["cost_final"], rel=1e-9)
    assert not np.array_equal(q.camera_params[:, 6:], p.camera_params[:, 6:])    # f, k1, k2 refined by default


def test_cli_fix_intrinsics_and_text_summary(rng, tmp_path):
    p = small_problem(rng)
    write_bal(tmp_path / "problem.txt", p)
    proc = run_cli(tmp_path / "problem.txt", "--out", tmp_path / "solved.txt", "--fix-intrinsics")
    assert proc.returncode == 0, proc.stderr
    assert "lm-schur: cost" in proc.stdout
    q = read_bal(tmp_path / "solved.txt")
    assert np.array_equal(q.camera_params[:, 6:], p.camera_params[:, 6:])


@pytest.mark.parametrize("text, pattern", [
    ("2 2 3\n0 0 1 2\n1 0 3 4\n", "line 4: the file ends after 2 of 3"),
    ("2 2 3\n0 0 1 2\n1 0 3 abc\n1 1 5 6\n", "line 3: pixel coordinates must be finite numbers"),
    ("2 2 3\n0 0 1 2\n1 5 3 4\n1 1 5 6\n", "line 3: point index 5 is out of range"),
    (GOOD + "7\n", "line 29: unexpected data"),
])
def test_cli_bad_files(tmp_path, text, pattern):
    (tmp_path / "bad.txt").write_text(text)
    out = tmp_path / "solved.txt"
    proc = run_cli(tmp_path / "bad.txt", "--out", out)
    assert proc.returncode != 0
    assert pattern in proc.stderr and "bad.txt" in proc.stderr
    assert not out.exists()


def test_cli_unsolvable_problem_and_missing_file(tmp_path):
    # a camera without observations: a ValueError from the solver, reported the same way
    text = GOOD.replace("2 2 3\n0 0 1 2\n1 0 3 4\n1 1 5 6\n", "3 2 3\n0 0 1 2\n1 0 3 4\n1 1 5 6\n") + "0.1\n" * 9
    text = text.replace("0\n0\n-5\n1\n0\n-5\n" + "0.1\n" * 9, "0.1\n" * 9 + "0\n0\n-5\n1\n0\n-5\n")
    (tmp_path / "p.txt").write_text(text)
    proc = run_cli(tmp_path / "p.txt", "--out", tmp_path / "o.txt")
    assert proc.returncode != 0 and "error:" in proc.stderr and not (tmp_path / "o.txt").exists()
    proc = run_cli(tmp_path / "missing.txt", "--out", tmp_path / "o.txt")
    assert proc.returncode != 0 and "missing.txt" in proc.stderr
