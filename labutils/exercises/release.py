"""The student edition of the notebooks, made by nbgrader's own preprocessors (issue 10).

The instructor notebooks carry nbgrader's cell metadata (solution cells, autograded test cells with points, locked
cells, manually graded answers; see :mod:`labutils.exercises`). The student edition of a notebook is what
``nbgrader generate_assignment`` makes of it: its preprocessors, in its order (:func:`student_preprocessors`), run
through nbconvert on each notebook — solutions replaced by stubs, hidden tests removed, outputs cleared, grade and
solution cells locked against deletion, checksums recorded, the metadata validated. Two differences, both
nbgrader's own switches:

- nothing is written to a gradebook database (``SaveCells`` is left out, as ``nbgrader generate_assignment
  --no-db`` does): a hand-out needs none, and a course that grades with nbgrader records its cells when it runs
  ``generate_assignment`` itself;
- the stub says what to write. nbgrader's ``ClearSolutions`` puts one fixed ``code_stub`` in every solution cell;
  :class:`NamedStubClearSolutions` hands it, cell by cell, a stub naming the function whose body the student
  writes: ``raise NotImplementedError("write the body of eight_point(x1, x2) here (see its docstring), ...")``.

Why the preprocessors rather than the ``GenerateAssignment`` converter: the converter works in a course directory
(``source/<assignment>/`` in, ``release/<assignment>/`` out, a gradebook beside it) and reports a bad notebook in
its log; run directly, the same preprocessors turn each notebook into text in memory, so that a bad cell fails
the command (one line naming the notebook and the cell) before anything is written. The output is byte for byte
what ``nbgrader generate_assignment`` writes with the same configuration (``tests/test_student_edition.py`` holds
it), and a course can give nbgrader the same stubs (``nbgrader_config.py``, see :func:`student_preprocessors`).

:func:`release_files` makes everything ``python -m labutils.exercises release OUTDIR`` writes: the student edition
of every notebook, a ``README.md`` for students and a ``requirements.txt`` (what to install: the workbook's
requirements without the developer tools; ``labutils`` itself comes from where the course says).
"""
import ast
import copy
import os
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import nbformat
from nbconvert.exporters import NotebookExporter
from nbgrader import utils as nbgrader_utils
from nbgrader.converters import GenerateAssignment
from nbgrader.nbgraderformat import ValidationError
from nbgrader.preprocessors import ClearSolutions, SaveCells
from traitlets.config import Config

__all__ = ["NamedStubClearSolutions", "NotebookContents", "code_stub", "notebook_contents", "release_files",
           "student_edition", "student_preprocessors", "student_readme", "student_requirements"]

DELIMITERS = {                      # nbgrader's default delimiters, the regions they open, the cells they belong in
    "solution": ("BEGIN SOLUTION", "END SOLUTION"),
    "hidden tests": ("BEGIN HIDDEN TESTS", "END HIDDEN TESTS"),
    "mark scheme": ("BEGIN MARK SCHEME", "END MARK SCHEME"),
}
README_MARK = "<!-- student edition: made by python -m labutils.exercises release -->"
REQUIREMENTS_MARK = "# student edition: made by python -m labutils.exercises release"
DEVELOPER_ONLY = {"nbval", "pytest", "pytest-xdist", "nbstripout", "ruff", "nbgrader"}    # the suite's tools


