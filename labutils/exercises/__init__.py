"""Exercises: the self-checks a student runs after writing a function, and the student edition.

The house convention for an exercise (every core notebook has at least two; every new notebook follows it
from its first commit):

1. **A solution cell** (nbgrader metadata ``solution: true``, a ``grade_id`` unique in the notebook) holds one
   function with a numpydoc docstring giving shapes and the convention, and the reference body between
   ``### BEGIN SOLUTION`` and ``### END SOLUTION``. The student edition (``python -m labutils.exercises
   release OUTDIR``, made by nbgrader's own preprocessors) replaces the body by a stub that raises
   ``NotImplementedError``.
2. **A visible self-check cell** right after it calls a check from this package, e.g.
   ``check_eight_point(eight_point)``: several cases (noise-free exactness, a random scene, an edge case),
   each printed as ``pass`` or a *specific hint* naming the likely mistake. A stub that is not written yet is
   reported as such; the cell never raises, so the student edition runs from top to bottom.
3. **An autograded test cell** (``grade: true``, ``locked: true``, with ``points``) whose only code is between
   ``### BEGIN HIDDEN TESTS`` and ``### END HIDDEN TESTS`` (plus a comment saying what is tested); hidden
   from the student edition, run by nbgrader's autograder and by nbval on the instructor notebooks.
4. **The notebook goes on with the library's implementation** and says so in a sentence, so a student who
   is stuck is never blocked.

At least one written question per notebook is a markdown cell with ``solution: true, grade: true`` and
``points`` (manually graded), whose model answer sits between ``### BEGIN SOLUTION`` / ``### END SOLUTION``.
Section headings say **(core)** or **(optional)**; the introduction gives a time estimate for the core.

This module holds the runner the checks share (:func:`run_checks`); each notebook's checks live in a module
of its own (``labutils.exercises.ex01_fundamental`` ...), so that a wrong answer can be tested against its
hint by the unit tests, without running the notebook.
"""
from dataclasses import dataclass, field

__all__ = ["CaseResult", "CheckReport", "run_checks", "up_to_sign_scale"]


@dataclass
class CaseResult:
    """One case of a self-check: its description, whether it passed, and the hint when it did not."""

    name: str
    passed: bool
    hint: str = ""


@dataclass
class CheckReport:
    """What :func:`run_checks` found: one :class:`CaseResult` per case.

    ``passed`` is True only when every case passed; ``written`` is False while the function is still the
    student edition's stub (it raised ``NotImplementedError``).
    """

    exercise: str
    cases: list = field(default_factory=list)
    written: bool = True

    @property
    def passed(self):
        return self.written and bool(self.cases) and all(c.passed for c in self.cases)

    @property
    def hints(self):
        """The hints of the cases that failed (empty when all passed)."""
        return [c.hint for c in self.cases if not c.passed]

    def text(self):
        """The report as printed: a heading, then one line per case."""
        if not self.written:
            return (f"self-check · {self.exercise}: not written yet — write the function's body (see its "
                    "docstring), run its cell, then this one. Meanwhile the notebook goes on with the library's "
                    "version.")
        lines = [f"self-check · {self.exercise}: "
                 + ("all cases pass" if self.passed else f"{len(self.hints)} of {len(self.cases)} cases fail")]
        for c in self.cases:
            hint = "" if c.passed else f"\n        hint: {c.hint}"
            lines.append(f"  {'pass' if c.passed else 'FAIL'}  {c.name}{hint}")
        return "\n".join(lines)


def run_checks(exercise, func, cases, *, verbose=True):
    """Run the cases of one exercise on a student's function and print pass or a hint for each.

    Parameters
    ----------
    exercise : str
        The exercise's name (the function the student writes).
    func : callable
        The student's function.
    cases : sequence of (str, callable)
        ``(description, case)``; ``case(func)`` returns None when the function passes, else a hint: a sentence
        naming the likely mistake ("your F has rank 3: enforce rank 2 after the SVD"). An exception raised by
        ``func`` inside a case becomes that case's hint (with its type and message); ``NotImplementedError``
        means the stub is not written yet, and no further case is run.
    verbose : bool
        Print the report (:meth:`CheckReport.text`).

    Returns
    -------
    CheckReport

    Examples
    --------
    >>> def double(x):
    ...     return x + x
    >>> cases = [("2 -> 4", lambda f: None if f(2) == 4 else f"f(2) = {f(2)}, expected 4"),
    ...          ("0 -> 0", lambda f: None if f(0) == 0 else "f(0) should be 0")]
    >>> run_checks("double", double, cases, verbose=False).passed
    True
    >>> report = run_checks("double", lambda x: x * 3, cases)
    self-check · double: 1 of 2 cases fail
      FAIL  2 -> 4
            hint: f(2) = 6, expected 4
      pass  0 -> 0
    """
    report = CheckReport(exercise)
    for name, case in cases:
        try:
            hint = case(func)
        except NotImplementedError:
            report.written = False
            break
        except Exception as exc:       # the student's code raised: that is the hint
            hint = f"raised {type(exc).__name__}: {exc}"
        report.cases.append(CaseResult(name, hint is None, "" if hint is None else str(hint)))
    if verbose:
        print(report.text())
    return report


def up_to_sign_scale(A, B):
    """Largest entry of ``A/‖A‖ ∓ B/‖B‖`` for the better sign: 0 when A and B agree up to scale and sign.

    F, E, H and homogeneous vectors are defined up to scale (and sign); this is the one way the workbook
    compares them.

    >>> up_to_sign_scale([[1.0, 2.0]], [[-2.0, -4.0]])
    0.0
    """
    import numpy as np

    A, B = np.asarray(A, float), np.asarray(B, float)
    A, B = A / np.linalg.norm(A), B / np.linalg.norm(B)
    return float(min(np.abs(A - B).max(), np.abs(A + B).max()))
