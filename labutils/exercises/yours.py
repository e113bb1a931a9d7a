"""Your functions, from then on: the student's exercise functions drive the rest of the workbook.

After an exercise, a notebook goes on with **the student's** function, and later notebooks import it from the
notebook where the student wrote it (d2l's ``#@save`` is the precedent; here nothing needs marking: every solution
cell is "saved" by saving the notebook). Where a function is not written yet, the library's version stands in and
one line says so.

Three entry points:

- :func:`pick` — in the notebook of the exercise: ``F_of = yours.pick(eight_point)`` returns the student's
  ``eight_point`` (or the library's ``fundamental_8point`` while it is a stub) and says which in one line.
- :func:`load` — in a later notebook: ``eight_point = yours.load("eight_point")`` reads the solution cells of
  ``01_fundamental_matrix.ipynb`` *as last saved in this folder*, defines them in a fresh namespace with that
  notebook's own imports, and returns :func:`pick` of the function. No notebook file, a stub, or a cell that does
  not run: the library's version, and the line says why.
- :func:`assert_own` — in a hidden test: runs the student's function once and fails if, inside it, the library's
  implementation of the same thing was called (``return fundamental_8point(x1, x2)`` earns no points). The spy is
  :func:`sys.setprofile`, active only while the student's function runs, so the test's own checks may still use
  the library.

The folder read by :func:`load` is the working directory (where Jupyter, nbval and ``nbgrader autograde`` run a
notebook), or ``$LABUTILS_YOURS_DIR`` when it is set. :func:`summary` is the table of notebook 14: which pieces
of the pipeline are yours.

Registry: :data:`EXERCISES` maps each exercise function to its notebook, its library fallback and the references
a hand-in must not call. A new exercise that later cells use gets one entry.
"""
import ast
import functools
import importlib
import inspect
import json
import os
import sys
import textwrap
import traceback
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["EXERCISES", "Exercise", "assert_own", "load", "pick", "summary"]


@dataclass(frozen=True)
class Exercise:
    """One exercise function: where it is written, what stands in for it, what it must not call.

    ``fallback`` and ``references`` are ``"module:attribute"`` strings, imported only when needed (so that this
    module imports no estimator). ``references`` lists the library functions that compute the same thing; the
    fallback is always one of them.
    """

    name: str
    notebook: str
    fallback: str
    references: tuple = field(default_factory=tuple)

    def forbidden(self):
        return (self.fallback,) + tuple(r for r in self.references if r != self.fallback)


def _ex(name, notebook, fallback, *references):
    return name, Exercise(name, notebook, fallback, tuple(references))


