"""labutils.exercises.yours: the student's functions drive later cells, the library stands in, the spy catches a
hand-in that only calls the library."""
import json

import numpy as np
import pytest

from labutils.core.synthetic import make_scene
from labutils.exercises import yours
from labutils.twoview import fundamental_8point


def _pair(seed=0):
    s = make_scene(40, 2, noise_px=0.5, rng=np.random.default_rng(seed))
    x1, x2, _ = s.pair(0, 1)
    return x1, x2


def _notebook(tmp_path, stem, cells):
    nb = {"cells": [], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}
    for source, solution in cells:
        meta = {"nbgrader": {"solution": True, "grade": False, "grade_id": "x", "locked": False,
                             "schema_version": 3, "task": False}} if solution else {}
        nb["cells"].append({"cell_type": "code", "source": source, "metadata": meta, "outputs": [],
                            "execution_count": None})
    (tmp_path / f"{stem}.ipynb").write_text(json.dumps(nb))


def test_load_reads_the_students_function_with_the_notebooks_imports(tmp_path, monkeypatch, capsys):
    _notebook(tmp_path, "01_fundamental_matrix", [
        ("import numpy as np\nfrom labutils import homogeneous\n", False),
        ("def sampson(F, x1, x2):\n    return np.zeros(len(homogeneous(x1)))\n", True)])
    monkeypatch.setenv("LABUTILS_YOURS_DIR", str(tmp_path))
    f = yours.load("sampson")
    assert f.is_yours and "sampson: yours, from 01_fundamental_matrix.ipynb" in capsys.readouterr().out
    x1, x2 = _pair()
    assert np.array_equal(f(np.eye(3), x1, x2), np.zeros(len(x1)))     # the student's (wrong) answer, not the library's