# ---------------------------------------------------------------------------------------------------------------
# the stub
# ---------------------------------------------------------------------------------------------------------------
def _enclosing_functions(source, begin):
    """``name(arg, ...)`` of the innermost function around each solution region of ``source``, in order (None for
    a region outside any function). ``begin`` is the opening delimiter."""
    lines = source.split("\n")
    starts = [k + 1 for k, line in enumerate(lines) if begin in line]          # 1-based, like ast
    try:
        functions = [n for n in ast.walk(ast.parse(source)) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    except SyntaxError:                                       # IPython syntax (magics): the nearest def above it
        out = []
        for s in starts:
            defs = [re.match(r"\s*(?:async\s+)?def\s+(\w+)", line) for line in lines[:s - 1]]
            names = [m.group(1) for m in defs if m]
            out.append(f"{names[-1]}(...)" if names else None)
        return out
    out = []
    for s in starts:
        around = [f for f in functions if f.lineno < s <= f.end_lineno]
        if not around:
            out.append(None)
            continue
        f = max(around, key=lambda f: f.lineno)
        a = f.args
        params = [p.arg for p in a.posonlyargs + a.args] + ([f"*{a.vararg.arg}"] if a.vararg else
                                                             (["*"] if a.kwonlyargs else []))
        params += [p.arg for p in a.kwonlyargs] + ([f"**{a.kwarg.arg}"] if a.kwarg else [])
        out.append(f"{f.name}({', '.join(params)})")
    return out


def code_stub(source, begin="BEGIN SOLUTION"):
    """The stub that replaces the solution regions of one solution cell: nbgrader's, with a message that says what
    to write.

    Parameters
    ----------
    source : str
        The instructor's cell.
    begin : str
        The delimiter that opens a solution region (``ClearSolutions.begin_solution_delimeter``).

    Returns
    -------
    str
        ``# YOUR CODE HERE`` and a ``raise NotImplementedError("...")`` naming the function (and its parameters)
        whose body the student writes, for nbgrader to indent like the region it replaces.

    Examples
    --------
    >>> print(code_stub('def double(x):\\n    \"\"\"2 x.\"\"\"\\n    ### BEGIN SOLUTION\\n    return 2 * x\\n'
    ...                 '    ### END SOLUTION'))
    # YOUR CODE HERE
    raise NotImplementedError("write the body of double(x) here (see its docstring), then run the self-check below")
    """
    names = list(dict.fromkeys(n for n in _enclosing_functions(source, begin) if n))
    if not names:
        what = "write your code here (see the exercise above)"
    elif len(names) == 1:
        what = f"write the body of {names[0]} here (see its docstring)"
    else:
        what = f"write the bodies of {', '.join(names[:-1])} and {names[-1]} here (see their docstrings)"
    return f'# YOUR CODE HERE\nraise NotImplementedError("{what}, then run the self-check below")'


class NamedStubClearSolutions(ClearSolutions):
    """nbgrader's ``ClearSolutions``, with a stub per cell that names the function to write (:func:`code_stub`).

    Everything else — which regions are replaced, the indentation, the text stub of written answers, the checks
    that a solution region sits in a solution cell — is nbgrader's own code.
    """

    def preprocess_cell(self, cell, resources, cell_index):
        if cell.cell_type != "code" or not nbgrader_utils.is_solution(cell):
            return super().preprocess_cell(cell, resources, cell_index)
        language = resources["language"]
        default = self.code_stub
        self.code_stub = {**default, language: code_stub(cell.source, self.begin_solution_delimeter)}
        try:
            return super().preprocess_cell(cell, resources, cell_index)
        finally:
            self.code_stub = default


def student_preprocessors(*, gradebook=False):
    """The preprocessors that make the student edition: ``GenerateAssignment``'s, in its order.

    Parameters
    ----------
    gradebook : bool
        Keep ``SaveCells``, which records the cells in nbgrader's gradebook database: for a course that runs
        ``nbgrader generate_assignment`` with these stubs. In its ``nbgrader_config.py``::

            from labutils.exercises.release import student_preprocessors
            c.GenerateAssignment.preprocessors = student_preprocessors(gradebook=True)

    Returns
    -------
    list of type
        nbgrader's list with ``ClearSolutions`` replaced by :class:`NamedStubClearSolutions` (and ``SaveCells``
        left out unless ``gradebook``).

    Examples
    --------
    >>> [p.__name__ for p in student_preprocessors()][:5]
    ['IncludeHeaderFooter', 'InstantiateTests', 'LockCells', 'NamedStubClearSolutions', 'ClearOutput']
    """
    chain = GenerateAssignment.class_traits()["preprocessors"].default()
    return [NamedStubClearSolutions if p is ClearSolutions else p for p in chain if gradebook or p is not SaveCells]


@lru_cache(maxsize=1)
def _exporter():
    config = Config()
    config.Exporter.default_preprocessors = []
    exporter = NotebookExporter(config=config)
    for preprocessor in student_preprocessors():
        exporter.register_preprocessor(preprocessor, enabled=True)
    return exporter


# ---------------------------------------------------------------------------------------------------------------
# checking the cells, and the student edition
# ---------------------------------------------------------------------------------------------------------------
def _check_cells(nb, name):
    """``ValueError`` naming the notebook and the cell for the mistakes nbgrader would report without the cell:
    unbalanced or nested delimiters, a region in a cell without the nbgrader metadata that clears it, a grade_id
    used twice."""
    seen = {}
    for k, cell in enumerate(nb.cells, 1):
        where = f"{name}, cell {k}"
        meta = cell.metadata.get("nbgrader", {})
        if meta:
            gid = meta.get("grade_id")
            if not gid:
                raise ValueError(f"{where}: nbgrader metadata without a grade_id")
            if gid in seen:
                raise ValueError(f"{where}: grade_id {gid!r} is used twice (also cell {seen[gid]}); nbgrader needs "
                                 "unique ids")
            seen[gid] = k
        for region, (begin, end) in DELIMITERS.items():
            depth = 0
            for line in cell.source.split("\n"):
                if begin in line:
                    if depth:
                        raise ValueError(f"{where}: a {region} region opens inside another ({begin!r} twice)")
                    depth = 1
                elif end in line:
                    if not depth:
                        raise ValueError(f"{where}: {end!r} without {begin!r} before it")
                    depth = 0
            if depth:
                raise ValueError(f"{where}: {begin!r} without {end!r}")
            opened = any(begin in line for line in cell.source.split("\n"))
            needs = {"solution": nbgrader_utils.is_solution, "hidden tests": nbgrader_utils.is_grade,
                     "mark scheme": nbgrader_utils.is_task}[region]
            if opened and not needs(cell):
                kind = {"solution": "a solution cell (nbgrader metadata solution: true)",
                        "hidden tests": "an autograded test cell (grade: true)",
                        "mark scheme": "a task cell (task: true)"}[region]
                raise ValueError(f"{where}: a {region} region in a cell that is not {kind}; the student edition "
                                 "would show it")


def student_edition(nb, name="notebook"):
    """The student edition of one instructor notebook, as nbgrader's preprocessors make it.

    Parameters
    ----------
    nb : nbformat.NotebookNode or str
        The instructor notebook (a node, or its JSON text). It is not changed.
    name : str
        Its name, for error messages.

    Returns
    -------
    str
        The student notebook, as the JSON text nbgrader writes.

    Raises
    ------
    ValueError
        Naming the notebook (and the cell where nbgrader's error does not): malformed JSON, a solution or hidden
        test region that is unbalanced or outside a cell with the metadata that clears it, a grade_id used twice,
        metadata nbgrader's validator refuses.

    Examples
    --------
    >>> nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(
    ...     "def f(x):\\n    ### BEGIN SOLUTION\\n    return x\\n    ### END SOLUTION",
    ...     metadata={"nbgrader": {"grade": False, "grade_id": "f", "locked": False, "schema_version": 3,
    ...                            "solution": True, "task": False}})])
    >>> print(nbformat.reads(student_edition(nb), as_version=4).cells[0].source)
    def f(x):
        # YOUR CODE HERE
        raise NotImplementedError("write the body of f(x) here (see its docstring), then run the self-check below")
    """
    if isinstance(nb, str):
        try:
            nb = nbformat.reads(nb, as_version=4)
        except Exception as exc:                  # nbformat raises several types for text that is not a notebook
            raise ValueError(f"{name}: not a notebook ({type(exc).__name__}: {str(exc).splitlines()[0]})") from None
    nb = copy.deepcopy(nb)
    _check_cells(nb, name)
    try:
        text, _ = _exporter().from_notebook_node(nb, resources={})
    except ValidationError as exc:
        first = str(exc).strip().splitlines()
        raise ValueError(f"{name}: nbgrader's metadata check refused it: {first[0] if first else exc!r}") from None
    except Exception as exc:                      # nbgrader reports its refusals as RuntimeError, ValueError, ...
        first = str(exc).strip().splitlines()
        raise ValueError(f"{name}: nbgrader refused it ({type(exc).__name__}: {first[0] if first else ''})") from None
    return text


@dataclass
class NotebookContents:
    """What a notebook asks of a student: its exercises (solution code cells), written questions (solution
    markdown cells), and the points of its autograded tests and questions."""

    exercises: list = field(default_factory=list)
    questions: list = field(default_factory=list)
    points: float = 0.0

    def text(self):
        """``"2 exercises, 1 written question, 7 points"``, or ``"no exercises"``."""
        if not (self.exercises or self.questions):
            return "no exercises"

        def n(k, word):
            return f"{k} {word}{'' if k == 1 else 's'}"
        return f"{n(len(self.exercises), 'exercise')}, {n(len(self.questions), 'written question')}, " \
               f"{self.points:g} points"


def notebook_contents(nb):
    """The :class:`NotebookContents` of a notebook (instructor or student edition: the metadata is the same).

    >>> notebook_contents(nbformat.v4.new_notebook()).text()
    'no exercises'
    """
    out = NotebookContents()
    for cell in nb.cells:
        meta = cell.metadata.get("nbgrader", {})
        if meta.get("solution") and cell.cell_type == "code":
            out.exercises.append(meta.get("grade_id"))
        elif meta.get("solution"):
            out.questions.append(meta.get("grade_id"))
        if meta.get("grade") or meta.get("task"):
            out.points += float(meta.get("points", 0) or 0)
    return out


# ---------------------------------------------------------------------------------------------------------------
# what goes beside the notebooks
# ---------------------------------------------------------------------------------------------------------------
def student_requirements(environment_text, labutils=None):
    """``requirements.txt`` for students: the workbook's ``environment.txt`` without the developer tools
    (:data:`DEVELOPER_ONLY`) and the editable install of the checkout, plus how to get ``labutils``.

    Parameters
    ----------
    environment_text : str
        The project's ``environment.txt``.
    labutils : str, optional
        A pip requirement for the package, e.g. ``"labutils @ git+https://github.com/ORG/REPO@v1"``; without it a
        comment says to install it as the course says.

    Examples
    --------
    >>> print(student_requirements("numpy>=1.26\\npytest>=8\\n# the checkout\\n-e .\\n", "labutils==0.1"))
    # student edition: made by python -m labutils.exercises release
    # pip install -r requirements.txt (in a fresh virtual environment), then: jupyter lab
    numpy>=1.26
    labutils==0.1
    """
    lines = [REQUIREMENTS_MARK, "# pip install -r requirements.txt (in a fresh virtual environment), then: jupyter lab"]
    for line in environment_text.splitlines():
        req = line.split("#")[0].strip()
        if req in ("-e .", "-e ./", "."):
            lines.append(labutils or "# labutils, the workbook's package: install it as your course says, e.g. "
                                     "pip install \"labutils @ git+https://<the workbook's repository>\"")
        elif req and re.match(r"[A-Za-z0-9_.\-]+", req).group(0).lower() in DEVELOPER_ONLY:
            continue
        elif req:                                    # the requirement (and its comment); not the file's comments
            lines.append(line.rstrip())
    return "\n".join(lines) + "\n"


def student_readme(rows):
    """``README.md`` for the students: setting up, the data, how an exercise works, what to hand in.

    Parameters
    ----------
    rows : list of (str, NotebookContents)
        Each notebook's file name and contents, in order.
    """
    table = "\n".join(f"| `{name}` | {c.text()} |" for name, c in rows)
    return f"""{README_MARK}
# 3D reconstruction workbook — student edition

Numbered notebooks that take you from two views to a bundle-adjusted reconstruction of a real object. Work through
them in order; each says at the top what you will learn and how long its core part takes.

| notebook | to do |
| --- | --- |
{table}

## Setting up

In a fresh virtual environment (`python3 -m venv .venv && source .venv/bin/activate`):

    pip install -r requirements.txt
    jupyter lab

`requirements.txt` installs JupyterLab and the workbook's package `labutils` (the estimators, data loaders and
plots the notebooks import). Where it has a comment instead of a `labutils` line, install `labutils` as your course
says.

**The data.** The notebooks use real data sets (the Oxford dinosaur and others). Choose a folder for them and fetch
them once:

    export LABUTILS_DATA=$HOME/workbook-data      # also in the shell you start jupyter lab from
    mkdir -p $LABUTILS_DATA
    python -m labutils.data fetch all             # python -m labutils.data list shows the sets and their sizes

Without the data every notebook still runs: it says so and uses a synthetic scene with known ground truth.

## How an exercise works

1. **Write the function.** An exercise cell holds a function with its docstring (shapes, conventions) and a body
   that raises `NotImplementedError("write the body of ... here")`. Replace those two lines by your code and run
   the cell.
2. **Run the self-check below it.** It tries your function on a few cases and prints `pass`, or a hint that names
   the likely mistake. Until you have written the function it says "not written yet".
3. **The autograded test cell** after it looks empty (a comment): its tests are hidden and run when your work is
   graded: the self-check's cases, and more. They also check that your function computes its answer itself: a
   body that calls the library's version of the same thing (`return fundamental_8point(x1, x2)`) gets no points.
4. **The notebook goes on with your function.** After the self-check one line says whose function the later cells
   use: `eight_point: yours`, or, while you have not written it, `not written yet: the library's ... stands in` —
   so you are never stuck. Later notebooks read your functions from the earlier notebooks *as you last saved them*
   in the same folder (`eight_point: yours, from 01_fundamental_matrix.ipynb`): keep the notebooks together and
   save after you change an exercise.

**Written questions** are cells that say `YOUR ANSWER HERE`: replace that text by your answer (Markdown and
equations are fine).

If your course uses nbgrader's *Validate* button: it cannot see the hidden tests, so it reports success even for an
exercise you have not written; the self-checks are what tell you how you are doing.

Do not delete, copy or split the exercise, test and answer cells, and do not edit the locked ones: the grader finds
them by their metadata, and restores the tests from its own copy. Add cells of your own anywhere you like.

## Before you hand in

Restart the kernel and run all cells (*Kernel → Restart Kernel and Run All Cells*): every cell must run without an
error, and every self-check should print `pass`. Hand in the notebooks (`.ipynb`) as your course says.
"""


def _environment_text(source):
    for folder in (Path(source).resolve().parent, Path(__file__).resolve().parents[2]):
        if (folder / "environment.txt").is_file():
            return (folder / "environment.txt").read_text(encoding="utf-8")
    return None


def _is_ours(path):
    """Whether an existing file in OUTDIR is from a student edition (so ``--force`` may replace it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    if path.suffix == ".ipynb":                       # a student notebook holds no solution or hidden test
        return not any(d in text for pair in DELIMITERS.values() for d in pair)
    return text.startswith(README_MARK if path.name == "README.md" else REQUIREMENTS_MARK)


def release_files(notebooks, outdir, *, force=False, labutils=None, progress=None):
    """Everything the student edition writes into ``outdir``: ``{path: text}``, checked before anything is written.

    Parameters
    ----------
    notebooks : list of path
        The instructor notebooks, in order.
    outdir : path
        The folder for the student edition (need not exist; its parent must).
    force : bool
        Replace the files of an earlier student edition in ``outdir`` (never an instructor notebook, nor a
        ``README.md`` or ``requirements.txt`` that a student edition did not write).
    labutils : str, optional
        The pip requirement students install ``labutils`` by (see :func:`student_requirements`).
    progress : labutils.core.cli.Progress, optional
        Stepped once per notebook.

    Returns
    -------
    files : dict {Path: str}
        The student notebooks (same file names), ``README.md`` and (when the project's ``environment.txt`` is
        found) ``requirements.txt``.
    rows : list of (str, NotebookContents)

    Raises
    ------
    ValueError
        One line naming the file: ``outdir`` unusable, holding files that are not to be replaced, or the instructor
        notebooks' own folder; a notebook that cannot be read or that nbgrader refuses.
    """
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise ValueError(f"{outdir}: exists and is not a folder")
    parent = outdir.resolve().parent
    if not outdir.exists() and not parent.is_dir():
        raise ValueError(f"{outdir}: its folder {parent} does not exist")
    if outdir.exists() and not os.access(outdir, os.W_OK | os.X_OK):
        raise ValueError(f"{outdir}: the folder is not writable")
    if not outdir.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{outdir}: cannot make it: {parent} is not writable")
    sources = {Path(p).resolve().parent for p in notebooks}
    if outdir.resolve() in sources:
        raise ValueError(f"{outdir}: is the folder of the instructor notebooks; the student edition goes elsewhere")
    env = _environment_text(notebooks[0]) if notebooks else None
    targets = [outdir / Path(p).name for p in notebooks] + [outdir / "README.md"]
    targets += [outdir / "requirements.txt"] if env is not None else []
    for target in targets:                                # before any work: what is there may not be replaced
        if target.exists():
            if target.is_dir():
                raise ValueError(f"{target}: is a folder")
            if not force:
                raise ValueError(f"{target}: already exists ({outdir} holds a student edition?); --force replaces it")
            if not _is_ours(target):
                raise ValueError(f"{target}: exists and is not from a student edition; not replacing it, even with "
                                 "--force")
    files, rows = {}, []
    for path in notebooks:
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: cannot read it ({getattr(exc, 'strerror', None) or exc})") from None
        student = student_edition(text, str(path))
        files[outdir / path.name] = student
        rows.append((path.name, notebook_contents(nbformat.reads(student, as_version=4))))
        if progress is not None:
            progress.step(note=path.name)
    files[outdir / "README.md"] = student_readme(rows)
    if env is not None:
        files[outdir / "requirements.txt"] = student_requirements(env, labutils)
    return files, rows