EXERCISES = dict([
    # notebook 01
    _ex("normalisation_matrix", "01_fundamental_matrix", "labutils.twoview.epipolar:hartley_normalisation",
        "labutils.exercises.ex01_fundamental:_similarity"),
    _ex("eight_point", "01_fundamental_matrix", "labutils.twoview.epipolar:fundamental_8point",
        "labutils.twoview.seven_point:fundamental_ransac", "labutils.twoview.seven_point:fundamental_7point",
        "labutils.twoview.epipolar:_eight_point_normalised", "labutils.twoview.epipolar:_enforce_rank2",
        "labutils.exercises.ex01_fundamental:_eight_point_T", "labutils.exercises.ex01_fundamental:_rank2",
        "cv2:findFundamentalMat"),
    _ex("sampson", "01_fundamental_matrix", "labutils.twoview.epipolar:sampson_distance",
        "labutils.twoview.epipolar:_sampson", "labutils.twoview.epipolar:_sampson_and_gradient",
        "labutils.exercises.ex01_fundamental:_sampson_parts",
        "labutils.exercises.ex01_fundamental:_sampson_variants"),
    _ex("gold_standard_residuals", "01_fundamental_matrix", "labutils.twoview.gold_standard:gold_standard_residuals",
        "labutils.exercises.ex01_fundamental:_gs_variants"),
    # notebook 02
    _ex("four_poses", "02_essential_and_pose", "labutils.twoview.essential:decompose_essential",
        "labutils.exercises.ex02_essential:_svd_variants", "cv2:decomposeEssentialMat"),
    _ex("choose_pose", "02_essential_and_pose", "labutils.twoview.essential:cheirality_choice",
        "labutils.twoview.essential:_cheirality_counts", "labutils.twoview.essential:pose_from_essential",
        "labutils.exercises.ex02_essential:_depths", "cv2:recoverPose"),
    _ex("triangulate_linear", "02_essential_and_pose", "labutils.twoview.triangulation:triangulate",
        "labutils.twoview.triangulation:triangulate_multiview", "labutils.twoview.triangulation:_triangulate_multiview",
        "labutils.exercises.ex02_essential:_dlt",
        "cv2:triangulatePoints"),
    _ex("adaptive_ransac", "03_pnp", "labutils.core.ransac:ransac", "labutils.pose.pnp:pnp_ransac",
        "cv2:solvePnPRansac"),
    _ex("projection_jacobian", "04_bundle_adjustment", "labutils.bundle.reprojection:reprojection_blocks",
        "labutils.bundle.reprojection:reprojection_jacobian", "labutils.bundle.reprojection:project_observations",
        "labutils.pose.pnp:pose_jacobian", "labutils.pose.pnp:_pose_jacobian"),
    _ex("sparsity_mask", "04_bundle_adjustment", "labutils.bundle.reprojection:jacobian_sparsity",
        "labutils.bundle.reprojection:jacobian_structure"),
    _ex("schur_step", "04_bundle_adjustment", "labutils.bundle.schur:schur_step_dense",
        "labutils.bundle.schur:schur_step"),
    _ex("levenberg_marquardt", "04_bundle_adjustment", "labutils.bundle.schur:levenberg_marquardt",
        "labutils.bundle.schur:lm_schur", "labutils.bundle.adjust:bundle_adjust",
        "labutils.bundle.adjust:bundle_adjust_params", "scipy.optimize:least_squares"),
    _ex("choose_next_view", "05_incremental_sfm", "labutils.exercises.ex05_sfm:next_view_reference",
        "labutils.sfm.view_selection:next_view"),
    _ex("accept_points", "05_incremental_sfm", "labutils.exercises.ex05_sfm:accept_points_reference",
        "labutils.twoview.triangulation:triangulate_tracks"),
    _ex("incremental_loop", "05_incremental_sfm", "labutils.exercises.ex05_sfm:incremental_loop_reference",
        "labutils.sfm.incremental:incremental_sfm", "labutils.sfm.global_sfm:global_sfm"),
    _ex("pose_from_depths", "03_pnp", "labutils.exercises.ex03_pnp:pose_from_depths_reference",
        "labutils.pose.pnp:p3p", "labutils.pose.pnp:p3p_bearings", "labutils.exercises.ex03_pnp:_build_R"),
])


def _resolve(spec):
    module, _, attr = spec.partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError):
        return None


def _label(spec):
    module, _, attr = spec.partition(":")
    return attr if module.startswith("labutils") else f"{module}.{attr}"


def _exercise(name):
    if not isinstance(name, str):
        raise ValueError(f"name must be the name of an exercise function (a str), got {type(name).__name__}")
    if name not in EXERCISES:
        raise ValueError(f"{name!r} is not an exercise that later cells use; known: {', '.join(EXERCISES)}")
    return EXERCISES[name]