def test_a_stub_or_a_missing_notebook_gives_the_library_with_the_reason(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LABUTILS_YOURS_DIR", str(tmp_path))
    f = yours.load("eight_point")
    assert not f.is_yours and "01_fundamental_matrix.ipynb is not in" in capsys.readouterr().out
    _notebook(tmp_path, "01_fundamental_matrix", [
        ('def eight_point(x1, x2):\n    """Doc."""\n    raise NotImplementedError("write it")\n', True)])
    f = yours.load("eight_point")
    assert not f.is_yours and "not written yet in 01_fundamental_matrix.ipynb" in capsys.readouterr().out
    x1, x2 = _pair()
    assert np.allclose(f(x1, x2), fundamental_8point(x1, x2))


def test_a_loaded_function_keeps_working_when_a_helper_of_its_notebook_is_a_stub(tmp_path, monkeypatch, capsys):
    """In a loaded notebook the stub helper is replaced by the library's stand-in: the student's function stays
    theirs (here it returns the helper's T, which is now hartley_normalisation's)."""
    from labutils.twoview import hartley_normalisation

    _notebook(tmp_path, "01_fundamental_matrix", [
        ("def normalisation_matrix(x):\n    raise NotImplementedError\n", True),
        ("def eight_point(x1, x2):\n    T = normalisation_matrix(x1)\n    return T\n", True)])
    monkeypatch.setenv("LABUTILS_YOURS_DIR", str(tmp_path))
    f = yours.load("eight_point")
    x1, x2 = _pair()
    assert f.is_yours and np.allclose(f(x1, x2), hartley_normalisation(x1))


def test_an_unwritten_helper_in_the_kernel_is_named_and_the_library_answers(capsys):
    ns = {}
    exec("def normalisation_matrix(x):\n    raise NotImplementedError\n"
         "def eight_point(x1, x2):\n    return normalisation_matrix(x1)\n", ns)
    f = yours.Yours(ns["eight_point"], yours.EXERCISES["eight_point"])
    x1, x2 = _pair()
    assert np.allclose(f(x1, x2), fundamental_8point(x1, x2))
    assert "your eight_point calls normalisation_matrix, which is not written yet" in capsys.readouterr().out


def test_a_name_from_outside_the_solution_cells_falls_back_and_says_so(tmp_path, monkeypatch, capsys):
    _notebook(tmp_path, "01_fundamental_matrix", [
        ("SCALE = 2.0\n", False),
        ("def sampson(F, x1, x2):\n    return SCALE * x1[:, 0]\n", True)])
    monkeypatch.setenv("LABUTILS_YOURS_DIR", str(tmp_path))
    f = yours.load("sampson")
    x1, x2 = _pair()
    F = fundamental_8point(x1, x2)
    from labutils.twoview import sampson_distance

    assert np.allclose(f(F, x1, x2), sampson_distance(F, x1, x2))
    assert "uses a name from outside its cells" in capsys.readouterr().out


def test_a_stand_in_is_named_for_its_exercise():
    s = yours._library(yours.EXERCISES["sampson"], "not written yet", True)
    assert s.__name__ == "sampson" and not s.is_yours and s.why == "not written yet"

def test_assert_own_fails_for_a_hand_in_that_calls_the_library_and_passes_for_ones_own():
    ns = {"fundamental_8point": fundamental_8point, "np": np}
    exec("def eight_point(x1, x2):\n    return fundamental_8point(x1, x2)\n", ns)
    x1, x2 = _pair()
    with pytest.raises(AssertionError, match="calls fundamental_8point"):
        yours.assert_own(ns["eight_point"], x1, x2)
    exec("def eight_point(x1, x2):\n    return np.ones((3, 3))\n", ns)       # wrong, but its own: the spy is silent
    assert yours.assert_own(ns["eight_point"], x1, x2).shape == (3, 3)


def test_every_registered_fallback_and_reference_resolves():
    for name, ex in yours.EXERCISES.items():
        for spec in ex.forbidden():
            assert yours._resolve(spec) is not None, (name, spec)


def test_bad_names_are_refused():
    with pytest.raises(ValueError, match="not an exercise"):
        yours.load("eigth_point")
    with pytest.raises(ValueError, match="a str"):
        yours.load(3)


def test_the_spy_names_what_the_hand_in_called_not_what_that_calls_in_turn():
    ns = {"fundamental_8point": fundamental_8point}
    exec("def eight_point(x1, x2):\n    return fundamental_8point(x1, x2)\n", ns)
    with pytest.raises(AssertionError) as info:
        yours.assert_own(ns["eight_point"], *_pair())
    message = str(info.value)
    assert "calls fundamental_8point:" in message and "_enforce_rank2" not in message, message


def test_choose_pose_and_the_gold_standard_cost_have_fallbacks_with_the_students_signature():
    import inspect
    for name, params in [("choose_pose", ["poses", "y1", "y2"]),
                         ("gold_standard_residuals", ["P2", "points", "x1", "x2"])]:
        fallback = yours._resolve(yours.EXERCISES[name].fallback)
        assert list(inspect.signature(fallback).parameters) == params, (name, fallback)



def test_the_private_kernels_behind_the_library_earn_nothing_either():
    """A hand-in that calls the unchecked kernel inside the library's function (``_sampson`` behind
    ``sampson_distance``, ``_triangulate_multiview`` behind ``triangulate``) is caught like one calling the function."""
    from labutils.twoview.epipolar import _sampson
    from labutils.twoview.triangulation import _triangulate_multiview

    ns = {"_sampson": _sampson, "_tm": _triangulate_multiview, "np": np}
    exec("def sampson(F, x1, x2):\n    return _sampson(F, x1, x2)\n"
         "def triangulate_linear(P1, P2, x1, x2):\n    return _tm(np.stack([P1, P2]), np.stack([x1, x2]))\n", ns)
    s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    x1, x2, _ = s.pair(0, 1)
    with pytest.raises(AssertionError, match="_sampson"):
        yours.assert_own(ns["sampson"], fundamental_8point(x1, x2), x1, x2)
    with pytest.raises(AssertionError, match="_triangulate_multiview"):
        yours.assert_own(ns["triangulate_linear"], s.P[0], s.P[1], x1, x2)
