"""A real nbgrader course, the way an instructor uses it (issue 19): generate the assignment, three hand-ins, autograde,
read the scores from the gradebook.

The assignment is notebook 01 cut down to its four exercises (sections 1–3 and the gold standard's cost; the RANSAC,
OpenCV and statistics sections are left out, so that three graded runs fit in CI's time). The hand-ins are the
student edition with the solution cells filled in:

- ``correct``: the reference solutions — every autograded point;
- ``wrong``: the Sampson distance squared (a typical mistake) — all points but that exercise's;
- ``library``: every body calls the library's implementation (``return fundamental_8point(x1, x2)``) — no points:
  ``yours.assert_own`` in the hidden tests fails each of them.

nbgrader runs as the instructor runs it, its command line in a subprocess, in a course folder under ``tmp_path``,
with a kernel of this interpreter; nothing outside ``tmp_path`` is written. Marked ``nbgrader``: deselect it with
``-m "not nbgrader"``; it is skipped where nbgrader is not installed.
"""
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

nbgrader_api = pytest.importorskip("nbgrader.api")

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "notebooks" / "01_fundamental_matrix.ipynb"
NAME = "01_fundamental_matrix.ipynb"            # the same name: notebook 02's yours.load reads it under this name

pytestmark = pytest.mark.nbgrader

# The library's answer, with the student's signature: what an honest grade must give nothing for.
LIBRARY = {
    "normalisation_matrix": "from labutils.twoview import hartley_normalisation\n"
                            "    return hartley_normalisation(x)",
    "eight_point": "from labutils.twoview import fundamental_8point\n    return fundamental_8point(x1, x2)",
    "sampson": "from labutils.twoview import sampson_distance\n    return sampson_distance(F, x1, x2)",
    "gold_standard_residuals": "from labutils.twoview import gold_standard_residuals as library\n"
                               "    return library(P2, points, x1, x2)",
}
WRONG_SAMPSON = "return (np.sum(homogeneous(x2) * (homogeneous(x1) @ F.T), axis=1) ** 2 / np.sum(" \
                "(homogeneous(x1) @ F.T)[:, :2] ** 2 + (homogeneous(x2) @ F)[:, :2] ** 2, axis=1))"


def _cut(nb):
    """Notebook 01 up to the Sampson distance's hidden tests, then the gold standard's cost exercise."""
    cells = nb["cells"]

    def at(text):
        return next(k for k, c in enumerate(cells) if text in "".join(c["source"]))

    first = cells[:at("# sampson: your own work") + 1]
    gold = cells[at("small = GoldStandardProblem("):at("# gold_standard_residuals: your own work") + 1]
    return {**nb, "cells": first + gold}


def _solution_cells(nb):
    return {c["metadata"]["nbgrader"]["grade_id"]: c for c in nb["cells"]
            if c["cell_type"] == "code" and c.get("metadata", {}).get("nbgrader", {}).get("solution")}


def _hand_in(released, instructor, bodies):
    """The released notebook with each solution cell's stub replaced: by the instructor's cell, or by a body."""
    nb = json.loads(json.dumps(released))
    reference = _solution_cells(instructor)
    for grade_id, cell in _solution_cells(nb).items():
        source = "".join(reference[grade_id]["source"])
        if grade_id in bodies:
            head = source.split("### BEGIN SOLUTION")[0]
            source = head + bodies[grade_id] + "\n"
        cell["source"] = source
    return nb


def _nbgrader(course, env, *args):
    tic = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "nbgrader", *args], cwd=course, env=env, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, f"nbgrader {' '.join(args)} failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    print(f"nbgrader {args[0]}: {time.perf_counter() - tic:.1f} s")
    return r.stdout + r.stderr


def test_three_hand_ins_score_full_partial_and_zero(tmp_path):
    course = tmp_path / "course"
    (course / "source" / "ps1").mkdir(parents=True)
    instructor = _cut(json.loads(SOURCE.read_text(encoding="utf-8")))
    (course / "source" / "ps1" / NAME).write_text(json.dumps(instructor, indent=1))
    (course / "nbgrader_config.py").write_text(
        "from labutils.exercises.release import student_preprocessors\n\n"
        "c = get_config()\n"
        "c.CourseDirectory.course_id = 'reconstruction'\n"
        "c.GenerateAssignment.preprocessors = student_preprocessors(gradebook=True)\n"
        "c.Execute.timeout = 300\n")
    kernels = tmp_path / "jupyter" / "kernels" / "python3"      # the kernel runs this interpreter
    kernels.mkdir(parents=True)
    (kernels / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "Python 3", "language": "python"}))
    env = {**os.environ, "JUPYTER_PATH": str(tmp_path / "jupyter"), "JUPYTER_CONFIG_DIR": str(tmp_path / "config"),
           "JUPYTER_DATA_DIR": str(tmp_path / "data"), "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}

    _nbgrader(course, env, "generate_assignment", "ps1")
    released = json.loads((course / "release" / "ps1" / NAME).read_text(encoding="utf-8"))
    assert "### BEGIN SOLUTION" not in json.dumps(released) and "HIDDEN TESTS" not in json.dumps(released)
    hand_ins = {
        "correct": _hand_in(released, instructor, {}),
        "wrong": _hand_in(released, instructor, {"sampson": "    " + WRONG_SAMPSON}),
        "library": _hand_in(released, instructor, {k: "    " + v for k, v in LIBRARY.items()}),
    }
    for student, nb in hand_ins.items():
        folder = course / "submitted" / student / "ps1"
        folder.mkdir(parents=True)
        (folder / NAME).write_text(json.dumps(nb, indent=1))
    log = _nbgrader(course, env, "autograde", "ps1")

    with nbgrader_api.Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        scores = {}
        for student in hand_ins:
            notebook = gb.find_submission_notebook(NAME.removesuffix(".ipynb"), "ps1", student)
            auto = {g.name: (g.auto_score, g.max_score) for g in notebook.grades if g.cell_type == "code"}
            scores[student] = auto
    points = {k: m for k, (_, m) in scores["correct"].items()}
    assert set(points) == {"normalisation_matrix_tests", "eight_point_tests", "sampson_tests",
                           "gold_standard_residuals_tests"}, points
    total = sum(points.values())
    got = {s: sum(a or 0 for a, _ in auto.values()) for s, auto in scores.items()}
    print(f"autograded points of {total}: {got}")
    assert got["correct"] == total, scores["correct"]
    assert got["wrong"] == total - points["sampson_tests"], scores["wrong"]
    assert got["library"] == 0, scores["library"]
    print("\n".join(line for line in log.splitlines() if re.search(r"checksum|modified|WARNING", line, re.I)))