def _is_stub(fn):
    """True when the body of ``fn`` (its source) only raises NotImplementedError, after an optional docstring."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    except (OSError, TypeError, SyntaxError):
        return False
    return bool(tree.body) and _is_stub_node(tree.body[0])


def _is_stub_node(node):
    if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
        return False
    body = [s for s in node.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant)
                                         and isinstance(s.value.value, str))]
    if len(body) != 1 or not isinstance(body[0], ast.Raise) or body[0].exc is None:
        return False
    exc = body[0].exc.func if isinstance(body[0].exc, ast.Call) else body[0].exc
    return isinstance(exc, ast.Name) and exc.id == "NotImplementedError"


def _unwritten_in(tb):
    """Name of the innermost function whose frame raised NotImplementedError."""
    frames = traceback.extract_tb(tb)
    return frames[-1].name if frames else "?"


class Yours:
    """The student's function, standing in for the library's; the library's on an unwritten helper.

    Calls go to the student's function. If a NotImplementedError comes out of it (the student's function calls a
    helper of theirs that is still a stub), the library's version answers instead and one line names the helper.
    """

    def __init__(self, fn, exercise, *, quiet=False):
        self.fn, self.exercise, self.quiet, self._warned = fn, exercise, quiet, False
        functools.update_wrapper(self, fn)
        self.is_yours = True

    def __call__(self, *args, **kwargs):
        try:
            return self.fn(*args, **kwargs)
        except (NotImplementedError, NameError) as err:
            # NotImplementedError: a helper of the student's still a stub; NameError: a name the function uses that
            # lives outside the notebook's solution cells (only those are loaded by load()); both are said, once
            what = (f"calls {_unwritten_in(err.__traceback__)}, which is not written yet"
                    if isinstance(err, NotImplementedError) else f"uses a name from outside its cells ({err})")
            if not self._warned and not self.quiet:
                print(f"your {self.exercise.name} {what}: the library's {_label(self.exercise.fallback)} answers "
                      "instead")
            self._warned = True
            return _resolve(self.exercise.fallback)(*args, **kwargs)

    def __repr__(self):
        return f"<your {self.exercise.name}>"


def _library(exercise, why, quiet):
    fallback = _resolve(exercise.fallback)
    if not quiet:
        print(f"{exercise.name}: {why}: the library's {_label(exercise.fallback)} stands in")

    def stand_in(*args, **kwargs):
        return fallback(*args, **kwargs)

    stand_in.__name__ = stand_in.__qualname__ = exercise.name      # named for the exercise (assert_own, summary)
    stand_in.__doc__ = fallback.__doc__
    stand_in.is_yours, stand_in.why = False, why
    return stand_in


def pick(fn, name=None, *, quiet=False):
    """The student's exercise function if written, else the library's version; one line says which.

    Parameters
    ----------
    fn : callable
        The function the student wrote in the exercise cell (a stub raising NotImplementedError counts as not
        written).
    name : str, optional
        The exercise's name in :data:`EXERCISES`; by default ``fn.__name__``.
    quiet : bool
        No line printed.

    Returns
    -------
    f : callable
        Calls the student's function (attribute ``is_yours`` True), or the library's (``is_yours`` False, ``why``).

    Examples
    --------
    >>> def sampson(F, x1, x2):
    ...     raise NotImplementedError("write the body of sampson(F, x1, x2) here")
    >>> f = pick(sampson)
    sampson: not written yet: the library's sampson_distance stands in
    >>> f.is_yours
    False
    """
    if not callable(fn):
        raise ValueError(f"fn must be the exercise's function, got {type(fn).__name__}")
    exercise = _exercise(fn.__name__ if name is None else name)
    if _is_stub(fn):
        return _library(exercise, "not written yet", quiet)
    if not quiet:
        print(f"{exercise.name}: yours")
    return Yours(fn, exercise, quiet=quiet)


def folder():
    """The folder :func:`load` reads notebooks from: ``$LABUTILS_YOURS_DIR``, else the working directory."""
    env = os.environ.get("LABUTILS_YOURS_DIR", "").strip()
    return Path(env) if env else Path.cwd()


def _solution_sources(nb):
    imports, defs = [], []
    for cell in nb.get("cells", []):
        if cell.get("cell_type") != "code":
            continue
        source = "".join(cell.get("source", ""))
        try:
            tree = ast.parse(source)
        except SyntaxError:
            continue
        solution = cell.get("metadata", {}).get("nbgrader", {}).get("solution", False)
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)) and not solution:
                imports.append(node)
            elif isinstance(node, (ast.Import, ast.ImportFrom, ast.FunctionDef)) and solution:
                defs.append(node)
    return imports, defs


@functools.lru_cache(maxsize=32)
def _namespace(path, mtime):
    nb = json.loads(Path(path).read_text(encoding="utf-8"))
    imports, defs = _solution_sources(nb)
    ns = {"__name__": f"yours_{Path(path).stem}"}
    for node in imports:                            # the notebook's own imports, one by one: a failing one is skipped
        try:
            exec(compile(ast.Module(body=[node], type_ignores=[]), str(path), "exec"), ns)
        except Exception:                          # noqa: BLE001 — an import that fails here leaves a NameError later
            pass
    exec(compile(ast.Module(body=defs, type_ignores=[]), str(path), "exec"), ns)
    ns["__stubs__"] = {node.name for node in defs if isinstance(node, ast.FunctionDef) and _is_stub_node(node)}
    for name in ns["__stubs__"] & set(EXERCISES):   # a stub helper: the library's stands in, so that the student's
        ns[name] = _library(EXERCISES[name], "not written yet", True)      # function that calls it stays theirs
    return ns


def load(name, *, quiet=False):
    """The student's function from the notebook where they wrote it (as last saved), else the library's.

    Parameters
    ----------
    name : str
        An exercise in :data:`EXERCISES`, e.g. ``"eight_point"``.
    quiet : bool
        No line printed.

    Returns
    -------
    f : callable
        As :func:`pick`.
    """
    exercise = _exercise(name)
    path = folder() / f"{exercise.notebook}.ipynb"
    if not path.is_file():
        return _library(exercise, f"{path.name} is not in {folder()}", quiet)
    try:
        ns = _namespace(str(path), path.stat().st_mtime_ns)
    except Exception as err:                        # noqa: BLE001 — the student's cells, whatever they raise
        return _library(exercise, f"the solution cells of {path.name} do not run ({type(err).__name__}: {err})",
                        quiet)
    fn = ns.get(name)
    if not callable(fn):
        return _library(exercise, f"{path.name} defines no {name}", quiet)
    if name in ns["__stubs__"]:
        return _library(exercise, f"not written yet in {path.name}", quiet)
    if not quiet:
        print(f"{name}: yours, from {path.name}")
    return Yours(fn, exercise, quiet=quiet)


class _Spy:
    """Records the forbidden functions called while the target runs: the outermost ones only (what the hand-in itself
    called, not what they call in turn)."""

    def __init__(self, target, forbidden):
        self.target, self.calls, self.depth, self.inside = target, [], 0, []
        self.codes = {f.__code__: s for s, f in forbidden.items() if hasattr(f, "__code__")}
        self.builtins = {id(f): s for s, f in forbidden.items() if not hasattr(f, "__code__")}

    def __call__(self, frame, event, arg):
        if event == "call":
            if frame.f_code is self.target:
                self.depth += 1
            elif self.depth and frame.f_code in self.codes:
                if not self.inside:
                    self.calls.append(self.codes[frame.f_code])
                self.inside.append(frame)
        elif event == "return":
            if frame.f_code is self.target:
                self.depth -= 1
            elif self.inside and frame is self.inside[-1]:
                self.inside.pop()
        elif event == "c_call" and self.depth and not self.inside and id(arg) in self.builtins:
            self.calls.append(self.builtins[id(arg)])


def assert_own(fn, *args, name=None, **kwargs):
    """Run the student's ``fn(*args, **kwargs)`` once; fail if it calls the library's version of itself.

    Parameters
    ----------
    fn : callable
        The student's function (a :class:`Yours` wrapper is unwrapped).
    *args, **kwargs
        One call's arguments (the notebook's own data).
    name : str, optional
        The exercise in :data:`EXERCISES`; by default ``fn.__name__``.

    Returns
    -------
    result
        What ``fn`` returned.

    Raises
    ------
    AssertionError
        If, while ``fn`` ran, one of the exercise's references was called (directly or through other functions):
        the hand-in computes nothing itself.
    """
    fn = getattr(fn, "fn", fn)
    exercise = _exercise(fn.__name__ if name is None else name)
    code = getattr(fn, "__code__", None)
    if code is None:
        raise AssertionError(f"{exercise.name} must be a Python function written in the notebook")
    forbidden = {s: f for s in exercise.forbidden() if (f := _resolve(s)) is not None}
    spy = _Spy(code, forbidden)
    previous = sys.getprofile()
    sys.setprofile(spy)
    try:
        result = fn(*args, **kwargs)
    finally:
        sys.setprofile(previous)
    if spy.calls:
        called = ", ".join(dict.fromkeys(_label(c) for c in spy.calls))
        raise AssertionError(f"{exercise.name} calls {called}: that is the library's answer, not yours — "
                             f"write the algorithm itself")
    return result


def summary(names=None):
    """Which pieces are yours: rows ``(name, notebook, "yours" or "library: why")``, read as :func:`load` reads.

    Parameters
    ----------
    names : iterable of str, optional
        Exercises to report; by default all of :data:`EXERCISES`.

    Returns
    -------
    rows : list of tuple
    """
    rows = []
    for name in (EXERCISES if names is None else names):
        f = load(name, quiet=True)
        rows.append((name, EXERCISES[name].notebook, "yours" if f.is_yours else f"library: {f.why}"))
    return rows
